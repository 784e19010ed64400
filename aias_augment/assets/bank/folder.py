"""A bank folder: mesh files (``NNNN.glb``) and the ``bank.json`` index that says what each one is.

Written by ``aias-assets from-labels``, ``deform`` and ``reconstruct``; read by
:func:`aias_augment.assets.bank.lift.bank_paths` (``aias-augment --assets-bank``, ``InsertObjects(assets=...)``),
:class:`aias_augment.assets.bank.lift.LiftedAssets` and, per file, :func:`aias_augment.assets.asset.bank_entry_meta`.
The index is JSON, replaced atomically: a reader never sees half of it, and nothing in it can run.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from aias_augment.assets.asset import Asset, axis_rotation_to_z_up


def add_to_bank(folder: str | Path, asset: Asset, entry: dict) -> dict:
    """Write ``asset`` as the next free ``NNNN.glb`` of ``folder`` (glTF is y-up) and append ``entry`` (plus file,
    category, height) to its ``bank.json``, creating both when missing. Returns the entry written."""
    import trimesh

    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    index = folder / "bank.json"
    bank = json.loads(index.read_text()) if index.is_file() else {"report": {"assets": [], "rejected": {}}}
    taken = {e["file"] for e in bank["report"]["assets"]}
    k = len(taken)
    while f"{k:04d}.glb" in taken or (folder / f"{k:04d}.glb").exists():
        k += 1
    name = f"{k:04d}.glb"
    y_up = np.linalg.inv(axis_rotation_to_z_up("Y"))
    scene = trimesh.Scene()
    for i, m in enumerate(asset.meshes):
        c = m.copy()
        c.apply_transform(y_up)
        scene.add_geometry(c, geom_name=f"part{i}")
    scene.export(folder / name)
    full = {"file": name, "category": asset.category, "height_m": round(asset.height_m, 4), **entry}
    bank["report"]["assets"].append(full)
    bank.setdefault("category", asset.category)
    tmp = index.with_suffix(".json.tmp")
    tmp.write_text(json.dumps(bank, indent=1))
    tmp.replace(index)
    return full

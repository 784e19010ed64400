"""A bank folder: mesh files (``NNNN.glb``) and the ``bank.json`` index that says what each one is.

Written by ``aias-assets from-labels``, ``deform`` and ``reconstruct``; read by
:func:`aias_augment.assets.bank.lift.bank_paths` (``aias-augment --assets-bank``, ``InsertObjects(assets=...)``),
:class:`aias_augment.assets.bank.lift.LiftedAssets` and, per file, :func:`aias_augment.assets.asset.bank_entry_meta`.
The folder is a small database (:mod:`aias_augment.assets.bank.db`): unique names, appends that never overwrite, the
index replaced atomically under an exclusive lock; it is JSON, so nothing in it can run.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from aias_augment.assets.asset import Asset, axis_rotation_to_z_up


def glb_bytes(meshes) -> bytes:
    """The z-up ``meshes`` as one GLB (glTF is y-up), parts named ``part<i>``."""
    import trimesh

    y_up = np.linalg.inv(axis_rotation_to_z_up("Y"))
    scene = trimesh.Scene()
    for i, m in enumerate(meshes):
        c = m.copy()
        c.apply_transform(y_up)
        scene.add_geometry(c, geom_name=f"part{i}")
    return scene.export(file_type="glb")


def add_to_bank(folder: str | Path, asset: Asset, entry: dict) -> dict:
    """Append ``asset`` to the bank ``folder`` as its next free ``NNNN.glb`` with ``entry`` (plus file, category,
    height, sha256) in its ``bank.json``, creating both when missing
    (:func:`aias_augment.assets.bank.db.append_entry`: an identical entry already there is not added twice). Returns
    the entry as listed."""
    from aias_augment.assets.bank.db import append_entry

    full = {"category": asset.category, "height_m": round(asset.height_m, 4), **entry}
    listed, _ = append_entry(folder, glb_bytes(asset.meshes), full, header={"category": asset.category})
    return listed

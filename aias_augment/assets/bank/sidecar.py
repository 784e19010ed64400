"""Importer for any folder of meshes (OBJ, GLB/GLTF, PLY, ...) described by small YAML sidecars.

Each ``<stem>.<ext>`` mesh needs a ``<stem>.yaml`` beside it; unknown keys are errors. Example::

    category: traffic_cone      # taxonomy name (configs/taxonomy.yaml)
    height_m: 0.7               # real height: the model is scaled uniformly to it ...
    # scale: 0.01               # ... or metres per file unit (exactly one of height_m / scale)
    up_axis: Y                  # Y (default for OBJ/GLTF) or Z
    name: my cone
    licence: CC0
    creator: me
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import trimesh

from aias_augment.assets.asset import MESH_SUFFIXES, AssetError, axis_rotation_to_z_up, normalise_meshes
from aias_augment.assets.bank.catalog import CatalogRecord
from aias_augment.assets.bank.meshio import load_raw_parts, missing_obj_textures
from aias_augment.assets.bank.taxonomy import Taxonomy
from aias_augment.assets.bank.validate import repair_parts
from aias_augment.core.config import from_dict
from aias_augment.core.config_files import load_yaml_file

__all__ = ["Sidecar", "read_sidecar", "read_sidecar_records", "load_sidecar_parts"]


@dataclass(frozen=True)
class Sidecar:
    category: str
    height_m: float | None = None
    scale: float | None = None
    up_axis: str | None = None
    name: str | None = None
    licence: str = ""
    creator: str = ""

    def __post_init__(self):
        if (self.height_m is None) == (self.scale is None):
            raise ValueError("sidecar: give exactly one of height_m (real height) or scale (metres per unit)")
        for k in ("height_m", "scale"):
            v = getattr(self, k)
            if v is not None and not (np.isfinite(v) and v > 0):
                raise ValueError(f"sidecar: {k} must be positive and finite, got {v}")
        if self.up_axis is not None and self.up_axis.upper() not in ("X", "Y", "Z"):
            raise ValueError(f"sidecar: up_axis must be X, Y or Z, got {self.up_axis!r}")


def read_sidecar(path: str | Path) -> Sidecar:
    path = Path(path)
    data = load_yaml_file(path) or {}  # bounded: size, UTF-8, alias expansion (ConfigFileError, a ValueError)
    try:
        return from_dict(Sidecar, data, where=str(path))
    except (TypeError, ValueError, KeyError) as e:
        raise AssetError(f"{path}: {e}") from e


def read_sidecar_records(directory: str | Path, taxonomy: Taxonomy) -> tuple[list[CatalogRecord], list[str]]:
    """Records for every mesh with a sidecar in ``directory`` (recursive); meshes without one are reported."""
    directory = Path(directory)
    if not directory.is_dir():
        raise AssetError(f"sidecar folder not found: {directory}")
    records, skipped = [], []
    for mesh in sorted(p for p in directory.rglob("*") if p.suffix.lower() in MESH_SUFFIXES and p.is_file()):
        sc_path = mesh.with_suffix(".yaml")
        if not sc_path.is_file():
            skipped.append(f"{mesh}: no sidecar {sc_path.name}")
            continue
        try:
            sc = read_sidecar(sc_path)
        except AssetError as e:
            skipped.append(str(e))
            continue
        if sc.category not in taxonomy.categories:
            skipped.append(f"{sc_path}: category {sc.category!r} is not in the taxonomy")
            continue
        rel = mesh.relative_to(directory).as_posix()
        records.append(
            CatalogRecord(
                id=f"sidecar:{directory.name}/{rel}",
                name=sc.name or mesh.stem,
                category=sc.category,
                dimensions_m=None,
                importer="sidecar",
                source=str(mesh),
                licence=sc.licence,
                creator=sc.creator,
                params={"mesh": str(mesh), "height_m": sc.height_m, "scale": sc.scale, "up_axis": sc.up_axis},
            )
        )
    return records, skipped


def load_sidecar_parts(record: CatalogRecord) -> tuple[tuple[trimesh.Trimesh, ...], list[str]]:
    mesh = Path(record.params["mesh"])
    notes = [f"missing texture {t}: diffuse colour used" for t in missing_obj_textures(mesh)]
    parts, rep = repair_parts(load_raw_parts(mesh), where=str(mesh))
    up = record.params.get("up_axis") or ("Y" if mesh.suffix.lower() in {".obj", ".gltf", ".glb"} else "Z")
    R = axis_rotation_to_z_up(up)
    for p in parts:
        p.apply_transform(R)
    if record.params.get("scale") is not None:
        s = float(record.params["scale"])
    else:
        b = np.array([p.bounds for p in parts])
        h = b[:, 1, 2].max() - b[:, 0, 2].min()
        if not np.isfinite(h) or h <= 0:
            raise AssetError(f"{mesh}: zero height along the up axis {up}; wrong up_axis?")
        s = float(record.params["height_m"]) / h
    for p in parts:
        p.apply_scale(s)
    return normalise_meshes(parts), notes + rep

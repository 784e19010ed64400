"""Importer for gazebo model folders (``model.sdf`` + ``meshes/``), built on :func:`aias_augment.assets.asset.load_asset`,
which applies the ``<scale>`` of ``model.sdf`` and the COLLADA ``<unit meter=...>``; the parts are then repaired."""

from __future__ import annotations

import xml.etree.ElementTree as ET
from pathlib import Path

import trimesh

from aias_augment.assets.asset import AssetError, gazebo_visual_mesh, load_asset, normalise_meshes
from aias_augment.assets.bank.catalog import CatalogRecord
from aias_augment.assets.bank.meshio import load_raw_parts, missing_obj_textures
from aias_augment.assets.bank.taxonomy import Taxonomy
from aias_augment.assets.bank.validate import repair_parts
from aias_augment.core.config import data_root

__all__ = ["IMPORTER_VERSION", "default_gazebo_dir", "find_gazebo_models", "read_gazebo_records", "load_gazebo_parts"]

GAZEBO_LICENCE = "CC-BY-3.0 (osrf/gazebo_models)"
IMPORTER_VERSION = 2  # 2: OBJ models keep their UVs and find their textures in materials/textures


def default_gazebo_dir() -> Path:
    return data_root() / "meshes" / "gazebo_models"


def find_gazebo_models(directory: str | Path) -> list[Path]:
    d = Path(directory)
    return sorted(p.parent for p in d.glob("*/model.sdf")) if d.is_dir() else []


def _display_name(model_dir: Path) -> str:
    """Human name for classification: the folder name without the ``drc_practice_`` prefix, underscores as spaces."""
    return model_dir.name.removeprefix("drc_practice_").replace("_", " ")


def _author(model_dir: Path) -> str:
    cfg = model_dir / "model.config"
    try:
        el = ET.parse(cfg).getroot().find(".//author/name")
        return (el.text or "").strip() if el is not None else ""
    except (ET.ParseError, OSError):
        return ""


def read_gazebo_records(directory: str | Path, taxonomy: Taxonomy) -> list[CatalogRecord]:
    """One record per model folder; the size is only known once imported (``dimensions_m`` None until then)."""
    out = []
    for d in find_gazebo_models(directory):
        name = _display_name(d)
        licence = GAZEBO_LICENCE if (d.parent / "LICENSE").exists() else ""
        out.append(
            CatalogRecord(
                id=f"gazebo:{d.name}",
                name=name,
                category=taxonomy.classify(name),
                dimensions_m=None,
                importer="gazebo",
                source=str(d),
                licence=licence,
                creator=_author(d),
                params={"model_dir": str(d)},
            )
        )
    return out


def load_gazebo_parts(record: CatalogRecord) -> tuple[tuple[trimesh.Trimesh, ...], list[str]]:
    """COLLADA models through ``load_asset`` (sdf scale x COLLADA unit); OBJ models through the bank's raw reader
    with the same sdf scale and gazebo's z-up, because ``load_mesh_file`` loses OBJ UVs (see ``meshio``)."""
    model_dir = Path(record.params["model_dir"])
    try:
        mesh_path, sdf_scale = gazebo_visual_mesh(model_dir)
        if mesh_path.suffix.lower() == ".obj":
            tex_dirs = (model_dir / "materials" / "textures",)
            notes = [f"missing texture {t}: diffuse colour used" for t in missing_obj_textures(mesh_path, tex_dirs)]
            parts, rep = repair_parts(load_raw_parts(mesh_path, tex_dirs), where=str(mesh_path))
            for p in parts:
                p.apply_scale(sdf_scale)  # gazebo meshes are in the model's z-up frame: no axis change
            return normalise_meshes(parts), notes + rep
        asset = load_asset(model_dir, category=record.category, name=record.name)
    except (ET.ParseError, OSError) as e:
        raise AssetError(f"{record.source}: unreadable gazebo model ({type(e).__name__}: {e})") from e
    parts, notes = repair_parts(list(asset.meshes), where=record.source)
    return normalise_meshes(parts), notes

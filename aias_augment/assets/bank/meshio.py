"""Raw mesh reading for the importers: every part with its material, no checks (those live in ``validate``).

Why not ``assets.load_mesh_file``: it rejects non-finite vertices before the validator can repair them, and
the importers need every part with its raw material.
"""

from __future__ import annotations

import logging
import re
from pathlib import Path

import numpy as np
import trimesh

from aias_augment.assets.asset import MESH_SUFFIXES, AssetError, scene_parts
from aias_augment.assets.references import ConfinedResolver

log = logging.getLogger(__name__)

__all__ = ["load_raw_parts", "missing_obj_textures", "part_texture_image", "part_base_color"]


class _SearchResolver(ConfinedResolver):
    """Finds referenced files (MTL, textures) inside the mesh's folder, else by base name in extra folders (gazebo
    keeps textures in ``materials/textures`` and names them ``model://<model>/...``)."""

    def __init__(self, mesh_path: Path, search_dirs: tuple[Path, ...]):
        super().__init__(mesh_path)
        self.search_dirs = search_dirs

    def get(self, name: str) -> bytes:
        try:
            return super().get(name)
        except Exception:  # noqa: BLE001 - fall back to the search folders below
            base = Path(name.replace("\\", "/").split("model://", 1)[-1]).name
            for d in self.search_dirs:
                if (d / base).is_file():
                    return (d / base).read_bytes()
            raise


def _find_texture(name: str, mtl_dir: Path, search_dirs: tuple[Path, ...]) -> bool:
    if (mtl_dir / name.replace("\\", "/")).is_file():
        return True
    base = Path(name.replace("\\", "/").split("model://", 1)[-1]).name
    return any((d / base).is_file() for d in search_dirs)


def load_raw_parts(path: str | Path, search_dirs: tuple[Path, ...] = ()) -> list[trimesh.Trimesh]:
    """All triangle parts of a mesh file in file units and axes (scene graph transforms applied), one per material.

    ``search_dirs``: extra folders where referenced textures are looked up by base name."""
    path = Path(path)
    if not path.is_file():
        raise AssetError(f"mesh file not found: {path}")
    if path.suffix.lower() not in MESH_SUFFIXES:
        raise AssetError(f"{path}: unsupported mesh format {path.suffix!r} (supported: {sorted(MESH_SUFFIXES)})")
    from aias_augment.assets.references import check_gltf_references

    if path.suffix.lower() in (".gltf", ".glb"):
        check_gltf_references(path)  # external files only from the asset's own folder
    try:
        if search_dirs:
            with open(path, "rb") as f:
                loaded = trimesh.load(
                    f,
                    file_type=path.suffix.lower()[1:],
                    process=False,
                    resolver=_SearchResolver(path, tuple(search_dirs)),
                )
        else:
            loaded = trimesh.load(str(path), process=False, resolver=ConfinedResolver(path))
    except AssetError:
        raise
    except Exception as e:  # trimesh raises many types for broken files
        raise AssetError(f"{path}: failed to load ({type(e).__name__}: {e})") from e
    parts = scene_parts(loaded, path)
    if not parts:
        raise AssetError(f"{path}: contains no triangle meshes")
    return parts


_MAP_RE = re.compile(r"^\s*map_Kd\s+(?:-\S+\s+\S+\s+)*(.+?)\s*$", re.IGNORECASE)


def missing_obj_textures(obj_path: str | Path, search_dirs: tuple[Path, ...] = ()) -> list[str]:
    """Diffuse texture files named by an OBJ's MTL libraries that do not exist (an unreadable MTL counts too)."""
    obj_path = Path(obj_path)
    missing = []
    if obj_path.suffix.lower() != ".obj":
        return missing
    with open(obj_path, "rb") as f:
        libs = [
            ln.split(None, 1)[1].decode("utf-8", "replace").strip()
            for ln in f
            if ln.startswith(b"mtllib") and len(ln.split(None, 1)) == 2
        ]
    for lib in libs:
        mtl = obj_path.parent / lib
        if not mtl.is_file():
            missing.append(lib)
            continue
        for ln in mtl.read_text(errors="replace").splitlines():
            m = _MAP_RE.match(ln)
            if m and not _find_texture(m.group(1), mtl.parent, tuple(search_dirs)):
                missing.append(m.group(1))
    return missing


def part_texture_image(part: trimesh.Trimesh):
    """The part's diffuse texture (PIL image) or None."""
    mat = getattr(part.visual, "material", None)
    if mat is None:
        return None
    img = getattr(mat, "image", None)
    if img is None:
        img = getattr(mat, "baseColorTexture", None)
    return img


def part_base_color(part: trimesh.Trimesh) -> np.ndarray:
    """RGBA uint8 base colour of the part's material (white when it has none)."""
    mat = getattr(part.visual, "material", None)
    col = None
    if mat is not None:
        col = getattr(mat, "diffuse", None)
        if col is None:
            col = getattr(mat, "baseColorFactor", None)
    if col is None:
        return np.array([255, 255, 255, 255], np.uint8)
    col = np.asarray(col)
    is_float = np.issubdtype(col.dtype, np.floating)  # float factors are in [0, 1], integer colours in [0, 255]
    col = col.astype(np.float64).ravel()
    if col.size == 3:
        col = np.r_[col, 1.0 if is_float else 255.0]
    if is_float:
        col = col * 255.0
    return np.clip(np.round(col[:4]), 0, 255).astype(np.uint8)

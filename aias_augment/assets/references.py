"""A mesh file reads nothing outside its own folder: external references (glTF buffer and image URIs, OBJ material
libraries and textures) must resolve inside the folder that holds the file.

- :func:`check_gltf_references` reads a glTF's JSON (or a GLB's JSON chunk) before the loader does and refuses, with
  an :class:`~aias_augment.assets.asset.AssetError` naming the file and the URI, any buffer or image URI that is not
  embedded (``data:``) and does not resolve, percent-decoded and with its links followed, to a path inside the folder
  (``../../etc/passwd``, ``/etc/passwd``, ``file:///...``, ``http://...``).
- :class:`ConfinedResolver` is the resolver handed to trimesh for every format: a name that resolves outside the
  folder is refused the same way, whatever loader asks for it.
"""

from __future__ import annotations

import json
import struct
from pathlib import Path
from urllib.parse import unquote, urlsplit

import trimesh

from aias_augment.assets.errors import AssetError

__all__ = ["ConfinedResolver", "check_gltf_references", "inside"]


def inside(folder: Path, name: str) -> Path | None:
    """The path ``name`` (relative to ``folder``) resolves to, or None when it lies outside ``folder``."""
    root = Path(folder).resolve()
    target = (root / name.replace("\\", "/")).resolve()
    return target if target == root or root in target.parents else None


def _gltf_json(path: Path) -> dict:
    data = path.read_bytes()
    if path.suffix.lower() == ".glb":
        if len(data) < 20 or data[:4] != b"glTF":
            raise AssetError(f"{path}: not a GLB file (no glTF header)")
        chunk_len, chunk_type = struct.unpack_from("<I4s", data, 12)
        if chunk_type != b"JSON" or 20 + chunk_len > len(data):
            raise AssetError(f"{path}: GLB without a readable JSON chunk")
        data = data[20 : 20 + chunk_len]
    try:
        doc = json.loads(data.decode("utf-8"))
    except (UnicodeDecodeError, ValueError) as e:
        raise AssetError(f"{path}: not a readable glTF ({type(e).__name__}: {e})") from None
    if not isinstance(doc, dict):
        raise AssetError(f"{path}: not a glTF document (its JSON is not an object)")
    return doc


def check_gltf_references(path: str | Path) -> None:
    """Refuse a glTF / GLB whose buffer or image URIs point outside its folder (module docstring)."""
    path = Path(path)
    doc = _gltf_json(path)
    for kind in ("buffers", "images"):
        items = doc.get(kind) or []
        for i, item in enumerate(items if isinstance(items, list) else []):
            uri = item.get("uri") if isinstance(item, dict) else None
            if uri is None:
                continue
            if not isinstance(uri, str):
                raise AssetError(f"{path}: {kind}[{i}].uri is not a string")
            if uri.startswith("data:"):
                continue
            parts = urlsplit(uri)
            if parts.scheme or parts.netloc or inside(path.parent, unquote(uri)) is None:
                raise AssetError(
                    f"{path}: {kind}[{i}] refers to {uri!r}, outside the asset's folder {path.parent}: refused "
                    "(keep the referenced files beside the asset, or embed them)"
                )


class ConfinedResolver(trimesh.resolvers.FilePathResolver):
    """trimesh's file resolver restricted to the mesh's folder (and ``extra_roots``)."""

    def __init__(self, mesh_path: str | Path, extra_roots: tuple[Path, ...] = ()):
        super().__init__(str(mesh_path))
        self.mesh_path = Path(mesh_path)
        self.roots = (Path(self.parent), *extra_roots)

    def get(self, name: str) -> bytes:
        name = unquote(str(name).strip())
        for root in self.roots:
            target = inside(root, name)
            if target is not None and target.is_file():
                return target.read_bytes()
        if all(inside(root, name) is None for root in self.roots):
            raise AssetError(f"{self.mesh_path}: refers to {name!r}, outside the asset's folder: refused")
        raise FileNotFoundError(f"{self.mesh_path}: referenced file {name!r} not found")

"""Cache of normalised meshes: one ``.npz`` per asset under the cache dir (never inside the repository).

Cache dir: ``$AIAS_CACHE`` or ``~/.cache/aias_augment``. An entry's key hashes the record id with a stamp of its
source (file size, mtime, importer version), so editing a source file or the importer invalidates it. Entries are
written to a temp file and renamed, so a killed import leaves no half entry. Textures are stored encoded (JPEG for
opaque, PNG with alpha) and decoded lazily when the renderer first reads them.
"""

from __future__ import annotations

import hashlib
import io
import json
import os
from pathlib import Path

import numpy as np
import trimesh
from PIL import Image

from aias_augment.assets.bank.meshio import part_base_color, part_texture_image

__all__ = ["default_cache_dir", "MeshCache", "source_stamp", "CACHE_FORMAT"]

CACHE_FORMAT = 3
MAX_TEXTURE_SIDE = (
    2048  # larger textures are downscaled (noted by the importer): a thumbnail-to-HD object never needs more
)


def default_cache_dir() -> Path:
    env = os.environ.get("AIAS_CACHE")
    return Path(env) if env else Path.home() / ".cache" / "aias_augment"


def source_stamp(path: str | Path, *extra) -> str:
    """Identity of a source file for cache invalidation: resolved path, size, mtime, plus importer details."""
    p = Path(path)
    st = p.stat()
    return json.dumps([str(p.resolve()), st.st_size, int(st.st_mtime), CACHE_FORMAT, *map(str, extra)])


def _encode_texture(img: Image.Image) -> tuple[bytes, bool]:
    """Encoded bytes and whether it was downscaled."""
    downscaled = max(img.size) > MAX_TEXTURE_SIDE
    if downscaled:
        s = MAX_TEXTURE_SIDE / max(img.size)
        img = img.resize((max(1, round(img.size[0] * s)), max(1, round(img.size[1] * s))), Image.Resampling.LANCZOS)
    buf = io.BytesIO()
    has_alpha = img.mode in ("RGBA", "LA") or (img.mode == "P" and "transparency" in img.info)
    if has_alpha:
        img.convert("RGBA").save(buf, format="PNG", compress_level=1)
    else:
        img.convert("RGB").save(buf, format="JPEG", quality=92)
    return buf.getvalue(), downscaled


class MeshCache:
    """Content-keyed store of normalised parts (vertices, faces, normals, UVs, colours, textures)."""

    def __init__(self, root: str | Path | None = None):
        self.root = Path(root) if root is not None else default_cache_dir()

    @staticmethod
    def key(record_id: str, stamp: str) -> str:
        return hashlib.sha1(f"{record_id}\n{stamp}".encode()).hexdigest()

    def path(self, key: str) -> Path:
        return self.root / "meshes" / key[:2] / f"{key}.npz"

    def has(self, key: str) -> bool:
        return self.path(key).is_file()

    def save(self, key: str, parts: list[trimesh.Trimesh], notes: list[str] = ()) -> bool:
        """Store parts and the import's repair notes; returns whether any texture had to be downscaled."""
        arrays: dict[str, np.ndarray] = {
            "count": np.array([len(parts)], np.int32),
            "rgba": np.stack([part_base_color(p) for p in parts]),
        }
        downscaled = False
        for i, p in enumerate(parts):
            arrays[f"v{i}"] = np.asarray(p.vertices, np.float32)
            arrays[f"f{i}"] = np.asarray(p.faces, np.int32)
            arrays[f"n{i}"] = np.asarray(p.vertex_normals, np.float32)
            img = part_texture_image(p)
            uv = getattr(p.visual, "uv", None)
            if img is not None and uv is not None and len(uv) == len(p.vertices):
                arrays[f"uv{i}"] = np.asarray(uv, np.float32)
                data, ds = _encode_texture(img)
                downscaled |= ds
                arrays[f"tex{i}"] = np.frombuffer(data, np.uint8)
            elif p.visual.kind in ("vertex", "face"):
                arrays[f"vc{i}"] = np.asarray(p.visual.vertex_colors, np.uint8)
        notes = list(notes) + (["texture downscaled to at most 2048 px"] if downscaled else [])
        arrays["notes"] = np.frombuffer(json.dumps(notes).encode(), np.uint8)
        path = self.path(key)
        path.parent.mkdir(parents=True, exist_ok=True)
        tmp = path.with_name(path.name + f".tmp{os.getpid()}")
        with open(tmp, "wb") as f:
            np.savez(f, **arrays)
        os.replace(tmp, path)
        return downscaled

    def load(self, key: str) -> tuple[tuple[trimesh.Trimesh, ...], list[str]] | None:
        """The cached parts and their repair notes, or None on a miss or an unreadable entry (then deleted)."""
        path = self.path(key)
        if not path.is_file():
            return None
        try:
            with np.load(path) as z:
                data = {k: z[k] for k in z.files}
            if "count" not in data or "notes" not in data:
                raise ValueError("incomplete cache entry")
        except Exception:  # truncated/corrupt entry: treat as a miss and rebuild
            path.unlink(missing_ok=True)
            return None
        parts = []
        for i in range(int(data["count"][0])):
            rgba = data["rgba"][i]
            if f"tex{i}" in data:
                img = Image.open(io.BytesIO(data[f"tex{i}"].tobytes()))
                visual = trimesh.visual.TextureVisuals(
                    uv=data[f"uv{i}"], material=trimesh.visual.material.SimpleMaterial(image=img, diffuse=rgba)
                )
            elif f"vc{i}" in data:
                visual = trimesh.visual.ColorVisuals(vertex_colors=data[f"vc{i}"])
            else:
                visual = trimesh.visual.TextureVisuals(material=trimesh.visual.material.SimpleMaterial(diffuse=rgba))
            parts.append(
                trimesh.Trimesh(
                    data[f"v{i}"].astype(np.float64),
                    data[f"f{i}"].astype(np.int64),
                    vertex_normals=data[f"n{i}"],
                    visual=visual,
                    process=False,
                )
            )
        return tuple(parts), json.loads(data["notes"].tobytes().decode())

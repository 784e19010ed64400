"""Validation and repair of imported meshes: every repair is noted, every rejection raises with its reason.

Repaired (with a note): faces touching non-finite vertices (when few), degenerate faces (repeated index or zero
area), a texture without UVs or with non-finite UVs (the texture's mean colour replaces it), empty parts.
Rejected (:class:`AssetError`): no triangles left, face indices out of range, many non-finite vertices, absurd size
for the category (outside ``[lo / factor, hi * factor]`` of the taxonomy's height range) or for anything at all.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import trimesh

from aias_augment.assets.asset import AssetError
from aias_augment.assets.bank.meshio import part_base_color, part_texture_image

__all__ = ["ValidationLimits", "repair_parts", "check_size"]


@dataclass(frozen=True)
class ValidationLimits:
    max_nonfinite_face_fraction: float = 0.05  # above: reject rather than cut a visible hole
    rel_area_eps: float = 1e-14  # face area below eps * bbox_diag^2 counts as degenerate
    min_height_m: float = 1e-3  # anything: 1 mm .. 100 m
    max_height_m: float = 100.0
    category_size_factor: float = 3.0  # allowed slack around the category's height range
    max_triangles: int = 3_000_000


def _mean_texture_colour(img, base: np.ndarray) -> np.ndarray:
    arr = np.asarray(img.convert("RGB"), dtype=np.float64)
    mean = arr.reshape(-1, 3).mean(0) * base[:3] / 255.0
    return np.r_[np.clip(np.round(mean), 0, 255), base[3]].astype(np.uint8)


def _plain_part(part: trimesh.Trimesh, rgba: np.ndarray) -> trimesh.Trimesh:
    mat = trimesh.visual.material.SimpleMaterial(diffuse=rgba)
    return trimesh.Trimesh(
        part.vertices,
        part.faces,
        vertex_normals=part.vertex_normals,
        visual=trimesh.visual.TextureVisuals(material=mat),
        process=False,
    )


def _repair_one(
    part: trimesh.Trimesh, where: str, limits: ValidationLimits, notes: list[str]
) -> trimesh.Trimesh | None:
    v = np.asarray(part.vertices, dtype=np.float64)
    f = np.asarray(part.faces)
    if f.size == 0:
        notes.append("dropped an empty part")
        return None
    if f.min() < 0 or f.max() >= len(v):
        raise AssetError(f"{where}: face index out of range (max {int(f.max())}, {len(v)} vertices)")
    bad_v = ~np.all(np.isfinite(v), axis=1)
    keep = np.ones(len(f), bool)
    if bad_v.any():
        touched = bad_v[f].any(axis=1)
        frac = touched.mean()
        if frac > limits.max_nonfinite_face_fraction:
            raise AssetError(
                f"{where}: non-finite vertex coordinates in {100 * frac:.1f}% of faces "
                f"({int(bad_v.sum())} vertices); refusing to repair more than "
                f"{100 * limits.max_nonfinite_face_fraction:.0f}%"
            )
        keep &= ~touched
        notes.append(f"removed {int(touched.sum())} faces with non-finite vertices")
    repeated = (f[:, 0] == f[:, 1]) | (f[:, 1] == f[:, 2]) | (f[:, 0] == f[:, 2])
    vf = np.where(bad_v[:, None], 0.0, v)  # finite copy; faces touching bad vertices are already dropped
    good = vf[~bad_v]
    diag2 = float(np.sum((good.max(0) - good.min(0)) ** 2)) if len(good) else 0.0
    area2 = np.sum(np.cross(vf[f[:, 1]] - vf[f[:, 0]], vf[f[:, 2]] - vf[f[:, 0]]) ** 2, axis=1)  # (2 area)^2
    tiny = area2 <= (2 * limits.rel_area_eps * diag2) ** 2
    degenerate = (repeated | tiny) & keep
    if degenerate.any():
        keep &= ~degenerate
        notes.append(f"removed {int(degenerate.sum())} degenerate faces")
    if not keep.all():
        part = part.copy()
        part.update_faces(keep)
        part.remove_unreferenced_vertices()
    if len(part.faces) == 0:
        notes.append("dropped a part with only degenerate faces")
        return None
    img = part_texture_image(part)
    uv = getattr(part.visual, "uv", None)
    if img is not None:
        uv_ok = uv is not None and len(uv) == len(part.vertices) and np.all(np.isfinite(uv))
        if not uv_ok:
            rgba = _mean_texture_colour(img, part_base_color(part))
            notes.append("texture without valid UVs replaced by its mean colour")
            return _plain_part(part, rgba)
    return part


def repair_parts(
    parts: list[trimesh.Trimesh], *, where: str, limits: ValidationLimits = ValidationLimits()
) -> tuple[list[trimesh.Trimesh], list[str]]:
    """Repair what can be repaired; raise :class:`AssetError` (reason in the message) for the rest."""
    notes: list[str] = []
    out = [p for p in (_repair_one(p, where, limits, notes) for p in parts) if p is not None]
    if not out:
        raise AssetError(f"{where}: no usable triangles (all faces degenerate or empty)")
    n = sum(len(p.faces) for p in out)
    if n > limits.max_triangles:
        raise AssetError(f"{where}: {n} triangles exceeds the limit of {limits.max_triangles}")
    return out, notes


def check_size(
    extents_m: np.ndarray,
    category: str,
    height_range_m: tuple[float, float],
    *,
    where: str,
    limits: ValidationLimits = ValidationLimits(),
) -> None:
    """Reject an absurd scale: height outside [min, max] or far outside the category's real height range."""
    ext = np.asarray(extents_m, dtype=np.float64)
    if ext.shape != (3,) or not np.all(np.isfinite(ext)) or ext.max() <= 0:
        raise AssetError(f"{where}: degenerate extents {ext}")
    h = float(ext[2])
    if not (limits.min_height_m <= h <= limits.max_height_m):
        raise AssetError(
            f"{where}: absurd height {h:.4g} m (allowed {limits.min_height_m}..{limits.max_height_m} m); wrong units?"
        )
    lo, hi = height_range_m
    k = limits.category_size_factor
    if not (lo / k <= h <= hi * k):
        raise AssetError(
            f"{where}: height {h:.3g} m is absurd for category {category!r} (real range {lo}..{hi} m, "
            f"x{k} slack); wrong units or wrong category?"
        )

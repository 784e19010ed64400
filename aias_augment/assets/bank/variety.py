"""Seeded variety: scale, colour and texture jitter that keeps an asset inside its category's real size range.

Choosing (:func:`sample_variety`, all randomness through the passed ``numpy.random.Generator``) is split from doing
(:func:`apply_variety`, pure and deterministic given the parameters), so a sample can be replayed from its record.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import cv2
import numpy as np
import trimesh
from PIL import Image

from aias_augment.assets.asset import Asset

__all__ = ["VarietyConfig", "VarietyParams", "sample_variety", "apply_variety", "scale_range"]


@dataclass(frozen=True)
class VarietyConfig:
    scale_jitter: float = 0.12  # relative: scale drawn in [1 - j, 1 + j] (then clipped to the category range)
    hue_shift_max: float = 0.02  # fraction of the colour circle; small so a cone stays orange
    saturation_gain_range: tuple[float, float] = (0.85, 1.15)
    value_gain_range: tuple[float, float] = (0.8, 1.15)

    def __post_init__(self):
        if not 0 <= self.scale_jitter < 1:
            raise ValueError(f"scale_jitter must be in [0, 1), got {self.scale_jitter}")
        if not 0 <= self.hue_shift_max <= 0.5:
            raise ValueError(f"hue_shift_max must be in [0, 0.5], got {self.hue_shift_max}")
        for name in ("saturation_gain_range", "value_gain_range"):
            lo, hi = getattr(self, name)
            if not 0 < lo <= hi:
                raise ValueError(f"{name} must satisfy 0 < lo <= hi, got {(lo, hi)}")


@dataclass(frozen=True)
class VarietyParams:
    scale: float
    hue_shift: float
    saturation_gain: float
    value_gain: float


def scale_range(height_m: float, height_range_m: tuple[float, float], jitter: float) -> tuple[float, float]:
    """Allowed uniform scale factors: [1 - j, 1 + j] intersected with what keeps the height in the category range.

    An asset already outside its category range (a sitting person is lower than a standing one) keeps [1 - j, 1 + j]
    clipped towards the range, never pushed across it: the catalog's real size wins over the category prior.
    """
    lo, hi = 1.0 - jitter, 1.0 + jitter
    rlo, rhi = height_range_m[0] / height_m, height_range_m[1] / height_m
    a, b = max(lo, rlo), min(hi, rhi)
    if a <= b:
        return a, b
    return (lo, min(hi, max(lo, rhi))) if rhi < lo else (max(lo, min(hi, rlo)), hi)


def sample_variety(
    height_m: float, height_range_m: tuple[float, float], cfg: VarietyConfig, rng: np.random.Generator
) -> VarietyParams:
    if not (np.isfinite(height_m) and height_m > 0):
        raise ValueError(f"height_m must be positive and finite, got {height_m}")
    a, b = scale_range(height_m, height_range_m, cfg.scale_jitter)
    return VarietyParams(
        scale=float(rng.uniform(a, b)),
        hue_shift=float(rng.uniform(-cfg.hue_shift_max, cfg.hue_shift_max)),
        saturation_gain=float(rng.uniform(*cfg.saturation_gain_range)),
        value_gain=float(rng.uniform(*cfg.value_gain_range)),
    )


def _jitter_rgb_uint8(rgb: np.ndarray, p: VarietyParams) -> np.ndarray:
    """HSV jitter of (..., 3) uint8 RGB colours: hue rotated (wraps), saturation and value scaled and clipped.

    Same maths as colorsys.rgb_to_hsv / hsv_to_rgb (tested against it), through OpenCV's float HSV for speed
    (a 2048 x 2048 texture takes milliseconds).
    """
    shape = rgb.shape
    x = np.ascontiguousarray(rgb.reshape(-1, 1, 3), dtype=np.float32) / 255.0
    hsv = cv2.cvtColor(x, cv2.COLOR_RGB2HSV)  # float input: H in degrees [0, 360), S and V in [0, 1]
    hsv[..., 0] = np.mod(hsv[..., 0] + 360.0 * p.hue_shift, 360.0)
    hsv[..., 1] = np.clip(hsv[..., 1] * p.saturation_gain, 0.0, 1.0)
    hsv[..., 2] = np.clip(hsv[..., 2] * p.value_gain, 0.0, 1.0)
    out = cv2.cvtColor(hsv, cv2.COLOR_HSV2RGB)
    return np.clip(np.round(out * 255.0), 0, 255).astype(np.uint8).reshape(shape)


def _jitter_part(m: trimesh.Trimesh, p: VarietyParams) -> trimesh.Trimesh:
    vis = m.visual
    if vis.kind in ("vertex", "face"):
        vc = np.array(vis.vertex_colors, np.uint8)
        vc[:, :3] = _jitter_rgb_uint8(vc[:, :3], p)
        return trimesh.Trimesh(
            m.vertices,
            m.faces,
            vertex_normals=m.vertex_normals,
            visual=trimesh.visual.ColorVisuals(vertex_colors=vc),
            process=False,
        )
    mat = getattr(vis, "material", None)
    if mat is None:
        return m.copy()
    from aias_augment.assets.bank.meshio import part_base_color, part_texture_image

    rgba = part_base_color(m).copy()
    rgba[:3] = _jitter_rgb_uint8(rgba[None, :3], p)[0]
    img = part_texture_image(m)
    uv = getattr(vis, "uv", None)
    if img is not None and uv is not None:
        arr = np.asarray(img.convert("RGBA"))
        rgb = _jitter_rgb_uint8(arr[..., :3], p)
        opaque = arr[..., 3].min() == 255
        img = Image.fromarray(np.ascontiguousarray(rgb) if opaque else np.dstack([rgb, arr[..., 3]]))
        new_mat = trimesh.visual.material.SimpleMaterial(image=img, diffuse=rgba)
        visual = trimesh.visual.TextureVisuals(uv=uv, material=new_mat)
    else:
        visual = trimesh.visual.TextureVisuals(material=trimesh.visual.material.SimpleMaterial(diffuse=rgba))
    return trimesh.Trimesh(m.vertices, m.faces, vertex_normals=m.vertex_normals, visual=visual, process=False)


def apply_variety(asset: Asset, p: VarietyParams) -> Asset:
    """A new asset: uniformly scaled about its contact point and colour-jittered (materials and textures)."""
    scaled = asset.scaled(p.scale)
    meshes = tuple(_jitter_part(m, p) for m in scaled.meshes)
    return Asset(
        asset.name,
        asset.category,
        meshes,
        asset.source,
        asset.licence,
        asset.procedural,
        {**scaled.meta, "variety": asdict(p)},
    )

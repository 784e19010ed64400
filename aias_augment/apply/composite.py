"""Compositing in linear light: differential shadows on the real ground, occlusion by scene depth, alpha blending.

All functions are pure: inputs are never modified.
"""

from __future__ import annotations

import numpy as np

from aias_augment.core.srgb import linear_to_srgb_uint8, srgb_to_linear

#: Relative depth margin (fraction of the object depth) inside which the scene is *not* considered in front of an
#: inserted surface: stereo/LiDAR depth is noisy and the object stands on the very surface it is compared with.
OCCLUSION_MARGIN_REL = 0.03


def visible_fraction_against_depth(
    object_depth: np.ndarray, scene_depth: np.ndarray | None, margin_rel: float = OCCLUSION_MARGIN_REL
) -> np.ndarray:
    """(H, W) float: 1 where the scene is not in front of the inserted surface, 0 where it is.

    Unknown scene depth (0, NaN, inf) never occludes.
    """
    if scene_depth is None:
        return np.ones_like(object_depth, dtype=np.float32)
    known = np.isfinite(scene_depth) & (scene_depth > 0)
    in_front = known & (object_depth > 0) & (scene_depth < object_depth * (1.0 - margin_rel))
    return (~in_front).astype(np.float32)


def apply_shadow(background_linear: np.ndarray, shadow_ratio: np.ndarray) -> np.ndarray:
    """Differential rendering on the real ground: multiply the photo's radiance by the rendered ratio
    (ground with the object / ground without it), which is 1 outside the shadow."""
    return background_linear * np.clip(shadow_ratio, 0.0, 1.0)[..., None]


def alpha_over(background_linear: np.ndarray, foreground_linear: np.ndarray, alpha: np.ndarray) -> np.ndarray:
    a = np.clip(alpha, 0.0, 1.0)[..., None]
    return foreground_linear * a + background_linear * (1.0 - a)


#: ``srgb_to_linear(k / 255)`` for the 256 uint8 levels: :func:`to_linear` is a table lookup with the same values.
_SRGB_TO_LINEAR_U8 = srgb_to_linear(np.arange(256, dtype=np.float32) / np.float32(255.0))


def to_linear(image_rgb_uint8: np.ndarray) -> np.ndarray:
    """uint8 sRGB -> float32 linear: ``srgb_to_linear(image / 255)``, by table lookup (the same values; a float
    input is converted as before)."""
    if image_rgb_uint8.dtype == np.uint8:
        return np.take(_SRGB_TO_LINEAR_U8, image_rgb_uint8)
    return srgb_to_linear(image_rgb_uint8.astype(np.float32) / 255.0)


def to_uint8(image_linear: np.ndarray) -> np.ndarray:
    """float linear -> uint8 sRGB: ``round(linear_to_srgb(x) * 255)``."""
    return linear_to_srgb_uint8(image_linear)

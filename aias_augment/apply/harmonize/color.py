"""Colour-space helpers shared by the harmonizers: sRGB <-> linear light, luminance, uint8 <-> float.

Convention: float images are (..., 3) RGB in [0, 1]; "linear" means linear-light sRGB primaries (IEC 61966-2-1).
"""

from __future__ import annotations

import numpy as np

from aias_augment.core.srgb import linear_to_srgb, srgb_to_linear  # noqa: F401  (the harmonizers' names)

# Rec.709 / sRGB luminance weights for linear RGB.
LUMA_WEIGHTS = np.array([0.2126, 0.7152, 0.0722], dtype=np.float32)


def to_float(image_uint8: np.ndarray) -> np.ndarray:
    return image_uint8.astype(np.float32) / 255.0


def to_uint8(image_float: np.ndarray) -> np.ndarray:
    """[0, 1] float -> uint8 with rounding; NaN is mapped to 0 so nothing non-finite leaves."""
    img = np.nan_to_num(image_float, nan=0.0, posinf=1.0, neginf=0.0)
    return np.clip(np.rint(img * 255.0), 0, 255).astype(np.uint8)


def luminance(rgb: np.ndarray) -> np.ndarray:
    return rgb @ LUMA_WEIGHTS

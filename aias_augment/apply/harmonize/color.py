"""Colour-space helpers shared by the harmonizers: sRGB <-> linear light, luminance, uint8 <-> float.

Convention: float images are (..., 3) RGB in [0, 1]; "linear" means linear-light sRGB primaries (IEC 61966-2-1).
"""

from __future__ import annotations

import numpy as np

# Rec.709 / sRGB luminance weights for linear RGB.
LUMA_WEIGHTS = np.array([0.2126, 0.7152, 0.0722], dtype=np.float32)


def to_float(image_uint8: np.ndarray) -> np.ndarray:
    return image_uint8.astype(np.float32) / 255.0


def to_uint8(image_float: np.ndarray) -> np.ndarray:
    """[0, 1] float -> uint8 with rounding; NaN is mapped to 0 so nothing non-finite leaves."""
    img = np.nan_to_num(image_float, nan=0.0, posinf=1.0, neginf=0.0)
    return np.clip(np.rint(img * 255.0), 0, 255).astype(np.uint8)


def srgb_to_linear(srgb: np.ndarray) -> np.ndarray:
    x = np.clip(srgb, 0.0, 1.0)
    return np.where(x <= 0.04045, x / 12.92, ((x + 0.055) / 1.055) ** 2.4).astype(np.float32)


def linear_to_srgb(linear: np.ndarray) -> np.ndarray:
    x = np.clip(linear, 0.0, 1.0)
    return np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1.0 / 2.4) - 0.055).astype(np.float32)


def luminance(rgb: np.ndarray) -> np.ndarray:
    return rgb @ LUMA_WEIGHTS

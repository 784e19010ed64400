"""The sRGB transfer curve of IEC 61966-2-1, the package's one implementation: decoding (sRGB-encoded values to
linear light) and encoding, element-wise.

- Input: uint8 (divided by 255) or float; values are clipped to [0, 1] with NaN counted as 0 (``fmax``/``fmin``
  ignore NaN), so nothing non-finite comes out.
- The arithmetic and the result are in ``dtype`` (float32 by default; float64 where a caller keeps double precision).
- The curve: decode ``v / 12.92`` up to 0.04045, else ``((v + 0.055) / 1.055) ** 2.4``; encode ``12.92 v`` up to
  0.0031308, else ``1.055 v ** (1 / 2.4) - 0.055``; uint8 input is decoded through a 256-entry table of those values
  (``cv2.LUT``). OpenCV and PIL have no sRGB curve, and the colour libraries
  that do (colour-science, kornia) are not dependencies.
"""

from __future__ import annotations

import functools

import cv2
import numpy as np

__all__ = ["srgb_to_linear", "linear_to_srgb", "linear_to_srgb_uint8"]


def _unit(values, dtype) -> np.ndarray:
    """``values`` as a new ``dtype`` array in [0, 1]: uint8 / 255, NaN -> 0, clipped."""
    a = np.asarray(values)
    out = np.empty(a.shape, dtype)  # written through out=: a 0-d input stays an array
    if a.dtype == np.uint8:
        out[...] = a
        out /= dtype(255.0)
        return out
    if not np.issubdtype(a.dtype, np.floating):  # 16-bit or int values have no one scale to [0, 1]
        raise ValueError(f"sRGB curve: expected uint8 or float values, got {a.dtype}")
    np.fmax(a.astype(dtype, copy=False), dtype(0.0), out=out)
    return np.fmin(out, dtype(1.0), out=out)


def _decode(c: np.ndarray, dtype) -> np.ndarray:
    return np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4).astype(dtype, copy=False)


@functools.cache
def _decode_table(dtype) -> np.ndarray:
    """The curve at the 256 uint8 levels, computed as for any uint8 array (so a lookup gives the same values)."""
    table = _decode(_unit(np.arange(256, dtype=np.uint8), dtype), dtype)
    table.setflags(write=False)
    return table


def srgb_to_linear(srgb, dtype=np.float32) -> np.ndarray:
    """sRGB-encoded values (uint8, or float in [0, 1]) -> linear light in [0, 1], as ``dtype``. uint8 values are
    looked up in a 256-entry table of the curve (an image is decoded once per pixel, not once per level)."""
    a = np.asarray(srgb)
    if a.dtype == np.uint8:
        flat = np.ascontiguousarray(a).reshape(-1)
        return cv2.LUT(flat, _decode_table(np.dtype(dtype).type)).reshape(a.shape)  # a 0-d input stays an array
    return _decode(_unit(a, dtype), dtype)


def linear_to_srgb(linear, dtype=np.float32) -> np.ndarray:
    """Linear light (clipped to [0, 1]) -> sRGB-encoded values in [0, 1], as ``dtype`` (a new array)."""
    c = _unit(linear, dtype)
    y = np.power(c, 1 / 2.4, out=np.empty_like(c))
    y *= 1.055
    y -= 0.055
    low = c <= 0.0031308
    y[low] = 12.92 * c[low]
    return y


def linear_to_srgb_uint8(linear) -> np.ndarray:
    """Linear light -> uint8 sRGB: ``round(255 linear_to_srgb(linear))`` in float32."""
    y = linear_to_srgb(linear)
    y *= 255.0
    np.round(y, out=y)
    np.clip(y, 0, 255, out=y)
    return y.astype(np.uint8)

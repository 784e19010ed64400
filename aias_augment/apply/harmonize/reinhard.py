"""Reinhard et al. (2001) colour transfer: the foreground's per-channel Lab mean and standard deviation are matched to
the background's. The classic baseline of the harmonization literature; it ignores that the object has its own
colours, so it over-corrects strongly coloured objects.

CIELAB via OpenCV (float input in [0, 1]: L in [0, 100], a and b about [-127, 127]) stands in for Reinhard's
l-alpha-beta; both are decorrelated opponent spaces and the transfer is the same mean/std matching.
"""

from __future__ import annotations

import cv2
import numpy as np

# Floor on the foreground standard deviation (Lab units) so a flat region is not stretched to infinity.
STD_FLOOR = 1e-3


def reinhard_transfer(image_float: np.ndarray, mask_bool: np.ndarray, strength: float = 1.0) -> np.ndarray:
    """Return a new float image whose foreground (``mask_bool``) has the background's Lab statistics.

    ``strength`` in [0, 1] interpolates the target statistics between the foreground's own (0) and the background's (1).
    """
    if not 0.0 <= strength <= 1.0:
        raise ValueError(f"reinhard_transfer: strength must be in [0, 1], got {strength}")
    bg = ~mask_bool
    if not mask_bool.any() or not bg.any():
        return image_float.copy()
    lab = cv2.cvtColor(np.ascontiguousarray(image_float, dtype=np.float32), cv2.COLOR_RGB2Lab)
    fg_px, bg_px = lab[mask_bool], lab[bg]
    mu_f, sd_f = fg_px.mean(0), np.maximum(fg_px.std(0), STD_FLOOR)
    mu_b, sd_b = bg_px.mean(0), bg_px.std(0)
    mu_t = (1 - strength) * mu_f + strength * mu_b
    sd_t = (1 - strength) * sd_f + strength * sd_b
    lab_out = lab.copy()
    lab_out[mask_bool] = (fg_px - mu_f) / sd_f * sd_t + mu_t
    out = cv2.cvtColor(lab_out, cv2.COLOR_Lab2RGB)
    return np.clip(out, 0.0, 1.0)

"""Harmonization metrics as in iHarmony4 / DoveNet: MSE, foreground MSE (fMSE) and PSNR on the 0..255 scale."""

from __future__ import annotations

import numpy as np

# A zero-area mask has no foreground error: fMSE divides by max(area, EPS_AREA) (pixels).
EPS_AREA = 1.0


def _check(pred: np.ndarray, target: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    if pred.shape != target.shape or pred.ndim != 3 or pred.shape[2] != 3:
        raise ValueError(f"metrics: need two (H, W, 3) images of one shape, got {pred.shape} and {target.shape}")
    return pred.astype(np.float64), target.astype(np.float64)


def mse(pred_uint8: np.ndarray, target_uint8: np.ndarray) -> float:
    """Mean over all pixels and channels of the squared error (0..255 scale)."""
    p, t = _check(pred_uint8, target_uint8)
    return float(np.mean((p - t) ** 2))


def fmse(pred_uint8: np.ndarray, target_uint8: np.ndarray, mask: np.ndarray) -> float:
    """Squared error summed over the foreground (mask-weighted) / (3 * foreground area): iHarmony4's fMSE."""
    p, t = _check(pred_uint8, target_uint8)
    if mask.shape != p.shape[:2]:
        raise ValueError(f"fmse: mask {mask.shape} does not match image {p.shape[:2]}")
    m = mask.astype(np.float64)
    return float(np.sum(((p - t) ** 2) * m[..., None]) / (3.0 * max(m.sum(), EPS_AREA)))


def psnr(pred_uint8: np.ndarray, target_uint8: np.ndarray) -> float:
    """10 log10(255^2 / MSE); identical images give +inf (reported as such, never NaN)."""
    err = mse(pred_uint8, target_uint8)
    return float("inf") if err == 0.0 else float(10.0 * np.log10(255.0**2 / err))

"""Colour statistics inside object boxes (what a person sees first: bright fluorescent orange vs a dull model)."""

from __future__ import annotations

import cv2
import numpy as np

__all__ = ["box_colour_stats", "saturated_orange_mask"]


def saturated_orange_mask(
    rgb: np.ndarray, hue_range_deg: tuple[float, float] = (0.0, 30.0), min_sat: float = 0.6, min_val: float = 0.5
) -> np.ndarray:
    """Pixels of (*, 3) uint8 sRGB whose HSV hue lies in ``hue_range_deg`` (red through orange), saturation >= min_sat
    and value >= min_val (HSV as defined by max/min of R, G, B; hue in degrees)."""
    x = np.asarray(rgb, np.float64) / 255.0
    mx, mn = x.max(-1), x.min(-1)
    sat = np.where(mx > 0, (mx - mn) / np.maximum(mx, 1e-9), 0.0)  # eps: black pixels
    r, g, b = x[..., 0], x[..., 1], x[..., 2]
    # red is the max: hue = 60 (g - b) / (max - min) in [-60, 60]
    hue = np.where(r >= mx, 60.0 * (g - b) / np.maximum(mx - mn, 1e-9), 999.0)
    return (r >= mx) & (hue >= hue_range_deg[0]) & (hue <= hue_range_deg[1]) & (sat >= min_sat) & (mx >= min_val)


def box_colour_stats(image: np.ndarray, boxes_xyxy: np.ndarray) -> list[dict]:
    """Per box (pixels inside it): mean brightness (grey level 0-255, OpenCV's luma), saturated-orange fraction and
    the fraction of clipped pixels (any channel 255) inside the box and in a ring of the same area around it."""
    out = []
    H, W = image.shape[:2]
    grey = cv2.cvtColor(image, cv2.COLOR_RGB2GRAY)
    clipped = (image >= 255).any(-1)
    for b in np.asarray(boxes_xyxy, np.float64).reshape(-1, 4):
        x0, y0 = max(int(np.floor(b[0])), 0), max(int(np.floor(b[1])), 0)
        x1, y1 = min(int(np.ceil(b[2])), W), min(int(np.ceil(b[3])), H)
        if x1 <= x0 or y1 <= y0:
            continue
        m = np.zeros((H, W), bool)
        m[y0:y1, x0:x1] = True
        pad = int(round(0.2 * max(x1 - x0, y1 - y0)))
        ring = np.zeros((H, W), bool)
        ring[max(y0 - pad, 0) : min(y1 + pad, H), max(x0 - pad, 0) : min(x1 + pad, W)] = True
        ring &= ~m
        out.append(
            {
                "mean_brightness": float(grey[m].mean()),
                "saturated_orange_fraction": float(saturated_orange_mask(image[m]).mean()),
                "clipped_fraction": float(clipped[m].mean()),
                "clipped_fraction_ring": float(clipped[ring].mean()) if ring.any() else 0.0,
            }
        )
    return out

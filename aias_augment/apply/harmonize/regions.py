"""Mask geometry shared by training-pair synthesis and inference: context crops around objects, components, rings.

Boxes are pixel ``(x0, y0, x1, y1)`` with exclusive ``x1, y1`` (numpy slicing convention).
"""

from __future__ import annotations

import cv2
import numpy as np

Box = tuple[int, int, int, int]


def mask_box(mask_bool: np.ndarray) -> Box | None:
    """Tight box of the True pixels, or None when the mask is empty."""
    ys, xs = np.nonzero(mask_bool)
    if ys.size == 0:
        return None
    return int(xs.min()), int(ys.min()), int(xs.max()) + 1, int(ys.max()) + 1


def context_box(box: Box, image_hw: tuple[int, int], context: float) -> Box:
    """Square of side ``context * max(box w, h)`` centred on ``box``, clipped to the image.

    Clipping can make the crop non-square; training and inference use this same function, so the network sees crops
    with the same statistics in both.
    """
    x0, y0, x1, y1 = box
    h, w = image_hw
    side = context * max(x1 - x0, y1 - y0, 1)
    cx, cy = 0.5 * (x0 + x1), 0.5 * (y0 + y1)
    cx0 = int(np.floor(max(0.0, cx - side / 2)))
    cy0 = int(np.floor(max(0.0, cy - side / 2)))
    cx1 = int(np.ceil(min(float(w), cx + side / 2)))
    cy1 = int(np.ceil(min(float(h), cy + side / 2)))
    # The crop always contains the object itself.
    return min(cx0, x0), min(cy0, y0), max(cx1, x1), max(cy1, y1)


def components(mask_bool: np.ndarray, min_area_px: int = 1) -> list[np.ndarray]:
    """Boolean masks of the 8-connected components of ``mask_bool`` with at least ``min_area_px`` pixels."""
    n, labels, stats, _ = cv2.connectedComponentsWithStats(mask_bool.astype(np.uint8), connectivity=8)
    return [labels == i for i in range(1, n) if stats[i, cv2.CC_STAT_AREA] >= min_area_px]


def ring(mask_bool: np.ndarray, width_px: int) -> np.ndarray:
    """Background pixels within ``width_px`` (chessboard distance) of the mask: the object's surroundings."""
    width_px = max(int(width_px), 1)
    kernel = np.ones((2 * width_px + 1, 2 * width_px + 1), np.uint8)
    return cv2.dilate(mask_bool.astype(np.uint8), kernel).astype(bool) & ~mask_bool


def resize(image: np.ndarray, size_wh: tuple[int, int]) -> np.ndarray:
    """Area interpolation when shrinking, bilinear when enlarging."""
    h, w = image.shape[:2]
    shrink = size_wh[0] * size_wh[1] < w * h
    return cv2.resize(image, size_wh, interpolation=cv2.INTER_AREA if shrink else cv2.INTER_LINEAR)

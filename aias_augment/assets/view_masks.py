"""The views a reconstruction is made from, and the masks it reads: :class:`View` (a photo, its object mask, its
camera), a silhouette's signed distance and GrabCut from a box. Below :mod:`aias_augment.assets.reconstruct`, its
quality checks and the views file, which all use them."""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from aias_augment.core.geometry import Intrinsics

__all__ = ["View", "grabcut_mask", "signed_distance_px"]


@dataclass(frozen=True)
class View:
    """One photo of the object: RGB uint8, its object mask, its camera (OpenCV ``cam_from_object``, metres)."""

    image_rgb: np.ndarray
    mask: np.ndarray
    intrinsics: Intrinsics
    cam_from_object: np.ndarray

    def __post_init__(self):
        h, w = self.mask.shape[:2]
        if self.image_rgb.shape[:2] != (h, w) or self.image_rgb.dtype != np.uint8 or self.image_rgb.ndim != 3:
            raise ValueError("View: image_rgb must be (H, W, 3) uint8 and the mask (H, W)")
        if (self.intrinsics.width, self.intrinsics.height) != (w, h):
            raise ValueError(f"View: intrinsics are {self.intrinsics.width}x{self.intrinsics.height}, image {w}x{h}")
        if not np.asarray(self.mask, bool).any():
            raise ValueError("View: empty mask (the object is not in this view)")


def signed_distance_px(mask: np.ndarray) -> np.ndarray:
    """(H, W) float32: distance in pixels to the silhouette's boundary, negative inside, positive outside."""
    m = np.asarray(mask, bool).astype(np.uint8)
    inside = cv2.distanceTransform(m, cv2.DIST_L2, 5)
    outside = cv2.distanceTransform(1 - m, cv2.DIST_L2, 5)
    # pixel centres: the boundary runs half a pixel from the outermost inside and innermost outside pixels
    return (np.where(m > 0, 0.5 - inside, outside - 0.5)).astype(np.float32)


def grabcut_mask(image_rgb: np.ndarray, box_xyxy, iterations: int = 5) -> np.ndarray:
    """The object's mask inside ``box_xyxy`` by GrabCut initialised from the box (OpenCV; no learnt weights)."""
    x0, y0, x1, y1 = (int(round(float(c))) for c in box_xyxy)
    h, w = image_rgb.shape[:2]
    x0, y0, x1, y1 = max(x0, 0), max(y0, 0), min(x1, w - 1), min(y1, h - 1)
    if x1 - x0 < 4 or y1 - y0 < 4:
        raise ValueError(f"grabcut_mask: box {box_xyxy} is too small or outside the {w}x{h} image")
    mask = np.zeros((h, w), np.uint8)
    bgd, fgd = np.zeros((1, 65), np.float64), np.zeros((1, 65), np.float64)
    cv2.setRNGSeed(0)  # GrabCut's GMM initialisation draws from OpenCV's generator: fixed, so masks repeat
    cv2.grabCut(
        cv2.cvtColor(image_rgb, cv2.COLOR_RGB2BGR),
        mask,
        (x0, y0, x1 - x0, y1 - y0),
        bgd,
        fgd,
        iterations,
        cv2.GC_INIT_WITH_RECT,
    )
    return (mask == cv2.GC_FGD) | (mask == cv2.GC_PR_FGD)

"""Object crops for realism metrics, normalised so that a classifier cannot tell the sets apart by resolution or
compression alone: a square window around each box with context, shrunk so the box is ``target_height_px`` tall
(targets drawn from one distribution for every set), resized to ``out_size`` and JPEG re-encoded at one quality."""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

__all__ = ["CropConfig", "context_window", "normalise_crop", "object_crops"]


@dataclass(frozen=True)
class CropConfig:
    context: float = 0.25  # window side = longer box side x (1 + 2 context)
    out_size: int = 64
    jpeg_quality: int = 85
    target_height_range_px: tuple[float, float] = (20.0, 48.0)  # log-uniform box heights after shrinking
    min_box_px: float = 8.0  # boxes smaller than this (either side) are skipped


def context_window(box_xyxy, image_hw: tuple[int, int], context: float) -> tuple[int, int, int, int]:
    """Integer square window (x0, y0, x1, y1) of side ``max(w, h) (1 + 2 context)`` centred on the box, shifted to lie
    inside the image (and cut to it when the image is smaller than the side)."""
    x0, y0, x1, y1 = (float(v) for v in box_xyxy)
    H, W = image_hw
    side = max(x1 - x0, y1 - y0) * (1.0 + 2.0 * context)
    side = int(round(min(side, W, H)))
    cx, cy = (x0 + x1) / 2, (y0 + y1) / 2
    wx = int(round(np.clip(cx - side / 2, 0, W - side)))
    wy = int(round(np.clip(cy - side / 2, 0, H - side)))
    return wx, wy, wx + side, wy + side


def normalise_crop(window: np.ndarray, box_height_px: float, target_height_px: float, cfg: CropConfig) -> np.ndarray:
    """Shrink ``window`` (area) so the box inside it would be ``target_height_px`` tall (never enlarged), then resize
    to out_size x out_size (bilinear) and round-trip through JPEG at ``cfg.jpeg_quality``."""
    scale = min(1.0, target_height_px / max(box_height_px, 1e-6))  # eps: degenerate box
    w = window
    if scale < 1.0:
        side = max(1, int(round(window.shape[0] * scale)))
        w = cv2.resize(window, (side, side), interpolation=cv2.INTER_AREA)
    w = cv2.resize(
        w, (cfg.out_size, cfg.out_size), interpolation=cv2.INTER_AREA if w.shape[0] > cfg.out_size else cv2.INTER_LINEAR
    )
    ok, buf = cv2.imencode(".jpg", cv2.cvtColor(w, cv2.COLOR_RGB2BGR), [cv2.IMWRITE_JPEG_QUALITY, cfg.jpeg_quality])
    return cv2.cvtColor(cv2.imdecode(buf, cv2.IMREAD_COLOR), cv2.COLOR_BGR2RGB)


def object_crops(
    image: np.ndarray, boxes_xyxy: np.ndarray, rng: np.random.Generator, cfg: CropConfig = CropConfig()
) -> tuple[list[np.ndarray], list[int]]:
    """Normalised crops of the boxes of one image and the indices of the boxes they came from (small boxes skipped).
    Target heights are drawn log-uniformly from ``cfg.target_height_range_px`` with ``rng``."""
    crops, kept = [], []
    lo, hi = np.log(cfg.target_height_range_px[0]), np.log(cfg.target_height_range_px[1])
    for i, b in enumerate(np.asarray(boxes_xyxy, np.float64).reshape(-1, 4)):
        t = float(np.exp(rng.uniform(lo, hi)))
        if b[2] - b[0] < cfg.min_box_px or b[3] - b[1] < cfg.min_box_px:
            continue
        x0, y0, x1, y1 = context_window(b, image.shape[:2], cfg.context)
        crops.append(normalise_crop(np.ascontiguousarray(image[y0:y1, x0:x1]), b[3] - b[1], t, cfg))
        kept.append(i)
    return crops, kept

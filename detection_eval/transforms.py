"""Training-time augmentation as pure functions of (image, boxes, labels, rng).

Images are RGB uint8 (H, W, 3); boxes xyxy pixels (N, 4); labels (N,). Every function returns new arrays (inputs
are never modified) and takes its randomness from the ``numpy.random.Generator`` passed in.
"""

from __future__ import annotations

import cv2
import numpy as np

from .boxes import PAD_VALUE
from .config import AugmentConfig


def place_scaled(image: np.ndarray, boxes: np.ndarray, size: int, scale: float, offset_xy: tuple[float, float]):
    """Resize ``image`` by ``scale`` and paste it at integer ``offset_xy`` (may be negative) into a ``size`` square
    grey canvas; boxes follow (``x * scale + offset``) and are clipped to the canvas."""
    h, w = image.shape[:2]
    new_w, new_h = max(1, round(w * scale)), max(1, round(h * scale))
    resized = cv2.resize(image, (new_w, new_h), interpolation=cv2.INTER_AREA if scale < 1 else cv2.INTER_LINEAR)
    ox, oy = int(round(offset_xy[0])), int(round(offset_xy[1]))
    canvas = np.full((size, size, 3), PAD_VALUE, dtype=np.uint8)
    x0, y0 = max(ox, 0), max(oy, 0)
    x1, y1 = min(ox + new_w, size), min(oy + new_h, size)
    if x1 > x0 and y1 > y0:
        canvas[y0:y1, x0:x1] = resized[y0 - oy : y1 - oy, x0 - ox : x1 - ox]
    sx, sy = new_w / w, new_h / h
    out = np.asarray(boxes, np.float64).reshape(-1, 4) * [sx, sy, sx, sy] + [ox, oy, ox, oy]
    return canvas, np.clip(out, 0, size)


def filter_boxes(boxes: np.ndarray, labels: np.ndarray, min_side: float):
    keep = ((boxes[:, 2] - boxes[:, 0]) >= min_side) & ((boxes[:, 3] - boxes[:, 1]) >= min_side)
    return boxes[keep], labels[keep]


def hflip(image: np.ndarray, boxes: np.ndarray):
    w = image.shape[1]
    out = boxes.copy()
    out[:, [0, 2]] = w - boxes[:, [2, 0]]
    return image[:, ::-1].copy(), out


def hsv_jitter(image: np.ndarray, gains: tuple[float, float, float], rng: np.random.Generator) -> np.ndarray:
    """Multiply hue/saturation/value by ``1 + U(-gain, gain)`` (hue wraps at 180, OpenCV units)."""
    r = rng.uniform(-1, 1, 3) * np.asarray(gains) + 1
    hue, sat, val = cv2.split(cv2.cvtColor(image, cv2.COLOR_RGB2HSV))
    x = np.arange(256, dtype=np.float64)
    lut_h = ((x * r[0]) % 180).astype(np.uint8)
    lut_s = np.clip(x * r[1], 0, 255).astype(np.uint8)
    lut_v = np.clip(x * r[2], 0, 255).astype(np.uint8)
    hsv = cv2.merge((cv2.LUT(hue, lut_h), cv2.LUT(sat, lut_s), cv2.LUT(val, lut_v)))
    return cv2.cvtColor(hsv, cv2.COLOR_HSV2RGB)


def random_scale_translate(image, boxes, size: int, cfg: AugmentConfig, rng: np.random.Generator):
    """Letterbox-fit ``image`` into ``size`` times a random factor from ``scale_range``, centred then shifted by up
    to ``translate_frac * size``."""
    h, w = image.shape[:2]
    scale = size / max(h, w) * rng.uniform(*cfg.scale_range)
    shift = rng.uniform(-cfg.translate_frac, cfg.translate_frac, 2) * size
    offset = ((size - w * scale) / 2 + shift[0], (size - h * scale) / 2 + shift[1])
    return place_scaled(image, boxes, size, scale, offset)


def mosaic(samples, size: int, cfg: AugmentConfig, rng: np.random.Generator):
    """YOLOX-style mosaic of four (image, boxes, labels) samples around a random centre, each tile scaled to half the
    canvas times a random factor."""
    cx, cy = rng.uniform(0.3, 0.7, 2) * size
    canvas = np.full((size, size, 3), PAD_VALUE, dtype=np.uint8)
    all_boxes, all_labels = [], []
    for k, (image, boxes, labels) in enumerate(samples):
        h, w = image.shape[:2]
        scale = size / 2 / max(h, w) * rng.uniform(*cfg.scale_range)
        tw, th = w * scale, h * scale
        ox = cx - tw if k in (0, 2) else cx  # tiles meet at the centre: 0 top-left, 1 top-right, ...
        oy = cy - th if k in (0, 1) else cy
        tile, b = place_scaled(image, boxes, size, scale, (ox, oy))
        region = np.zeros((size, size), bool)
        x0, y0 = int(round(ox)), int(round(oy))
        region[max(y0, 0) : max(y0 + round(th), 0), max(x0, 0) : max(x0 + round(tw), 0)] = True
        canvas[region] = tile[region]
        all_boxes.append(b)
        all_labels.append(np.asarray(labels, np.int64))
    return canvas, np.concatenate(all_boxes).reshape(-1, 4), np.concatenate(all_labels)


def augment_sample(image, boxes, labels, size: int, cfg: AugmentConfig, rng: np.random.Generator, extra=None):
    """One training sample: optional mosaic (``extra`` supplies three more samples), random scale/translate,
    horizontal flip, HSV jitter; boxes smaller than ``min_box_side_px`` are dropped."""
    boxes = np.asarray(boxes, np.float64).reshape(-1, 4)
    labels = np.asarray(labels, np.int64)
    if extra is not None and cfg.mosaic_prob > 0 and rng.random() < cfg.mosaic_prob:
        image, boxes, labels = mosaic([(image, boxes, labels), *extra], size, cfg, rng)
    else:
        image, boxes = random_scale_translate(image, boxes, size, cfg, rng)
    if rng.random() < cfg.hflip_prob:
        image, boxes = hflip(image, boxes)
    if any(cfg.hsv_gains):
        image = hsv_jitter(image, cfg.hsv_gains, rng)
    boxes, labels = filter_boxes(boxes, labels, cfg.min_box_side_px)
    return image, boxes, labels

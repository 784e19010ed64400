"""TraCon photos with labelled cones standing on their ground, and what the realism studies measure on a cone's box:
shared by ``realism.parts_and_sizes`` and ``realism.labelled_scenes``."""

from __future__ import annotations

import cv2
import numpy as np

from aias_augment.core.config import data_root

SPREAD_PX = 30


def photos(split: str, n: int):
    """(stem, RGB <= 640 px, cone boxes xyxy) of TraCon ``split`` photos with >= 2 whole cones whose bottom rows
    spread >= 30 px."""
    root = data_root() / "tracon"
    for lab_path in sorted((root / f"labels/{split}").glob("*.txt")):
        if lab_path.stat().st_size == 0:
            continue
        lab = np.loadtxt(lab_path, ndmin=2)
        if len(lab) < 2:
            continue
        path = next((root / f"images/{split}").glob(lab_path.stem + ".*"))
        img = cv2.cvtColor(cv2.imread(str(path)), cv2.COLOR_BGR2RGB)
        s = min(1.0, 640 / max(img.shape[:2]))
        img = cv2.resize(img, None, fx=s, fy=s, interpolation=cv2.INTER_AREA) if s < 1 else img
        H, W = img.shape[:2]
        cx, cy, bw, bh = lab[:, 1] * W, lab[:, 2] * H, lab[:, 3] * W, lab[:, 4] * H
        boxes = np.c_[cx - bw / 2, cy - bh / 2, cx + bw / 2, cy + bh / 2]
        if len(whole_boxes(boxes, H)) >= 2 and np.ptp(whole_boxes(boxes, H)[:, 3]) >= SPREAD_PX:
            yield lab_path.stem, img, boxes
            n -= 1
            if n == 0:
                return


def whole_boxes(boxes: np.ndarray, height: int) -> np.ndarray:
    return boxes[(boxes[:, 1] > 1) & (boxes[:, 3] < height - 2)]


def base_v(img: np.ndarray, box) -> float:
    x0, y0, x1, y1 = box
    h, w = y1 - y0, x1 - x0
    band = img[int(y0 + 0.88 * h) : int(np.ceil(y0 + 0.98 * h)), int(x0 + 0.2 * w) : int(np.ceil(x1 - 0.2 * w))]
    return float(np.median(band.max(-1))) if band.size else float("nan")

"""Pictures for people: boxes drawn on images, contact sheets."""
from __future__ import annotations

import cv2
import numpy as np


def draw_boxes(image_rgb: np.ndarray, boxes_xywh, labels, inserted=None) -> np.ndarray:
    """Copy of the image with boxes: inserted objects in green, existing ones in orange."""
    out = image_rgb.copy()
    inserted = [False] * len(labels) if inserted is None else inserted
    t = max(1, round(min(out.shape[:2]) / 300))
    for (x, y, w, h), lab, ins in zip(boxes_xywh, labels, inserted):
        color = (40, 220, 40) if ins else (255, 150, 0)
        p0, p1 = (int(round(x)), int(round(y))), (int(round(x + w)) - 1, int(round(y + h)) - 1)
        cv2.rectangle(out, p0, p1, color, t)
        cv2.putText(out, str(lab), (p0[0], max(p0[1] - 3, 10)), cv2.FONT_HERSHEY_SIMPLEX, 0.4 * t, color, t,
                    cv2.LINE_AA)
    return out


def contact_sheet(images: list[np.ndarray], cols: int = 3, cell_width: int = 480, titles=None) -> np.ndarray:
    """Tile RGB images (resized to a common width) into one sheet."""
    if not images:
        raise ValueError("contact_sheet: no images")
    cells = []
    for i, im in enumerate(images):
        s = cell_width / im.shape[1]
        c = cv2.resize(im, (cell_width, max(1, int(round(im.shape[0] * s)))), interpolation=cv2.INTER_AREA)
        if titles:
            cv2.putText(c, str(titles[i]), (5, 15), cv2.FONT_HERSHEY_SIMPLEX, 0.45, (255, 255, 255), 1, cv2.LINE_AA)
        cells.append(c)
    rows = []
    for r in range(0, len(cells), cols):
        cell_h = max(c.shape[0] for c in cells[r:r + cols])  # each row as tall as its tallest image
        row = [np.pad(c, ((0, cell_h - c.shape[0]), (0, 0), (0, 0))) for c in cells[r:r + cols]]
        row += [np.zeros((cell_h, cell_width, 3), np.uint8)] * (cols - len(row))
        rows.append(np.concatenate(row, axis=1))
    return np.concatenate(rows, axis=0)

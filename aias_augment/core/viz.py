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
        cv2.putText(
            out, str(lab), (p0[0], max(p0[1] - 3, 10)), cv2.FONT_HERSHEY_SIMPLEX, 0.4 * t, color, t, cv2.LINE_AA
        )
    return out


def contact_sheet(
    images: list[np.ndarray], cols: int = 3, cell_width: int = 480, titles=None, gap_px: int = 4, background: int = 235
) -> np.ndarray:
    """Tile RGB images into one sheet ``cols * cell_width`` wide in justified rows: each row holds images of one
    height, chosen so that the row fills the width exactly (no empty cells under short images); images join a row
    until their widths at the nominal height ``0.6 * cell_width`` reach the sheet's width, at most ``cols`` per
    row. The last row keeps the nominal height and is left-aligned. ``gap_px`` of ``background`` grey between
    tiles; ``titles`` are drawn in each tile's top-left corner."""
    if not images:
        raise ValueError("contact_sheet: no images")
    width = cols * cell_width
    nominal = 0.6 * cell_width
    aspects = [im.shape[1] / max(im.shape[0], 1) for im in images]
    rows, cur = [], []
    for i, a in enumerate(aspects):
        cur.append(i)
        if len(cur) == cols or sum(aspects[j] for j in cur) * nominal + gap_px * (len(cur) - 1) >= width:
            rows.append((cur, True))
            cur = []
    if cur:
        rows.append((cur, False))
    strips = []
    for idx, full in rows:
        free = width - gap_px * (len(idx) - 1)
        h = free / sum(aspects[j] for j in idx) if full else nominal
        h = max(1, int(round(min(h, 2.0 * nominal))))  # a single very wide image may not fill: keep it sane
        ws = [max(1, int(round(aspects[j] * h))) for j in idx]
        if full:  # rounding: the last tile of a full row ends exactly at the sheet's edge
            ws[-1] = max(1, width - gap_px * (len(idx) - 1) - sum(ws[:-1]))
        row = np.full((h, width, 3), background, np.uint8)
        x = 0
        for j, w in zip(idx, ws):
            im = images[j]
            c = cv2.resize(
                np.ascontiguousarray(im), (w, h), interpolation=cv2.INTER_AREA if w < im.shape[1] else cv2.INTER_LINEAR
            )
            if titles:  # white on a dark outline: readable on bright and dark tiles alike
                for colour, thickness in (((0, 0, 0), 3), ((255, 255, 255), 1)):
                    cv2.putText(
                        c, str(titles[j]), (5, 15), cv2.FONT_HERSHEY_SIMPLEX, 0.45, colour, thickness, cv2.LINE_AA
                    )
            w = min(w, width - x)
            if w <= 0:
                break
            row[:, x : x + w] = c[:, :w]
            x += w + gap_px
        strips.append(row)
    sep = np.full((gap_px, width, 3), background, np.uint8)
    out = [strips[0]]
    for r in strips[1:]:
        out += [sep, r]
    return np.concatenate(out, axis=0)

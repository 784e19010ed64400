"""COCO annotations of inserted objects: visible box from the rendered mask after occlusion, amodal box,
visibility ratio, RLE mask; visibility of existing boxes under the inserted objects."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from pycocotools import mask as mask_utils


@dataclass(frozen=True)
class ObjectAnnotation:
    category: str
    visible_box_xywh: tuple[float, float, float, float] | None   # None when nothing is visible
    amodal_box_xywh: tuple[float, float, float, float]
    visibility: float                                             # visible pixels / amodal pixels
    area: float                                                   # visible pixels
    rle: dict                                                     # COCO RLE of the visible mask (counts as str)

    def to_dict(self) -> dict:
        return {"category": self.category, "visible_box_xywh": self.visible_box_xywh,
                "amodal_box_xywh": self.amodal_box_xywh, "visibility": self.visibility, "area": self.area,
                "rle": self.rle}


def mask_box_xywh(mask: np.ndarray) -> tuple[float, float, float, float] | None:
    """Tight COCO box [x, y, w, h] of a boolean mask in pixel-edge coordinates (pixel i spans [i, i+1])."""
    ys, xs = np.nonzero(mask)
    if len(xs) == 0:
        return None
    x0, y0, x1, y1 = xs.min(), ys.min(), xs.max() + 1, ys.max() + 1
    return float(x0), float(y0), float(x1 - x0), float(y1 - y0)


def encode_rle(mask: np.ndarray) -> dict:
    rle = mask_utils.encode(np.asfortranarray(mask, dtype=np.uint8))   # no copy when already uint8, column-major
    rle["counts"] = rle["counts"].decode("ascii")
    return rle


def annotate_object(category: str, amodal_alpha: np.ndarray, visible_alpha: np.ndarray,
                    threshold: float = 0.5) -> ObjectAnnotation:
    amodal = amodal_alpha > threshold
    visible = visible_alpha > threshold
    amodal_box = mask_box_xywh(amodal)
    if amodal_box is None:
        raise ValueError("annotate_object: the object covers no pixel")
    n_amodal = int(amodal.sum())
    n_vis = int(visible.sum())
    return ObjectAnnotation(category, mask_box_xywh(visible), amodal_box, n_vis / max(n_amodal, 1), float(n_vis),
                            encode_rle(visible))


def box_visibility_under_cover(boxes_xyxy: np.ndarray, cover: np.ndarray) -> np.ndarray:
    """Fraction of each existing box's pixels NOT covered by the inserted objects (``cover`` in [0, 1]).

    Boxes are in pixel-edge coordinates; a box with no pixel area counts as fully visible.
    """
    boxes = np.asarray(boxes_xyxy, dtype=np.float64).reshape(-1, 4)
    h, w = cover.shape
    out = np.ones(len(boxes))
    if len(boxes) == 0:
        return out
    integral = np.pad(np.cumsum(np.cumsum(cover.astype(np.float64), 0), 1), ((1, 0), (1, 0)))
    for i, (x0, y0, x1, y1) in enumerate(boxes):
        xa, ya = int(np.clip(np.floor(x0), 0, w)), int(np.clip(np.floor(y0), 0, h))
        xb, yb = int(np.clip(np.ceil(x1), 0, w)), int(np.clip(np.ceil(y1), 0, h))
        area = (xb - xa) * (yb - ya)
        if area <= 0:
            continue
        covered = integral[yb, xb] - integral[ya, xb] - integral[yb, xa] + integral[ya, xa]
        out[i] = 1.0 - covered / area
    return out

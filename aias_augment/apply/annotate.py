"""COCO annotations of inserted objects: visible box from the rendered mask after occlusion, amodal box,
visibility ratio, RLE mask; visibility of existing boxes under the inserted objects. Boxes are mask-tight unless a
labelling convention (:func:`follow_convention`: margins measured from the user's own labels) says otherwise."""

from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np
from pycocotools import mask as mask_utils


@dataclass(frozen=True)
class ObjectAnnotation:
    category: str
    visible_box_xywh: tuple[float, float, float, float] | None  # None when nothing is visible
    amodal_box_xywh: tuple[float, float, float, float]
    visibility: float  # visible pixels / amodal pixels
    area: float  # visible pixels
    rle: dict  # COCO RLE of the visible mask (counts as str)
    decoy: bool = False  # inserted but not a label (the placement's decoy): left out of every box output

    def to_dict(self) -> dict:
        d = {
            "category": self.category,
            "visible_box_xywh": self.visible_box_xywh,
            "amodal_box_xywh": self.amodal_box_xywh,
            "visibility": self.visibility,
            "area": self.area,
            "rle": self.rle,
        }
        if self.decoy:
            d["decoy"] = True
        return d

    @classmethod
    def from_dict(cls, d: dict) -> "ObjectAnnotation":
        """The annotation :meth:`to_dict` wrote (its boxes as tuples again)."""
        vis = d["visible_box_xywh"]
        return cls(
            d["category"],
            None if vis is None else tuple(vis),
            tuple(d["amodal_box_xywh"]),
            d["visibility"],
            d["area"],
            d["rle"],
            bool(d.get("decoy", False)),
        )


def mask_box_xywh(mask: np.ndarray) -> tuple[float, float, float, float] | None:
    """Tight COCO box [x, y, w, h] of a boolean mask in pixel-edge coordinates (pixel i spans [i, i+1])."""
    m = np.asarray(mask)
    x, y, w, h = cv2.boundingRect(
        m.view(np.uint8) if m.dtype == bool and m.flags.c_contiguous else (m != 0).astype(np.uint8)
    )
    if w == 0:
        return None
    return float(x), float(y), float(w), float(h)


def follow_convention(
    box_xywh: tuple[float, float, float, float] | None, margins: tuple[float, float, float, float], frame_hw
) -> tuple[float, float, float, float] | None:
    """The box a dataset's labellers would draw around an object whose mask-tight box is ``box_xywh``: ``margins``
    (left, top, right, bottom) are how far their label lies outside the mask on each side, as a fraction of the
    label's own width or height (``assets.bank.lift.measure_box_convention``), so the label is ``w / (1 - left -
    right)`` wide with ``left`` of that before the mask. Clipped to the frame ``(H, W)``; all-zero margins (the
    default) return the box itself."""
    if box_xywh is None or not any(margins):
        return box_xywh
    left, top, right, bottom = margins
    x, y, w, h = box_xywh
    lw, lh = w / (1.0 - left - right), h / (1.0 - top - bottom)
    x0, y0 = max(0.0, x - left * lw), max(0.0, y - top * lh)
    x1, y1 = min(float(frame_hw[1]), x + w + right * lw), min(float(frame_hw[0]), y + h + bottom * lh)
    return x0, y0, x1 - x0, y1 - y0


def encode_rle(mask: np.ndarray) -> dict:
    rle = mask_utils.encode(np.asfortranarray(mask, dtype=np.uint8))  # no copy when already uint8, column-major
    rle["counts"] = rle["counts"].decode("ascii")
    return rle


def encode_rle_in_window(mask_w: np.ndarray, x0: int, y0: int, full_hw: tuple[int, int]) -> dict:
    """:func:`encode_rle` of the (H, W) frame that is 0 except for the bool window ``mask_w`` at (x0, y0), without
    building the frame: COCO's column-major run lengths of the window's columns (full height), the empty columns
    before and after added to the first and last runs of zeros."""
    H, W = full_hw
    h, w = mask_w.shape
    cols = np.zeros((H, w), bool, order="F")
    cols[y0 : y0 + h] = mask_w
    flat = cols.ravel(order="F")
    edges = np.flatnonzero(flat[1:] != flat[:-1]) + 1
    counts = np.diff(np.concatenate(([0], edges, [flat.size]))).tolist()
    if flat[0]:
        counts.insert(0, 0)  # runs start with zeros
    counts[0] += x0 * H
    after = (W - x0 - w) * H
    if len(counts) % 2:  # the last run is zeros
        counts[-1] += after
    elif after:
        counts.append(after)
    rle = mask_utils.frPyObjects({"counts": counts, "size": [H, W]}, H, W)
    rle["counts"] = rle["counts"].decode("ascii")
    return rle


def _annotation_parts(amodal_alpha: np.ndarray, visible_alpha: np.ndarray, threshold: float):
    amodal = amodal_alpha > threshold
    visible = visible_alpha > threshold
    amodal_box = mask_box_xywh(amodal)
    if amodal_box is None:
        raise ValueError("annotate_object: the object covers no pixel")
    n_amodal = int(np.count_nonzero(amodal))
    n_vis = int(np.count_nonzero(visible))
    return visible, mask_box_xywh(visible), amodal_box, n_vis / max(n_amodal, 1), float(n_vis)


def annotate_object(
    category: str, amodal_alpha: np.ndarray, visible_alpha: np.ndarray, threshold: float = 0.5
) -> ObjectAnnotation:
    visible, vbox, abox, visibility, area = _annotation_parts(amodal_alpha, visible_alpha, threshold)
    return ObjectAnnotation(category, vbox, abox, visibility, area, encode_rle(visible))


def annotate_in_window(
    category: str,
    win: tuple[int, int, int, int],
    amodal_w: np.ndarray,
    visible_w: np.ndarray,
    full_hw: tuple[int, int],
    threshold: float = 0.5,
    decoy: bool = False,
    box_margins: tuple[float, float, float, float] = (0.0, 0.0, 0.0, 0.0),
) -> ObjectAnnotation:
    """:func:`annotate_object` of the full frame whose layers are 0 outside the window ``win`` (x0, y0, x1, y1),
    computed on the window: the same boxes (shifted by its origin), visibility, area and RLE. ``box_margins``: the
    labelling convention both boxes follow (:func:`follow_convention`); the mask stays the object's."""
    visible, vbox, abox, visibility, area = _annotation_parts(amodal_w, visible_w, threshold)

    def shift(b):
        b = None if b is None else (b[0] + win[0], b[1] + win[1], b[2], b[3])
        return follow_convention(b, box_margins, full_hw)

    return ObjectAnnotation(
        category,
        shift(vbox),
        shift(abox),
        visibility,
        area,
        encode_rle_in_window(visible, win[0], win[1], full_hw),
        decoy,
    )


def box_visibility_under_cover(
    boxes_xyxy: np.ndarray, cover: np.ndarray, origin: tuple[int, int] = (0, 0), frame_hw: tuple[int, int] | None = None
) -> np.ndarray:
    """Fraction of each existing box's pixels NOT covered by the inserted objects (``cover`` in [0, 1]).

    Boxes are in pixel-edge coordinates, clipped to the frame; a box with no pixel area counts as fully visible.
    ``cover`` may be a window of the frame: placed at ``origin`` (x, y) in a frame of ``frame_hw`` (default: the
    cover is the whole frame), 0 outside it.
    """
    boxes = np.asarray(boxes_xyxy, dtype=np.float64).reshape(-1, 4)
    h, w = cover.shape if frame_hw is None else frame_hw
    ox, oy = origin
    ch, cw = cover.shape
    out = np.ones(len(boxes))
    if len(boxes) == 0 or cover.size == 0:
        return out
    integral = np.pad(np.cumsum(np.cumsum(cover.astype(np.float64), 0), 1), ((1, 0), (1, 0)))
    for i, (x0, y0, x1, y1) in enumerate(boxes.tolist()):
        xa, ya = min(max(math.floor(x0), 0), w), min(max(math.floor(y0), 0), h)
        xb, yb = min(max(math.ceil(x1), 0), w), min(max(math.ceil(y1), 0), h)
        area = (xb - xa) * (yb - ya)
        if area <= 0:
            continue
        # the box in the cover's own pixels, clipped to it
        ca, cb = min(max(xa - ox, 0), cw), min(max(xb - ox, 0), cw)
        ra, rb = min(max(ya - oy, 0), ch), min(max(yb - oy, 0), ch)
        covered = integral[rb, cb] - integral[ra, cb] - integral[rb, ca] + integral[ra, ca]
        out[i] = 1.0 - covered / area
    return out

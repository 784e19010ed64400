"""What one insertion does to the targets beside the image: instance masks, a semantic mask, keypoints.

Pure functions of the insertion's record (its :class:`~aias_augment.apply.annotate.ObjectAnnotation` list: one COCO
RLE of the visible pixels per object that rendered) and the targets as albumentations holds them, shared by the
albumentations transform and the torchvision door:

- instance masks (``masks``, (N, H, W[, C])): each existing mask loses the pixels an inserted object now hides; a
  mask whose box the insertion dropped (``keep_existing``) is dropped with it when there is one mask per box; the
  inserted objects' masks follow, in the order of their boxes;
- a semantic mask (``mask``): the inserted objects' visible pixels painted with their category's value;
- keypoints: a keypoint under an inserted object is hidden, as one outside the image is: removed when the
  ``KeypointParams`` say ``remove_invisible`` (albumentations' default), kept otherwise.

Decoys (objects inserted as negatives, without a label) hide what is behind them but get no box, mask or paint.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np
from pycocotools import mask as mask_utils


def _decoded(rle: dict, hw: tuple[int, int]) -> np.ndarray:
    """(H, W) bool of a COCO RLE (counts as str or bytes) of a frame of size ``hw``."""
    r = dict(rle)
    if isinstance(r.get("counts"), str):
        r["counts"] = r["counts"].encode("ascii")
    m = mask_utils.decode(r).astype(bool)
    if m.shape != tuple(hw):
        raise ValueError(f"an inserted object's mask is {m.shape}, the image {tuple(hw)}")
    return m


def labelled(annotations: Sequence) -> list:
    """The annotations that became boxes, in the boxes' order: visible and not decoys (as
    :func:`aias_augment.pipeline.image.assemble_result` appends them)."""
    return [a for a in annotations if a.visible_box_xywh is not None and not a.decoy]


def inserted_masks(annotations: Sequence, hw: tuple[int, int]) -> np.ndarray:
    """(K, H, W) bool: the visible mask of each labelled inserted object, in the order of their boxes."""
    ms = [_decoded(a.rle, hw) for a in labelled(annotations)]
    return np.stack(ms) if ms else np.zeros((0, *hw), bool)


def cover(annotations: Sequence, hw: tuple[int, int]) -> np.ndarray:
    """(H, W) bool: the pixels any inserted object (decoys included) now shows."""
    out = np.zeros(hw, bool)
    for a in annotations:
        if a.visible_box_xywh is not None:
            out |= _decoded(a.rle, hw)
    return out


def instance_masks_after(
    masks: np.ndarray, keep_existing: np.ndarray, new_masks: np.ndarray, hidden: np.ndarray
) -> np.ndarray:
    """The instance masks after the insertion: ``masks`` (N, H, W[, C]) with the ``hidden`` pixels set to 0, the
    ones of dropped boxes removed when ``len(masks) == len(keep_existing)`` (one mask per box), then ``new_masks``
    (K, H, W) as 1 in the masks' dtype (broadcast over channels)."""
    masks = np.asarray(masks)
    if masks.ndim < 3 or masks.shape[1:3] != hidden.shape:
        raise ValueError(f"masks must be (N, H, W[, C]) with (H, W) = {hidden.shape}, got {masks.shape}")
    keep = np.asarray(keep_existing, bool)
    kept = masks[keep] if len(keep) == len(masks) else masks
    kept = kept.copy()
    kept[:, hidden] = 0
    new = new_masks.astype(masks.dtype)
    if masks.ndim == 4:
        new = np.repeat(new[..., None], masks.shape[3], axis=3)
    return np.concatenate([kept, new], axis=0)


def paint_semantic(mask: np.ndarray, annotations: Sequence, values: Mapping[str, float]) -> np.ndarray:
    """``mask`` (H, W[, C]) with each labelled inserted object's visible pixels set to ``values[category]`` (all
    channels), later objects over earlier ones (their masks do not overlap: each pixel shows one object). A value
    the mask's dtype cannot hold raises."""
    mask = np.asarray(mask)
    out = mask.copy()
    hw = mask.shape[:2]
    for a in labelled(annotations):
        v = values[a.category]
        if np.array(v, np.float64).astype(mask.dtype).astype(np.float64) != float(v):
            raise ValueError(f"mask_values[{a.category!r}] = {v!r} does not fit the mask's dtype {mask.dtype}")
        out[_decoded(a.rle, hw)] = v
    return out


def keypoints_after(keypoints: np.ndarray, hidden: np.ndarray, remove_invisible: bool) -> np.ndarray:
    """``keypoints`` (N, 2+) in pixels (albumentations' internal x, y first) without the ones whose pixel an
    inserted object now shows, when ``remove_invisible`` (else unchanged). Keypoints outside the image are left for
    albumentations' own filter."""
    kp = np.asarray(keypoints)
    if not remove_invisible or len(kp) == 0:
        return kp
    h, w = hidden.shape
    x, y = np.floor(kp[:, 0]).astype(np.int64), np.floor(kp[:, 1]).astype(np.int64)
    inside = (x >= 0) & (x < w) & (y >= 0) & (y < h)
    under = np.zeros(len(kp), bool)
    under[inside] = hidden[y[inside], x[inside]]
    return kp[~under]

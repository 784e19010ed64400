"""Thin structures that may stand in front of an insertion site: poles, rails, posts, fences.

An object pasted over a rail or a pole that stands nearer than it looks afloat. Such structures are seldom labelled,
but they show as long straight edges off the ground: line segments (OpenCV's fast line detector) at least
:data:`MIN_LENGTH_FRAC` of the image height long whose points lie mostly outside the placeable ground, with ground
on at most one of their sides. The ground is taken with its small holes closed (:data:`CLOSE_PX`), and a segment
with ground on both sides is paint or a crack on the road (lane markings), not a structure; so a rail across the
road with road seen on both sides of it is not found either (only labelled objects occlude there). The placement (:func:`aias_augment.plan.placement.sample_placement`) refuses a site whose
object window such a segment crosses (a rail: its foot is unseen, so it may be nearer) or that a near-vertical
segment crosses down to the object's base row or below it (a pole whose foot is nearer than the object's).
"""

from __future__ import annotations

import cv2
import numpy as np

__all__ = ["MIN_LENGTH_FRAC", "CLOSE_PX", "thin_structure_segments"]

#: Shortest segment kept, as a fraction of the image height (a rail or pole spans more than a few pixels).
MIN_LENGTH_FRAC = 0.06
#: The placeable ground's holes up to about this size (pixels at 480 rows, scaled with the image) are closed before
#: asking whether a segment lies on the ground (markings, cracks, patches).
CLOSE_PX = 15
#: Points sampled along each segment; it is kept when fewer than half lie on the closed ground.
SAMPLES = 9


def thin_structure_segments(image: np.ndarray, region_mask: np.ndarray) -> np.ndarray:
    """(N, 4) float32 segments x1, y1, x2, y2 (pixels of ``image``) of long straight edges off the ground
    ``region_mask`` ((H, W) bool, the placeable region)."""
    h, w = region_mask.shape
    if image.shape[:2] != (h, w):
        raise ValueError(f"image {image.shape[:2]} and region mask {(h, w)} differ in size")
    grey = cv2.cvtColor(np.ascontiguousarray(image), cv2.COLOR_RGB2GRAY) if image.ndim == 3 else image
    min_len = max(8.0, MIN_LENGTH_FRAC * h)
    fld = cv2.ximgproc.createFastLineDetector(length_threshold=int(min_len))
    lines = fld.detect(grey)
    if lines is None or not region_mask.any():
        return np.zeros((0, 4), np.float32)
    seg = lines.reshape(-1, 4).astype(np.float32)
    k = max(3, int(round(CLOSE_PX * h / 480.0)) | 1)
    ground = cv2.morphologyEx(region_mask.astype(np.uint8), cv2.MORPH_CLOSE, cv2.getStructuringElement(2, (k, k)))
    t = np.linspace(0.0, 1.0, SAMPLES, dtype=np.float32)
    d = seg[:, 2:] - seg[:, :2]
    normal = np.c_[-d[:, 1], d[:, 0]] / np.maximum(np.hypot(d[:, 0], d[:, 1]), 1e-6)[:, None]

    def ground_share(offset: float) -> np.ndarray:
        xs = seg[:, None, 0] + t[None] * d[:, None, 0] + offset * normal[:, None, 0]
        ys = seg[:, None, 1] + t[None] * d[:, None, 1] + offset * normal[:, None, 1]
        xi = np.clip(np.rint(xs).astype(np.int64), 0, w - 1)
        yi = np.clip(np.rint(ys).astype(np.int64), 0, h - 1)
        return ground[yi, xi].mean(axis=1)

    side = float(k)
    on_ground = ground_share(0.0) >= 0.5
    marking = (ground_share(side) >= 0.5) & (ground_share(-side) >= 0.5)  # ground on both sides: paint, a crack
    return np.ascontiguousarray(seg[~on_ground & ~marking])

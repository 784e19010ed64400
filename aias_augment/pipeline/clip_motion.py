"""A clip object's motion and the room it takes: how far it has gone in each frame (:func:`travel_m`), its fall
when knocked over (:func:`topple`), and its box in the world per frame, which keeps several objects of one clip
apart (:func:`first_collision`)."""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from aias_augment.assets.asset import Asset
from aias_augment.core.oriented_box import OrientedBox
from aias_augment.plan.collision import boxes_intersect

if TYPE_CHECKING:
    from aias_augment.pipeline.clip_plan import ClipPlan, VideoInsertionConfig


def travel_m(n: int, start: int, cfg: VideoInsertionConfig) -> np.ndarray:
    """(n,) metres the object has gone along its heading in each frame, from where it is at frame ``start``: at its
    speed throughout, or standing for ``move_after_frames`` and then speeding up from rest over
    ``accelerate_frames`` (distance a k^2 / 2 with a = speed / frames, then speed per frame)."""
    v, wait, ramp = cfg.speed_m_per_frame, cfg.move_after_frames, cfg.accelerate_frames
    k = np.arange(n, dtype=np.float64) - start
    if not wait and not ramp:
        return k * v
    k = np.clip(k - wait, 0.0, None)
    if not ramp:
        return k * v
    return np.where(k <= ramp, 0.5 * v / ramp * k**2, 0.5 * v * ramp + v * (k - ramp))


def topple(obj: Asset, n: int, cfg: VideoInsertionConfig, rng: np.random.Generator):
    """Per frame the toppling object's asset (None before the fall) and ``object_from_frame`` (where that asset's
    origin lies in the upright object's frame), and the fall's record. The angle grows as t^2 (a constant angular
    acceleration from rest) over ``cfg.topple_frames`` frames up to the rest angle, and stays there."""
    from aias_augment.assets.deform import fall_segments, tipped

    frames = cfg.topple_frames
    if frames >= n:
        raise ValueError(f"topple_frames {frames} must be shorter than the clip ({n} frames)")
    start = int(rng.integers(0, n - frames)) if cfg.topple_start is None else cfg.topple_start
    if start + frames >= n:
        raise ValueError(f"the fall from frame {start} over {frames} frames does not end in the clip of {n}")
    azimuth = float(rng.uniform(-np.pi, np.pi))
    fall = fall_segments(obj, azimuth)
    rest = float(sum(t for _, t in fall[2]))
    assets: list[Asset | None] = [None] * n
    poses = [np.eye(4)] * n
    landed = None
    for i in range(start + 1, n):
        t = min((i - start) / frames, 1.0)
        if t == 1.0 and landed is not None:
            assets[i], poses[i] = landed
            continue
        tipped_obj, origin = tipped(obj, azimuth, rest * t * t, fall)
        T = np.eye(4)
        T[:3, 3] = origin
        assets[i], poses[i] = tipped_obj, T
        if t == 1.0:
            landed = (tipped_obj, T)
    fall = {
        "start": start,
        "frames": frames,
        "azimuth": assets[-1].meta["tipped"]["azimuth"],  # the base edge it tips over
        "rest_angle": rest,
    }
    return assets, poses, fall


def object_boxes_in_world(plan: ClipPlan) -> list[OrientedBox]:
    """The object's bounding box in the world in every frame of the clip (as it moves or falls), whether or not a
    camera sees it there: objects share the world, not the frame."""
    boxes = []
    for i, world_from_object in enumerate(plan.worlds_from_object):
        lo, hi = plan.asset_at(i).bounds_m
        T = world_from_object.copy()
        T[:3, 3] += T[:3, :3] @ ((lo + hi) / 2)
        boxes.append(OrientedBox(T, tuple(hi - lo)))
    return boxes


def first_collision(a: ClipPlan, b: ClipPlan, margin_m: float = 0.1) -> int | None:
    """The first frame in which the two planned objects' boxes, each inflated by ``margin_m``, intersect (exact
    separating-axis test), or None when they stay apart through the whole clip."""
    boxes_a, boxes_b = object_boxes_in_world(a), object_boxes_in_world(b)
    if len(boxes_a) != len(boxes_b):
        raise ValueError(f"plans of clips of {len(boxes_a)} and {len(boxes_b)} frames")
    for i, (ba, bb) in enumerate(zip(boxes_a, boxes_b)):
        if boxes_intersect(ba, bb, margin_m):
            return i
    return None

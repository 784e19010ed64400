"""A clip's labelled objects as occluders of the inserted ones, by depth order: per frame,
:mod:`aias_augment.apply.occluders` (the same rule as the image door's) on the clip's planned objects' projected
boxes and grounds. The labelled objects' depth maps go to the image door's compositor
(:func:`aias_augment.apply.composite.visible_fraction_against_depth`); their own visibility counts only the inserted
objects nearer than them.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from aias_augment.apply.occluders import (
    MIN_MASK_FRACTION,
    contact_depth,
    labelled_depth,
    object_mask_from_box,
    visibility_under_nearer,
)
from aias_augment.core.geometry import Intrinsics, project_points, transform_points

__all__ = ["MIN_MASK_FRACTION", "OccluderMaps", "labelled_visibility", "object_mask_from_box", "occluder_depths"]


@dataclass
class OccluderMaps:
    """Per frame, the labelled objects' depth map (None: nothing can occlude there) and, per labelled box of the
    frame, its occluder mask (None: not segmented, it meets no inserted object) and contact z (None: no contact)."""

    depths: list[np.ndarray | None]
    masks: list[list[np.ndarray | None]]
    contact_z: list[list[float | None]]
    grabcut: int = 0  # masks from GrabCut
    whole_box: int = 0  # boxes used whole (GrabCut found too little)


def _projected_boxes(plans, i: int, intrinsics: Intrinsics) -> list[np.ndarray]:
    """xyxy boxes of the planned objects' projected corners in frame ``i`` (those in front of the camera)."""
    out = []
    for plan in plans:
        T = plan.cams_from_object[i]
        if T is None:
            continue
        uv, z = project_points(transform_points(T, plan.asset_at(i).corners_m()), intrinsics.K)
        if np.all(z > 0) and np.all(np.isfinite(uv)):
            out.append(np.r_[uv.min(0), uv.max(0)])
    return out


def occluder_depths(frames, intrinsics: Intrinsics, plans, labels: list[list]) -> OccluderMaps:
    """The labelled objects' depth maps of the clip (see the module docstring). ``plans``: the inserted objects'
    :class:`~aias_augment.pipeline.clip.ClipPlan` (their grounds and projected boxes); ``labels``: per frame its
    :class:`~aias_augment.core.track_labels.TrackBox` list."""
    maps = OccluderMaps([], [], [])
    for i, (img, boxes) in enumerate(zip(frames, labels)):
        xywh = np.array([b.box_xywh for b in boxes], float).reshape(-1, 4)
        zs = [contact_depth(b, plans[0].grounds[i], intrinsics) for b in xywh]
        frame = labelled_depth(np.asarray(img), xywh, zs, _projected_boxes(plans, i, intrinsics))
        maps.grabcut += frame.grabcut
        maps.whole_box += frame.whole_box
        maps.depths.append(frame.depth)
        maps.masks.append(frame.masks)
        maps.contact_z.append(frame.contact_z)
    return maps


def labelled_visibility(
    boxes: list, contact_z: list[float | None], object_masks: list[np.ndarray | None], object_z: list[float | None]
) -> np.ndarray:
    """(len(boxes),) the fraction of each labelled box not covered by the visible coverages of the inserted objects
    nearer than it (``object_masks``/``object_z``: one frame's coverage and contact z per inserted object, None where
    it is not drawn; a labelled box without a contact z is far, behind every inserted object)."""
    xywh = np.array([b.box_xywh for b in boxes], float).reshape(-1, 4)
    return visibility_under_nearer(xywh, contact_z, object_masks, object_z)

"""A clip's labelled objects as occluders of the inserted ones, by depth order.

A labelled object stands on the ground: the ground point under the middle of its box's bottom edge (its contact)
gives its distance (z in the camera, :meth:`aias_augment.analyse.ground.GroundPlane.intersect_pixels`). Its pixels
are its box's GrabCut mask (:func:`aias_augment.assets.reconstruct.grabcut_mask` on a context crop around the box;
the whole box where GrabCut finds under :data:`MIN_MASK_FRACTION` of it). Those pixels get that z in a depth map
(0 elsewhere: unknown, which never occludes), which the image door's compositor compares with each inserted
surface's depth (:func:`aias_augment.apply.composite.visible_fraction_against_depth`): an inserted object behind a
labelled one is hidden inside the mask (its shadow too), one in front covers it. A box whose bottom edge is at or
above the horizon has no ground contact and is taken as far (it occludes nothing).

Only labelled boxes that meet an inserted object's projected box in that frame are segmented: the others cannot
hide anything, and the depth map is the same without them where it matters.

The labelled objects' own visibility under the inserted ones is the image door's, counting only the inserted
objects nearer than the labelled one (by contact z): the fraction of the box not covered by their visible coverage (:func:`aias_augment.apply.annotate.box_visibility_under_cover`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from aias_augment.analyse.ground import GroundPlane
from aias_augment.apply.annotate import box_visibility_under_cover
from aias_augment.core.geometry import Intrinsics, project_points, transform_points

__all__ = ["MIN_MASK_FRACTION", "OccluderMaps", "labelled_visibility", "object_mask_from_box", "occluder_depths"]

MIN_MASK_FRACTION = 0.1  # a GrabCut mask under this share of its box is a failed segmentation: the box is used
CONTEXT = 0.5  # context around the box given to GrabCut, as a fraction of the box's size on each side


@dataclass
class OccluderMaps:
    """Per frame, the labelled objects' depth map (None: nothing can occlude there) and, per labelled box of the
    frame, its occluder mask (None: not segmented, it meets no inserted object) and contact z (None: no contact)."""

    depths: list[np.ndarray | None]
    masks: list[list[np.ndarray | None]]
    contact_z: list[list[float | None]]
    grabcut: int = 0  # masks from GrabCut
    whole_box: int = 0  # boxes used whole (GrabCut found too little)


def object_mask_from_box(image_rgb: np.ndarray, box_xywh) -> tuple[np.ndarray, bool]:
    """(H, W) bool mask of the object in its COCO box (GrabCut on a context crop), and whether GrabCut gave it
    (False: the whole box, GrabCut found under :data:`MIN_MASK_FRACTION` of it or the box is under 4 px)."""
    from aias_augment.assets.reconstruct import grabcut_mask

    h, w = image_rgb.shape[:2]
    x, y, bw, bh = (float(v) for v in box_xywh)
    xa, ya = int(np.clip(np.floor(x), 0, w)), int(np.clip(np.floor(y), 0, h))
    xb, yb = int(np.clip(np.ceil(x + bw), 0, w)), int(np.clip(np.ceil(y + bh), 0, h))
    mask = np.zeros((h, w), bool)
    if xb <= xa or yb <= ya:
        return mask, False
    cx0, cy0 = max(0, int(xa - CONTEXT * bw)), max(0, int(ya - CONTEXT * bh))
    cx1, cy1 = min(w, int(np.ceil(xb + CONTEXT * bw))), min(h, int(np.ceil(yb + CONTEXT * bh)))
    try:
        cut = grabcut_mask(image_rgb[cy0:cy1, cx0:cx1], (xa - cx0, ya - cy0, xb - cx0, yb - cy0))
    except ValueError:  # a box under 4 px a side
        cut = None
    if cut is not None:
        mask[cy0:cy1, cx0:cx1] = cut
        mask[:ya], mask[yb:], mask[:, :xa], mask[:, xb:] = False, False, False, False
        if mask[ya:yb, xa:xb].mean() >= MIN_MASK_FRACTION:
            return mask, True
    mask[:] = False
    mask[ya:yb, xa:xb] = True
    return mask, False


def contact_depth(box_xywh, ground: GroundPlane, intrinsics: Intrinsics) -> float | None:
    """z (m) of the ground point under the middle of the box's bottom edge; None at or above the horizon."""
    x, y, w, h = (float(v) for v in box_xywh)
    p = ground.intersect_pixels(np.array([x + w / 2, y + h]), intrinsics)
    return float(p[2]) if np.all(np.isfinite(p)) and p[2] > 0 else None


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


def _meets(box_xywh, boxes_xyxy: list[np.ndarray]) -> bool:
    x, y, w, h = box_xywh
    return any(x < b[2] and b[0] < x + w and y < b[3] and b[1] < y + h for b in boxes_xyxy)


def occluder_depths(frames, intrinsics: Intrinsics, plans, labels: list[list]) -> OccluderMaps:
    """The labelled objects' depth maps of the clip (see the module docstring). ``plans``: the inserted objects'
    :class:`~aias_augment.pipeline.clip.ClipPlan` (their grounds and projected boxes); ``labels``: per frame its
    :class:`~aias_augment.core.track_labels.TrackBox` list."""
    maps = OccluderMaps([], [], [])
    for i, (img, boxes) in enumerate(zip(frames, labels)):
        inserted = _projected_boxes(plans, i, intrinsics)
        depth, masks, zs = None, [], []
        for b in boxes:
            z = contact_depth(b.box_xywh, plans[0].grounds[i], intrinsics)
            zs.append(z)
            if z is None or not _meets(b.box_xywh, inserted):
                masks.append(None)
                continue
            mask, cut = object_mask_from_box(np.asarray(img), b.box_xywh)
            maps.grabcut += cut
            maps.whole_box += not cut
            masks.append(mask)
            if depth is None:
                depth = np.zeros(mask.shape, np.float32)
            nearer = mask & ((depth <= 0) | (depth > z))  # overlapping labelled objects: the nearer one's z
            depth[nearer] = z
        maps.depths.append(depth)
        maps.masks.append(masks)
        maps.contact_z.append(zs)
    return maps


def labelled_visibility(
    boxes: list, contact_z: list[float | None], object_masks: list[np.ndarray | None], object_z: list[float | None]
) -> np.ndarray:
    """(len(boxes),) the fraction of each labelled box not covered by the visible coverages of the inserted objects
    nearer than it (``object_masks``/``object_z``: one frame's coverage and contact z per inserted object, None where
    it is not drawn; a labelled box without a contact z is far, behind every inserted object)."""
    out = np.ones(len(boxes))
    for j, (b, z) in enumerate(zip(boxes, contact_z)):
        nearer = [m for m, zk in zip(object_masks, object_z) if m is not None and (z is None or zk < z)]
        if nearer:
            x, y, w, h = b.box_xywh
            cover = np.clip(np.maximum.reduce(nearer), 0, 1)
            out[j] = box_visibility_under_cover(np.array([[x, y, x + w, y + h]], float), cover)[0]
    return out

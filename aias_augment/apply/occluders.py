"""A frame's labelled objects as occluders of the inserted ones, by depth order (images and clips alike).

A labelled object stands on the ground: the ground point under the middle of its box's bottom edge (its contact)
gives its distance (z in the camera, :meth:`aias_augment.analyse.ground.GroundPlane.intersect_pixels`). Its pixels
are its box's GrabCut mask (:func:`aias_augment.assets.reconstruct.grabcut_mask` on a context crop around the box;
the whole box where GrabCut finds under :data:`MIN_MASK_FRACTION` of it). Those pixels get that z in a depth map
(0 elsewhere: unknown, which never occludes), which the compositor compares with each inserted surface's depth
(:func:`aias_augment.apply.composite.visible_fraction_against_depth`): an inserted object behind a labelled one is
hidden inside the mask (its shadow too), one in front covers it. A box whose bottom edge is at or above the horizon
has no ground contact and is taken as far (it occludes nothing).

Only labelled boxes that meet an inserted object's box are segmented: the others cannot hide anything, and the depth
map is the same without them where it matters.

A labelled object's own visibility counts only the inserted objects nearer than it (by contact z): the fraction of
its box not covered by their visible coverage (:func:`aias_augment.apply.annotate.box_visibility_under_cover`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from aias_augment.analyse.ground import GroundPlane
from aias_augment.apply.annotate import box_visibility_under_cover
from aias_augment.core.geometry import Intrinsics

__all__ = [
    "MIN_MASK_FRACTION",
    "LabelledDepth",
    "contact_depth",
    "ground_scale",
    "image_occluders",
    "labelled_depth",
    "object_mask_from_box",
    "visibility_under_nearer",
]

MIN_MASK_FRACTION = 0.1  # a GrabCut mask under this share of its box is a failed segmentation: the box is used
CONTEXT = 0.5  # context around the box given to GrabCut, as a fraction of the box's size on each side


@dataclass
class LabelledDepth:
    """One frame's labelled objects as occluders: ``depth`` (H, W) float32 z of the segmented objects' pixels (0
    elsewhere; None: none was segmented), per labelled box its mask (None: not segmented, it meets no inserted
    object or has no contact) and contact z (None: no ground contact, far); how many masks came from GrabCut and
    how many are whole boxes (GrabCut found too little)."""

    depth: np.ndarray | None
    masks: list[np.ndarray | None]
    contact_z: list[float | None]
    grabcut: int = 0
    whole_box: int = 0


def object_mask_from_box(image_rgb: np.ndarray, box_xywh) -> tuple[np.ndarray, bool]:
    """(H, W) bool mask of the object in its COCO box (GrabCut on a context crop), and whether GrabCut gave it
    (False: the whole box, GrabCut found under :data:`MIN_MASK_FRACTION` of it or the box is under 4 px)."""
    from aias_augment.assets.view_masks import grabcut_mask

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


def _meets(box_xywh, boxes_xyxy) -> bool:
    x, y, w, h = (float(v) for v in box_xywh)
    return any(x < b[2] and b[0] < x + w and y < b[3] and b[1] < y + h for b in boxes_xyxy)


def labelled_depth(image_rgb: np.ndarray, boxes_xywh, contact_z: list[float | None], inserted_xyxy) -> LabelledDepth:
    """The labelled objects' depth map of one frame (see the module docstring). ``boxes_xywh`` (N, 4) COCO boxes
    with their contact z (``contact_z``, from :func:`contact_depth`; None: far); ``inserted_xyxy``: the inserted
    objects' boxes in this frame (only labelled boxes meeting one are segmented)."""
    out = LabelledDepth(None, [], list(contact_z))
    for b, z in zip(np.asarray(boxes_xywh, float).reshape(-1, 4), contact_z):
        if z is None or not _meets(b, inserted_xyxy):
            out.masks.append(None)
            continue
        mask, cut = object_mask_from_box(image_rgb, b)
        out.grabcut += cut
        out.whole_box += not cut
        out.masks.append(mask)
        if out.depth is None:
            out.depth = np.zeros(mask.shape, np.float32)
        nearer = mask & ((out.depth <= 0) | (out.depth > z))  # overlapping labelled objects: the nearer one's z
        out.depth[nearer] = z
    return out


def visibility_under_nearer(
    boxes_xywh,
    contact_z: list[float | None],
    covers: list[np.ndarray | None],
    object_z: list[float | None],
    origin: tuple[int, int] = (0, 0),
    frame_hw: tuple[int, int] | None = None,
) -> np.ndarray:
    """(N,) the fraction of each labelled box not covered by the visible coverages of the inserted objects nearer
    than it. ``covers``: per inserted object its visible coverage in [0, 1] (None: not drawn), all of one shape,
    placed at ``origin`` (x, y) of a ``frame_hw`` frame (default: the covers are the frame); ``object_z``: their
    contact z. A labelled box without a contact z is far, behind every inserted object."""
    boxes = np.asarray(boxes_xywh, float).reshape(-1, 4)
    out = np.ones(len(boxes))
    for j, (b, z) in enumerate(zip(boxes, contact_z)):
        nearer = [c for c, zk in zip(covers, object_z) if c is not None and (z is None or zk is None or zk < z)]
        if nearer:
            cover = np.clip(np.maximum.reduce(nearer), 0, 1)
            xyxy = np.array([[b[0], b[1], b[0] + b[2], b[1] + b[3]]])
            out[j] = box_visibility_under_cover(xyxy, cover, origin, frame_hw)[0]
    return out


def ground_scale(ground: GroundPlane, placement) -> float:
    """The factor by which a placement scaled the scene about the camera (an assumed-scale ground,
    :func:`aias_augment.plan.placement.scaled_ground`): its contact point's distance from the camera along
    ``ground``'s normal over ``ground``'s own (1 where either is not positive). Depths on ``ground`` times it are
    depths on the placement's ground: each inserted object is ordered against the labelled ones on its own."""
    d = -float(np.asarray(ground.normal, float) @ np.asarray(placement.contact_point_in_cam, float))
    return d / ground.d if ground.d > 0 and d > 0 else 1.0


def image_occluders(
    image_rgb: np.ndarray, boxes_xywh, ground: GroundPlane | None, intrinsics: Intrinsics, placements
) -> tuple[LabelledDepth | None, str]:
    """The labelled boxes of one image as occluders of its planned ``placements`` (their ``amodal_box_xyxy``),
    with what was done; depths on ``ground`` (scale them by :func:`ground_scale` for each placement). None (and
    why) without a ground or a placement."""
    boxes = np.asarray(boxes_xywh, float).reshape(-1, 4)
    if ground is None or not placements:
        return None, "no ground or nothing placed: labelled objects are not occluders"
    zs = [contact_depth(b, ground, intrinsics) for b in boxes]
    out = labelled_depth(image_rgb, boxes, zs, [np.asarray(p.amodal_box_xyxy, float) for p in placements])
    far = sum(z is None for z in zs)
    return out, (
        f"{len(boxes)} labelled boxes by contact depth ({far} without ground contact: far): "
        f"{out.grabcut + out.whole_box} meet an inserted object, segmented ({out.grabcut} GrabCut, "
        f"{out.whole_box} whole box); nearer ones hide the inserted objects, farther ones are covered"
    )

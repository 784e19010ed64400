"""Collision and occlusion checks for an object standing on the ground.

An inserted (or existing) object is an :class:`OrientedBox` in the camera frame. A candidate is rejected when
- scene 3D points (LiDAR, stereo/RGB-D depth) lie inside its box above the ground (``min_points_inside`` of them,
  ignoring a ``ground_clearance_m`` slab so that ground points under the footprint do not count);
- it intersects an existing object's box (separating-axis test on the two boxes);
- the scene depth says it would be mostly hidden (fraction of its projected footprint/box pixels where the scene
  is nearer than the object by ``depth_margin_m``).
Each check returns a reason string or None, so a placement report can say why a candidate was rejected; reasons
read ``"<stable key>: <detail>"`` so reports can count by ``reason.split(":")[0]``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from aias_augment.analyse.ground import GroundPlane
from aias_augment.core.config import checked_config
from aias_augment.core.geometry import Intrinsics, check_shape, project_points, transform_points
from aias_augment.core.oriented_box import OrientedBox

__all__ = [
    "CollisionConfig",
    "points_inside_box",
    "boxes_intersect",
    "box_pixel_mask",
    "scene_points_collision",
    "existing_objects_collision",
    "depth_occlusion",
    "check_candidate",
    "Rejection",
]


@checked_config(
    {  # every field checked at construction (type hint and these bounds)
        "margin_m": "[0, inf)",
        "ground_clearance_m": "[0, inf)",
        "min_points_inside": "[1, inf)",
        "depth_margin_m": "[0, inf)",
        "max_occluded_frac": "[0, 1]",
    }
)
@dataclass(frozen=True)
class CollisionConfig:
    margin_m: float = 0.05  # inflate the inserted box by this much on every side
    ground_clearance_m: float = 0.15  # points closer than this to the ground plane never collide
    min_points_inside: int = 3  # a LiDAR/stereo "cluster" needs this many points inside
    depth_margin_m: float = 0.3  # scene nearer than object - margin = occluder
    max_occluded_frac: float = 0.5  # reject when more of the object is hidden than this


def points_inside_box(points_in_cam: np.ndarray, box: OrientedBox, margin_m: float = 0.0) -> np.ndarray:
    """(N, 3) -> (N,) bool, inside the box inflated by ``margin_m``."""
    p = check_shape(points_in_cam, (None, 3), "points_in_cam")
    T = box.cam_from_box
    local = (p - T[:3, 3]) @ T[:3, :3]  # box_from_cam applied row-wise
    half = np.asarray(box.size_xyz_m) / 2 + margin_m
    return np.all(np.abs(local) <= half, axis=1)


def boxes_intersect(a: OrientedBox, b: OrientedBox, margin_m: float = 0.0) -> bool:
    """Exact separating-axis test for two oriented boxes (15 axes); ``margin_m`` inflates both."""
    ra, rb = a.cam_from_box[:3, :3], b.cam_from_box[:3, :3]
    ha = np.asarray(a.size_xyz_m) / 2 + margin_m
    hb = np.asarray(b.size_xyz_m) / 2 + margin_m
    t = b.cam_from_box[:3, 3] - a.cam_from_box[:3, 3]
    axes = [ra[:, i] for i in range(3)] + [rb[:, i] for i in range(3)]
    axes += [np.cross(ra[:, i], rb[:, j]) for i in range(3) for j in range(3)]
    for axis in axes:
        length = np.linalg.norm(axis)
        if length < 1e-9:  # parallel edges: axis already covered by the face normals
            continue
        axis = axis / length
        proj_a = np.sum(ha * np.abs(ra.T @ axis))
        proj_b = np.sum(hb * np.abs(rb.T @ axis))
        if abs(t @ axis) > proj_a + proj_b:
            return False
    return True


def box_pixel_mask(box: OrientedBox, intrinsics: Intrinsics) -> np.ndarray | None:
    """(H, W) bool of the convex hull of the box's projected corners; None if a corner is behind the camera."""
    import cv2  # local: keeps the pure-numpy checks importable without OpenCV

    uv, z = project_points(box.corners(), intrinsics.K)
    if np.any(z <= 0) or not np.all(np.isfinite(uv)):
        return None
    mask = np.zeros((intrinsics.height, intrinsics.width), np.uint8)
    hull = cv2.convexHull(np.round(uv).astype(np.int32))
    cv2.fillConvexPoly(mask, hull, 1)
    return mask.astype(bool)


@dataclass(frozen=True)
class Rejection:
    """Why a candidate was refused: ``kind``, what the placement report counts, and ``detail``, its numbers."""

    kind: str
    detail: str = ""

    def __str__(self) -> str:
        return f"{self.kind}: {self.detail}" if self.detail else self.kind


def scene_points_collision(
    box: OrientedBox, points_in_cam: np.ndarray | None, ground: GroundPlane, cfg: CollisionConfig = CollisionConfig()
) -> Rejection | None:
    if points_in_cam is None or len(points_in_cam) == 0:
        return None
    p = np.asarray(points_in_cam, dtype=np.float64)
    above = ground.signed_distance(p) > cfg.ground_clearance_m
    inside = points_inside_box(p[above], box, cfg.margin_m)
    n = int(inside.sum())
    if n >= cfg.min_points_inside:
        return Rejection("intersects scene points above the ground", f"{n} points")
    return None


def existing_objects_collision(
    box: OrientedBox, existing: list[OrientedBox] | None, cfg: CollisionConfig = CollisionConfig()
) -> Rejection | None:
    for other in existing or ():
        if boxes_intersect(box, other, cfg.margin_m):
            return Rejection("intersects an existing object", other.label or "(unnamed)")
    return None


def depth_occlusion(
    box: OrientedBox, depth: np.ndarray | None, intrinsics: Intrinsics, cfg: CollisionConfig = CollisionConfig()
) -> tuple[Rejection | None, float]:
    """(rejection or None, occluded fraction) from a per-pixel test of the box's nearest depth against scene depth.

    The object's depth at a pixel is approximated by its nearest corner depth (conservative: calls a pixel
    occluded only when the scene is nearer than every part of the box). Unknown scene depth (0/NaN) is not
    evidence of occlusion.
    """
    if depth is None:
        return None, 0.0
    mask = box_pixel_mask(box, intrinsics)
    if mask is None:
        return Rejection("object crosses the camera plane"), 1.0
    if not mask.any():
        return Rejection("object projects outside the image"), 1.0
    scene = np.asarray(depth, dtype=np.float32)[mask]
    known = np.isfinite(scene) & (scene > 0)
    if not known.any():
        return None, 0.0
    nearest = float(transform_points(np.eye(4), box.corners())[:, 2].min())
    occluded = float(np.mean(scene[known] < nearest - cfg.depth_margin_m))
    if occluded > cfg.max_occluded_frac:
        return Rejection("hidden behind nearer scene surfaces", f"{occluded:.0%} of its pixels"), occluded
    return None, occluded


def check_candidate(
    box: OrientedBox,
    ground: GroundPlane,
    intrinsics: Intrinsics,
    *,
    points_in_cam: np.ndarray | None = None,
    existing: list[OrientedBox] | None = None,
    depth: np.ndarray | None = None,
    cfg: CollisionConfig = CollisionConfig(),
) -> Rejection | None:
    """The first reason to reject the candidate box, or None when it passes every check."""
    return (
        existing_objects_collision(box, existing, cfg)
        or scene_points_collision(box, points_in_cam, ground, cfg)
        or depth_occlusion(box, depth, intrinsics, cfg)[0]
    )

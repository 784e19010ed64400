"""KITTI-3D object labels (the devkit's ``label_2`` lines and ``calib`` files) from an inserted object's pose.

A label line is ``type truncated occluded alpha x0 y0 x1 y1 h w l x y z rotation_y`` in the camera frame of the
KITTI devkit (OpenCV: x right, y down, z forward; metres):

- ``h w l``: the box's height (object z, up), width (object y) and length (object x, the heading);
- ``x y z``: the centre of the box's bottom face;
- ``rotation_y``: the heading about the camera's y axis, so that the devkit's box corners
  ``R_y(ry) @ [±l/2, 0 or -h, ±w/2] + (x, y, z)`` are the object's (the heading is ``(cos ry, 0, -sin ry)``);
- ``alpha = rotation_y - atan2(x, z)``, the observation angle, wrapped to [-pi, pi);
- ``truncated``: the share of the projected 3D box outside the image, in [0, 1];
- ``occluded``: 0 fully visible (visibility >= :data:`VISIBLE_FULLY`), 1 partly (>= :data:`VISIBLE_PARTLY`),
  2 largely occluded, from the visible share of the object's pixels.

The devkit's box stands upright on ``y``: an object standing on a ground plane that is not level in the camera
frame (a rolled or pitched camera) is written with its heading projected onto the camera's x-z plane and its tilt
from upright returned (:attr:`Box3D.tilt_deg`), so an export can say how far from exact its boxes are.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

__all__ = [
    "Box3D",
    "VISIBLE_FULLY",
    "VISIBLE_PARTLY",
    "box_from_pose",
    "calib_text",
    "devkit_corners",
    "dontcare_line",
    "label_line",
    "occlusion_level",
    "truncation",
]

VISIBLE_FULLY = 0.9
VISIBLE_PARTLY = 0.5


@dataclass(frozen=True)
class Box3D:
    """A KITTI 3D box: dimensions (m), bottom-face centre in the camera frame (m), heading about camera y (rad)."""

    h: float
    w: float
    l: float  # noqa: E741  (the devkit's name)
    x: float
    y: float
    z: float
    rotation_y: float
    tilt_deg: float  # angle between the object's up axis and the camera's up (-y): 0 for level ground

    @property
    def alpha(self) -> float:
        return wrap_angle(self.rotation_y - math.atan2(self.x, self.z))


def wrap_angle(a: float) -> float:
    """``a`` in [-pi, pi)."""
    return (a + math.pi) % (2.0 * math.pi) - math.pi


def box_from_pose(cam_from_object, box_in_object_m) -> Box3D:
    """The KITTI box of an object at ``cam_from_object`` (4x4, object x the heading, z up) whose axis-aligned bounds
    in its own frame are ``box_in_object_m`` ((x0, y0, z0), (x1, y1, z1))."""
    T = np.asarray(cam_from_object, float)
    lo, hi = (np.asarray(v, float) for v in box_in_object_m)
    if T.shape != (4, 4) or lo.shape != (3,) or hi.shape != (3,) or np.any(hi <= lo):
        raise ValueError(f"expected a 4x4 pose and bounds lo < hi, got {T.shape} and {lo}, {hi}")
    bottom_in_object = np.array([(lo[0] + hi[0]) / 2, (lo[1] + hi[1]) / 2, lo[2], 1.0])
    x, y, z = (T @ bottom_in_object)[:3]
    R = T[:3, :3]
    heading = R[:, 0]
    up = R[:, 2] / np.linalg.norm(R[:, 2])
    tilt = math.degrees(math.acos(float(np.clip(-up[1], -1.0, 1.0))))  # clamped: arccos of a rounded dot
    ry = math.atan2(-heading[2], heading[0])
    l, w, h = (hi - lo).tolist()  # noqa: E741
    return Box3D(h, w, l, float(x), float(y), float(z), wrap_angle(ry), tilt)


def devkit_corners(box: Box3D) -> np.ndarray:
    """(8, 3) corners in the camera frame, as the KITTI devkit's ``computeBox3D`` builds them."""
    c, s = math.cos(box.rotation_y), math.sin(box.rotation_y)
    R = np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])
    xs = np.array([1, 1, -1, -1, 1, 1, -1, -1]) * box.l / 2
    ys = np.array([0, 0, 0, 0, -1, -1, -1, -1]) * box.h
    zs = np.array([1, -1, -1, 1, 1, -1, -1, 1]) * box.w / 2
    return (R @ np.stack([xs, ys, zs])).T + np.array([box.x, box.y, box.z])


def truncation(box_xyxy, width: int, height: int) -> float:
    """The share of the (projected, unclipped) box ``box_xyxy`` outside the image [0, width] x [0, height]."""
    x0, y0, x1, y1 = (float(v) for v in box_xyxy)
    area = max(x1 - x0, 0.0) * max(y1 - y0, 0.0)
    if area <= 0:
        return 1.0
    inside = max(min(x1, width) - max(x0, 0.0), 0.0) * max(min(y1, height) - max(y0, 0.0), 0.0)
    return float(min(max(1.0 - inside / area, 0.0), 1.0))


def occlusion_level(visibility: float) -> int:
    """KITTI's occluded field from the visible share of the object's pixels."""
    if visibility >= VISIBLE_FULLY:
        return 0
    return 1 if visibility >= VISIBLE_PARTLY else 2


def label_line(type_name: str, box: Box3D, box2d_xyxy, truncated: float, occluded: int) -> str:
    """One ``label_2`` line (the devkit's two decimals). ``type_name`` must not contain white space."""
    if not type_name or any(ch.isspace() for ch in type_name):
        raise ValueError(f"KITTI type {type_name!r}: one word without spaces")
    x0, y0, x1, y1 = (float(v) for v in box2d_xyxy)
    values = (truncated, occluded, box.alpha, x0, y0, x1, y1, box.h, box.w, box.l, box.x, box.y, box.z)
    head = f"{type_name} {values[0]:.2f} {int(values[1])} " + " ".join(f"{v:.2f}" for v in values[2:])
    return f"{head} {box.rotation_y:.2f}"


def dontcare_line(box2d_xyxy) -> str:
    """A ``DontCare`` region (an object in the image without a 3D label): the devkit ignores detections there."""
    x0, y0, x1, y1 = (float(v) for v in box2d_xyxy)
    return f"DontCare -1 -1 -10 {x0:.2f} {y0:.2f} {x1:.2f} {y1:.2f} -1 -1 -1 -1000 -1000 -1000 -10"


def calib_text(K) -> str:
    """A KITTI ``calib`` file for one image: every camera matrix ``P0..P3 = [K | 0]`` (the labels are in the
    image's own camera frame), ``R0_rect`` the identity, the LiDAR and IMU transforms the identity."""
    K = np.asarray(K, float)
    if K.shape != (3, 3):
        raise ValueError(f"K must be 3x3, got {K.shape}")
    P = np.c_[K, np.zeros(3)]
    rigid = np.c_[np.eye(3), np.zeros(3)]

    def row(name, m):
        return f"{name}: " + " ".join(f"{v:.12e}" for v in np.asarray(m, float).ravel())

    rows = [row(f"P{i}", P) for i in range(4)]
    rows += [row("R0_rect", np.eye(3)), row("Tr_velo_to_cam", rigid), row("Tr_imu_to_velo", rigid)]
    return "\n".join(rows) + "\n"

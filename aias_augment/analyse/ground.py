"""The ground plane ``n . p + d = 0`` (the paper's Ax + By + Cz + D = 0) in the OpenCV camera frame of one frame.

Conventions:
- ``normal`` is unit length and points UP, i.e. toward the side of the plane where the camera is. With the camera
  at the origin, ``d = n . 0 + d`` is the signed distance of the camera above the ground: the camera height (> 0).
- ``signed_distance(p) > 0`` above the ground, < 0 below it.
- A plane is attached to one camera frame; :meth:`GroundPlane.transformed` moves it to another.

Robust fitting: RANSAC over 3-point samples whose normal lies within ``max_tilt_deg`` of ``up_hint`` and whose
plane passes below the origin, then a least-squares refit (SVD) on the inliers of the best sample.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from aias_augment.core.geometry import (
    CAMERA_HEIGHT_PRIOR_M,
    MIN_DEPTH,
    Intrinsics,
    check_rigid,
    check_shape,
    rotation_about_axis,
    transform_points,
    unproject_points,
)
from aias_augment.core.plane_fit import GroundFitError, fit_plane

__all__ = [
    "GroundFitError",
    "GroundPlane",
    "fit_ground_plane",
    "ground_plane_from_depth",
    "prior_ground_plane",
    "project_world_point_track",
    "depth_to_points",
]

#: |n . r| below this (rays parallel to the plane, i.e. at the horizon) never hit the ground.
RAY_PARALLEL_EPS = 1e-9


@dataclass(frozen=True, eq=False)
class GroundPlane:
    """Plane ``normal . p + d = 0`` in one camera frame (OpenCV axes, metres); normal unit, pointing up.
    ``assumed_scale``: its distance ``d`` is a prior (an assumed camera height), not a measurement (depth, LiDAR,
    poses), so a placement may rescale the scene about the camera."""

    normal: np.ndarray
    d: float
    source: str
    inlier_ratio: float = 1.0
    rms_m: float = 0.0
    num_inliers: int = field(default=0, compare=False)
    assumed_scale: bool = False

    def __eq__(self, other):
        if not isinstance(other, GroundPlane):
            return NotImplemented
        return (
            np.array_equal(self.normal, other.normal)
            and self.d == other.d
            and self.source == other.source
            and self.inlier_ratio == other.inlier_ratio
            and self.rms_m == other.rms_m
            and self.assumed_scale == other.assumed_scale
        )

    __hash__ = None  # mutable-free but holds an ndarray: compare with ==, do not hash

    def __post_init__(self):
        n = np.asarray(self.normal, dtype=np.float64).reshape(-1)
        if n.shape != (3,) or not np.all(np.isfinite(n)):
            raise ValueError(f"GroundPlane.normal must be 3 finite numbers, got {self.normal}")
        length = np.linalg.norm(n)
        if length < 1e-12:
            raise ValueError("GroundPlane.normal has zero length")
        if not np.isfinite(self.d):
            raise ValueError(f"GroundPlane.d must be finite, got {self.d}")
        n = n / length
        n.setflags(write=False)
        object.__setattr__(self, "normal", n)
        object.__setattr__(self, "d", float(self.d / length))

    @property
    def camera_height_m(self) -> float:
        """Height of the camera centre above the plane (negative: camera below it)."""
        return self.d

    @property
    def coefficients(self) -> np.ndarray:
        """(A, B, C, D) of the paper's Ax + By + Cz + D = 0."""
        return np.array([*self.normal, self.d])

    def signed_distance(self, points_in_cam: np.ndarray) -> np.ndarray:
        """(*, 3) -> (*,) metres, > 0 above the ground."""
        p = check_shape(points_in_cam, ("*", 3), "points_in_cam").astype(np.float64)
        return p @ self.normal + self.d

    def project_to_plane(self, points_in_cam: np.ndarray) -> np.ndarray:
        """Orthogonal projection onto the plane, (*, 3) -> (*, 3)."""
        p = check_shape(points_in_cam, ("*", 3), "points_in_cam").astype(np.float64)
        return p - self.signed_distance(p)[..., None] * self.normal

    def intersect_rays(self, rays_in_cam: np.ndarray) -> np.ndarray:
        """Where rays from the camera centre meet the plane, (*, 3) directions -> (*, 3) points.

        NaN where the ray does not hit the ground in front: rays parallel to the plane (at the horizon,
        |n . r| < RAY_PARALLEL_EPS), rays pointing away from it (above the horizon, t <= 0), zero rays, and hits
        behind the camera plane (z <= MIN_DEPTH).
        Directions need not be unit length.
        """
        r = check_shape(rays_in_cam, ("*", 3), "rays_in_cam").astype(np.float64)
        denom = r @ self.normal
        hits = np.abs(denom) > RAY_PARALLEL_EPS
        t = np.where(hits, -self.d / np.where(hits, denom, 1.0), np.nan)
        t = np.where(t > 0, t, np.nan)
        points = r * t[..., None]
        points[~(points[..., 2] > MIN_DEPTH)] = np.nan  # behind the camera plane: not visible, not placeable
        return points

    def intersect_pixels(self, uv: np.ndarray, intrinsics: Intrinsics) -> np.ndarray:
        """Ground point seen at pixels (*, 2) -> (*, 3) in camera frame, NaN above the horizon."""
        rays = unproject_points(uv, np.ones(np.asarray(uv).shape[:-1]), intrinsics.K)
        return self.intersect_rays(rays)

    def transformed(self, cam2_from_cam1: np.ndarray) -> "GroundPlane":
        """The same physical plane expressed in another frame: n2 = R n1, d2 = d1 - n2 . t."""
        T = check_rigid(cam2_from_cam1, "cam2_from_cam1")
        n2 = T[:3, :3] @ self.normal
        return GroundPlane(
            n2,
            self.d - float(n2 @ T[:3, 3]),
            self.source,
            self.inlier_ratio,
            self.rms_m,
            self.num_inliers,
            self.assumed_scale,
        )

    def horizon_line(self, intrinsics: Intrinsics) -> np.ndarray:
        """Vanishing line of the plane in the image: l = K^-T n (a, b, c) with a u + b v + c = 0, scaled so that
        (a, b) is unit length and ground pixels (below the horizon) have a u + b v + c > 0."""
        line = np.linalg.inv(intrinsics.K).T @ self.normal
        # Ground pixels have rays with n . r < 0; flip so that they are on the positive side.
        line = -line
        norm_ab = np.hypot(line[0], line[1])
        if norm_ab < 1e-12:
            raise ValueError("plane is parallel to the image plane: its horizon is at infinity")
        return line / norm_ab

    def horizon_row_at(self, u: float | np.ndarray, intrinsics: Intrinsics) -> np.ndarray:
        """Image row v of the horizon at column(s) u (NaN if the horizon is vertical)."""
        a, b, c = self.horizon_line(intrinsics)
        u = np.asarray(u, dtype=np.float64)
        return np.where(abs(b) > 1e-12, -(a * u + c) / (b if abs(b) > 1e-12 else 1.0), np.nan)

    def pitch_roll_rad(self) -> tuple[float, float]:
        """Camera pitch (> 0 looking down) and roll implied by the normal, inverse of :func:`prior_ground_plane`."""
        nx, ny, nz = self.normal
        pitch = float(np.arcsin(np.clip(-nz, -1.0, 1.0)))
        roll = float(np.arctan2(nx, -ny))
        return pitch, roll

    def to_dict(self) -> dict:
        return {
            "normal": self.normal.tolist(),
            "d": self.d,
            "source": self.source,
            "inlier_ratio": self.inlier_ratio,
            "rms_m": self.rms_m,
            "num_inliers": self.num_inliers,
        }


def prior_ground_plane(
    camera_height_m: float = CAMERA_HEIGHT_PRIOR_M, pitch_rad: float = 0.0, roll_rad: float = 0.0
) -> GroundPlane:
    """Ground for a camera ``camera_height_m`` above flat ground.

    Level camera: normal (0, -1, 0), d = height. ``pitch_rad`` > 0 tilts the optical axis down (the horizon moves
    up in the image: v = cy - fy tan(pitch)); ``roll_rad`` rotates the camera about its optical axis.
    """
    if not (np.isfinite(camera_height_m) and camera_height_m > 0):
        raise ValueError(f"camera_height_m must be positive, got {camera_height_m}")
    # cam_from_level = Rz(roll) Rx(pitch): up (0,-1,0) of the level frame seen from the tilted camera.
    up = rotation_about_axis([0, 0, 1], roll_rad) @ rotation_about_axis([1, 0, 0], pitch_rad) @ np.array([0, -1.0, 0])
    return GroundPlane(up, float(camera_height_m), "prior", assumed_scale=True)


def fit_ground_plane(
    points_in_cam: np.ndarray,
    rng: np.random.Generator,
    *,
    up_hint=(0.0, -1.0, 0.0),
    max_tilt_deg: float = 20.0,
    threshold_m: float = 0.05,
    iterations: int = 200,
    local_center=None,
    local_radius_m: float | None = None,
    min_inliers: int = 3,
    max_score_points: int = 20000,
    source: str = "ransac",
) -> GroundPlane:
    """Robust ground plane through 3D points in a camera (or sensor) frame whose origin is above the ground.

    points_in_cam: (N, 3); non-finite rows are dropped.
    up_hint: approximate world-up in this frame (OpenCV camera: (0, -1, 0)); the fitted normal is within
        ``max_tilt_deg`` of it, and oriented along it.
    local_center, local_radius_m: keep only points whose distance to ``local_center`` measured perpendicular to
        ``up_hint`` is below the radius (the ground near an insertion point).
    Candidates must pass below the origin (d > 0): a plane above the camera is not its ground.
    Scoring uses at most ``max_score_points`` points drawn with ``rng``; the final refit uses all inliers.

    Raises GroundFitError on too few points, collinear points, or no plane near ``up_hint`` with ``min_inliers``.
    """
    fit = fit_plane(
        points_in_cam,
        rng,
        up_hint=up_hint,
        max_tilt_deg=max_tilt_deg,
        threshold_m=threshold_m,
        iterations=iterations,
        local_center=local_center,
        local_radius_m=local_radius_m,
        min_inliers=min_inliers,
        max_score_points=max_score_points,
    )
    return GroundPlane(
        fit.normal, fit.d, source, inlier_ratio=fit.inlier_ratio, rms_m=fit.rms_m, num_inliers=fit.num_inliers
    )


def depth_to_points(
    depth: np.ndarray, intrinsics: Intrinsics, mask: np.ndarray | None = None, max_depth_m: float | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """Valid depth pixels -> (points (N, 3) in camera frame, pixel indices (N, 2) as (row, col))."""
    depth = np.asarray(depth, dtype=np.float32)
    if depth.shape != (intrinsics.height, intrinsics.width):
        raise ValueError(f"depth {depth.shape} does not match intrinsics {intrinsics.height}x{intrinsics.width}")
    valid = np.isfinite(depth) & (depth > MIN_DEPTH)
    if max_depth_m is not None:
        valid &= depth < max_depth_m
    if mask is not None:
        mask = np.asarray(mask, dtype=bool)
        if mask.shape != depth.shape:
            raise ValueError(f"mask {mask.shape} does not match depth {depth.shape}")
        valid &= mask
    rows, cols = np.nonzero(valid)
    uv = np.stack([cols, rows], axis=-1).astype(np.float64)
    points = unproject_points(uv, depth[rows, cols].astype(np.float64), intrinsics.K)
    return points, np.stack([rows, cols], axis=-1)


def ground_plane_from_depth(
    depth: np.ndarray,
    intrinsics: Intrinsics,
    rng: np.random.Generator,
    *,
    mask: np.ndarray | None = None,
    max_depth_m: float | None = None,
    max_points: int = 60000,
    **fit_kw,
) -> GroundPlane:
    """Fit the ground to a depth map (0 / non-finite = unknown), optionally restricted to ``mask`` pixels and to
    depths below ``max_depth_m`` (stereo noise grows with z^2). At most ``max_points`` pixels drawn with ``rng``."""
    points, _ = depth_to_points(depth, intrinsics, mask, max_depth_m)
    if len(points) > max_points:
        points = points[rng.choice(len(points), max_points, replace=False)]
    fit_kw.setdefault("source", "depth")
    return fit_ground_plane(points, rng, **fit_kw)


def project_world_point_track(
    point_in_world: np.ndarray, intrinsics: Intrinsics, cams_from_world
) -> tuple[np.ndarray, np.ndarray]:
    """The paper's projection of one world point through K [R | t] of every frame.

    point_in_world: (3,), e.g. the ground under the camera position of frame N + T.
    cams_from_world: sequence of (4, 4) OpenCV ``cam_from_world`` poses, one per frame.
    Returns pixels (N, 2) (NaN where the point is on or behind the camera plane) and visibility (N,) bool: in front
    of the camera and inside the image ([-0.5, W - 0.5) x [-0.5, H - 0.5)).
    """
    pw = check_shape(np.asarray(point_in_world, dtype=np.float64), (3,), "point_in_world")
    poses = np.asarray(cams_from_world, dtype=np.float64)
    if poses.ndim != 3 or poses.shape[1:] != (4, 4):
        raise ValueError(f"cams_from_world must be a sequence of 4x4 poses, got shape {poses.shape}")
    points_in_cams = np.stack([transform_points(T, pw) for T in poses])
    z = points_in_cams[:, 2]
    in_front = z > MIN_DEPTH
    zs = np.where(in_front, z, 1.0)
    uv = (points_in_cams @ intrinsics.K.T)[:, :2] / zs[:, None]
    uv[~in_front] = np.nan
    inside = in_front.copy()
    inside[in_front] = (
        (uv[in_front, 0] >= -0.5)
        & (uv[in_front, 0] < intrinsics.width - 0.5)
        & (uv[in_front, 1] >= -0.5)
        & (uv[in_front, 1] < intrinsics.height - 0.5)
    )
    return uv, inside

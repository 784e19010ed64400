"""A robust plane through 3D points, with a prior on its normal: RANSAC over 3-point samples whose normal lies within
``max_tilt_deg`` of ``up_hint`` and whose plane passes below the origin, then a least-squares refit (SVD) on the
inliers of the best sample. The ground of a frame (:func:`aias_augment.analyse.ground.fit_ground_plane`) and the
floor under a photographed object (:func:`aias_augment.assets.sfm.ground_gauge`) are found this way.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from aias_augment.core.errors import AiasError
from aias_augment.core.geometry import check_shape

__all__ = ["COLLINEAR_RATIO", "DEGENERATE_AREA_EPS", "GroundFitError", "PlaneFit", "fit_plane"]

#: A 3-point sample whose cross product is shorter than this (m^2) is degenerate (collinear) and skipped.
DEGENERATE_AREA_EPS = 1e-9
#: Points whose second singular value is below this fraction of the first are collinear (no unique plane).
COLLINEAR_RATIO = 1e-6


class GroundFitError(AiasError, ValueError):
    """No trustworthy ground plane: too few points, collinear points, or no plane near the up direction."""


@dataclass(frozen=True, eq=False)
class PlaneFit:
    """The fitted plane ``normal . p + d = 0`` as the fit leaves it (normal of unit length up to rounding, oriented
    along the up hint), the share of the points that are its inliers, their rms distance and count."""

    normal: np.ndarray
    d: float
    inlier_ratio: float
    rms_m: float
    num_inliers: int


def _plane_from_svd(points: np.ndarray, up: np.ndarray) -> tuple[np.ndarray, float, np.ndarray]:
    """Least-squares plane through points (normal = smallest singular vector), oriented toward ``up``."""
    centroid = points.mean(axis=0)
    _, s, vt = np.linalg.svd(points - centroid, full_matrices=False)
    n = vt[-1]
    if n @ up < 0:
        n = -n
    return n, float(-n @ centroid), s


def _check_not_collinear(points: np.ndarray) -> None:
    if len(points) < 3:
        raise GroundFitError(f"need at least 3 points to fit a plane, got {len(points)}")
    _, s, _ = np.linalg.svd(points - points.mean(axis=0), full_matrices=False)
    if s[0] < 1e-12 or s[1] < COLLINEAR_RATIO * s[0]:
        raise GroundFitError(f"points are collinear or coincident (singular values {s.tolist()}): no unique plane")


def fit_plane(
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
) -> PlaneFit:
    """Robust plane through 3D points in a frame whose origin is above the plane (a camera over the ground).

    points_in_cam: (N, 3); non-finite rows are dropped.
    up_hint: approximate up in this frame (OpenCV camera: (0, -1, 0)); the fitted normal is within ``max_tilt_deg``
        of it, and oriented along it.
    local_center, local_radius_m: keep only points whose distance to ``local_center`` measured perpendicular to
        ``up_hint`` is below the radius (the ground near an insertion point).
    Candidates must pass below the origin (d > 0): a plane above the origin is not its ground.
    Scoring uses at most ``max_score_points`` points drawn with ``rng``; the final refit uses all inliers.

    Raises GroundFitError on too few points, collinear points, or no plane near ``up_hint`` with ``min_inliers``.
    """
    p = check_shape(np.asarray(points_in_cam, dtype=np.float64), (None, 3), "points_in_cam")
    p = p[np.all(np.isfinite(p), axis=1)]
    up = np.asarray(up_hint, dtype=np.float64).reshape(3)
    up_len = np.linalg.norm(up)
    if up_len < 1e-12:
        raise ValueError("up_hint has zero length")
    up = up / up_len
    if not (0 < max_tilt_deg <= 90):
        raise ValueError(f"max_tilt_deg must be in (0, 90], got {max_tilt_deg}")
    if threshold_m <= 0 or iterations < 1:
        raise ValueError(f"threshold_m must be > 0 and iterations >= 1, got {threshold_m}, {iterations}")
    if local_center is not None:
        if local_radius_m is None or local_radius_m <= 0:
            raise ValueError("local_center needs a positive local_radius_m")
        offset = p - np.asarray(local_center, dtype=np.float64).reshape(3)
        horizontal = offset - (offset @ up)[:, None] * up
        p = p[np.linalg.norm(horizontal, axis=1) < local_radius_m]
    _check_not_collinear(p)
    min_inliers = max(3, int(min_inliers))
    cos_max_tilt = np.cos(np.deg2rad(max_tilt_deg))

    score_pts = p if len(p) <= max_score_points else p[rng.choice(len(p), max_score_points, replace=False)]
    # Vectorised RANSAC: all 3-point samples at once.
    idx = np.stack([rng.choice(len(p), 3, replace=False) for _ in range(iterations)])
    a, b, c = p[idx[:, 0]], p[idx[:, 1]], p[idx[:, 2]]
    normals = np.cross(b - a, c - a)
    area = np.linalg.norm(normals, axis=1)
    ok = area > DEGENERATE_AREA_EPS
    normals = normals / np.where(ok, area, 1.0)[:, None]
    normals *= np.where(normals @ up < 0, -1.0, 1.0)[:, None]
    ds = -np.einsum("ij,ij->i", normals, a)
    ok &= (normals @ up >= cos_max_tilt) & (ds > 0)
    if not np.any(ok):
        raise GroundFitError(
            f"no plane within {max_tilt_deg} deg of up {up.tolist()} below the origin among {iterations} samples "
            f"of {len(p)} points"
        )
    normals, ds = normals[ok], ds[ok]
    dist = np.abs(score_pts @ normals.T + ds)  # (M, K)
    inl = dist < threshold_m
    counts = inl.sum(axis=0)
    # Tie-break equal counts by the smaller truncated residual (MSAC-like).
    cost = np.where(inl, dist, threshold_m).sum(axis=0)
    best = int(np.lexsort((cost, -counts))[0])
    n, d = normals[best], ds[best]

    for _ in range(3):  # refit on inliers, re-select inliers with the refined plane
        inliers = np.abs(p @ n + d) < threshold_m
        if inliers.sum() < min_inliers:
            break
        n_new, d_new, _ = _plane_from_svd(p[inliers], up)
        if n_new @ up < cos_max_tilt or d_new <= 0:
            break
        n, d = n_new, d_new
    residual = p @ n + d
    inliers = np.abs(residual) < threshold_m
    num_inliers = int(inliers.sum())
    if num_inliers < min_inliers:
        raise GroundFitError(f"best plane has {num_inliers} inliers < min_inliers={min_inliers}")
    rms = float(np.sqrt(np.mean(residual[inliers] ** 2)))
    return PlaneFit(n, d, num_inliers / len(p), rms, num_inliers)

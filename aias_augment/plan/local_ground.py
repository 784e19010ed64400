"""The ground refit around a contact point: the measured points near the coarse plane (LiDAR, stereo or depth),
a local RANSAC plane through those around the contact, and a check that it agrees with the points right under the
object (a kerb or a ramp inside the window is not one plane)."""

from __future__ import annotations

import numpy as np

from aias_augment.analyse.ground import GroundFitError, GroundPlane, depth_to_points, fit_ground_plane
from aias_augment.core.geometry import Intrinsics
from aias_augment.plan.placement_config import PlacementConfig

__all__ = ["UnevenGroundError", "ground_band_points", "refit_local_ground"]


def ground_band_points(
    ground: GroundPlane,
    intrinsics: Intrinsics,
    rng: np.random.Generator,
    *,
    points_in_cam: np.ndarray | None = None,
    depth: np.ndarray | None = None,
    cfg: PlacementConfig = PlacementConfig(),
) -> np.ndarray | None:
    """Measured points that may be ground: within ``cfg.local_ground_band_m`` of the coarse plane, (N, 3) or None.

    Source: ``points_in_cam`` (LiDAR / stereo points) when given, else ``depth`` pixels nearer than
    ``cfg.local_max_depth_m``. At most ``cfg.local_max_points`` points, drawn with ``rng``.
    """
    if points_in_cam is not None:
        pts = np.asarray(points_in_cam, dtype=np.float64).reshape(-1, 3)
        pts = pts[np.all(np.isfinite(pts), axis=1) & (pts[:, 2] < cfg.local_max_depth_m)]
    elif depth is not None:
        pts, _ = depth_to_points(depth, intrinsics, max_depth_m=cfg.local_max_depth_m)
    else:
        return None
    pts = pts[np.abs(ground.signed_distance(pts)) < cfg.local_ground_band_m]
    if len(pts) > cfg.local_max_points:
        pts = pts[rng.choice(len(pts), cfg.local_max_points, replace=False)]
    return pts


class UnevenGroundError(GroundFitError):
    """Measured points are under the contact, but no local plane agrees with them (kerb edge, ramp, clutter)."""


def _support_residual_m(
    points: np.ndarray, plane: GroundPlane, contact_in_cam: np.ndarray, radius_m: float, min_points: int
) -> float | None:
    """Median |distance to plane| of the points within ``radius_m`` (along the plane) of the contact; None when
    fewer than ``min_points`` are there."""
    rel = points - contact_in_cam
    along = rel - (rel @ plane.normal)[:, None] * plane.normal
    near = points[np.einsum("ij,ij->i", along, along) < radius_m**2]
    if len(near) < min_points:
        return None
    return float(np.median(np.abs(plane.signed_distance(near))))


def refit_local_ground(
    band_points: np.ndarray,
    ground: GroundPlane,
    contact_in_cam: np.ndarray,
    rng: np.random.Generator,
    cfg: PlacementConfig = PlacementConfig(),
    pixel_uv: np.ndarray | None = None,
    intrinsics: Intrinsics | None = None,
) -> tuple[GroundPlane, np.ndarray]:
    """(local plane, contact on it): ground refit on ``band_points`` within ``cfg.local_radius_m`` (horizontally) of
    ``contact_in_cam``, normal within ``cfg.local_max_tilt_deg`` of the coarse ``ground``'s.

    The contact is re-intersected along ``pixel_uv``'s ray (given with ``intrinsics``), else projected onto the
    plane. A plane that disagrees with the points under the new contact (see ``local_support_radius_m``) is refit
    with half, then a quarter of the radius. Raises UnevenGroundError when planes were found but none agrees with
    the points under the contact, GroundFitError when there are too few points for a plane.
    """
    last_error, uneven = "no radius tried", None
    for radius in (cfg.local_radius_m, cfg.local_radius_m / 2, cfg.local_radius_m / 4):
        try:
            local = fit_ground_plane(
                band_points,
                rng,
                up_hint=ground.normal,
                max_tilt_deg=cfg.local_max_tilt_deg,
                threshold_m=cfg.local_threshold_m,
                local_center=contact_in_cam,
                local_radius_m=radius,
                min_inliers=cfg.local_min_inliers,
                source="local",
            )
        except GroundFitError as e:
            last_error = str(e)
            break  # a smaller window has even fewer points
        if pixel_uv is not None:
            contact = local.intersect_pixels(np.asarray(pixel_uv, float), intrinsics)
            if not np.all(np.isfinite(contact)):
                last_error = "the pixel's ray misses the local plane"
                continue
        else:
            contact = local.project_to_plane(np.asarray(contact_in_cam, float))
        res = _support_residual_m(band_points, local, contact, cfg.local_support_radius_m, cfg.local_support_min_points)
        if res is None or res <= cfg.local_support_max_residual_m:
            return local, contact
        uneven = f"local plane ({radius:.2g} m window) is {res:.3f} m off the points under the contact"
    if uneven is not None:
        raise UnevenGroundError(uneven)
    raise GroundFitError(last_error)

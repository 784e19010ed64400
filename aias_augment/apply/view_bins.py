"""What a view of the view cache is (:mod:`aias_augment.apply.view_cache`): the bins of view direction, nearness
and resolution (:class:`ViewBinning`), a sample's bin (:func:`view_key`), the view camera of a bin, and the
rendered layers a bin holds (:class:`CachedView`)."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from aias_augment.assets.asset import Asset
from aias_augment.core.geometry import Intrinsics

__all__ = [
    "DEFAULT_BINNING",
    "MAX_ELEVATION_DEG",
    "CachedView",
    "ViewBinning",
    "bin_direction",
    "centre_and_radius",
    "view_key",
    "view_rotation",
]


@dataclass(frozen=True)
class ViewBinning:
    """Bin sizes of the view cache (see the module docstring). ``max_nearness``: a closer object (u above it) and an
    object whose projected size exceeds 1.5 ``max_px`` are rendered in full instead (the caller's fallback)."""

    azimuth_step_deg: float = 7.5
    elevation_step_deg: float = 4.0
    nearness_step: float = 0.04
    min_px: int = 16
    max_px: int = 256
    max_nearness: float = 0.5
    ssaa: int = 2

    def __post_init__(self):
        if not (0 < self.azimuth_step_deg <= 90 and 0 < self.elevation_step_deg <= 45 and 0 < self.nearness_step < 1):
            raise ValueError(f"ViewBinning: bad steps {self}")
        if self.min_px < 8 or self.max_px < self.min_px:
            raise ValueError(f"ViewBinning: need 8 <= min_px <= max_px, got {self.min_px}, {self.max_px}")


DEFAULT_BINNING = ViewBinning()
#: The view camera never looks straight down/up its up axis (the view's "up" would be undefined).
MAX_ELEVATION_DEG = 85.0


@dataclass(frozen=True, eq=False)
class CachedView:
    """One rendered view. Layers cover ``roi`` of the view image (x0, y0 offset); ``K_view`` the view camera's
    intrinsics (full view image), ``distance`` the bin's distance to the object's centre (root units).
    ``premultiplied`` (h, w, 8) float32: albedo x coverage (3), normal (object frame) x coverage (3), depth offset
    from ``distance`` x coverage (1), coverage (1): interpolating premultiplied layers keeps edges clean."""

    premultiplied: np.ndarray
    roi: tuple[int, int, int, int]
    K_view: np.ndarray
    distance: float

    @property
    def nbytes(self) -> int:
        return int(self.premultiplied.nbytes)


def centre_and_radius(asset: Asset) -> tuple[np.ndarray, float]:
    got = asset.__dict__.get("_view_centre_radius")  # a memo on the (immutable) asset, as its bounds
    if got is None:
        lo, hi = asset.bounds_m
        got = ((lo + hi) / 2.0, float(np.linalg.norm(hi - lo) / 2.0))
        got[0].setflags(write=False)
        asset.__dict__["_view_centre_radius"] = got
    return got


def view_rotation(v_obj: np.ndarray) -> np.ndarray:
    """view_from_object rotation (rows x, y, z of the OpenCV view camera in the object frame) of a camera looking
    along -v_obj (v_obj: unit, from the object toward the camera) with the object's up (z) pointing up in the image."""
    vx, vy, vz = (float(c) for c in v_obj)
    zx, zy, zz = -vx, -vy, -vz
    ux, uy, uz = (0.0, 0.0, 1.0) if abs(vz) < 0.999 else (1.0, 0.0, 0.0)
    k = ux * zx + uy * zy + uz * zz
    yx, yy, yz = -(ux - k * zx), -(uy - k * zy), -(uz - k * zz)
    n = math.sqrt(yx * yx + yy * yy + yz * yz)
    yx, yy, yz = yx / n, yy / n, yz / n
    return np.array([[yy * zz - yz * zy, yz * zx - yx * zz, yx * zy - yy * zx], [yx, yy, yz], [zx, zy, zz]])


def bin_direction(ia: int, ie: int, b: ViewBinning) -> np.ndarray:
    az = math.radians(ia * b.azimuth_step_deg)
    el = math.radians(
        min((ie + 0.5) * b.elevation_step_deg, MAX_ELEVATION_DEG)
        if ie >= 0
        else max((ie + 0.5) * b.elevation_step_deg, -MAX_ELEVATION_DEG)
    )
    return np.array([math.cos(el) * math.cos(az), math.cos(el) * math.sin(az), math.sin(el)])


def view_key(
    asset: Asset,
    cam_from_object: np.ndarray,
    intrinsics: Intrinsics,
    binning: ViewBinning = DEFAULT_BINNING,
    znear: float = 0.05,
) -> tuple | None:
    """(azimuth bin, elevation bin, nearness bin, resolution px) of the sample, or None when the view cache does not
    apply (the object is partly behind ``znear``, nearer than ``max_nearness``, or larger than 1.5 ``max_px``)."""
    c_obj, r = centre_and_radius(asset)
    R, t = cam_from_object[:3, :3], cam_from_object[:3, 3]
    if float((asset.corners_m() @ R[2] + t[2]).min()) <= znear:  # the corners' z in the camera
        return None
    c_cam = R @ c_obj + t
    d = math.sqrt(float(c_cam @ c_cam))
    u = r / d
    if u >= binning.max_nearness:
        return None
    vx, vy, vz = (-(R.T @ c_cam) / d).tolist()
    az = math.degrees(math.atan2(vy, vx))
    el = math.degrees(math.asin(min(max(vz, -1.0), 1.0)))
    n_az = int(round(360.0 / binning.azimuth_step_deg))
    ia = int(round(az / binning.azimuth_step_deg)) % n_az
    ie = int(math.floor(el / binning.elevation_step_deg))
    iu = int(math.floor(u / binning.nearness_step))
    diameter_px = 2.0 * max(intrinsics.fx, intrinsics.fy) * math.tan(math.asin(u))
    if diameter_px > 1.5 * binning.max_px:
        return None
    px = int(min(max(2 ** math.ceil(math.log2(max(diameter_px, 1.0))), binning.min_px), binning.max_px))
    return ia, ie, iu, px

"""Shadow operations on image-space maps: shadow strength from the sun/sky ratio, penumbra softening, contact shadows.

Convention (used everywhere in the project): ``sun_sky_ratio r`` = irradiance the sun delivers to the (horizontal)
receiving ground divided by the irradiance the sky (everything but the sun) delivers to it. A ground point whose sun
visibility is ``v`` in [0, 1] and whose sky is occluded by a factor ``a`` in [0, 1] (ambient occlusion, 1 = open sky)
receives ``(a + r v) / (1 + r)`` of the light of a fully lit point; this multiplies the background pixel (in linear
radiance). Full shadow of an open-sky point is ``1 / (1 + r)``; measured on a photo, ``r = lit / shadow - 1``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import ndimage, spatial

__all__ = [
    "shadow_ratio_from_sun_sky",
    "soften_shadow",
    "occluder_distance_from_footprint",
    "contact_occlusion",
    "fill_nearest",
    "SUN_ANGULAR_RADIUS_RAD",
    "SunShadowLimits",
    "sun_shadow_limits",
]

#: Half the sun's apparent diameter (0.53 deg).
SUN_ANGULAR_RADIUS_RAD = float(np.deg2rad(0.265))
#: Footprints of up to this many distinct points are searched by brute force (a k-d tree only pays off above it).
_BRUTE_FORCE_POINTS = 32

#: Below this sun confidence no sun shadow is darker than :data:`UNCERTAIN_SUN_DARKEST` of the lit ground: a false
#: sun's black hard shadow costs far more than a missed sun's faint one (the bound is 0.5 below 0.8; 0.55 leaves
#: room for the output's 8-bit rounding).
UNCERTAIN_SUN_CONFIDENCE = 0.8
UNCERTAIN_SUN_DARKEST = 0.55
#: At confidence c the sun is drawn as a disc widened by (1 - c) x this (rad) and the penumbra is at least
#: (1 - c) x :data:`UNCERTAIN_SUN_MIN_SIGMA_PX` wider: an uncertain direction gives a soft edge, not a crisp one.
UNCERTAIN_SUN_SPREAD_RAD = float(np.deg2rad(6.0))
UNCERTAIN_SUN_MIN_SIGMA_PX = 4.0


@dataclass(frozen=True)
class SunShadowLimits:
    """How dark and how hard a sun shadow may be: ``darkest`` the least share of the lit ground's light a sun
    shadow leaves (0: no limit), ``angular_radius_rad`` the sun disc's for the penumbra, ``min_sigma_px`` the
    penumbra's least Gaussian sigma."""

    darkest: float
    angular_radius_rad: float
    min_sigma_px: float

    def sun_sky_ratio(self, ratio: float) -> float:
        """``ratio`` limited so that a full shadow of an open-sky point (``1 / (1 + r)``) is at least ``darkest``."""
        return ratio if self.darkest <= 0 else min(ratio, 1.0 / self.darkest - 1.0)


def sun_shadow_limits(confidence: float) -> SunShadowLimits:
    """The shadow a sun of ``confidence`` (the sun decision's, in [0, 1]) may cast. The shadow's depth (1 - the
    darkest share) grows linearly from 0 at confidence 0 to ``1 - UNCERTAIN_SUN_DARKEST`` at
    :data:`UNCERTAIN_SUN_CONFIDENCE`, then to no limit at 1; its edge softens linearly as the confidence drops."""
    c = float(np.clip(confidence, 0.0, 1.0))
    c0, deepest = UNCERTAIN_SUN_CONFIDENCE, 1.0 - UNCERTAIN_SUN_DARKEST
    depth = deepest * c / c0 if c < c0 else deepest + (1.0 - deepest) * (c - c0) / (1.0 - c0)
    return SunShadowLimits(
        1.0 - depth,
        SUN_ANGULAR_RADIUS_RAD + (1.0 - c) * UNCERTAIN_SUN_SPREAD_RAD,
        0.5 + (1.0 - c) * UNCERTAIN_SUN_MIN_SIGMA_PX,
    )


def shadow_ratio_from_sun_sky(
    visibility: np.ndarray, sun_sky_ratio: float, ambient_occlusion: np.ndarray | None = None
) -> np.ndarray:
    """``(a + r v) / (1 + r)``, see module docstring. ``visibility`` (H, W) in [0, 1]; returns float32 in [0, 1].

    r = 0 (no sun) gives ``a`` (only contact/ambient darkening); r -> inf gives ``v``. NaN visibility is an error.
    """
    v = np.asarray(visibility, dtype=np.float64)
    if not np.all(np.isfinite(v)):
        raise ValueError("visibility contains NaN or Inf")
    r = float(sun_sky_ratio)
    if not np.isfinite(r) or r < 0:
        raise ValueError(f"sun_sky_ratio must be finite and >= 0, got {sun_sky_ratio}")
    v = np.clip(v, 0.0, 1.0)
    a = np.ones_like(v) if ambient_occlusion is None else np.clip(np.asarray(ambient_occlusion, np.float64), 0.0, 1.0)
    return ((a + r * v) / (1.0 + r)).astype(np.float32)


def fill_nearest(values: np.ndarray, valid: np.ndarray) -> np.ndarray:
    """``values`` with each invalid pixel taken from its nearest valid one (all zeros when none is valid)."""
    if valid.all():
        return values
    if not valid.any():
        return np.zeros_like(values)
    _, (ri, ci) = ndimage.distance_transform_edt(~valid, return_indices=True)
    return values[ri, ci]


def soften_shadow(
    shadow_ratio: np.ndarray,
    occluder_distance_m: np.ndarray | float | None,
    sun_angular_radius_rad: float = SUN_ANGULAR_RADIUS_RAD,
    pixels_per_metre: np.ndarray | float = 100.0,
    *,
    default_distance_m: float = 0.5,
    min_sigma_px: float = 0.5,
    max_sigma_px: float = 24.0,
    n_levels: int = 8,
) -> np.ndarray:
    """Blur a hard shadow map with a penumbra that grows with the distance from the occluder.

    The sun is a disc of angular radius alpha, so a shadow edge cast by an occluder at distance d (along the sun ray)
    spreads over a penumbra of half-width d tan(alpha) on the receiver: the local Gaussian sigma is
    ``d * tan(alpha) * pixels_per_metre`` (pixels), clamped to [min_sigma_px, max_sigma_px]. The spatially varying blur
    blends a stack of ``n_levels`` Gaussian blurs (geometric sigmas) per pixel. ``occluder_distance_m``: (H, W) map
    (non-finite or <= 0 = unknown, filled from the nearest known pixel), a scalar, or None (``default_distance_m``).
    ``pixels_per_metre``: scalar or (H, W) (e.g. fx / depth on the receiver). Output in [min, max] of the input.
    """
    s = np.asarray(shadow_ratio, dtype=np.float64)
    if s.ndim != 2:
        raise ValueError(f"soften_shadow: shadow_ratio must be (H, W), got {s.shape}")
    if not np.all(np.isfinite(s)):
        raise ValueError("soften_shadow: shadow_ratio contains NaN or Inf")
    alpha = float(sun_angular_radius_rad)
    if not 0.0 <= alpha < np.pi / 4:
        raise ValueError(f"sun_angular_radius_rad must be in [0, pi/4), got {alpha}")
    if n_levels < 2 or not 0 < min_sigma_px < max_sigma_px:
        raise ValueError("need n_levels >= 2 and 0 < min_sigma_px < max_sigma_px")
    ppm = np.broadcast_to(np.asarray(pixels_per_metre, dtype=np.float64), s.shape)
    ppm = np.where(np.isfinite(ppm) & (ppm > 0), ppm, 0.0)
    if occluder_distance_m is None:
        d = np.full(s.shape, float(default_distance_m))
    else:
        d = np.broadcast_to(np.asarray(occluder_distance_m, dtype=np.float64), s.shape)
        known = np.isfinite(d) & (d > 0)
        if not known.any():
            d = np.full(s.shape, float(default_distance_m))
        elif (~known & (ppm > 0)).any():
            d = fill_nearest(np.where(known, d, 0.0), known)
        else:  # the unknown pixels have no scale (off the ground): their sigma is the least whatever their distance
            d = np.where(known, d, 0.0)
    sigma = np.clip(d * np.tan(alpha) * ppm, min_sigma_px, max_sigma_px)
    levels = np.geomspace(min_sigma_px, max_sigma_px, n_levels)
    # Per-pixel linear interpolation in log-sigma between the two enclosing levels.
    t = np.log(sigma / min_sigma_px) / np.log(max_sigma_px / min_sigma_px) * (n_levels - 1)
    lo = np.clip(np.floor(t).astype(int), 0, n_levels - 2)
    frac = np.clip(t - lo, 0.0, 1.0)
    # Only the levels some pixel interpolates between are blurred (the same values: the others have weight 0).
    first, last = int(lo.min()), int(lo.max()) + 1
    stack = np.stack([ndimage.gaussian_filter(s, sg, mode="nearest") for sg in levels[first : last + 1]], axis=0)
    below = np.take_along_axis(stack, (lo - first)[None], axis=0)[0]
    above = np.take_along_axis(stack, (lo + 1 - first)[None], axis=0)[0]
    out = below * (1 - frac) + above * frac
    return np.clip(out, s.min(), s.max()).astype(np.float32)


def occluder_distance_from_footprint(
    ground_points_xy: np.ndarray, footprint_xy: np.ndarray, sun_elevation_rad: float, min_cos: float = 0.05
) -> np.ndarray:
    """Approximate distance (m) along the sun ray from ground points to an upright occluder standing on the ground.

    A ground point at horizontal distance rho from the object's footprint is shadowed by the part of the object at
    height rho tan(el), i.e. at distance rho / cos(el) along the ray. ``ground_points_xy`` (*, 2) and ``footprint_xy``
    (M, 2) in the same metric ground frame; cos(el) clamped to >= ``min_cos`` (sun near the zenith).
    """
    g = np.asarray(ground_points_xy, dtype=np.float64)
    f = np.asarray(footprint_xy, dtype=np.float64).reshape(-1, 2)
    if f.size == 0:
        raise ValueError("footprint_xy is empty")
    f = np.unique(f, axis=0)
    if len(f) > _BRUTE_FORCE_POINTS:
        rho, _ = spatial.cKDTree(f).query(g.reshape(-1, 2))
    else:  # a box's corners: the nearest by brute force, the same sums and root as the tree's
        x, y = g.reshape(-1, 2).T
        d2 = None
        for fx, fy in f:
            dx, dy = x - fx, y - fy
            s = dx * dx + dy * dy
            d2 = s if d2 is None else np.minimum(d2, s)
        rho = np.sqrt(d2)
    return (rho / max(np.cos(float(sun_elevation_rad)), min_cos)).reshape(g.shape[:-1])


def contact_occlusion(
    distance_to_object_m: np.ndarray, object_height_m: float, strength: float = 0.6, radius_fraction: float = 0.25
) -> np.ndarray:
    """Ambient occlusion of the ground near an object's base (a contact shadow): ``1 - strength exp(-rho / R)`` with
    R = ``radius_fraction`` x object height; rho (H, W) is the horizontal distance (m) to the footprint (0 under it).
    Returns the factor ``a`` for :func:`shadow_ratio_from_sun_sky` in [1 - strength, 1]."""
    if not 0.0 <= strength <= 1.0:
        raise ValueError(f"strength must be in [0, 1], got {strength}")
    rho = np.clip(np.nan_to_num(np.asarray(distance_to_object_m, dtype=np.float64), nan=np.inf), 0.0, None)
    return contact_occlusion_of(rho, object_height_m, strength, radius_fraction)


def contact_occlusion_of(
    rho_m: np.ndarray, object_height_m: float, strength: float = 0.6, radius_fraction: float = 0.25
) -> np.ndarray:
    """:func:`contact_occlusion` of distances known to be >= 0 and not NaN (float64; not checked)."""
    R = max(float(object_height_m) * radius_fraction, 1e-3)  # eps: a flat object still gets a thin contact line
    e = np.exp(-rho_m / R)
    e *= strength
    return (1.0 - e).astype(np.float32)

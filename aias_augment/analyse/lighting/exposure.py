"""The estimate's exposure and tempering: the irradiance anchored on the ground's implied albedo, an optional
white balance on the road, a saturation guard so a white surface does not clip where the frame does not, and an
uncertain sun softened into its own SH lobe."""

from __future__ import annotations

import numpy as np

from aias_augment.analyse.lighting.config import LightingConfig
from aias_augment.analyse.lighting.frame import FrameContext
from aias_augment.analyse.lighting.sh import sh_irradiance
from aias_augment.core.hdr import luminance, max_channel, srgb_to_linear

__all__ = [
    "anchor_and_cap",
    "ground_exposure_scale",
    "ground_white_balance_gains",
    "peak_white_radiance",
    "soft_sun_irradiance_factor",
    "temper_sun",
]


def ground_exposure_scale(
    ground_luminance: float, ground_irradiance: float, albedo_range: tuple[float, float]
) -> float:
    """Factor k for the irradiance so that the implied ground albedo pi L / (k E) is ``albedo_range`` clamped: k =
    implied / clamp(implied). 1 when the inputs are not positive and finite (nothing to anchor on)."""
    if (
        not (np.isfinite(ground_luminance) and np.isfinite(ground_irradiance))
        or ground_luminance <= 0
        or ground_irradiance <= 0
    ):
        return 1.0
    implied = np.pi * ground_luminance / ground_irradiance
    return float(implied / np.clip(implied, *albedo_range))


def ground_white_balance_gains(
    ground_rgb: np.ndarray, irradiance_rgb: np.ndarray, strength: float = 1.0, max_gain: float = 2.0
) -> np.ndarray:
    """Per-channel gains (3,) that give ``irradiance_rgb`` the chromaticity of ``ground_rgb`` (a neutral surface
    shows the light's colour), raised to ``strength`` (1: all the way, 0.5: half way in log), each clamped to
    [1 / max_gain, max_gain], then scaled to keep the luminance. Ones when either input is not positive."""
    g, e = np.asarray(ground_rgb, np.float64), np.asarray(irradiance_rgb, np.float64)
    if not (np.all(np.isfinite(g)) and np.all(np.isfinite(e))) or g.min() <= 0 or e.min() <= 0:
        return np.ones(3)
    gains = ((g / float(luminance(g))) / (e / float(luminance(e)))) ** strength
    gains = np.clip(gains, 1.0 / max_gain, max_gain)
    return gains * float(luminance(e)) / float(luminance(gains * e))


def temper_sun(
    sh: np.ndarray,
    sun_irr: np.ndarray,
    cos_z: float,
    keep: float,
    sun_dir: np.ndarray | None = None,
    up_in_cam: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Keep the share ``keep`` of the sun as a directional light; the rest, (1 - keep) E_sun, becomes a smooth light
    with the same irradiance on the ground, (1 - keep) E_sun cos z.

    With ``sun_dir`` and ``up_in_cam`` (what the estimator passes) the rest is the sun's own order-2 SH lobe: the SH of a
    directional light (radiance coefficients E Y_lm(l)), whose irradiance is the band-limited clamped cosine
    f(n.l) = 0.25 + 0.5 t + 0.15625 (3 t^2 - 1) (1.06 facing the sun, 0.06 facing away), scaled by cos z / f(l.up)
    so that the ground gets exactly the irradiance the shadow contrast was measured with. An uncertain direction thus
    gives a softer terminator around the SAME sun that casts the shadow: a surface facing away from it stays dark
    (with a uniform rest, as before, a barrel lit from behind had its camera-facing side as bright as the lit road
    while its shadow fell toward the camera). Without ``sun_dir`` the rest is uniform ambient (a uniform radiance L
    gives E = pi L; its DC coefficient is L 4 pi C0, so E = pi C0 c00 and c00 += dE / (pi C0))."""
    keep = float(np.clip(keep, 0.0, 1.0))
    if keep >= 1.0:
        return sh, sun_irr
    from aias_augment.analyse.lighting.sh import SH_C0, sh_basis

    sh = np.array(sh, dtype=np.float64, copy=True)
    rest = (1.0 - keep) * np.asarray(sun_irr, np.float64)
    if sun_dir is None or up_in_cam is None:
        sh[0] += rest * cos_z / (np.pi * SH_C0)
        return sh, np.asarray(sun_irr, np.float64) * keep
    l_dir = np.asarray(sun_dir, np.float64) / np.linalg.norm(sun_dir)
    up = np.asarray(up_in_cam, np.float64) / np.linalg.norm(up_in_cam)
    t = float(l_dir @ up)
    f_ground = 0.25 + 0.5 * t + 0.15625 * (3.0 * t * t - 1.0)  # > 0.09 for a sun above the horizon (t > 0)
    scale = float(cos_z) / max(f_ground, 1e-3)
    sh += sh_basis(l_dir)[:, None] * rest[None, :] * scale
    return sh, np.asarray(sun_irr, np.float64) * keep


def soft_sun_irradiance_factor(cos_angle: np.ndarray) -> np.ndarray:
    """f(t) of :func:`temper_sun`: irradiance of a unit directional light through order-2 SH at n.l = t."""
    t = np.asarray(cos_angle, np.float64)
    return 0.25 + 0.5 * t + 0.15625 * (3.0 * t * t - 1.0)


def _fibonacci_sphere(n: int = 256) -> np.ndarray:
    i = np.arange(n) + 0.5
    z = 1.0 - 2.0 * i / n
    phi = np.pi * (1.0 + 5.0**0.5) * i
    r = np.sqrt(1.0 - z * z)
    return np.stack([r * np.cos(phi), r * np.sin(phi), z], -1)


def peak_white_radiance(sh: np.ndarray, sun_irr: np.ndarray | None, sun_dir: np.ndarray | None) -> float:
    """Largest radiance (any channel) of a white Lambertian surface over all normal directions: max_n (E_sh(n) +
    E_sun max(0, n.l)) / pi, on 256 Fibonacci normals plus the sun direction itself."""
    n = _fibonacci_sphere()
    if sun_dir is not None:
        n = np.vstack([n, np.asarray(sun_dir, np.float64)[None] / np.linalg.norm(sun_dir)])
    E = sh_irradiance(sh, n)
    if sun_dir is not None and sun_irr is not None:
        E = E + np.maximum(n @ (np.asarray(sun_dir, np.float64) / np.linalg.norm(sun_dir)), 0.0)[:, None] * sun_irr
    return float(np.max(E) / np.pi)


def anchor_and_cap(
    ctx: FrameContext,
    sh: np.ndarray,
    sun_irr: np.ndarray | None,
    sun_dir: np.ndarray | None,
    cos_z: float,
    ground_lum: float | None,
    config: LightingConfig,
):
    """The exposure anchor on the ground's implied albedo, then the saturation guard (see LightingConfig); both
    scale the ambient SH and the sun by one factor (colour and sun/sky ratio unchanged)."""
    lin = srgb_to_linear(ctx.img)
    k = 1.0
    has_ground = ctx.region is not None and bool(ctx.region.any())
    if config.ground_white_balance > 0 and has_ground:
        e_rgb = sh_irradiance(sh, ctx.up_in_cam)
        if sun_irr is not None and sun_dir is not None:
            e_rgb = e_rgb + np.asarray(sun_irr) * cos_z
        gains = ground_white_balance_gains(np.median(lin[ctx.region], axis=0), e_rgb, config.ground_white_balance)
        sh = np.asarray(sh) * gains[None, :]
        sun_irr = None if sun_irr is None else np.asarray(sun_irr) * gains
    if config.ground_albedo_range is not None and has_ground:
        if ground_lum is None:
            ground_lum = float(np.median(luminance(lin[ctx.region])))
        e_ground = float(luminance(sh_irradiance(sh, ctx.up_in_cam)))
        if sun_irr is not None and sun_dir is not None:
            e_ground += float(luminance(sun_irr)) * cos_z
        k = ground_exposure_scale(ground_lum, e_ground, config.ground_albedo_range)
        g = config.ground_anchor_max_gain
        k = float(np.clip(k, 1.0 / g, g))
    if config.cap_white_to_scene_percentile is not None:
        ref = float(np.percentile(max_channel(lin), config.cap_white_to_scene_percentile))
        if ref < 0.98:
            peak = k * peak_white_radiance(sh, sun_irr, sun_dir)
            if peak > config.white_cap_linear:
                k *= config.white_cap_linear / peak
    if k == 1.0:
        return sh, sun_irr
    return np.asarray(sh) * k, (None if sun_irr is None else np.asarray(sun_irr) * k)

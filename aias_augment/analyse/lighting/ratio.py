"""Sun-to-sky ratio from lit versus shadowed ground of one material, and detection of scenes with no dominant sun.

Method: inside a ground region (given, or the road-like area below the horizon), fit a two-component Gaussian mixture to
log-luminance (:class:`TwoGaussians`, on an evenly spaced sample of the region's pixels: no draws). A sunny ground with
cast shadows is bimodal: the dark mode is shadow (sky light only), the bright mode lit (sky + sun). Same material is
enforced loosely by dropping pixels whose chromaticity is far from the region's median (lane paint, grass, cars). Pixels
near the class boundary (penumbrae, texture) are dropped by keeping only confident posteriors and eroding each class.
The ratio uses class medians of linear luminance.

A scene has a dominant sun when the mixture is clearly bimodal (Ashman's D >= ``min_separation``), both modes hold at
least ``min_fraction`` of the region, and lit / shadow >= ``min_lit_to_shadow``. Overcast and indoor ground is unimodal
(D < 2 for a single Gaussian's best two-component fit) or too flat. See ``shadows`` for the ratio convention.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np
from scipy import ndimage, special

from aias_augment.analyse.lighting.envmap import camera_ray_directions
from aias_augment.core.geometry import CAMERA_HEIGHT_PRIOR_M, Intrinsics
from aias_augment.core.hdr import luminance, max_channel
from aias_augment.core.rng import systematic_sample

__all__ = [
    "TwoGaussians",
    "LitShadowMeasurement",
    "measure_lit_shadow",
    "ground_region_mask",
    "ground_coordinates",
    "shadow_axis_on_ground",
]


@dataclass(frozen=True)
class TwoGaussians:
    """A two-component Gaussian mixture in one dimension, fitted by EM from the two-means split of the sorted sample
    (the k-means start, found exactly in 1-D). No draws: the fit is a property of the sample."""

    weights: np.ndarray
    means: np.ndarray
    variances: np.ndarray

    @classmethod
    def fit(cls, x: np.ndarray, *, max_iter: int = 100, tol: float = 1e-3, reg: float = 1e-6) -> TwoGaussians:
        """EM until the mean log-likelihood gains less than ``tol``; ``reg`` is added to each variance (sklearn's
        ``reg_covar``). ``x`` needs two or more distinct values."""
        xs = np.sort(np.asarray(x, dtype=np.float64).ravel())
        n = xs.size
        if n < 2 or xs[0] == xs[-1]:
            raise ValueError(f"TwoGaussians.fit: need two or more distinct values, got {n} samples")
        csum = np.concatenate([[0.0], np.cumsum(xs)])
        k = n // 2
        for _ in range(64):  # two-means in 1-D: the split at the midpoint of the two halves' means, to a fixed point
            mid = 0.5 * (csum[k] / k + (csum[n] - csum[k]) / (n - k))
            k_next = int(np.clip(np.searchsorted(xs, mid, side="right"), 1, n - 1))
            if k_next == k:
                break
            k = k_next
        w = np.array([k, n - k], dtype=np.float64) / n
        mu = np.array([xs[:k].mean(), xs[k:].mean()])
        var = np.array([xs[:k].var(), xs[k:].var()]) + reg
        previous = -np.inf
        for _ in range(max_iter):
            log_odds, log_second = _log_odds(xs, w, mu, var)
            r0 = special.expit(log_odds)  # component 0's responsibility; component 1's is 1 - r0
            r1 = 1.0 - r0
            nk = np.array([r0.sum(), r1.sum()]) + 10.0 * np.finfo(np.float64).eps
            mu = np.array([r0 @ xs, r1 @ xs]) / nk
            var = np.array([r0 @ (xs - mu[0]) ** 2, r1 @ (xs - mu[1]) ** 2]) / nk + reg
            w = nk / n
            mean_ll = float(np.mean(log_second) + np.mean(np.logaddexp(log_odds, 0.0)))  # E[log p(x)], old model
            if abs(mean_ll - previous) < tol:
                break
            previous = mean_ll
        return cls(w, mu, var)

    def log_odds(self, x: np.ndarray) -> np.ndarray:
        """log p(component 0 | x) - log p(component 1 | x) for each value (the posterior's logit)."""
        return _log_odds(np.asarray(x, dtype=np.float64).ravel(), self.weights, self.means, self.variances)[0]

    def posterior(self, x: np.ndarray) -> np.ndarray:
        """(N, 2) probability of each component given each value."""
        r0 = special.expit(self.log_odds(x))
        return np.stack([r0, 1.0 - r0], axis=1)


def _log_odds(x: np.ndarray, w: np.ndarray, mu: np.ndarray, var: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """log p(x, component 0) - log p(x, component 1), and log p(x, component 1), for each value."""
    c = np.log(w) - 0.5 * np.log(2.0 * np.pi * var)
    t0, t1 = x - mu[0], x - mu[1]
    second = c[1] - (0.5 / var[1]) * (t1 * t1)
    return c[0] - (0.5 / var[0]) * (t0 * t0) - second, second


@dataclass(frozen=True)
class LitShadowMeasurement:
    """Result of :func:`measure_lit_shadow`. Luminances and RGB are linear; masks are (H, W) bool."""

    lit_rgb: np.ndarray
    shadow_rgb: np.ndarray
    lit_luminance: float
    shadow_luminance: float
    shadow_to_lit: float
    sun_sky_ratio: float
    separation: float
    shadow_fraction: float
    n_pixels: int
    dominant_sun: bool
    lit_mask: np.ndarray
    shadow_mask: np.ndarray


def ground_coordinates(
    intrinsics: Intrinsics, up_in_cam: np.ndarray, camera_height_m: float = CAMERA_HEIGHT_PRIOR_M
) -> tuple[np.ndarray, np.ndarray]:
    """Where each pixel's ray meets a flat ground ``camera_height_m`` below the camera: (H, W, 2) (lateral, forward)
    metres in the gravity-aligned camera frame (lateral positive to the right, forward along the camera's heading) and
    (H, W) bool (False at or above the horizon, where the ray never meets the ground). Both read-only: the last few
    (camera, up, height) are kept, one analysis asks for them once per ground box."""
    up = np.asarray(up_in_cam, dtype=np.float64).reshape(3)
    return _ground_coordinates(
        float(intrinsics.fx),
        float(intrinsics.fy),
        float(intrinsics.cx),
        float(intrinsics.cy),
        int(intrinsics.width),
        int(intrinsics.height),
        tuple(float(x) for x in up),
        float(camera_height_m),
    )


@functools.lru_cache(maxsize=8)
def _ground_coordinates(fx, fy, cx, cy, width, height, up_in_cam, camera_height_m):
    intrinsics = Intrinsics(fx, fy, cx, cy, width, height)
    up = np.asarray(up_in_cam, dtype=np.float64)
    up = up / np.linalg.norm(up)
    rays = camera_ray_directions(intrinsics)
    down_cos = -(rays @ up)
    ok = down_cos > 1e-6  # rays at or above the horizon never meet the ground
    t = np.where(ok, camera_height_m / np.maximum(down_cos, 1e-6), 0.0)
    pts = rays * t[..., None]
    fwd = np.array([0.0, 0.0, 1.0]) - up[2] * up
    fwd /= np.linalg.norm(fwd)
    right = np.cross(fwd, up)  # level OpenCV camera: z x (-y) = +x
    g = np.stack([pts @ right, pts @ fwd], axis=-1)
    g.flags.writeable = ok.flags.writeable = False
    return g, ok


def ground_region_mask(
    intrinsics: Intrinsics,
    up_in_cam: np.ndarray,
    camera_height_m: float = CAMERA_HEIGHT_PRIOR_M,
    lateral_range_m: tuple[float, float] = (-3.0, 3.0),
    forward_range_m: tuple[float, float] = (5.0, 25.0),
) -> np.ndarray:
    """Pixels whose ray meets a flat ground ``camera_height_m`` below the camera inside a box in front of it.

    The box is in the gravity-aligned frame of the camera: lateral (x, right positive) and forward distance (m). KITTI's
    camera is 1.65 m above the road. Returns (H, W) bool.
    """
    g, ok = ground_coordinates(intrinsics, up_in_cam, camera_height_m)
    lat, fwd_d = g[..., 0], g[..., 1]
    return (
        ok
        & (lat >= lateral_range_m[0])
        & (lat <= lateral_range_m[1])
        & (fwd_d >= forward_range_m[0])
        & (fwd_d <= forward_range_m[1])
    )


def shadow_axis_on_ground(
    shadow_mask: np.ndarray,
    region_mask: np.ndarray,
    ground_xy: np.ndarray,
    bin_m: float = 0.1,
    step_deg: float = 2.0,
    min_pixels: int = 50,
) -> tuple[float, float]:
    """Axis of straight cast-shadow bands on the ground by projection profiles: (angle, strength).

    Shadows of upright thin occluders (poles, posts, trunks) are long bands along the sun's azimuth. For each candidate
    axis angle theta, shadow points (``ground_xy`` (H, W, 2) lateral/forward metres) are projected on the axis normal
    and histogrammed (``bin_m``); bands aligned with theta make the histogram peaky (large sum of squared counts). The
    peakiness is divided by that of all ``region_mask`` points at the same theta, so the region's own shape does not
    bias the answer. Works on fragmented 1-2 px lines, unlike connected components. Angle = atan2(forward, lateral)
    in [0, pi) (the sun lies along it, on one of its two sides); strength = 1 - median / max of the normalised
    peakiness over theta (0: no direction stands out). Fewer than ``min_pixels`` shadow points give (0, 0).
    """
    shadow = np.asarray(shadow_mask, bool) & region_mask
    if shadow.sum() < min_pixels or region_mask.sum() < min_pixels:
        return 0.0, 0.0
    pr = ground_xy[region_mask]
    in_shadow = shadow[region_mask]  # the shadow points among the region's, in the region's order
    n_shadow = int(in_shadow.sum())
    thetas = np.deg2rad(np.arange(0.0, 180.0, step_deg))
    rel = np.empty(len(thetas))
    for k, th in enumerate(thetas):
        normal = np.array([-np.sin(th), np.cos(th)])
        b = pr @ normal
        edges = np.arange(b.min(), b.max() + 2 * bin_m, bin_m)
        # np.histogram's bins ([e_i, e_i+1); every point is below the last edge) found once for the region's
        # points; the shadow's counts are those of its points' bins: no sort per histogram
        bins = np.searchsorted(edges, b, side="right") - 1
        hr = np.bincount(bins, minlength=len(edges) - 1).astype(np.float64)
        hs = np.bincount(bins[in_shadow], minlength=len(edges) - 1).astype(np.float64)
        rel[k] = (np.sum(hs**2) / n_shadow**2) / max(np.sum(hr**2) / len(b) ** 2, 1e-12)
    rel = ndimage.uniform_filter1d(rel, 3, mode="wrap")
    best = int(np.argmax(rel))
    return float(thetas[best]), float(np.clip(1.0 - np.median(rel) / max(rel[best], 1e-12), 0.0, 1.0))


def measure_lit_shadow(
    image_linear: np.ndarray,
    region_mask: np.ndarray,
    *,
    max_chroma_dev: float = 0.04,
    min_posterior: float = 0.95,
    erode_px: int = 0,
    min_separation: float = 2.0,
    min_fraction: float = 0.01,
    min_lit_to_shadow: float = 1.5,
    max_samples: int = 8000,
) -> LitShadowMeasurement | None:
    """Measure lit and shadowed luminance of the ground in ``region_mask``; None if fewer than 200 usable pixels.

    ``image_linear``: (H, W, 3) float linear RGB (use ``hdr.srgb_to_linear``; clipped pixels are excluded). The
    per-pixel tests run on the region's pixels only (float64, as every statistic below), the luminance on the image.
    """
    img = np.asarray(image_linear)
    region = np.asarray(region_mask, bool)
    if img.ndim != 3 or img.shape[2] != 3 or region.shape != img.shape[:2]:
        raise ValueError(f"measure_lit_shadow: image {img.shape} and mask {region.shape} do not match")
    flat = img.reshape(-1, 3)
    Y = luminance(img).astype(np.float64).ravel()

    def rgb_at(i: np.ndarray) -> np.ndarray:  # float64 colours of the pixels at flat indices ``i``
        return flat[i].astype(np.float64)

    def mask_at(i: np.ndarray) -> np.ndarray:  # the (H, W) mask of the pixels at flat indices ``i``
        m = np.zeros(Y.size, bool)
        m[i] = True
        return m.reshape(region.shape)

    idx = np.flatnonzero(region)
    px, y = rgb_at(idx), Y[idx]
    ok = np.isfinite(y) & (y > 1e-4) & (max_channel(px) < 0.97)
    if ok.sum() < 200:
        return None
    idx, px, y = idx[ok], px[ok], y[ok]
    total = (px[:, 0] + px[:, 1]) + px[:, 2]  # px.sum(1), in numpy's order, without its per-pixel reduction
    chroma = px / np.maximum(total, 1e-6)[:, None]  # eps: black pixels are already excluded
    med = np.median(chroma, axis=0)
    # Shadows are bluer (sky light), so allow more deviation toward blue than elsewhere.
    dev = chroma - med
    dev[..., 2] = np.where(dev[..., 2] > 0, dev[..., 2] * 0.5, dev[..., 2])
    ok = max_channel(np.abs(dev)) < max_chroma_dev * 2.0
    if ok.sum() < 200:
        return None
    idx, px, y = idx[ok], px[ok], y[ok]  # the usable pixels: flat indices (ascending), colours, luminances
    usable = mask_at(idx)
    logY = np.log(np.maximum(y, 1e-6))  # eps: usable pixels have Y > 1e-4
    fit_logY = logY[systematic_sample(idx.size, max_samples)]
    n = int(idx.size)
    if float(np.ptp(fit_logY)) < 1e-3:  # one flat colour: nothing to separate
        rgb, yy = np.median(px, 0), float(np.median(y))
        return LitShadowMeasurement(rgb, rgb, yy, yy, 1.0, 0.0, 0.0, 0.0, n, False, usable, np.zeros_like(usable))
    mixture = TwoGaussians.fit(fit_logY)
    mu, var = mixture.means, mixture.variances
    dark, bright = int(np.argmin(mu)), int(np.argmax(mu))
    separation = float(abs(mu[bright] - mu[dark]) / np.sqrt(0.5 * (var[0] + var[1])))
    dark_odds = mixture.log_odds(logY) * (1.0 if dark == 0 else -1.0)  # the shadow mode's posterior logit
    confident = np.log(min_posterior / (1.0 - min_posterior))
    shadow = mask_at(idx[dark_odds >= confident])
    lit = mask_at(idx[dark_odds <= -confident])
    if erode_px > 0:
        shadow = ndimage.binary_erosion(shadow, iterations=erode_px)
        lit = ndimage.binary_erosion(lit, iterations=erode_px)
    if shadow.sum() < 20 or lit.sum() < 20:
        shadow_fraction = float(shadow.sum()) / n
        return LitShadowMeasurement(
            np.median(px, 0),
            np.median(px, 0),
            float(np.median(y)),
            float(np.median(y)),
            1.0,
            0.0,
            separation,
            shadow_fraction,
            n,
            False,
            lit,
            shadow,
        )
    lit_i, shadow_i = np.flatnonzero(lit), np.flatnonzero(shadow)
    lit_rgb = np.median(rgb_at(lit_i), axis=0)
    shadow_rgb = np.median(rgb_at(shadow_i), axis=0)
    lit_y, shadow_y = float(np.median(Y[lit_i])), float(np.median(Y[shadow_i]))
    shadow_to_lit = shadow_y / max(lit_y, 1e-12)
    frac = float(shadow.sum()) / max(float(shadow.sum() + lit.sum()), 1.0)
    dominant = bool(
        separation >= min_separation
        and min_fraction <= frac <= 1.0 - min_fraction
        and lit_y / max(shadow_y, 1e-12) >= min_lit_to_shadow
    )
    return LitShadowMeasurement(
        lit_rgb,
        shadow_rgb,
        lit_y,
        shadow_y,
        float(shadow_to_lit),
        float(max(lit_y / max(shadow_y, 1e-12) - 1.0, 0.0)),
        separation,
        frac,
        n,
        dominant,
        lit,
        shadow,
    )

"""Where the sun is: from GPS + UTC time (pvlib), from an HDR environment map, or from image cues with a confidence.

Frames:
- ENU: x east, y north, z up (what pvlib's azimuth/elevation describe).
- Env frame: see ``envmap`` (z up, Blender convention).
- Camera: OpenCV (x right, y down, z forward). A "sun direction" always points FROM the scene TOWARD the sun.
- Image cues score a fixed grid of candidate sun directions expressed in the scene's *world* frame (whatever
  ``cam_from_world`` maps from) so that per-frame scores of a clip add up in one frame (:func:`fuse_sun_cues`). The
  world's up vector must be known (``up_in_world``); for a single image with no pose, world = camera and up is taken as
  -y of a level camera.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import numpy as np
from scipy import ndimage

from aias_augment.analyse.lighting.envmap import (
    azimuth_elevation_to_direction,
    camera_ray_directions,
    pixel_directions,
    pixel_solid_angles,
)
from aias_augment.analyse.lighting.sky import preetham_exposure_fit_cost
from aias_augment.analyse.lighting.solar_position import (
    enu_from_cam_from_metadata,
    rotation_of,
    solar_direction_enu,
    sun_direction_in_cam_from_metadata,
)
from aias_augment.core.geometry import Intrinsics
from aias_augment.core.hdr import luminance, max_channel, srgb_to_linear
from aias_augment.core.rng import systematic_sample

__all__ = [
    "enu_from_cam_from_metadata",
    "rotation_of",
    "solar_direction_enu",
    "sun_direction_in_cam_from_metadata",
    "SunFromEnv",
    "sun_from_envmap",
    "remove_sun",
    "SunCue",
    "sun_direction_grid",
    "sun_cue_from_image",
    "sun_exclusion_by_visible_sky",
    "sun_whiteness_loglik",
    "fuse_sun_cues",
    "angle_between_deg",
    "frame_from_up",
]

EPS = 1e-12


def _unit(v: np.ndarray) -> np.ndarray:
    v = np.asarray(v, dtype=np.float64)
    n = np.linalg.norm(v, axis=-1, keepdims=True)
    if np.any(n < 1e-9):
        raise ValueError("zero-length direction")
    return v / n


def angle_between_deg(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Angle between directions (*, 3), (*, 3) in degrees (dot clamped before arccos)."""
    return np.rad2deg(np.arccos(np.clip(np.sum(_unit(a) * _unit(b), axis=-1), -1.0, 1.0)))


def frame_from_up(up: np.ndarray, forward_hint: np.ndarray | None = None) -> np.ndarray:
    """Rotation ``up_frame_from_frame`` (3, 3) whose z axis is ``up``; x is ``forward_hint`` made horizontal if given."""
    z = _unit(up)
    hint = np.array([1.0, 0.0, 0.0]) if forward_hint is None else np.asarray(forward_hint, dtype=np.float64)
    x = hint - (hint @ z) * z
    if np.linalg.norm(x) < 1e-6:
        x = np.array([0.0, 1.0, 0.0]) - z[1] * z
        if np.linalg.norm(x) < 1e-6:
            x = np.array([0.0, 0.0, 1.0]) - z[2] * z
    x = _unit(x)
    y = np.cross(z, x)
    return np.stack([x, y, z], axis=0)


# ------------------------------------------------------------------------------------------------ from an HDR map


@dataclass(frozen=True)
class SunFromEnv:
    """The dominant compact light of an environment map.

    direction_in_env: unit (3,), energy-weighted centroid of the light's excess radiance.
    irradiance_rgb: (3,) irradiance it delivers at normal incidence: sum over its pixels of (L - background) dOmega.
    background_rgb: (3,) radiance of the ring around it (what the region becomes when the light is removed).
    solid_angle_sr: area of the region; peak_radiance: max luminance; mask: (H, W) bool region.
    """

    direction_in_env: np.ndarray
    irradiance_rgb: np.ndarray
    background_rgb: np.ndarray
    solid_angle_sr: float
    peak_radiance: float
    mask: np.ndarray


def sun_from_envmap(
    radiance: np.ndarray,
    core_fraction: float = 0.05,
    halo_deg: float = 3.0,
    ring_deg: float = 6.0,
    peak_blur_deg: float = 1.0,
    centroid_deg: float = 5.0,
) -> SunFromEnv:
    """Find the brightest compact light of an equirectangular map (any height; seam and poles handled on the sphere).

    Peak: argmax of the luminance blurred by ~``peak_blur_deg`` (energy, not a single hot pixel). Region: the connected
    set of pixels >= ``core_fraction`` x the blurred peak containing it, grown by ``halo_deg`` (angular distance on the
    sphere) to include the circumsolar glow. Background: median radiance of the ``ring_deg`` ring around the region.
    Direction: energy-weighted centroid of the excess radiance within ``centroid_deg`` of the peak, so a broad area
    light (window, bright cloud) points at its brightest part. A map with no light returns zeros and the
    zenith.
    """
    from scipy.spatial import cKDTree

    rad = np.asarray(radiance, dtype=np.float64)
    h, w = rad.shape[:2]
    omega = np.broadcast_to(pixel_solid_angles(h, w), (h, w))
    lum = luminance(rad).astype(np.float64)
    dirs = pixel_directions(h, w)
    peak = float(lum.max())
    if peak <= 0:
        return SunFromEnv(np.array([0.0, 0.0, 1.0]), np.zeros(3), np.zeros(3), 0.0, 0.0, np.zeros((h, w), bool))
    sigma_px = max(peak_blur_deg / (180.0 / h), 0.5)
    smooth = ndimage.gaussian_filter(lum, sigma_px, mode=("nearest", "wrap"))
    r0, c0 = np.unravel_index(int(np.argmax(smooth)), smooth.shape)
    shift = w // 2 - c0  # put the peak at the centre column so the region does not straddle the seam
    lum_s = np.roll(smooth, shift, axis=1)
    # Threshold relative to the raw peak near the blurred maximum (blurring lowers a small sun's peak a lot).
    win = max(2, int(round(3 * sigma_px)))
    local_peak = float(
        np.roll(lum, shift, axis=1)[max(0, r0 - win) : r0 + win + 1, w // 2 - win : w // 2 + win + 1].max()
    )
    # ... but never above the blurred peak itself, so the peak is always inside its own region.
    labels, _ = ndimage.label(lum_s >= min(core_fraction * local_peak, 0.5 * float(smooth[r0, c0])))
    core = np.roll(labels == labels[r0, w // 2], -shift, axis=1)
    # The brightest part: within ``centroid_deg`` of the peak (a sun disc and its glow; the hot spot of a window).
    bright = core & ((dirs @ dirs[r0, c0]) >= np.cos(np.deg2rad(centroid_deg)))
    core_dirs = dirs[core]
    if len(core_dirs) > 4000:
        core_dirs = core_dirs[:: len(core_dirs) // 4000 + 1]
    dist, _ = cKDTree(core_dirs).query(dirs.reshape(-1, 3))
    ang = (2.0 * np.arcsin(np.clip(dist / 2.0, 0.0, 1.0))).reshape(h, w)  # chord -> angle
    region = core | (ang <= np.deg2rad(halo_deg))
    ring = ~region & (ang <= np.deg2rad(halo_deg + ring_deg))
    bg = np.median(rad[ring], axis=0) if ring.any() else np.zeros(3)
    excess = np.clip(rad - bg, 0.0, None) * omega[..., None]
    excess[~region] = 0.0
    irr = excess.sum(axis=(0, 1))
    wlum = luminance(excess).astype(np.float64) * bright
    if wlum.sum() <= 0:
        direction = dirs[r0, c0]
    else:
        direction = _unit((dirs * wlum[..., None]).sum(axis=(0, 1)))
    return SunFromEnv(direction, irr, bg, float(omega[region].sum()), peak, region)


def remove_sun(radiance: np.ndarray, sun: SunFromEnv) -> np.ndarray:
    """The map with the light's region replaced by its background radiance (for ambient SH without the sun)."""
    out = np.array(radiance, dtype=np.float32, copy=True)
    out[sun.mask] = np.minimum(out[sun.mask], sun.background_rgb.astype(np.float32))
    return out


# ------------------------------------------------------------------------------------------------ from image cues


def sun_direction_grid(
    az_step_deg: float = 4.0, el_min_deg: float = -2.0, el_max_deg: float = 86.0, el_step_deg: float = 4.0
) -> tuple[np.ndarray, np.ndarray]:
    """Candidate sun directions in an up-frame (z up): unit (N, 3) and their (azimuth, elevation) in rad, (N, 2)."""
    az = np.deg2rad(np.arange(-180.0, 180.0, az_step_deg))
    el = np.deg2rad(np.arange(el_min_deg, el_max_deg + 1e-9, el_step_deg))
    A, E = np.meshgrid(az, el, indexing="xy")
    return azimuth_elevation_to_direction(A.ravel(), E.ravel()), np.stack([A.ravel(), E.ravel()], axis=-1)


@dataclass(frozen=True)
class SunCue:
    """Per-candidate log-likelihood of the sun direction, on a grid fixed in the world frame.

    grid_in_world: (N, 3) unit candidates; log_likelihood: (N,) (0 = uninformative); direction_in_world: best candidate
    refined by a local posterior mean; confidence in [0, 1] (azimuth concentration of the posterior); sun_visible: a
    clipped sun disc was found in the image; n_sky_pixels: sky samples used; up_in_world: (3,).
    """

    grid_in_world: np.ndarray
    log_likelihood: np.ndarray
    direction_in_world: np.ndarray
    confidence: float
    sun_visible: bool
    n_sky_pixels: int
    up_in_world: np.ndarray


def posterior_summary(grid: np.ndarray, loglik: np.ndarray, up: np.ndarray) -> tuple[np.ndarray, float]:
    ll = loglik - loglik.max()
    p = np.exp(ll)
    p /= p.sum()
    best = int(np.argmax(ll))
    near = np.sum(grid * grid[best], axis=-1) > np.cos(np.deg2rad(10.0))
    direction = _unit((grid[near] * p[near, None]).sum(axis=0))
    # Azimuth concentration about the up axis: 1 = one azimuth, 0 = uniform.
    horiz = grid - (grid @ up)[:, None] * up
    hn = np.linalg.norm(horiz, axis=-1, keepdims=True)
    horiz = np.where(hn > 1e-6, horiz / np.maximum(hn, EPS), 0.0)
    confidence = float(np.linalg.norm((horiz * p[:, None]).sum(axis=0)))
    return direction, float(np.clip(confidence, 0.0, 1.0))


def _find_sun_disc(
    unit_rgb: np.ndarray,
    above: np.ndarray,
    max_area_frac: float = 0.08,
    clip_level: float = 250.0 / 255.0,
    linear: np.ndarray | None = None,
) -> tuple[float, float] | None:
    """(u, v) of a visible sun: a clipped (white) blob above the horizon that is compact (< ``max_area_frac`` of the
    image), not cut by the image border, round (area <= 2.5 x the disc inscribed at its deepest point) and surrounded by glare (the 2-pixel ring around it
    is bright everywhere: 10th percentile >= 0.45 linear, mean >= 2x the median above the horizon; 8 samples at 1.5x
    its radius within a factor 0.35 of each other). Returns its deepest point, or None. ``linear``: the image's
    linear radiance when the caller has it (else decoded from ``unit_rgb``)."""
    clipped = (np.minimum(np.minimum(unit_rgb[..., 0], unit_rgb[..., 1]), unit_rgb[..., 2]) >= clip_level) & above
    if not clipped.any():
        return None
    lum = luminance(srgb_to_linear(unit_rgb) if linear is None else linear)
    sky_median = float(np.median(lum[above & ~clipped])) if (above & ~clipped).any() else 0.0
    labels, n = ndimage.label(clipped)
    sizes = ndimage.sum(clipped, labels, index=np.arange(1, n + 1))
    boxes = ndimage.find_objects(labels)
    h, w = clipped.shape
    best = None
    for idx in np.argsort(sizes)[::-1][:5]:
        area = float(sizes[idx])
        if area < 4 or area > max_area_frac * h * w:
            continue
        rows, cols = boxes[idx]
        if rows.start == 0 or cols.start == 0 or rows.stop == h or cols.stop == w:
            continue  # cut by the image border: its centre is unknown (the sky fit still sees the glare)
        # The blob on its box grown by 2 pixels (its distance map and its 2-pixel ring lie within): the same
        # numbers as on the whole image, at the cost of the blob's size.
        r0, c0 = max(rows.start - 2, 0), max(cols.start - 2, 0)
        box = (slice(r0, min(rows.stop + 2, h)), slice(c0, min(cols.stop + 2, w)))
        blob = labels[box] == idx + 1
        dist = ndimage.distance_transform_edt(np.pad(blob, 1))[1:-1, 1:-1]
        depth = float(dist.max())
        if area > 2.5 * np.pi * depth**2:  # elongated or ragged: a white object or a gap between leaves
            continue
        v, u = np.unravel_index(int(np.argmax(dist)), dist.shape)
        v, u = v + r0, u + c0
        # Glare is isotropic: 8 samples around the blob at 1.5x its radius must all be bright relative to each other.
        ang = np.arange(8) * np.pi / 4
        rad_px = 1.5 * depth + 3.0
        su = np.round(u + rad_px * np.cos(ang)).astype(int)
        sv = np.round(v + rad_px * np.sin(ang)).astype(int)
        inside = (su >= 0) & (su < w) & (sv >= 0) & (sv < h)
        if inside.sum() < 5:
            continue
        samples = lum[sv[inside], su[inside]]
        if float(samples.min()) < 0.35 * float(samples.max()):
            continue
        # Glare: every pixel just outside a clipped sun is nearly clipped too; a white facade or a sky gap between
        # leaves has dark pixels on its border.
        ring = ndimage.binary_dilation(blob, iterations=2) & ~blob
        ring_lum = lum[box][ring]
        if not ring.any() or float(np.percentile(ring_lum, 10)) < 0.45 or float(ring_lum.mean()) < 2.0 * sky_median:
            continue
        if best is None or area > best[0]:
            best = (area, float(u), float(v))
    return None if best is None else (best[1], best[2])


#: Image width (px) at which the sky's smoothness window is ``SKY_SMOOTH_WINDOW_PX`` (estimate's analysis width).
SKY_SMOOTH_REFERENCE_WIDTH = 400
SKY_SMOOTH_WINDOW_PX = 5


def sky_smooth_window_px(width: int) -> int:
    """Side (px) of the window of the sky's local log-luminance std: ``SKY_SMOOTH_WINDOW_PX`` at
    ``SKY_SMOOTH_REFERENCE_WIDTH`` and wider, proportionally smaller below (at least 2): the same patch of the scene."""
    return int(np.clip(round(SKY_SMOOTH_WINDOW_PX * width / SKY_SMOOTH_REFERENCE_WIDTH), 2, SKY_SMOOTH_WINDOW_PX))


def _sky_pixels(unit, lin, Y, logY, above, sky_mask) -> np.ndarray:
    """(H, W) bool: the sky pixels the luminance fit uses (see :func:`sun_cue_from_image`); ``unit`` is the image in
    [0, 1], ``lin`` its linear radiance, ``Y`` / ``logY`` its luminance, ``above`` the pixels above the horizon."""
    if sky_mask is not None:
        return np.asarray(sky_mask, bool) & above & (max_channel(unit) < 0.98)
    # The smoothness window is 5 px at the estimator's analysis width (400 px) and shrinks with narrower images
    # (down to 2 px at 160, the fast preset's cheap analysis): a fixed 5 px window there spans 2.5x more of the
    # scene, so branches and roof edges leave a quarter of the open sky "rough" (KITTI 06: 5 % of the pixels
    # above the horizon instead of 20 %), and the indoor guard (min_sky_fraction_for_sun) then refused the sun.
    win = sky_smooth_window_px(unit.shape[1])
    mean = ndimage.uniform_filter(logY, win)
    sq = ndimage.uniform_filter(logY * logY, win)
    local_std = np.sqrt(np.clip(sq - mean * mean, 0.0, None))
    ref = np.percentile(Y[above], 95) if above.any() else 1.0
    bluish = lin[..., 2] >= lin[..., 0]
    return (
        above
        & (local_std < 0.06)
        & (max_channel(unit) < 0.98)
        & (Y > max(0.15 * ref, 0.01))
        & (bluish | (Y > 0.5 * ref))
    )


def _sky_pattern_loglik(
    d, ly, lin_px, up_in_cam, grid_in_cam, grid_in_world, up_in_world, turbidities, effective_samples, whiteness_weight
) -> tuple[np.ndarray, float, float]:
    """The sky cues of :func:`sun_cue_from_image` for the sampled sky pixels (rays ``d`` (P, 3) in the camera frame,
    log-luminance ``ly`` (P,), linear colours ``lin_px`` (P, 3)): the candidates' log-likelihood (luminance pattern,
    plus the weighted colour cue), the sky's contrast in [0, 1] (0: no azimuthal information) and the agreement
    factor of the two cues (1 when they point the same way, down to 0.2 when opposite)."""
    cue_agreement = 1.0
    cos_theta = d @ up_in_cam  # view zenith cosine
    cos_gamma = grid_in_cam @ d.T  # (N, P); clipped to [-1, 1] where it is read (the fit clips its own)
    best_cost = preetham_exposure_fit_cost(ly, cos_theta, cos_gamma, turbidities)
    sigma2 = max(float(best_cost.min()), 1e-4)  # eps: a perfect fit would otherwise be infinitely sharp
    # How much better the best sun explains the sky than a typical candidate: 0 = no azimuthal information.
    sky_contrast = float(np.clip(1.0 - best_cost.min() / max(float(np.median(best_cost)), 1e-12), 0.0, 1.0))
    sky_loglik = -0.5 * effective_samples * (best_cost - best_cost.min()) / sigma2
    if whiteness_weight > 0:
        blue = _blue_chromaticity(lin_px)
        cos_gamma = np.clip(cos_gamma, -1.0, 1.0)
        colour_loglik = whiteness_weight * sun_whiteness_loglik(blue, cos_gamma, cos_theta, effective_samples)
    else:  # the colour cue is off (the default): not computed at all
        colour_loglik = np.zeros(len(grid_in_world))
    if colour_loglik.max() - colour_loglik.min() > 1.0:  # the colour says something: compare the two sky cues
        h = grid_in_world - (grid_in_world @ up_in_world)[:, None] * up_in_world
        a, b = h[int(np.argmax(sky_loglik))], h[int(np.argmax(colour_loglik))]
        cos_dphi = float(a @ b) / max(float(np.linalg.norm(a) * np.linalg.norm(b)), 1e-9)  # eps: zenith candidate
        cue_agreement = max(0.2, 0.5 * (1.0 + cos_dphi))
    return sky_loglik + colour_loglik, sky_contrast, cue_agreement


def _checked_image(image_rgb_uint8, intrinsics: Intrinsics) -> np.ndarray:
    img = np.asarray(image_rgb_uint8)
    if img.ndim != 3 or img.shape[2] != 3 or img.dtype != np.uint8:
        raise ValueError(f"sun_cue_from_image: expected (H, W, 3) uint8, got {img.shape} {img.dtype}")
    if (intrinsics.height, intrinsics.width) != img.shape[:2]:
        raise ValueError("sun_cue_from_image: intrinsics do not match the image size")
    return img


def _sky_confidence(concentration: float, sky_contrast: float, n_sky: int, cue_agreement: float, excluded: bool):
    """Confidence of a sky-only cue (no sun disc): the posterior's concentration, the sky's contrast, how much sky
    there is (full at 400 pixels) and the agreement of the two sky cues."""
    confidence = concentration * sky_contrast * min(1.0, n_sky / 400.0) * cue_agreement
    # Honesty: when the sky fit's favourite is a sun the visible sky rules out, the cues disagree and what is left
    # (the best of the remaining candidates) is weaker evidence.
    if excluded:
        confidence *= 0.5
    return confidence


def sun_cue_from_image(
    image_rgb_uint8: np.ndarray,
    intrinsics: Intrinsics,
    cam_from_world: np.ndarray | None = None,
    up_in_world: np.ndarray | None = None,
    grid_in_world: np.ndarray | None = None,
    sky_mask: np.ndarray | None = None,
    turbidities: Sequence[float] = (2.5, 4.0, 7.0),
    max_sky_pixels: int = 800,
    effective_samples: float = 30.0,
    exclusion_kappa: float = 40.0,
    exclusion_min_elevation_deg: float = 10.0,
    whiteness_weight: float = 0.0,
) -> SunCue:
    """Score candidate sun directions from one image with a known camera.

    Cues: (1) a visible sun disc (clipped compact blob with glare) -> a sharp von Mises-Fisher term around its ray;
    (2) the sky's luminance pattern: the Preetham model's relative luminance F(theta, gamma) / F(0, theta_s) is fitted
    to the log-luminance of sky pixels for every candidate (the unknown exposure is one additive constant in log space,
    solved in closed form) and the best turbidity kept; the residual variance becomes a Gaussian log-likelihood with
    ``effective_samples`` independent samples (neighbouring sky pixels are strongly correlated).
    Sky pixels: above the horizon by > 2 deg, smooth (local log-luminance std < 0.06 in a window of
    :func:`sky_smooth_window_px`), not clipped, not dark, and
    blue-dominant or bright; or ``sky_mask`` if given.
    (3) circumsolar colour (:func:`sun_whiteness_loglik`): the sky is less blue (whiter, or warmer at sunset) toward
    the sun, independently of its brightness; weighted by ``whiteness_weight`` (off by default: on the Blender HDR
    crops weight 3 lowers the single-crop median azimuth error 86 -> 66 deg, but it flips KITTI frame 17 to the wrong
    side and worsens clip fusion on forest; see studies/lighting/README.md). When the luminance fit and the colour
    cue favour azimuths dphi apart, the confidence is scaled by max(0.2, (1 + cos dphi) / 2).
    (4) exclusion by visible sky (:func:`sun_exclusion_by_visible_sky`): when no sun disc is found, a candidate that
    lies on (or within a few degrees of) unclipped open sky cannot be the sun, since the sun and its aureole would clip
    there; ``exclusion_kappa`` x the exclusion score is added. This removes the Preetham fit's favourite failure, a
    hazy horizon in front of the camera read as a low sun in view.
    """
    img = _checked_image(image_rgb_uint8, intrinsics)
    cam_from_world = np.eye(3) if cam_from_world is None else rotation_of(cam_from_world)
    if up_in_world is None:
        up_in_world = cam_from_world.T @ np.array([0.0, -1.0, 0.0])  # level camera: up is -y
    up_in_world = _unit(up_in_world)
    if grid_in_world is None:
        grid_up, _ = sun_direction_grid()
        grid_in_world = grid_up @ frame_from_up(up_in_world)  # up-frame -> world (rows: R^T v)
    grid_in_cam = grid_in_world @ cam_from_world.T
    up_in_cam = cam_from_world @ up_in_world

    unit = img.astype(np.float32) / 255.0
    lin = srgb_to_linear(img)  # uint8 (checked): the curve of ``unit``, by table
    rays = camera_ray_directions(intrinsics)
    elev_sin = rays @ up_in_cam
    above = elev_sin > np.sin(np.deg2rad(2.0))
    loglik = np.zeros(len(grid_in_world))
    cue_agreement = 1.0  # 1: the luminance and colour sky cues point to the same azimuth; down to 0.2 when opposite

    disc = _find_sun_disc(unit, above, linear=lin)
    if disc is not None:
        ray = rays[int(round(disc[1])), int(round(disc[0]))]
        kappa = 1.0 / np.deg2rad(3.0) ** 2  # ~3 deg spread
        loglik += kappa * (grid_in_cam @ ray - 1.0)

    Y = np.maximum(luminance(lin), 1e-4)
    logY = np.log(Y)
    sky = _sky_pixels(unit, lin, Y, logY, above, sky_mask)
    idx = np.flatnonzero(sky.ravel())
    n_sky = int(idx.size)
    if n_sky >= 50:
        idx = idx[systematic_sample(n_sky, max_sky_pixels)]
        sky_loglik, sky_contrast, cue_agreement = _sky_pattern_loglik(
            rays.reshape(-1, 3)[idx],
            logY.ravel()[idx],
            lin.reshape(-1, 3)[idx],
            up_in_cam,
            grid_in_cam,
            grid_in_world,
            up_in_world,
            turbidities,
            effective_samples,
            whiteness_weight,
        )
        loglik += sky_loglik
    exclusion = np.zeros(len(grid_in_world))
    if disc is None and n_sky >= 50:
        exclusion = sun_exclusion_by_visible_sky(rays[sky], grid_in_cam)
        # A sun low on the horizon is dimmed by the long air path (air mass > 5 below 10 deg) and may not clip its
        # surroundings: no exclusion there.
        exclusion = np.where(grid_in_cam @ up_in_cam > np.sin(np.deg2rad(exclusion_min_elevation_deg)), exclusion, 0.0)
        loglik += exclusion_kappa * exclusion
    direction, concentration = posterior_summary(grid_in_world, loglik, up_in_world)
    if disc is not None:
        confidence = 0.9 * concentration
    elif n_sky < 50:
        confidence = 0.0
    else:
        excluded = bool(exclusion[int(np.argmax(sky_loglik))] < -0.5)
        confidence = _sky_confidence(concentration, sky_contrast, n_sky, cue_agreement, excluded)
    return SunCue(grid_in_world, loglik, direction, confidence, disc is not None, n_sky, up_in_world)


def _blue_chromaticity(linear_rgb: np.ndarray) -> np.ndarray:
    """Blue chromaticity B / (R + G + B) of linear RGB, (P, 3) -> (P,) in [0, 1] (eps 1e-6 for black)."""
    rgb = np.asarray(linear_rgb, dtype=np.float64)
    return rgb[..., 2] / np.maximum(rgb.sum(axis=-1), 1e-6)


def sun_whiteness_loglik(
    saturation: np.ndarray, cos_gamma: np.ndarray, cos_theta: np.ndarray, effective_samples: float = 30.0
) -> np.ndarray:
    """Log-likelihood per candidate sun from the colour of sky pixels: less blue toward the sun.

    Physics: near a high sun, forward (Mie) scattering by aerosols adds nearly white light to the blue Rayleigh sky;
    near a low sun the circumsolar sky turns yellow-orange (blue scattered out of the long path). Either way the blue
    chromaticity B / (R + G + B) falls as the angle gamma to the sun decreases (a plain saturation measure would not:
    an orange sunset glow is saturated). Near the horizon the long air path lowers it too, in every azimuth. Model per
    candidate: ``blue = a + b cos(gamma) + c cos(theta)`` (theta: view zenith angle), least squares with the physical
    sign ``b <= 0`` (a candidate that needs b > 0 gets the fit without the gamma term).
    ``saturation`` (P,): the blue chromaticity of the sky pixels; ``cos_gamma`` (N, P), ``cos_theta`` (P,). Returns (N,)
    ``-0.5 n_eff (cost - min) / var0`` (var0: residual variance without the gamma term) with ``n_eff = effective_samples`` (neighbouring sky pixels are correlated); a uniform sky gives ~0 everywhere.
    """
    y = np.asarray(saturation, dtype=np.float64)
    cg = np.asarray(cos_gamma, dtype=np.float64)
    ct = np.asarray(cos_theta, dtype=np.float64)
    n, p = cg.shape
    if y.shape != (p,) or ct.shape != (p,):
        raise ValueError("sun_whiteness_loglik: saturation, cos_theta must be (P,) matching cos_gamma (N, P)")
    if p < 10:
        return np.zeros(n)
    # Residualise against the gamma-free model [1, cos theta] (Frisch-Waugh): then the gamma coefficient is a 1-D fit.
    A = np.stack([np.ones(p), ct], axis=1)
    proj = A @ np.linalg.pinv(A)
    y_r = y - proj @ y
    g_r = cg - cg @ proj.T  # (N, P)
    base = float(np.mean(y_r * y_r))
    gg = np.sum(g_r * g_r, axis=1)
    b = np.sum(g_r * y_r[None, :], axis=1) / np.maximum(gg, 1e-12)  # eps: a constant gamma column has no slope
    b = np.minimum(b, 0.0)
    cost = base - (b * b * gg) / p
    cost = np.maximum(cost, 0.0)
    # Normalised by the gamma-free residual variance (eps 1e-9 for a flat sky): the term is bounded by n_eff / 2 nats,
    # so a near-perfect fit of a few pixels cannot override a sun disc or the luminance fit.
    return -0.5 * effective_samples * (cost - cost.min()) / max(base, 1e-9)


def sun_exclusion_by_visible_sky(
    sky_rays_in_cam: np.ndarray,
    grid_in_cam: np.ndarray,
    radius_deg: float = 4.0,
    min_pixels: int = 12,
    max_pixels: int = 4000,
) -> np.ndarray:
    """Score in [-1, 0] per candidate: -1 where the candidate sun lies on open, unclipped sky in the image.

    Physics: the solar disc is ~1e5 x brighter than the sky and its aureole (a few degrees) ~10-100 x; an exposure that
    leaves the sky unclipped clips them. So sky pixels seen *unclipped* within ``radius_deg`` of a direction rule it out
    as the sun (clouds that hide the sun leave a bright white glow that the sky mask rejects as clipped or textured;
    buildings and trees are not sky). ``sky_rays_in_cam`` (P, 3) unit rays of the sky pixels; ``grid_in_cam`` (N, 3).
    The score ramps from 0 to -1 as the number of such pixels goes from 0 to ``min_pixels`` (a few stray pixels, e.g.
    a misclassified sliver, do not veto). Candidates out of view get 0 (no information).
    """
    rays = np.asarray(sky_rays_in_cam, dtype=np.float64).reshape(-1, 3)
    grid = np.asarray(grid_in_cam, dtype=np.float64)
    if len(rays) == 0:
        return np.zeros(len(grid))
    scale = 1.0
    if len(rays) > max_pixels:  # a regular stride (deterministic, consumes no randomness): counts scale back up
        step = int(np.ceil(len(rays) / max_pixels))
        scale = len(rays) / len(rays[::step])
        rays = rays[::step]
    # Sky rays within radius_deg of each candidate, counted with a k-d tree on the unit vectors: the chord
    # |g - r| = 2 sin(angle / 2) grows with the angle, so "chord <= 2 sin(radius / 2)" is "g . r >= cos(radius)".
    from scipy.spatial import cKDTree

    chord = 2.0 * np.sin(np.deg2rad(radius_deg) / 2.0)
    count = cKDTree(rays).query_ball_point(grid, chord, return_length=True) * scale
    return -np.clip(count / float(min_pixels), 0.0, 1.0)


def fuse_sun_cues(cues: Sequence[SunCue]) -> SunCue:
    """Combine per-frame cues of one clip (same world grid): log-likelihoods add (frames as independent evidence)."""
    if len(cues) == 0:
        raise ValueError("fuse_sun_cues: no cues")
    grid = cues[0].grid_in_world
    for c in cues[1:]:
        if c.grid_in_world.shape != grid.shape or not np.allclose(c.grid_in_world, grid):
            raise ValueError("fuse_sun_cues: cues use different grids; pass the same grid_in_world to every frame")
    loglik = np.sum([c.log_likelihood for c in cues], axis=0)
    up = cues[0].up_in_world
    direction, confidence = posterior_summary(grid, loglik, up)
    return SunCue(
        grid,
        loglik,
        direction,
        confidence,
        any(c.sun_visible for c in cues),
        int(sum(c.n_sky_pixels for c in cues)),
        up,
    )

"""The sun's direction from image cues, on one grid of world directions: each frame's log-likelihood (sky or sun
disc, cast-shadow axis on the ground, lit and shaded walls, shadow ends, the elevation that GPS and time fix), summed
over a clip's frames, plus a weak elevation prior; the confidence weighs how clearly the non-axis cues pick the
axis's end."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import numpy as np

from aias_augment.analyse.lighting.config import LightingConfig
from aias_augment.analyse.lighting.frame import FrameContext, check_image, prepare_clip, prepare_frame
from aias_augment.analyse.lighting.ratio import ground_coordinates, shadow_axis_on_ground
from aias_augment.analyse.lighting.sun import (
    frame_from_up,
    posterior_summary,
    rotation_of,
    solar_direction_enu,
    sun_cue_from_image,
    sun_direction_grid,
)
from aias_augment.analyse.lighting.sun_side import sun_side_cue
from aias_augment.core.geometry import Intrinsics

__all__ = [
    "SunDirectionEstimate",
    "estimate_sun_direction",
    "estimate_sun_direction_clip",
    "image_cue_sun",
    "sky_side_mixture",
]


def _half_turn_index(azel: np.ndarray) -> np.ndarray:
    """Index of the candidate at the same elevation and the azimuth + 180 deg, for the grid of ``sun_direction_grid``
    (azimuth steps that divide 180 deg). (N, 2) -> (N,)."""
    az_vals = np.unique(np.round(azel[:, 0], 9))
    el_vals = np.unique(np.round(azel[:, 1], 9))
    n_az = len(az_vals)
    i_az = np.searchsorted(az_vals, np.round(azel[:, 0], 9))
    i_el = np.searchsorted(el_vals, np.round(azel[:, 1], 9))
    lookup = np.full((len(el_vals), n_az), -1)
    lookup[i_el, i_az] = np.arange(len(azel))
    out = lookup[i_el, (i_az + n_az // 2) % n_az]
    if n_az % 2 or np.any(out < 0):
        raise ValueError("sun grid has no half-turn symmetry")
    return out


def _in_view(d_cam: np.ndarray, K: Intrinsics) -> bool:
    """Whether a direction (camera frame) projects inside the image."""
    if d_cam[2] <= 1e-6:
        return False
    u = K.fx * d_cam[0] / d_cam[2] + K.cx
    v = K.fy * d_cam[1] / d_cam[2] + K.cy
    return bool(-0.5 <= u <= K.width - 0.5 and -0.5 <= v <= K.height - 0.5)


def sky_side_mixture(loglik: np.ndarray, half_turn: np.ndarray, p: float) -> np.ndarray:
    """Log-likelihood of "the sun is at d with probability p, at d's mirror under a half turn of the azimuth with
    probability 1 - p": ``logaddexp(log p + l(d), log(1 - p) + l(half_turn(d)))``. ``half_turn`` (N,) indexes each
    candidate's mirror. The result's side margin is at most log(p / (1 - p)); near the best candidate it equals
    l + log p (the peak's shape is unchanged); a symmetric l is returned unchanged up to the constant."""
    if not 0.5 <= p < 1.0:
        raise ValueError(f"side probability must be in [0.5, 1), got {p}")
    ll = np.asarray(loglik, dtype=np.float64)
    return np.logaddexp(np.log(p) + ll, np.log1p(-p) + ll[np.asarray(half_turn)])


def _sun_evidence(ctx: FrameContext, grid_world: np.ndarray, azel: np.ndarray, config: LightingConfig):
    """Log-likelihood of each world-grid sun direction from this frame: sky / sun-disc cue (tempered when no disc is
    visible), elevation from GPS + time when given without an orientation, cast-shadow axis on the ground, and the
    side cues (vertical surfaces, shadow ends). Returns (loglik, cue, axis_strength, side_loglik, side) where
    side_loglik is the part of the evidence that can tell the two ends of the shadow axis apart (all but the axis) and
    side the :class:`SunSideCue` (None where there is no sign of direct sun)."""
    cue = sun_cue_from_image(
        ctx.small,
        ctx.K_small,
        ctx.R_cw,
        ctx.up_in_world,
        grid_world,
        whiteness_weight=config.sky_colour_weight,
    )
    # The sky fit is sharp when it puts the sun inside the frame (the circumsolar sky is seen; 1.8 deg median on the HDR
    # crops) and unreliable on the side when it puts it outside: there it becomes a mixture of itself and its mirror
    # image under a half turn of the azimuth (``sky_out_of_view_side_prob``), which caps its side vote and keeps its
    # peak.
    in_view = cue.sun_visible or _in_view(ctx.R_cw @ grid_world[int(np.argmax(cue.log_likelihood))], ctx.K_small)
    loglik = cue.log_likelihood
    if not in_view:
        loglik = sky_side_mixture(loglik, _half_turn_index(azel), config.sky_out_of_view_side_prob)
    m = ctx.measurement
    side = None
    if (m is not None and m.dominant_sun) or cue.sun_visible:
        # Lit walls brighter than shaded ones and shadows running from their occluders presume direct sunlight: the
        # side cues run only where the ground shows cast shadows or the sun itself is seen (under an overcast sky
        # albedo differences between walls would read as a sun).
        side = sun_side_cue(
            ctx.img,
            ctx.K,
            ctx.up_in_cam,
            grid_world @ ctx.R_cw.T,
            camera_height_m=config.camera_height_m,
            analysis_width=config.side_analysis_width,
            facade_albedo_sigma=config.facade_albedo_sigma,
            shadow_end_kappa=config.shadow_end_kappa,
        )
        loglik = loglik + side.log_likelihood
    side_loglik = loglik.copy()
    meta = ctx.meta
    if all(k in meta for k in ("lat", "lon", "utc")):
        # Position and time without orientation still fix the sun's elevation.
        el = np.arcsin(np.clip(solar_direction_enu(meta["lat"], meta["lon"], meta["utc"])[2], -1, 1))
        loglik -= 0.5 * ((azel[:, 1] - el) / np.deg2rad(3.0)) ** 2
    axis_strength = 0.0
    if m is not None and m.dominant_sun:
        # Cast shadows need the sun above the horizon (at a few degrees they are long but real: a sunset's sun at 3.4
        # deg must survive on the 4-deg grid, whose rows sit at -2, 2, 6, ... deg).
        loglik = np.where(azel[:, 1] > 0.0, loglik, loglik - 1e3)
        # The shadow contrast bounds the elevation from below: on horizontal ground sun/sky = (E_sun,normal / E_sky)
        # sin(el), and E_sun,normal / E_sky cannot exceed a clear sky's direct-normal to diffuse-horizontal ratio, so
        # sin(el) >= ratio / max_direct_to_diffuse_ratio (soft: a Gaussian fall-off of 0.05 in sin(el) below it).
        sin_min = min(m.sun_sky_ratio / config.max_direct_to_diffuse_ratio, 0.95)
        short = np.clip(sin_min - np.sin(azel[:, 1]), 0.0, None)
        loglik = loglik - 0.5 * (short / 0.05) ** 2
        # Cast shadows on the ground are bands along the sun's azimuth (180 deg ambiguous: the sky and side cues, or
        # other frames of the clip, pick the end). Only on the main ground region: a fallback box's shadows (tree
        # crowns on a grass verge, mixed with the grass' own texture) are blobs, not bands; on the KITTI 06 grey frames
        # 10, 20, 35, 45 their "axis" put the sun at -2 / 174 / -162 / -174 deg against the real shadows' -110, and
        # without it the other cues give -102 to -114.
        axis_strength = 0.0
        if ctx.measurement_region is ctx.region:
            ground_xy, _ = ground_coordinates(ctx.K, ctx.up_in_cam, config.camera_height_m)
            axis, axis_strength = shadow_axis_on_ground(m.shadow_mask, ctx.region, ground_xy)
        if axis_strength > 0:
            d_cam = grid_world @ ctx.R_cw.T
            fwd = np.array([0.0, 0.0, 1.0]) - ctx.up_in_cam[2] * ctx.up_in_cam
            fwd /= np.linalg.norm(fwd)
            phi = np.arctan2(d_cam @ fwd, d_cam @ np.cross(fwd, ctx.up_in_cam))
            loglik = loglik + config.shadow_axis_kappa * axis_strength * np.cos(2.0 * (phi - axis))
    return loglik, cue, axis_strength, side_loglik, side


def _side_agreement(
    side_loglik: np.ndarray, grid: np.ndarray, chosen_dir: np.ndarray, up: np.ndarray, axis_strength: float
) -> float:
    """Confidence factor in [0.5, 1] for the side of the cast-shadow axis: the axis fixes the azimuth up to 180 deg and
    the other cues (sky, vertical surfaces, shadow ends: ``side_loglik``) pick the end. Their log-odds for the chosen
    half-plane is the margin between their best candidate on that side and their best on the other side; as a
    probability p = sigmoid(margin), the factor is 0.5 + 0.5 max(0, 2p - 1) = 0.5 + 0.5 tanh(max(margin, 0) / 2):
    0.5 for a coin flip (or when the axis term overrode them), 1 when they are decisive. 1 without an axis.
    """
    if axis_strength <= 0:
        return 1.0
    b = chosen_dir - (chosen_dir @ up) * up
    if float(np.linalg.norm(b)) < 1e-6:  # a zenith direction has no azimuth
        return 0.5
    h = grid - (grid @ up)[:, None] * up
    same = h @ b > 0
    if same.all() or not same.any():
        return 0.5
    margin = float(side_loglik[same].max() - side_loglik[~same].max())
    return 0.5 + 0.5 * float(np.tanh(max(margin, 0.0) / 2.0))


def _elevation_prior(azel: np.ndarray, config: LightingConfig) -> np.ndarray:
    """Weak Gaussian log-prior on the sun's elevation for image cues (sky fits are biased low: a hazy horizon looks
    like a low sun). Added once per estimate (once per clip, not per frame)."""
    mean, sigma = np.deg2rad(config.elevation_prior_deg[0]), np.deg2rad(config.elevation_prior_deg[1])
    return -0.5 * ((azel[:, 1] - mean) / sigma) ** 2


@dataclass(frozen=True)
class SunDirectionEstimate:
    """The image-cue sun of a frame or clip, whether or not it is dominant (see :func:`estimate_sun_direction`).

    direction_in_world: unit (3,) toward the sun in the world frame of ``cam_from_world``; confidence in [0, 1] (before
    the unknown-camera factor 0.5); axis_strength: strongest cast-shadow axis among the frames (0 = none);
    side_margin_nats: log-odds of the chosen end of that axis from the non-axis cues (sky, walls, shadow ends);
    sky_cues / side_cues: per frame (a side cue is None where the frame shows no sign of direct sun).
    """

    direction_in_world: np.ndarray
    confidence: float
    axis_strength: float
    side_margin_nats: float
    sky_cues: tuple
    side_cues: tuple


def _side_margin(side_loglik: np.ndarray, grid: np.ndarray, chosen_dir: np.ndarray, up: np.ndarray) -> float:
    b = chosen_dir - (chosen_dir @ up) * up
    h = grid - (grid @ up)[:, None] * up
    same = h @ b > 0
    if float(np.linalg.norm(b)) < 1e-6 or same.all() or not same.any():
        return 0.0
    return float(side_loglik[same].max() - side_loglik[~same].max())


def image_cue_sun(ctxs: list, up_in_world: np.ndarray, config: LightingConfig) -> SunDirectionEstimate:
    """Sum the frames' sun evidence on one world grid (frames as independent views of one distant sun), add the
    elevation prior once, take the best candidate; confidence = max(sky-cue confidence, 0.5 x axis strength x
    posterior concentration) x the side-agreement factor (``_side_agreement``)."""
    grid_up, azel = sun_direction_grid()
    grid_world = grid_up @ frame_from_up(up_in_world)
    evidence = [_sun_evidence(c, grid_world, azel, config) for c in ctxs]
    loglik = np.sum([e[0] for e in evidence], axis=0) + _elevation_prior(azel, config)
    d_world = grid_world[int(np.argmax(loglik))]
    _, concentration = posterior_summary(grid_world, loglik, up_in_world)
    axis = max(e[2] for e in evidence)
    side_loglik = np.sum([e[3] for e in evidence], axis=0)
    confidence = max(max(e[1].confidence for e in evidence), 0.5 * axis * concentration)
    confidence *= _side_agreement(side_loglik, grid_world, d_world, up_in_world, axis)
    return SunDirectionEstimate(
        d_world,
        float(np.clip(confidence, 0.0, 1.0)),
        float(axis),
        _side_margin(side_loglik, grid_world, d_world, up_in_world),
        tuple(e[1] for e in evidence),
        tuple(e[4] for e in evidence),
    )


def estimate_sun_direction(
    image_rgb_uint8: np.ndarray,
    intrinsics: Intrinsics | None = None,
    cam_from_world: np.ndarray | None = None,
    meta: dict | None = None,
    *,
    config: LightingConfig = LightingConfig(),
) -> SunDirectionEstimate:
    """The image-cue sun direction of one frame (sky or sun disc, cast-shadow axis, walls, shadow ends), as
    :func:`estimate_lighting` picks it, returned even where the sun is not dominant (for evaluation and for callers
    that decide dominance themselves). ``meta``: 'up_in_world', 'ground_mask', 'lat'/'lon'/'utc' (elevation only)."""
    img = check_image(image_rgb_uint8)
    meta = dict(meta or {})
    R_cw = np.eye(3) if cam_from_world is None else rotation_of(cam_from_world)
    ctx = prepare_frame(img, intrinsics, R_cw, meta, config)
    return image_cue_sun([ctx], ctx.up_in_world, config)


def estimate_sun_direction_clip(
    images: Sequence[np.ndarray],
    intrinsics: Sequence[Intrinsics | None] | Intrinsics | None,
    cams_from_world: Sequence[np.ndarray],
    metas: Sequence[dict] | dict | None = None,
    *,
    config: LightingConfig = LightingConfig(),
) -> SunDirectionEstimate:
    """The image-cue sun of a clip with known poses, fused in world coordinates as :func:`estimate_lighting_clip` does
    (the world's up: ``metas[0]['up_in_world']`` or the first camera's -y)."""
    ctxs, up_in_world = prepare_clip(images, intrinsics, cams_from_world, metas, config)
    return image_cue_sun([c for c in ctxs if not c.indoor] or ctxs, up_in_world, config)

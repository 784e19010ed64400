"""The ambient (sky and surroundings, without the sun) of a frame as order-2 SH, and its colour: an env map built
from the frame plus a Preetham sky and a ground fill, then given one colour, the light's as the photo's near-grey
surfaces show it, so a white surface stays white whichever way it faces."""

from __future__ import annotations

import numpy as np

from aias_augment.analyse.lighting.config import LightingConfig
from aias_augment.analyse.lighting.envmap import assemble_envmap, camera_ray_directions
from aias_augment.analyse.lighting.sh import project_envmap_to_sh, sh_irradiance
from aias_augment.analyse.lighting.sky import preetham_sky_radiance
from aias_augment.analyse.lighting.sun import frame_from_up
from aias_augment.core.geometry import Intrinsics
from aias_augment.core.hdr import luminance

__all__ = [
    "achromatic_light_colour",
    "ambient_from_image",
    "neutral_ambient",
    "sky_part_of_neutral",
    "sun_over_sky_rgb",
]


def ambient_from_image(
    linear: np.ndarray, K: Intrinsics, up_in_cam: np.ndarray, sun_dir_cam: np.ndarray | None, config: LightingConfig
) -> np.ndarray:
    """SH (9, 3) in the camera frame of an env map built from this one frame plus a Preetham sky and a ground fill."""
    env_from_cam = frame_from_up(up_in_cam, np.array([0.0, 0.0, 1.0]))  # env z = up, env x = camera forward
    cam_from_env = env_from_cam.T
    rays = camera_ray_directions(K)
    elev = rays @ up_in_cam
    above, below = elev > 0.03, elev < -0.03
    Y = luminance(linear)
    sun_env = env_from_cam @ (sun_dir_cam if sun_dir_cam is not None else up_in_cam)
    sky_scale = None
    if above.sum() > 50:
        # Match the model sky to the brightness of what the camera saw above the horizon (median, robust to clipping).
        model = luminance(preetham_sky_radiance(rays[above] @ env_from_cam.T, sun_env, turbidity=config.turbidity))
        sky_scale = float(np.median(Y[above])) / max(float(np.median(model)), 1e-12)
    if sky_scale is None or not np.isfinite(sky_scale):
        ref = float(np.percentile(Y, 90)) if Y.size else 0.0
        zen = float(luminance(preetham_sky_radiance(np.array([0.0, 0.0, 1.0]), sun_env, turbidity=config.turbidity)))
        sky_scale = ref / max(zen, 1e-12)
    ground_rgb = np.median(linear[below], axis=0) if below.sum() > 50 else np.median(linear.reshape(-1, 3), axis=0)
    chroma = None
    if config.sky_fill_colour == "seen":  # the camera's white balance: the seen sky's colour at unit luminance
        seen = np.median(linear[above], axis=0) if above.sum() > 50 else ground_rgb
        chroma = seen / float(luminance(seen)) if float(luminance(seen)) > 1e-6 and seen.min() > 0 else None

    def fill(dirs_env: np.ndarray) -> np.ndarray:
        sky = preetham_sky_radiance(dirs_env, sun_env, turbidity=config.turbidity) * sky_scale
        if chroma is not None:
            sky = luminance(sky)[:, None] * chroma[None, :]
        return np.where(dirs_env[:, 2:3] > 0, sky, ground_rgb[None, :])

    radiance, _ = assemble_envmap([linear], [K], [cam_from_env], height=config.ambient_map_height, fill=fill)
    sh = project_envmap_to_sh(radiance, cam_from_env)
    if config.ambient_colour == "neutral":
        return neutral_ambient(sh, up_in_cam, achromatic_light_colour(linear))
    return sh


def achromatic_light_colour(linear: np.ndarray, max_chroma: float = 0.05, min_share: float = 0.01) -> np.ndarray | None:
    """The light's colour (3,) at unit luminance as the photo's near-grey surfaces show it: the median colour of
    the unclipped, not dark pixels whose rg chromaticity lies within ``max_chroma`` of grey (roads, concrete,
    white paint, overcast sky), so a large coloured object (a red truck, an orange cone) has no say. None when
    fewer than ``min_share`` of the pixels qualify (a scene without grey surfaces: no evidence)."""
    px = np.asarray(linear).reshape(-1, 3)
    r, g, b = (px[:, j].astype(np.float64) for j in range(3))  # channel planes: no per-pixel reductions over 3
    s = (r + g) + b  # px.sum(1), in numpy's order
    ok = (np.maximum(np.maximum(r, g), b) < 0.98) & (s > 3 * 0.02)
    r, g, b, s = r[ok], g[ok], b[ok], s[ok]
    grey = np.maximum(np.abs(r / s - 1.0 / 3.0), np.abs(g / s - 1.0 / 3.0)) < max_chroma
    if grey.sum() < max(min_share * len(px), 20):
        return None
    c = np.array([np.median(r[grey]), np.median(g[grey]), np.median(b[grey])])  # the median over axis 0, by column
    lum = float(luminance(c))
    return c / lum if lum > 0 and c.min() > 0 else None


def neutral_ambient(sh: np.ndarray, up_in_cam: np.ndarray, colour: np.ndarray | None = None) -> np.ndarray:
    """SH (9, 3) whose every coefficient has one chromaticity, ``colour`` (the light's, e.g. from
    :func:`achromatic_light_colour`; None: that of the irradiance on an upward-facing surface), and its own
    luminance: the light's directional brightness kept, its colour one, so a white surface has the same colour
    whichever way it faces. Unchanged when that colour is not positive in every channel."""
    sh = np.asarray(sh, np.float64)
    c = sh_irradiance(sh, np.asarray(up_in_cam, np.float64)) if colour is None else np.asarray(colour, np.float64)
    lum = float(luminance(c))
    if not np.all(np.isfinite(c)) or c.min() <= 0 or lum <= 0:
        return sh
    return luminance(sh)[:, None] * (c / lum)[None, :]


def sun_over_sky_rgb(lit_rgb: np.ndarray, shadow_rgb: np.ndarray, max_chroma: float) -> np.ndarray:
    """Per channel r_c = E_sun,c cos z / E_sky,c = lit_c / shadow_c - 1 from a lit/shadowed pair of one surface.

    The sun's colour against the sky's is bounded by physics: both are daylight, and even a low sun against a deep
    blue sky stays within about 1.6 in r_R / r_G and 0.5 in r_B / r_G. A pair whose ratio leaves [1 / max_chroma,
    max_chroma] in either (a shadow on a coloured patch, a nearly black channel: a green-less sun, r_R / r_G 25, was
    measured on a TraCon photo) carries no colour evidence, so r keeps its luminance and becomes grey."""
    r = np.clip(np.asarray(lit_rgb, np.float64) / np.maximum(np.asarray(shadow_rgb, np.float64), 1e-6) - 1.0, 0, None)
    if r[1] > 0:
        chroma = np.array([r[0] / r[1], r[2] / r[1]])
        if np.all((chroma >= 1.0 / max_chroma) & (chroma <= max_chroma)):
            return r
    return np.full(3, float(luminance(r)))


def sky_part_of_neutral(sh: np.ndarray, up_in_cam: np.ndarray, sun_sky_rgb: np.ndarray) -> np.ndarray:
    """The neutral ambient's colour taken back to the sky's own. The photo's grey surfaces show the light they
    receive, mostly sky plus sun (E_sky,c (1 + r_c), r_c = E_sun,c cos z / E_sky,c per channel from lit against
    shadowed ground), so that colour is the ambient's only without a sun: with one, the sky's is that colour over
    (1 + r_c), and the sun added on top of it gives a sunlit white the grey surfaces' colour again instead of the
    sun's colour twice (a yellow cast wherever the sun is warmer than the sky)."""
    sh = np.asarray(sh, np.float64)
    r = np.asarray(sun_sky_rgb, np.float64)
    dc = sh[0]
    if not np.all(np.isfinite(r)) or r.min() < 0 or dc.min() <= 0:
        return sh
    return neutral_ambient(sh, up_in_cam, dc / (1.0 + r))

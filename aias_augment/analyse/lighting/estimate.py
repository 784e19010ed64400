"""Top-level lighting estimate of one frame: a sun (directional light, kept apart) plus SH ambient, in the camera frame.

Frames and units:
- Everything in :class:`LightingEstimate` is in the OpenCV camera frame (x right, y down, z forward) of the frame it
  was estimated for. The sun direction points FROM the scene TOWARD the sun.
- ``cam_from_world`` (4x4 or 3x3) maps the scene's world frame to the camera; only its rotation matters (light is at
  infinity). The world's up vector is ``meta['up_in_world']`` when given, else the up (-y) of this camera assumed level:
  for KITTI-style worlds (world = first camera) and z-up worlds seen by level cameras both are right.
- Radiometric units are those of the input: linear sRGB of the image (8-bit 255 -> 1.0), or of the env map. A white
  Lambertian surface with normal n shows radiance ``(E_sh(n) + E_sun max(0, n.l) v) / pi`` (see ``shading``).
- ``sun_sky_ratio`` is for the horizontal ground (normal = up); see ``shadows`` for how it sets shadow strength.

Sources, in order of preference: an environment map (``envmap``), GPS + UTC + camera orientation in ``meta`` (pvlib),
image cues with a known camera: visible sun disc, sky gradient, cast-shadow axis on the ground, and for the side of
that axis the lit versus shaded walls and the ends of cast shadows (``sun_side``). Sun strength always comes from the env map, or else
from lit vs shadowed ground in the image (``ratio``); ``meta['indoor'] = True`` forces environment light only.
Without metadata the evidence model (``sun_evidence``) decides first; where it rules a sun out, the image-cue search
and the lit/shadow measurement are not run (neither would change an estimate without a dominant sun).

This module decides whether the sun is dominant and assembles the estimate; its parts are modules of their own:
``config`` (:class:`LightingConfig`), ``frame`` (one frame made ready: up vector, analysis copy, lit/shadow ground),
``sun_direction`` (the image-cue sun, fused over a clip), ``ambient`` (the SH ambient and its colour) and
``exposure`` (the ground anchor, the saturation guard, an uncertain sun softened).
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, field
from typing import Sequence

import numpy as np

from aias_augment.analyse.lighting.ambient import (
    achromatic_light_colour,
    ambient_from_image,
    sky_part_of_neutral,
    sun_over_sky_rgb,
)
from aias_augment.analyse.lighting.config import LightingConfig
from aias_augment.analyse.lighting.exposure import anchor_and_cap, temper_sun
from aias_augment.analyse.lighting.frame import (
    FrameContext,
    check_image,
    measured,
    prepare_clip,
    prepare_frame,
    up_vectors,
)
from aias_augment.analyse.lighting.sh import project_envmap_to_sh, sh_irradiance
from aias_augment.analyse.lighting.sun import (
    remove_sun,
    rotation_of,
    sun_direction_in_cam_from_metadata,
    sun_from_envmap,
)
from aias_augment.analyse.lighting.sun_direction import (
    SunDirectionEstimate,
    estimate_sun_direction,
    estimate_sun_direction_clip,
    image_cue_sun,
)
from aias_augment.analyse.lighting.sun_evidence import decide_direct_sun, direct_sun_probability
from aias_augment.core.envmap import EnvironmentMap
from aias_augment.core.geometry import Intrinsics
from aias_augment.core.hdr import luminance

__all__ = [
    "LightingEstimate",
    "LightingConfig",
    "SunDirectionEstimate",
    "achromatic_light_colour",
    "estimate_lighting",
    "estimate_lighting_clip",
    "estimate_sun_direction",
    "estimate_sun_direction_clip",
    "lighting_from_envmap",
]

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class LightingEstimate:
    """Lighting of one frame in its camera frame (see module docstring).

    sun_direction_in_cam: unit (3,) toward the sun, or None when there is no dominant sun.
    sun_irradiance_rgb: (3,) linear irradiance of the sun at normal incidence (zeros without a dominant sun).
    ambient_sh: (9, 3) SH of the incident radiance without the sun (``sh`` conventions).
    sun_sky_ratio: sun / sky irradiance on the horizontal ground (0 without a dominant sun).
    dominant_sun: whether shadows should be cast. confidence: in [0, 1], of the sun direction.
    source: 'envmap' | 'metadata' | 'image_cues' | 'image_cues_clip' | 'none'. up_in_cam: unit (3,) up used for the ground.
    """

    sun_direction_in_cam: np.ndarray | None
    sun_irradiance_rgb: np.ndarray
    ambient_sh: np.ndarray
    sun_sky_ratio: float
    dominant_sun: bool
    confidence: float
    source: str
    up_in_cam: np.ndarray = field(default_factory=lambda: np.array([0.0, -1.0, 0.0]))

    def __post_init__(self):
        for name in ("sun_irradiance_rgb", "ambient_sh", "up_in_cam"):
            a = np.asarray(getattr(self, name), dtype=np.float64)
            if not np.all(np.isfinite(a)):
                raise ValueError(f"LightingEstimate.{name} contains NaN or Inf")
            object.__setattr__(self, name, a)
        if self.ambient_sh.shape != (9, 3) or self.sun_irradiance_rgb.shape != (3,):
            raise ValueError("LightingEstimate: ambient_sh must be (9, 3) and sun_irradiance_rgb (3,)")
        if self.sun_direction_in_cam is not None:
            d = np.asarray(self.sun_direction_in_cam, dtype=np.float64).reshape(3)
            n = np.linalg.norm(d)
            if not np.isfinite(n) or n < 1e-9:
                raise ValueError("LightingEstimate: sun direction must be a finite non-zero vector")
            object.__setattr__(self, "sun_direction_in_cam", d / n)
        if not (np.isfinite(self.sun_sky_ratio) and self.sun_sky_ratio >= 0):
            raise ValueError(f"LightingEstimate: sun_sky_ratio must be finite >= 0, got {self.sun_sky_ratio}")
        object.__setattr__(self, "confidence", float(np.clip(self.confidence, 0.0, 1.0)))

    def sky_irradiance_on_ground(self) -> np.ndarray:
        return sh_irradiance(self.ambient_sh, self.up_in_cam)

    def to_dict(self) -> dict:
        """JSON-ready record (written beside each insertion so it can be replayed)."""
        return {
            "sun_direction_in_cam": None if self.sun_direction_in_cam is None else self.sun_direction_in_cam.tolist(),
            "sun_irradiance_rgb": self.sun_irradiance_rgb.tolist(),
            "ambient_sh": self.ambient_sh.tolist(),
            "sun_sky_ratio": float(self.sun_sky_ratio),
            "dominant_sun": bool(self.dominant_sun),
            "confidence": float(self.confidence),
            "source": self.source,
            "up_in_cam": self.up_in_cam.tolist(),
        }

    @classmethod
    def from_dict(cls, d: dict) -> "LightingEstimate":
        """The estimate :meth:`to_dict` wrote, bit for bit: the sun direction is checked as any, then kept as
        written (it is unit already; normalising it again may move its last bit)."""
        sun = None if d["sun_direction_in_cam"] is None else np.array(d["sun_direction_in_cam"], np.float64)
        est = cls(
            sun,
            np.array(d["sun_irradiance_rgb"]),
            np.array(d["ambient_sh"]),
            d["sun_sky_ratio"],
            d["dominant_sun"],
            d["confidence"],
            d["source"],
            np.array(d["up_in_cam"]),
        )
        if sun is not None:
            object.__setattr__(est, "sun_direction_in_cam", sun)
        return est


def _downsample_map(radiance: np.ndarray, max_height: int = 128) -> np.ndarray:
    h, w = radiance.shape[:2]
    f = 1
    while h // (2 * f) >= max_height // 2 and h // f > max_height and h % (2 * f) == 0 and w % (2 * f) == 0:
        f *= 2
    return radiance.reshape(h // f, f, w // f, f, 3).mean(axis=(1, 3)) if f > 1 else radiance


def lighting_from_envmap(
    env: EnvironmentMap,
    cam_from_world: np.ndarray | None = None,
    up_in_world: np.ndarray | None = None,
    config: LightingConfig = LightingConfig(),
    indoor: bool = False,
) -> LightingEstimate:
    """Sun = the map's brightest compact light (kept only if dominant), ambient = SH of the map without it."""
    R_cw = np.eye(3) if cam_from_world is None else rotation_of(cam_from_world)
    cam_from_env = R_cw @ env.world_from_env
    up_in_cam = cam_from_env @ np.array([0.0, 0.0, 1.0]) if up_in_world is None else R_cw @ np.asarray(up_in_world)
    up_in_cam = up_in_cam / np.linalg.norm(up_in_cam)
    sun = sun_from_envmap(env.radiance)
    ambient = _downsample_map(remove_sun(env.radiance, sun))
    sh = project_envmap_to_sh(ambient, cam_from_env)
    sun_dir = cam_from_env @ sun.direction_in_env
    e_sky = float(luminance(sh_irradiance(sh, up_in_cam)))
    e_sun_ground = float(luminance(sun.irradiance_rgb)) * max(0.0, float(sun_dir @ up_in_cam))
    ratio = e_sun_ground / max(e_sky, 1e-12)  # eps: a black sky with a sun gives a huge but finite ratio
    dominant = (
        not indoor
        and sun.solid_angle_sr <= config.max_sun_solid_angle_sr
        and ratio >= config.min_dominant_sun_sky_ratio
        and float(sun_dir @ up_in_cam) > 0.0
    )
    if not dominant:
        full = project_envmap_to_sh(_downsample_map(env.radiance), cam_from_env)
        return LightingEstimate(None, np.zeros(3), full, 0.0, False, 1.0, "envmap", up_in_cam)
    return LightingEstimate(sun_dir, sun.irradiance_rgb, sh, float(ratio), True, 1.0, "envmap", up_in_cam)


#: Sources of a sun found in the image alone (one frame, or fused over a clip): the evidence model decides them.
IMAGE_CUE_SOURCES = ("image_cues", "image_cues_clip")


def _finish(
    ctx: FrameContext,
    sun_dir: np.ndarray | None,
    confidence: float,
    source: str,
    cue,
    config: LightingConfig,
    sun_probability: float | None = None,
) -> LightingEstimate:
    """Dominance, sun strength from lit/shadow, ambient SH from the frame + Preetham sky. ``sun_probability``: the
    evidence model's p(direct sun) (``config.sun_decision == "evidence"``), which decides for image-cue suns."""
    measurement, up_in_cam = ctx.measurement, ctx.up_in_cam
    sky_fraction = 0.0 if cue is None else cue.n_sky_pixels / max(ctx.n_above_small, 1)
    if ctx.indoor:
        dominant = False
    elif source in IMAGE_CUE_SOURCES and sun_probability is not None:
        dominant = decide_direct_sun(sun_probability, config.sun_threshold)
        confidence = sun_probability
    elif source in IMAGE_CUE_SOURCES and sky_fraction < config.min_sky_fraction_for_sun:
        # Without metadata, a sun is only declared where the frame shows open sky: indoors, dark and bright materials
        # (and lamps) look like lit/shadowed ground and sun discs.
        dominant = False
    elif measurement is not None and measurement.dominant_sun:
        dominant = True
    else:
        # No lit/shadow evidence on the ground: a sun needs a visible disc, or a confident sky when no ground could be
        # measured at all. Ground measured without cast shadows (overcast, or an open road with no occluders) counts
        # as no dominant sun: a missing shadow looks less wrong than a shadow under an overcast sky.
        dominant = cue is not None and (
            cue.sun_visible or (measurement is None and cue.confidence >= config.min_cue_confidence)
        )
        dominant = dominant or (source == "metadata" and (measurement is None or measurement.shadow_fraction >= 0.01))
    if sun_dir is not None and float(sun_dir @ up_in_cam) <= 0.0:
        dominant = False  # the sun is at or below the horizon: no direct light
    sh = ambient_from_image(ctx.linear_small, ctx.K_small, up_in_cam, sun_dir if dominant else None, config)
    if not dominant or sun_dir is None:
        sh, _ = anchor_and_cap(ctx, sh, None, None, 1.0, None, config)
        return LightingEstimate(None, np.zeros(3), sh, 0.0, False, confidence, source, up_in_cam)
    e_sky = sh_irradiance(sh, up_in_cam)
    min_cos = config.min_sun_cos_image_cues if source in IMAGE_CUE_SOURCES else config.min_sun_cos
    cos_z = max(float(sun_dir @ up_in_cam), min_cos)
    if measurement is not None and measurement.dominant_sun:
        # Per channel: lit / shadow - 1 = E_sun,c cos(z) / E_sky,c.
        r_rgb = sun_over_sky_rgb(measurement.lit_rgb, measurement.shadow_rgb, config.max_sun_sky_chroma)
        ratio = measurement.sun_sky_ratio
        if config.ambient_colour == "neutral":
            sh = sky_part_of_neutral(sh, up_in_cam, r_rgb)
            e_sky = sh_irradiance(sh, up_in_cam)
    else:
        r_rgb = np.full(3, config.default_sun_sky_ratio)
        ratio = config.default_sun_sky_ratio
    sun_irr = np.nan_to_num(r_rgb * e_sky / cos_z, nan=0.0, posinf=0.0)
    if source in IMAGE_CUE_SOURCES and config.sun_full_confidence > 0:
        sh, sun_irr = temper_sun(
            sh, sun_irr, cos_z, min(1.0, confidence / config.sun_full_confidence), sun_dir, up_in_cam
        )
    ground_lum = (
        measurement.lit_luminance
        if measurement is not None and measurement.dominant_sun and ctx.measurement_region is ctx.region
        else None
    )  # the anchor is for the road's albedo
    sh, sun_irr = anchor_and_cap(ctx, sh, sun_irr, sun_dir, cos_z, ground_lum, config)
    return LightingEstimate(sun_dir, sun_irr, sh, float(ratio), True, confidence, source, up_in_cam)


def _metadata_sun(ctx: FrameContext, cam_from_world_given: bool) -> np.ndarray | None:
    try:
        return sun_direction_in_cam_from_metadata(ctx.meta, ctx.R_cw if cam_from_world_given else None)
    except ValueError as e:
        log.warning("lighting: metadata sun position unusable (%s); falling back to image cues", e)
        return None


def estimate_lighting(
    image_rgb_uint8: np.ndarray,
    intrinsics: Intrinsics | None = None,
    cam_from_world: np.ndarray | None = None,
    meta: dict | None = None,
    envmap: EnvironmentMap | np.ndarray | None = None,
    *,
    config: LightingConfig = LightingConfig(),
) -> LightingEstimate:
    """Estimate the lighting of one RGB uint8 frame (see the module docstring for frames, units and sources).

    ``meta`` keys used: 'lat', 'lon', 'utc' (ISO string) with an orientation ('enu_from_cam', 'enu_from_world' or
    'heading_deg' [+ 'pitch_deg', 'roll_deg']); 'up_in_world' (3,); 'indoor' (bool); 'ground_mask' ((H, W) bool: the
    ground region used for lit/shadow); 'world_from_env' (3x3, orientation of ``envmap`` given as an array).
    No random draws: the estimate is a property of the inputs. The result is always finite.
    """
    img = check_image(image_rgb_uint8)
    meta = dict(meta or {})
    R_cw = np.eye(3) if cam_from_world is None else rotation_of(cam_from_world)
    if envmap is not None:
        up_in_world, _ = up_vectors(R_cw, meta)
        env = (
            envmap
            if isinstance(envmap, EnvironmentMap)
            else EnvironmentMap(np.asarray(envmap, dtype=np.float32), np.asarray(meta.get("world_from_env", np.eye(3))))
        )
        return lighting_from_envmap(
            env, R_cw, up_in_world if "up_in_world" in meta else None, config, bool(meta.get("indoor", False))
        )
    ctx = prepare_frame(img, intrinsics, R_cw, meta, config, measure=False)
    if ctx.indoor:
        return _finish(ctx, None, 0.0, "none", None, config)
    sun_dir = _metadata_sun(ctx, cam_from_world is not None)
    if sun_dir is not None:
        return _finish(measured(ctx, config), sun_dir, 0.95, "metadata", None, config)
    p_sun = direct_sun_probability(ctx.img) if config.sun_decision == "evidence" else None
    if p_sun is not None and not decide_direct_sun(p_sun, config.sun_threshold):
        # The evidence rules the sun out: neither its direction nor its strength would change the estimate.
        return _finish(ctx, None, p_sun, "image_cues", None, config, p_sun)
    ctx = measured(ctx, config)
    sun_est = image_cue_sun([ctx], ctx.up_in_world, config)
    sun_dir = ctx.R_cw @ sun_est.direction_in_world
    confidence = sun_est.confidence * (1.0 if ctx.known_camera else 0.5)
    cue = sun_est.sky_cues[0]
    return _finish(ctx, sun_dir, confidence, "image_cues", cue, config, p_sun)


def estimate_lighting_clip(
    images: Sequence[np.ndarray],
    intrinsics: Sequence[Intrinsics | None] | Intrinsics | None,
    cams_from_world: Sequence[np.ndarray],
    metas: Sequence[dict] | dict | None = None,
    *,
    config: LightingConfig = LightingConfig(),
) -> list[LightingEstimate]:
    """Lighting of the frames of one clip with known poses: one sun, fused in world coordinates.

    The per-frame sun evidence (sky, sun disc, cast-shadow axis, walls, shadow ends) is a log-likelihood on one grid
    of world directions;
    the clip's evidence is its sum (frames as independent views of the same, distant sun), and each frame gets the
    fused direction rotated into its camera. Metadata (GPS + UTC + orientation) on every frame overrides fusion. Sun
    strength and ambient stay per frame. The world's up is ``metas[0]['up_in_world']`` or the first camera's -y.
    """
    ctxs, up_in_world = prepare_clip(images, intrinsics, cams_from_world, metas, config, measure=False)
    meta_suns = [None if c.indoor else _metadata_sun(c, True) for c in ctxs]
    if all(s is not None for s in meta_suns):
        return [_finish(measured(c, config), s, 0.95, "metadata", None, config) for c, s in zip(ctxs, meta_suns)]
    if all(c.indoor for c in ctxs):
        return [_finish(c, None, 0.0, "none", None, config) for c in ctxs]
    # one decision for the clip: the median of its frames' probabilities (one sun, one weather)
    p_sun = (
        float(np.median([direct_sun_probability(c.img) for c in ctxs if not c.indoor]))
        if config.sun_decision == "evidence"
        else None
    )
    if p_sun is not None and not decide_direct_sun(p_sun, config.sun_threshold):
        # The evidence rules the sun out: neither its direction nor its strength would change the estimates.
        return [
            _finish(c, None, 0.0, "none", None, config)
            if c.indoor
            else _finish(c, None, p_sun, "image_cues_clip", None, config, p_sun)
            for c in ctxs
        ]
    ctxs = [c if c.indoor else measured(c, config) for c in ctxs]
    live = [c for c in ctxs if not c.indoor]
    sun_est = image_cue_sun(live, up_in_world, config)
    d_world, confidence = sun_est.direction_in_world, sun_est.confidence
    cues = iter(sun_est.sky_cues)
    out = []
    for c in ctxs:
        if c.indoor:
            out.append(_finish(c, None, 0.0, "none", None, config))
        else:
            conf = confidence * (1.0 if c.known_camera else 0.5)
            out.append(_finish(c, c.R_cw @ d_world, conf, "image_cues_clip", next(cues), config, p_sun))
    return out

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
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, field
from typing import Literal, Sequence

import numpy as np

from aias_augment.analyse.lighting.envmap import EnvironmentMap, assemble_envmap, camera_ray_directions
from aias_augment.analyse.lighting.ratio import (
    LitShadowMeasurement,
    ground_coordinates,
    ground_region_mask,
    measure_lit_shadow,
    shadow_axis_on_ground,
)
from aias_augment.analyse.lighting.sh import project_envmap_to_sh, sh_irradiance
from aias_augment.analyse.lighting.sky import preetham_sky_radiance
from aias_augment.analyse.lighting.sun import (
    frame_from_up,
    posterior_summary,
    remove_sun,
    rotation_of,
    solar_direction_enu,
    sun_cue_from_image,
    sun_direction_grid,
    sun_direction_in_cam_from_metadata,
    sun_from_envmap,
)
from aias_augment.analyse.lighting.sun_evidence import decide_direct_sun, direct_sun_probability
from aias_augment.analyse.lighting.sun_side import sun_side_cue
from aias_augment.core.config import checked_config
from aias_augment.core.geometry import CAMERA_HEIGHT_PRIOR_M, Intrinsics
from aias_augment.core.hdr import InverseToneMapParams, inverse_tone_map, luminance, srgb_to_linear
from aias_augment.core.rng import require_rng

__all__ = [
    "LightingEstimate",
    "LightingConfig",
    "SunDirectionEstimate",
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


# Every field is checked at construction against its type hint and these bounds (config.checked_config).
@checked_config(
    {
        "max_sun_solid_angle_sr": "(0, inf)",
        "min_dominant_sun_sky_ratio": "[0, inf)",
        "default_sun_sky_ratio": "[0, inf)",
        "min_sky_fraction_for_sun": "[0, 1]",
        "min_cue_confidence": "[0, 1]",
        "prior_hfov_deg": "(0, 180)",
        "ambient_map_height": "[4, 1024]",  # a (h, 2h) map per cue: 1024 is 2 M texels, far finer than sky light needs
        "min_sun_cos": "(0, 1]",
        "min_sun_cos_image_cues": "(0, 1]",
        "camera_height_m": "(0, inf)",
        "ground_lateral_range_m": "(-inf, inf) lo<hi",
        "ground_forward_range_m": "[0, inf) lo<hi",
        "fallback_ground_boxes_m": "(-inf, inf) lo<hi",
        "fallback_min_separation": "(0, inf)",
        "fallback_max_shadow_fraction": "(0, 1]",
        "turbidity": "[1, 20]",  # sky.perez_coefficients' range
        "elevation_prior_deg": ("[-90, 90]", "(0, inf)"),  # (mean, standard deviation)
        "shadow_axis_kappa": "[0, inf)",
        "analysis_width": "[16, inf)",
        "min_input_width": "[0, inf)",
        "sky_out_of_view_side_prob": "[0.5, 1)",
        "sky_colour_weight": "[0, inf)",
        "max_direct_to_diffuse_ratio": "(0, inf)",
        "facade_albedo_sigma": "(0, inf)",
        "shadow_end_kappa": "[0, inf)",
        "side_analysis_width": "[64, inf)",
        "ground_albedo_range": "(0, inf) lo<=hi",
        "ground_anchor_max_gain": "[1, inf)",
        "sun_full_confidence": "[0, inf)",
        "cap_white_to_scene_percentile": "[50, 100]",
        "white_cap_linear": "(0, 1]",
        "ground_white_balance": "[0, 1]",
        "max_sun_sky_chroma": "[1, inf)",
        "sun_threshold": "(0, 1)",
    }
)
@dataclass(frozen=True)
class LightingConfig:
    """Thresholds and priors of :func:`estimate_lighting` (loadable from YAML with ``config.load_config``)."""

    #: A light larger than this (sr) is an area (window, bright cloud), not a sun: 0.05 sr ~ a disc of 7 deg radius.
    max_sun_solid_angle_sr: float = 0.05
    #: Minimum sun/sky ratio on the ground for the sun to count as dominant (shadows visible).
    min_dominant_sun_sky_ratio: float = 0.3
    #: Sun/sky ratio assumed when the image shows the sun (disc or confident cue) but no lit/shadow ground pair.
    default_sun_sky_ratio: float = 3.0
    #: Fraction of the above-horizon pixels that must be sky before image cues may declare a sun (indoor guard).
    min_sky_fraction_for_sun: float = 0.08
    #: Minimum image-cue confidence to declare a sun without a lit/shadow measurement.
    min_cue_confidence: float = 0.6
    #: Field of view prior when no intrinsics are given (deg, horizontal).
    prior_hfov_deg: float = 60.0
    #: Resolution of the ambient maps built internally (rows; width is twice).
    ambient_map_height: int = 32
    #: cos(sun zenith) is clamped to at least this when turning the ground ratio into normal-incidence irradiance.
    min_sun_cos: float = 0.05
    #: ... and to at least this when the elevation comes from image cues (sin 15 deg): their elevation is uncertain and
    #: a too-low sun would make surfaces facing it 1 / sin(el) times brighter than the ground (blown-out objects).
    min_sun_cos_image_cues: float = 0.26
    camera_height_m: float = CAMERA_HEIGHT_PRIOR_M  # replaced by the ground plane's height where one is known
    #: Ground box used for lit/shadow when no ground mask is given (m, gravity-aligned camera frame).
    ground_lateral_range_m: tuple[float, float] = (-1.5, 1.5)
    ground_forward_range_m: tuple[float, float] = (5.0, 20.0)
    #: Where the ground region (the box above, or the caller's ground mask) shows no cast shadows, these boxes
    #: ((lateral), (forward) m, same frame) are measured in turn and the first that passes the stricter test below
    #: stands for the frame: a lit road lane with the street's shadows on the verges (KITTI 06 grey frames 10, 20,
    #: 35, 45: tree and pole shadows on the grass, none on the lane) is a sunny scene. Their measurement decides the
    #: sun and its strength (not the shadow axis: see ``_sun_evidence``); the road region keeps the white balance and
    #: the anchor.
    #: () turns it off.
    fallback_ground_boxes_m: tuple[tuple[tuple[float, float], tuple[float, float]], ...] = (
        ((-6.0, -1.5), (4.0, 20.0)),
        ((1.5, 6.0), (4.0, 20.0)),
    )
    #: A side box mixes materials (grass, kerb, paving, parked cars) more often than the lane, so its lit/shadow
    #: split must be clearer than the main region's (Ashman D >= 2): D >= this, a shadowed share in
    #: [0.02, ``fallback_max_shadow_fraction``] (a bright blob on dark ground is not lit ground with shadows), and a
    #: sun/sky ratio a clear sky can give (<= ``max_direct_to_diffuse_ratio``: white paving next to a dark car gives
    #: 25-33). On the real frames looked at (results/lighting/kitti_cast_shadow.md): the overcast video's side boxes
    #: reach D 2.0-2.7, NYU's 3.0-4.4 (with shadowed shares of 0.65-0.93), KITTI's shadowed verges 4.1-7.2.
    fallback_min_separation: float = 4.0
    fallback_max_shadow_fraction: float = 0.6
    turbidity: float = 3.0
    #: Mean and standard deviation (deg) of the weak prior on the sun elevation used with image cues.
    elevation_prior_deg: tuple[float, float] = (30.0, 20.0)
    #: Weight of the cast-shadow axis term (log-likelihood kappa x strength x cos 2 dphi) against the sky cue.
    shadow_axis_kappa: float = 20.0
    #: Sun cues and the ambient map are computed on a copy at most this wide (pixels).
    analysis_width: int = 400
    #: Callers that analyse a cheap copy of the image (``analysis_max_width``, e.g. 160) give the
    #: estimator a copy at least this wide (``insertion.analyse``). At 160 px the side cues (walls, shadow ends) and the
    #: thin cast shadows are lost: on KITTI 06 the sun came out on the wrong side in 7 of 9 frames checked (320 px: 2
    #: of 9, like the full frame) and the lit/shadow contrast at a third of the full frame's.
    min_input_width: int = 320
    #: Probability that the sky cue's side is right when neither a sun disc is visible nor the sky fit's best sun is
    #: inside the frame. The sky evidence is then the mixture "the sun is where the sky says (p) or at the mirrored
    #: azimuth (1 - p)", log L'(d) = logaddexp(log p + log L(d), log(1 - p) + log L(d + 180 deg)): its side vote is
    #: capped at log(p / (1 - p)) nats (1.7 at 0.85) while the shape of its peak (the azimuth and elevation within the
    #: chosen half-plane) is kept. Calibration on the HDR crops (sky cue alone, 127 crops of city, forest, sunrise,
    #: sunset without a sun disc, scripts/eval_lighting.py protocol): by the cue's own side margin m (best
    #: log-likelihood on the chosen half-plane minus the best on the other) m < 2 nats: 18 % correct, 2-5: 57 %,
    #: 5-10: 82 %, > 10: 87 %, where raw margins reach 5-300 nats. (Scaling the antisymmetric part by 0.25 instead also
    #: flattens the peak: a clear sunset sky's 9 deg becomes 28-60 deg.)
    sky_out_of_view_side_prob: float = 0.85
    #: Weight of the sky colour cue (``sun.sun_whiteness_loglik``: the sky is less blue toward the sun) inside the
    #: production estimator. 0 (off): its measured effect is in results/lighting/README.md (the sky's side vote).
    sky_colour_weight: float = 0.0
    #: Largest direct-normal / diffuse-horizontal irradiance ratio of a clear sky (DNI ~900-1000 W/m2 against a DHI of
    #: at least ~80-100 W/m2 in the clearest air): bounds the sun's elevation from below given the measured shadow
    #: contrast (sin el >= ground sun/sky ratio / this).
    max_direct_to_diffuse_ratio: float = 12.0
    #: Vertical-surface cue (``sun_side``): spread of wall albedos (ln units) around the Lambertian model.
    facade_albedo_sigma: float = 0.7
    #: Shadow-end cue (``sun_side``): log-likelihood scale of the mean base score (as ``shadow_axis_kappa``).
    shadow_end_kappa: float = 20.0
    #: The side cues run on a copy at most this wide (their pixel tolerances are set for ~800 px).
    side_analysis_width: int = 800
    #: Exposure anchor: the estimated irradiance on the ground is rescaled so that the ground's albedo it
    #: implies, pi x ground luminance / irradiance (linear sRGB of the image), lies in this range (the ground box ahead
    #: of the camera is mostly road: asphalt about 0.05 new to 0.2 worn or light). The sky model is fitted to pixels
    #: that are often clipped or tone-mapped, so its absolute level is not the photo's exposure: without the anchor,
    #: cones inserted into TraCon road photos were rendered at 0.76 [quartiles 0.58, 0.93] of the brightness of the
    #: same photo's real cones (median orange-pixel max channel, 106 photos of the matched protocol's half A); with
    #: (0.05, 0.2), 0.99 [0.81, 1.06] ((0.06, 0.15): 1.00; (0.05, 0.3): 0.95); the widest range that matched was
    #: kept, so brighter grounds (concrete) are left alone. None: off.
    ground_albedo_range: tuple[float, float] | None = (0.05, 0.2)
    #: The anchor changes the light by at most this factor either way: a ground lit by a sun the estimate did not
    #: find (or a bright pavement) would otherwise be explained by an ambient many times too strong, which lights
    #: the object's sides as brightly as the sunlit ground and blows it out (a sunlit TraCon street: x11.5, 56 % of
    #: the cone clipped). On half A, 3 keeps the median brightness ratio at 0.94 (unbounded 0.99, 2: 0.87, 5: 0.97).
    ground_anchor_max_gain: float = 3.0
    #: Sun tempering: an image-cue sun of confidence c keeps the share min(1, c / this) of its irradiance as a
    #: directional light; the rest becomes the sun's own order-2 SH lobe with the same irradiance on the ground (an
    #: uncertain direction gives a softer terminator around the sun that casts the shadow; a uniform ambient rest
    #: would light the side facing away from the sun: see ``temper_sun``). The shadow strength
    #: (sun_sky_ratio) is kept. 0: off.
    sun_full_confidence: float = 0.6
    #: Saturation guard: when the frame itself does not clip (this percentile of its brightest channel is below 0.98
    #: linear), the lighting is scaled so that a white Lambertian surface facing any direction stays at or below
    #: ``white_cap_linear`` (sRGB 250): no inserted pixel saturates where the scene does not. None: off.
    cap_white_to_scene_percentile: float | None = 99.5
    white_cap_linear: float = 0.95
    #: White balance on the road: the colour of the estimated irradiance on the ground is set to the colour
    #: of the ground pixels (roads are close to neutral grey, so their colour in the photo is the camera's view of
    #: the light). Without it the Preetham fill of the unseen sky makes the camera-facing side of an object 1.5-2.3x
    #: bluer in B than in R (white bands came out lavender, orange brown). The value is the strength (0: off; 0.75:
    #: three quarters of the way in log, since some roads are not grey); gains clamped to [1/2, 2], luminance kept.
    #: Off by default: the neutral ambient takes the light's colour from the photo's grey surfaces, and a ground that
    #: is not grey (grass, a warm floor) pulled it yellow (inserted white bands against the same photos' real white
    #: sleeves, 27 TraCon train photos: 37 % within 0.94-1.06 in R/G and B/G off, 15 % at 0.75; paired deviation
    #: -0.159 [-0.276, -0.067]; results/lighting/neutral_whites). Useful with ``ambient_colour="scene"``.
    ground_white_balance: float = 0.0
    #: Most the sun's colour may differ from the sky's, per channel against green, before a lit/shadow pair's colour
    #: is disbelieved (:func:`sun_over_sky_rgb`).
    max_sun_sky_chroma: float = 2.5
    #: Colour of the fill for the sky the camera did not see ("white stays white"): "seen" keeps the
    #: Preetham model's brightness distribution but takes its chroma from the sky the camera saw above the horizon
    #: (its median; the ground's when too little is seen): the photo went through the camera's white balance, the
    #: model's absolute daylight colour did not, and gave the light a colour the scene does not show: in grey copies
    #: of 7 TraCon roads a white band's B/R was 0.68-1.7 (median |log| 0.14) after the road balance with "preetham",
    #: 1.00 with "seen": tests/aias_augment/analyse/lighting/test_white_stays_white.py). "preetham": the model's colour.
    sky_fill_colour: Literal["seen", "preetham"] = "seen"
    #: Colour of the ambient light. "scene": each SH coefficient keeps the colour the photo gave it, so a red truck or
    #: sign filling the view tints the whole ambient (DC R/G 2.0-2.4 measured) and white parts come out pink.
    #: "neutral": the light's brightness distribution is kept and every coefficient takes one colour, the light's as
    #: the photo's near-grey surfaces show it (``achromatic_light_colour``; without any, the colour of the
    #: irradiance on the ground), not that of the largest object (scripts/eval_neutral_whites.py,
    #: results/lighting/neutral_whites: with harmonize_colour "luminance", the deviation of inserted white bands
    #: from the same photos' real white sleeves fell by 0.043 in max |log R/G|, |log B/G| [0.007, 0.080], 27 photos).
    ambient_colour: Literal["scene", "neutral"] = "neutral"
    #: Whether a photo without metadata has a dominant sun (hard shadows). "evidence": the probability of
    #: :mod:`.sun_evidence` (clear sky, sky-lit shadows bluer than lit surfaces, clipping) at or above the shipped
    #: model's threshold, set for a false sun costing far more than a missed one (results/lighting/asymmetric:
    #: held-out precision 0.75 / recall 0.075 at 0.971, 0.61 / 0.48 at the former 0.525); the estimate's confidence
    #: is that probability. Measured on one fixed-size copy, so every preset decides alike. "cues": a lit/shadow pair
    #: measured on the ground, a visible sun disc or a confident sky cue, with the direction's confidence.
    sun_decision: Literal["evidence", "cues"] = "evidence"
    #: The probability at or above which "evidence" declares a sun; None: the shipped model's own threshold (chosen
    #: for an asymmetric cost, a false sun worse than a missed one: results/lighting/asymmetric). A value in (0, 1)
    #: overrides it (lower: more suns and more false ones).
    sun_threshold: float | None = None


def _downsample_map(radiance: np.ndarray, max_height: int = 128) -> np.ndarray:
    h, w = radiance.shape[:2]
    f = 1
    while h // (2 * f) >= max_height // 2 and h // f > max_height and h % (2 * f) == 0 and w % (2 * f) == 0:
        f *= 2
    return radiance.reshape(h // f, f, w // f, f, 3).mean(axis=(1, 3)) if f > 1 else radiance


def _downscale(img: np.ndarray, K: Intrinsics, max_width: int) -> tuple[np.ndarray, Intrinsics]:
    """Area-resample an image (and its intrinsics) so that it is at most ``max_width`` wide."""
    import cv2

    h, w = img.shape[:2]
    if w <= max_width:
        return img, K
    s = max_width / w
    K2 = K.scaled(s)
    return cv2.resize(img, (K2.width, K2.height), interpolation=cv2.INTER_AREA), K2


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


def _ambient_from_image(
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
    px = np.asarray(linear, np.float64).reshape(-1, 3)
    s = px.sum(1)
    ok = (px.max(1) < 0.98) & (s > 3 * 0.02)
    rg = px[ok, :2] / s[ok, None]
    grey = np.abs(rg - 1.0 / 3.0).max(1) < max_chroma
    if grey.sum() < max(min_share * len(px), 20):
        return None
    c = np.median(px[ok][grey], axis=0)
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


@dataclass
class _FrameContext:
    """Everything about one frame that the sun evidence and the final estimate need."""

    img: np.ndarray
    meta: dict
    K: Intrinsics
    known_camera: bool
    R_cw: np.ndarray
    up_in_world: np.ndarray
    up_in_cam: np.ndarray
    indoor: bool
    small: np.ndarray
    K_small: Intrinsics
    linear_small: np.ndarray
    region: np.ndarray | None
    measurement: LitShadowMeasurement | None
    n_above_small: int  # pixels of the analysis copy more than 2 deg above the horizon
    #: the region ``measurement`` was taken on: ``region``, or a fallback box (``LightingConfig.fallback_ground_boxes_m``)
    measurement_region: np.ndarray | None = None


def _check_image(image_rgb_uint8) -> np.ndarray:
    img = np.asarray(image_rgb_uint8)
    if img.ndim != 3 or img.shape[2] != 3 or img.dtype != np.uint8:
        raise ValueError(f"estimate_lighting: image must be (H, W, 3) uint8 RGB, got {img.shape} {img.dtype}")
    if img.shape[0] < 8 or img.shape[1] < 8:
        raise ValueError(f"estimate_lighting: image too small ({img.shape[1]}x{img.shape[0]})")
    return img


def _up_vectors(R_cw: np.ndarray, meta: dict) -> tuple[np.ndarray, np.ndarray]:
    if "up_in_world" in meta:
        up_in_world = np.asarray(meta["up_in_world"], dtype=np.float64).reshape(3)
    else:
        up_in_world = R_cw.T @ np.array([0.0, -1.0, 0.0])
    n = np.linalg.norm(up_in_world)
    if not np.isfinite(n) or n < 1e-9:
        raise ValueError(f"estimate_lighting: invalid up_in_world {up_in_world}")
    up_in_world = up_in_world / n
    return up_in_world, R_cw @ up_in_world


def _prepare(
    img: np.ndarray,
    intrinsics: Intrinsics | None,
    R_cw: np.ndarray,
    meta: dict,
    config: LightingConfig,
    rng: np.random.Generator,
) -> _FrameContext:
    h, w = img.shape[:2]
    up_in_world, up_in_cam = _up_vectors(R_cw, meta)
    known_camera = intrinsics is not None
    K = intrinsics if known_camera else Intrinsics.from_fov(w, h, config.prior_hfov_deg)
    if (K.width, K.height) != (w, h):
        raise ValueError(f"estimate_lighting: intrinsics are for {K.width}x{K.height}, image is {w}x{h}")
    small, K_small = _downscale(img, K, config.analysis_width)
    linear_small = inverse_tone_map(small, InverseToneMapParams())
    # Sun strength: lit vs shadowed ground, at full resolution (thin cast shadows matter).
    region = meta.get("ground_mask")
    if region is None:
        region = ground_region_mask(
            K, up_in_cam, config.camera_height_m, config.ground_lateral_range_m, config.ground_forward_range_m
        )
    region = np.asarray(region, bool)
    if region.shape != (h, w):
        raise ValueError(f"estimate_lighting: ground_mask must be {(h, w)}, got {region.shape}")
    linear = srgb_to_linear(img)
    measurement = measure_lit_shadow(linear, region, rng=rng)
    measurement_region = region
    if not (measurement is not None and measurement.dominant_sun):
        for lateral, forward in config.fallback_ground_boxes_m:
            box = ground_region_mask(K, up_in_cam, config.camera_height_m, tuple(lateral), tuple(forward))
            m = measure_lit_shadow(linear, box, rng=rng)
            if fallback_measurement_ok(m, config):
                measurement, measurement_region = m, box
                break
    n_above = int(np.sum(camera_ray_directions(K_small) @ up_in_cam > np.sin(np.deg2rad(2.0))))
    return _FrameContext(
        img,
        meta,
        K,
        known_camera,
        R_cw,
        up_in_world,
        up_in_cam,
        bool(meta.get("indoor", False)),
        small,
        K_small,
        linear_small,
        region,
        measurement,
        n_above,
        measurement_region,
    )


def fallback_measurement_ok(m: LitShadowMeasurement | None, config: LightingConfig) -> bool:
    """Whether a fallback ground box's lit/shadow split counts as cast shadows (see
    ``LightingConfig.fallback_min_separation``)."""
    return bool(
        m is not None
        and m.dominant_sun
        and m.separation >= config.fallback_min_separation
        and 0.02 <= m.shadow_fraction <= config.fallback_max_shadow_fraction
        and m.sun_sky_ratio <= config.max_direct_to_diffuse_ratio
    )


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


def _sun_evidence(
    ctx: _FrameContext, grid_world: np.ndarray, azel: np.ndarray, config: LightingConfig, rng: np.random.Generator
):
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
        rng=rng,
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


#: Sources of a sun found in the image alone (one frame, or fused over a clip): the evidence model decides them.
IMAGE_CUE_SOURCES = ("image_cues", "image_cues_clip")


def _finish(
    ctx: _FrameContext,
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
    sh = _ambient_from_image(ctx.linear_small, ctx.K_small, up_in_cam, sun_dir if dominant else None, config)
    if not dominant or sun_dir is None:
        sh, _ = _anchor_and_cap(ctx, sh, None, None, 1.0, None, config)
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
    sh, sun_irr = _anchor_and_cap(ctx, sh, sun_irr, sun_dir, cos_z, ground_lum, config)
    return LightingEstimate(sun_dir, sun_irr, sh, float(ratio), True, confidence, source, up_in_cam)


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


def _anchor_and_cap(
    ctx: _FrameContext,
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
        ref = float(np.percentile(lin.max(-1), config.cap_white_to_scene_percentile))
        if ref < 0.98:
            peak = k * peak_white_radiance(sh, sun_irr, sun_dir)
            if peak > config.white_cap_linear:
                k *= config.white_cap_linear / peak
    if k == 1.0:
        return sh, sun_irr
    return np.asarray(sh) * k, (None if sun_irr is None else np.asarray(sun_irr) * k)


def _metadata_sun(ctx: _FrameContext, cam_from_world_given: bool) -> np.ndarray | None:
    try:
        return sun_direction_in_cam_from_metadata(ctx.meta, ctx.R_cw if cam_from_world_given else None)
    except ValueError as e:
        log.warning("lighting: metadata sun position unusable (%s); falling back to image cues", e)
        return None


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


def _image_cue_sun(
    ctxs: list, up_in_world: np.ndarray, config: LightingConfig, rng: np.random.Generator
) -> SunDirectionEstimate:
    """Sum the frames' sun evidence on one world grid (frames as independent views of one distant sun), add the
    elevation prior once, take the best candidate; confidence = max(sky-cue confidence, 0.5 x axis strength x
    posterior concentration) x the side-agreement factor (``_side_agreement``)."""
    grid_up, azel = sun_direction_grid()
    grid_world = grid_up @ frame_from_up(up_in_world)
    evidence = [_sun_evidence(c, grid_world, azel, config, rng) for c in ctxs]
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
    rng: np.random.Generator,
    config: LightingConfig = LightingConfig(),
) -> SunDirectionEstimate:
    """The image-cue sun direction of one frame (sky or sun disc, cast-shadow axis, walls, shadow ends), as
    :func:`estimate_lighting` picks it, returned even where the sun is not dominant (for evaluation and for callers
    that decide dominance themselves). ``meta``: 'up_in_world', 'ground_mask', 'lat'/'lon'/'utc' (elevation only)."""
    img = _check_image(image_rgb_uint8)
    meta = dict(meta or {})
    rng = require_rng(rng, "estimate_sun_direction")
    R_cw = np.eye(3) if cam_from_world is None else rotation_of(cam_from_world)
    ctx = _prepare(img, intrinsics, R_cw, meta, config, rng)
    return _image_cue_sun([ctx], ctx.up_in_world, config, rng)


def estimate_sun_direction_clip(
    images: Sequence[np.ndarray],
    intrinsics: Sequence[Intrinsics | None] | Intrinsics | None,
    cams_from_world: Sequence[np.ndarray],
    metas: Sequence[dict] | dict | None = None,
    *,
    rng: np.random.Generator,
    config: LightingConfig = LightingConfig(),
) -> SunDirectionEstimate:
    """The image-cue sun of a clip with known poses, fused in world coordinates as :func:`estimate_lighting_clip` does
    (the world's up: ``metas[0]['up_in_world']`` or the first camera's -y)."""
    rng = require_rng(rng, "estimate_sun_direction_clip")
    ctxs, up_in_world = _prepare_clip(images, intrinsics, cams_from_world, metas, config, rng)
    return _image_cue_sun([c for c in ctxs if not c.indoor] or ctxs, up_in_world, config, rng)


def _prepare_clip(images, intrinsics, cams_from_world, metas, config: LightingConfig, rng: np.random.Generator):
    """Frame contexts of a clip and its world up (``metas[0]['up_in_world']`` or the first camera's -y)."""
    n = len(images)
    if n == 0 or len(cams_from_world) != n:
        raise ValueError("estimate_lighting_clip: need one pose per image and at least one image")
    Ks = list(intrinsics) if isinstance(intrinsics, (list, tuple)) else [intrinsics] * n
    ms = [dict(m or {}) for m in metas] if isinstance(metas, (list, tuple)) else [dict(metas or {})] * n
    if len(Ks) != n or len(ms) != n:
        raise ValueError("estimate_lighting_clip: intrinsics and metas must match the number of images")
    R0 = rotation_of(cams_from_world[0])
    up_in_world, _ = _up_vectors(R0, ms[0])
    for m in ms:
        m.setdefault("up_in_world", up_in_world)
    ctxs = [
        _prepare(_check_image(img), K, rotation_of(T), m, config, rng)
        for img, K, T, m in zip(images, Ks, cams_from_world, ms)
    ]
    return ctxs, up_in_world


def estimate_lighting(
    image_rgb_uint8: np.ndarray,
    intrinsics: Intrinsics | None = None,
    cam_from_world: np.ndarray | None = None,
    meta: dict | None = None,
    envmap: EnvironmentMap | np.ndarray | None = None,
    *,
    rng: np.random.Generator,
    config: LightingConfig = LightingConfig(),
) -> LightingEstimate:
    """Estimate the lighting of one RGB uint8 frame (see the module docstring for frames, units and sources).

    ``meta`` keys used: 'lat', 'lon', 'utc' (ISO string) with an orientation ('enu_from_cam', 'enu_from_world' or
    'heading_deg' [+ 'pitch_deg', 'roll_deg']); 'up_in_world' (3,); 'indoor' (bool); 'ground_mask' ((H, W) bool: the
    ground region used for lit/shadow); 'world_from_env' (3x3, orientation of ``envmap`` given as an array).
    ``rng`` (required) subsamples pixels. The result is always finite.
    """
    img = _check_image(image_rgb_uint8)
    meta = dict(meta or {})
    rng = require_rng(rng, "estimate_lighting")
    R_cw = np.eye(3) if cam_from_world is None else rotation_of(cam_from_world)
    if envmap is not None:
        up_in_world, _ = _up_vectors(R_cw, meta)
        env = (
            envmap
            if isinstance(envmap, EnvironmentMap)
            else EnvironmentMap(np.asarray(envmap, dtype=np.float32), np.asarray(meta.get("world_from_env", np.eye(3))))
        )
        return lighting_from_envmap(
            env, R_cw, up_in_world if "up_in_world" in meta else None, config, bool(meta.get("indoor", False))
        )
    ctx = _prepare(img, intrinsics, R_cw, meta, config, rng)
    if ctx.indoor:
        return _finish(ctx, None, 0.0, "none", None, config)
    sun_dir = _metadata_sun(ctx, cam_from_world is not None)
    if sun_dir is not None:
        return _finish(ctx, sun_dir, 0.95, "metadata", None, config)
    sun_est = _image_cue_sun([ctx], ctx.up_in_world, config, rng)
    sun_dir = ctx.R_cw @ sun_est.direction_in_world
    confidence = sun_est.confidence * (1.0 if ctx.known_camera else 0.5)
    cue = sun_est.sky_cues[0]
    p_sun = direct_sun_probability(ctx.img) if config.sun_decision == "evidence" else None
    return _finish(ctx, sun_dir, confidence, "image_cues", cue, config, p_sun)


def estimate_lighting_clip(
    images: Sequence[np.ndarray],
    intrinsics: Sequence[Intrinsics | None] | Intrinsics | None,
    cams_from_world: Sequence[np.ndarray],
    metas: Sequence[dict] | dict | None = None,
    *,
    rng: np.random.Generator,
    config: LightingConfig = LightingConfig(),
) -> list[LightingEstimate]:
    """Lighting of the frames of one clip with known poses: one sun, fused in world coordinates.

    The per-frame sun evidence (sky, sun disc, cast-shadow axis, walls, shadow ends) is a log-likelihood on one grid
    of world directions;
    the clip's evidence is its sum (frames as independent views of the same, distant sun), and each frame gets the
    fused direction rotated into its camera. Metadata (GPS + UTC + orientation) on every frame overrides fusion. Sun
    strength and ambient stay per frame. The world's up is ``metas[0]['up_in_world']`` or the first camera's -y.
    """
    rng = require_rng(rng, "estimate_lighting_clip")
    ctxs, up_in_world = _prepare_clip(images, intrinsics, cams_from_world, metas, config, rng)
    meta_suns = [None if c.indoor else _metadata_sun(c, True) for c in ctxs]
    if all(s is not None for s in meta_suns):
        return [_finish(c, s, 0.95, "metadata", None, config) for c, s in zip(ctxs, meta_suns)]
    live = [c for c in ctxs if not c.indoor]
    if not live:
        return [_finish(c, None, 0.0, "none", None, config) for c in ctxs]
    sun_est = _image_cue_sun(live, up_in_world, config, rng)
    d_world, confidence = sun_est.direction_in_world, sun_est.confidence
    cues = iter(sun_est.sky_cues)
    # one decision for the clip: the median of its frames' probabilities (one sun, one weather)
    p_sun = (
        float(np.median([direct_sun_probability(c.img) for c in live])) if config.sun_decision == "evidence" else None
    )
    out = []
    for c in ctxs:
        if c.indoor:
            out.append(_finish(c, None, 0.0, "none", None, config))
        else:
            conf = confidence * (1.0 if c.known_camera else 0.5)
            out.append(_finish(c, c.R_cw @ d_world, conf, "image_cues_clip", next(cues), config, p_sun))
    return out

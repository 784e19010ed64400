"""The thresholds and priors of the lighting estimate (:func:`aias_augment.analyse.lighting.estimate.estimate_lighting`),
each with the measurement that set it."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

from aias_augment.core.config import checked_config
from aias_augment.core.geometry import CAMERA_HEIGHT_PRIOR_M

__all__ = ["LightingConfig"]


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

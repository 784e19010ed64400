"""The insertion config and its presets (``configs/presets/<name>.yaml``)."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, fields, is_dataclass, replace
from functools import cached_property
from typing import Literal

import numpy as np

from aias_augment.analyse.config import ANALYSE_BOUNDS, AnalyseConfig, check_analysis_widths
from aias_augment.analyse.lighting.estimate import LightingConfig
from aias_augment.apply.config import APPLY_BOUNDS, ApplyConfig, HarmonizeMethod
from aias_augment.assets.deform import DeformConfig
from aias_augment.core.config import CONFIG_DIR, ConfigValueError, UnknownConfigKeys, checked_config, load_config
from aias_augment.core.geometry import CAMERA_HEIGHT_PRIOR_M
from aias_augment.plan.config import PLAN_BOUNDS, PLAN_ORDERS, EdgeBlendMode, PlanConfig, check_plan_fields
from aias_augment.plan.placement import PlacementConfig

PRESETS = ("fast", "balanced", "accurate")

__all__ = ["InsertionConfig", "load_preset", "PRESETS", "HarmonizeMethod", "EdgeBlendMode"]


# Every field is checked at construction against its type hint and the bounds of the step that reads it
# (config.checked_config): a wrong type or a value out of range raises, naming the field, instead of a skip on every
# call.
@checked_config({**ANALYSE_BOUNDS, **PLAN_BOUNDS, **APPLY_BOUNDS, "naive_share": "[0, 1]"}, orders=PLAN_ORDERS)
@dataclass(frozen=True)
class InsertionConfig:
    """The insertion's config as users write it: flat keys (YAML presets, CLI ``--config``, keyword overrides). Each
    step reads its own record built from the effective values (:meth:`effective`): :attr:`analyse`, :attr:`plan`,
    :attr:`apply`."""

    categories: tuple[str, ...] = ("traffic_cone",)
    min_objects: int = 1
    max_objects: int = 3
    # Stages (ablation switches). naive_paste=True is 3D Copy-Paste's "random insertion": a plain render pasted at a
    # random position and scale, no geometry, lighting, shadow or harmonization.
    placement: bool = True
    shadow: bool = True
    lighting: bool = True
    harmonize: bool = True
    naive_paste: bool = False
    # Share of images made as naive pastes (as ``naive_paste``: the same objects at random 2D positions and sizes,
    # no geometry, lighting, shadow or harmonization) while the rest go through the pipeline: a detector then sees
    # cones both standing on the road in context and anywhere, at any size (results/study_core: the mixed pool).
    # Decided per image by one uniform from the call's generator, drawn only when the share is above 0 (so every
    # other config's draws are unchanged), and recorded (``InsertionRecord.mode``) so that a replay re-applies it.
    naive_share: float = 0.0
    harmonize_method: HarmonizeMethod = "camera"
    harmonize_test_time_views: bool = True  # learnt harmonizers: average 6 views (False: 1 view, ~2-6x faster)
    # What the harmonizer may change on the objects: "full" (its output as is) or "luminance" (its brightness and
    # contrast, per pixel, with the chromaticity the lighting gave the object kept): a learnt harmonizer pulls an
    # object toward its context's colour, and among orange cones or beside a red truck that turns white bands pink
    # (studies/lighting/neutral_whites/run.py, studies/lighting/neutral_whites/result: white bands against the same photos' real
    # white sleeves, R/G 1.30 with "full", 1.03 with "luminance"; with the neutral ambient the paired deviation fell
    # by 0.10 in max |log R/G|, |log B/G| [0.04, 0.17], 24 TraCon train photos).
    harmonize_colour: Literal["full", "luminance"] = "luminance"
    # After the colour harmonizer: camera-pipeline matching of blur, noise and JPEG (quality and chroma subsampling
    # read from the source image) against the object's surroundings (harmonize.api.match_camera; its noise drawn
    # from a generator seeded by the plan's harmonize_seed, so a replay gives the same bytes). Part of the
    # harmonization stage: off with it. Redundant (skipped) when harmonize_method is "camera".
    camera_match: bool = False
    # Motion blur of each object (core/stages/motion_blur.py): streak length range in output pixels, drawn
    # per object in the plan; (0, 0): off.
    motion_blur_px: tuple[float, float] = (0.0, 0.0)
    # Edge blending (core/stages/edge_blend.py): each object's boundary drawn uniformly from these modes
    # ("rendered", "hard", "feather", the last with a Gaussian sigma uniform in ``edge_feather_px``), so no one
    # boundary predicts the label; (): off (the rendered coverage).
    edge_blend: tuple[EdgeBlendMode, ...] = ()
    edge_feather_px: tuple[float, float] = (0.5, 2.0)
    # Where the objects come from: "default": the shared-data model per category, the bank for others; "bank": all
    # from the bank; "procedural": a new seeded procedural asset per object where the category has a generator
    # (traffic_cone), else as "default".
    asset_source: Literal["default", "bank", "procedural"] = "default"
    # With asset_source "procedural": None draws a new member of the family per object; N draws one of N members
    # made from ``family_seed`` (required then: every worker and epoch sees the same members), each built once per
    # process, so the view cache reuses its views (assets/bank/family_cache.py; the member index is in the record).
    family_members: int | None = None
    family_seed: int | None = None
    # "labels": with asset_source procedural, an image with labelled cones draws its inserted cones like them (body
    # colour, base, white sleeves measured on their crops: aias_augment/plan/looks.py); "variety": the family's own
    # colours, bases and sleeves everywhere. Images without labelled cones draw the family either way.
    cone_look: Literal["labels", "variety"] = "labels"
    # "labels": a cone drawn like a labelled one (above) is also made as bright as it: its shaded body scaled so
    # that its brightness (as analyse/instances.py measures a body) is the labelled cone's in the photo, the photo's
    # own light and exposure on the same material (apply/stages.py); "lighting": the estimated light alone.
    cone_brightness: Literal["labels", "lighting"] = "labels"
    # Share of objects inserted as a seeded physical variant of their asset (aias_augment/assets/deform.py: dented,
    # crushed, bent, knocked over; kinds and ranges in ``deform_cfg``), drawn in the plan and recorded in the
    # placement's ``asset_meta["deformation"]``, so a replay rebuilds the same variant. 0: off.
    deform_probability: float = 0.0
    deform_cfg: DeformConfig = DeformConfig()
    # Decoys: objects of ``decoy_categories`` inserted through the same stages (placement, lighting, shadow,
    # harmonization) but not annotated, ``decoys`` = (lo, hi) per image, drawn uniformly. A detector trained on the
    # output then cannot take the insertion itself (its edges, shadow, harmonization) as the sign of the class.
    decoy_categories: tuple[str, ...] = ()
    decoys: tuple[int, int] = (0, 0)
    # How the labelled objects of one image stand together: "independent" (each placed on its own), "line" (a row at
    # ``arrangement_spacing_m`` along the road or across it, as cones line a lane or close it), "cluster" (within
    # ``arrangement_cluster_radius_m`` of the first), "mixed" (one of the three per image), "row" (the row the
    # image's own labelled objects of the kind stand in, continued: at the spacing they show beyond either end and
    # in its gaps, on the ground they stand on by its look; an image without such a row places its objects as
    # "independent" does, draw for draw). In "line" and "cluster" the first object is placed as usual and the others
    # of its category stand where the arrangement puts them; an object whose place has no free ground, or of another
    # category (of a kind with no labelled row), is placed on its own, and the record says which joined. "row" is the
    # default: beside TraCon's labelled rows it brings the inserted cones' Lite0-KID from 0.048 to 0.040 on the
    # development halves (studies/realism/matched/result/arrangement); on unlabelled images nothing changes.
    arrangement: Literal["independent", "line", "cluster", "mixed", "row"] = "row"
    arrangement_spacing_m: tuple[float, float] = (1.0, 3.0)
    arrangement_cluster_radius_m: float = 1.2
    # How the output boxes sit around the objects: per side (left, top, right, bottom), how far a label lies outside
    # the object's mask as a fraction of the label's width or height, as the user's own labellers draw them
    # (``aias-assets box-convention`` measures it from their labels: apply/annotate.follow_convention). A detector
    # trained on boxes of another convention than its test labels loses AP at the high IoU thresholds. Zero:
    # mask-tight (TraCon's labels are: median margins 0-0.6 %, studies/assets/box_convention/result/box_convention.json).
    box_convention: tuple[float, float, float, float] = (0.0, 0.0, 0.0, 0.0)
    # A glossy dielectric coating on every object (apply/shading.Coating): reflectance at normal incidence (0: matte
    # Lambertian; 0.04: plastics and paint) and GGX roughness; it reflects the estimated sky and sun, so it is off
    # where the lighting stage is.
    coating_f0: float = 0.0
    coating_roughness: float = 0.4
    ssaa: int = 2  # supersampling of the object render (edge quality vs time, cost ~ssaa^2)
    # Sun visibility on the ground: "catcher" (GL shadow map: ground patch rendered with/without the object) or
    # "projected" (the object's triangles projected along the sun onto the ground, filled in numpy/OpenCV; no GL
    # call; tests/aias_augment/apply/test_projected_shadow.py: IoU >= 0.95 vs exact ray casting).
    shadow_method: Literal["catcher", "projected"] = "catcher"
    # The contact shadow (ambient occlusion of the ground next to the object's footprint): the ground there is
    # darkened by up to ``contact_shadow_strength``, falling off as exp(-distance / (radius x object height)).
    # 0.15: the band just below real cones' bases is 0.4-1.5 % darker than farther down in TraCon photos, and this
    # strength comes nearest on a train half (studies/lighting/contact_shadows/result; 0.6 made it 12-13 % darker).
    contact_shadow_strength: float = 0.15
    contact_shadow_radius: float = 0.25
    # Object layers: "full" (a GL render of the asset at the sample's pose) or "view_cache" (the asset's view for the
    # sample's view bin, rendered once per process and warped into the image, no GL call on a hit; poses the cache
    # does not cover fall back to "full": apply/view_cache.py, tests/aias_augment/apply/test_view_cache.py), or
    # "raycast" (procedural cones ray-cast in NumPy at their own pose, no view bin and no GL call: a new cone per
    # object costs what a cached view does; other assets as "view_cache": apply/cone_raycast.py).
    render_method: Literal["full", "view_cache", "raycast"] = "full"
    # Cheap analysis (the fast preset's lighting estimate for a new image): the camera (vanishing lines) and the
    # lighting are estimated on a copy at most this many pixels wide (0: the image as given); the record says so.
    analysis_max_width: int = 0
    # With ``analysis_max_width`` set: the camera (horizon, pitch, roll, focal from vanishing lines) is estimated on a
    # copy at least this wide (0: the analysis_max_width copy). Short segments vanish on a 160 px copy and the roll
    # goes with them (studies/lighting/fast_camera/result).
    camera_analysis_width: int = 0
    # Priors when the scene does not say.
    camera_height_m: float = CAMERA_HEIGHT_PRIOR_M
    estimate_camera: bool = True  # horizon/pitch/roll (and focal when unknown) from vanishing lines
    # Poles and rails (long straight edges off the ground) detected with the placeable region; a site one of them may
    # stand in front of is refused (analyse/thin_structures.py, plan/placement.py). False: not looked for.
    thin_structures: bool = False
    max_camera_pitch_deg: float = 25.0  # estimates beyond these bounds fall back to the level-camera prior
    max_camera_roll_deg: float = 10.0
    default_hfov_deg: float = 60.0
    naive_height_frac_range: tuple[float, float] = (0.05, 0.4)
    naive_height_frac_samples: tuple[float, ...] = ()  # when set, naive paste draws its heights from these instead
    placement_cfg: PlacementConfig = PlacementConfig()
    lighting_cfg: LightingConfig = LightingConfig()  # thresholds and analysis resolutions of estimate_lighting

    def __post_init__(self):  # after the checks of every field's type and bounds (checked_config)
        check_plan_fields(self, "InsertionConfig")
        check_analysis_widths(self, "InsertionConfig")
        if self.naive_paste and self.naive_share > 0:
            raise ConfigValueError(
                ("InsertionConfig", "naive_share"), "must be 0 when naive_paste is on (every image is a naive paste)"
            )

    def for_image(self, rng: np.random.Generator) -> "InsertionConfig":
        """The config one image is made with: with ``naive_share`` above 0, a uniform drawn from ``rng`` makes it
        a naive paste (below the share) or a pipeline insertion; the returned config has no share left, so what it
        makes is what :attr:`mode` names. Without a share: this config, and ``rng`` untouched."""
        if self.naive_share <= 0:
            return self
        return replace(self, naive_paste=bool(rng.random() < self.naive_share), naive_share=0.0)

    @property
    def mode(self) -> Literal["pipeline", "naive_paste"]:
        """How an image made with this config (after :meth:`for_image`) was made, as its record says."""
        return "naive_paste" if self.naive_paste else "pipeline"

    def for_mode(self, mode: str) -> "InsertionConfig":
        """This config as a recorded ``mode`` says the image was made (a replay's config)."""
        if mode not in ("pipeline", "naive_paste"):
            raise ValueError(f"unknown insertion mode {mode!r} (pipeline | naive_paste)")
        return replace(self, naive_paste=mode == "naive_paste", naive_share=0.0)

    def effective(self) -> "InsertionConfig":
        """naive_paste switches the geometry, lighting, shadow and harmonization stages off."""
        if self.naive_paste:
            return replace(self, placement=False, shadow=False, lighting=False, harmonize=False)
        return self

    def _record(self, cls):
        effective = self.effective()
        return cls(**{f.name: getattr(effective, f.name) for f in fields(cls)})

    @cached_property
    def analyse(self) -> AnalyseConfig:
        """The analysis step's record (:func:`aias_augment.analyse.analyse_scene`)."""
        return self._record(AnalyseConfig)

    @cached_property
    def plan(self) -> PlanConfig:
        """The planning step's record (:func:`aias_augment.plan.plan_insertion`)."""
        return self._record(PlanConfig)

    @cached_property
    def apply(self) -> ApplyConfig:
        """The apply step's record (:func:`aias_augment.apply.apply_plan`)."""
        return self._record(ApplyConfig)

    def analysis_fields(self) -> dict:
        """The fields :func:`aias_augment.analyse.analyse_scene` reads (part of the scene cache key)."""
        return self.analyse.key_fields()


def load_preset(name: str, **overrides) -> InsertionConfig:
    """``configs/presets/<name>.yaml`` (fast | balanced | accurate) with keyword overrides.

    Every value is checked (type, bounds) as in any construction. A nested config (``placement_cfg``,
    ``lighting_cfg``) may be given as a mapping of some of its fields: they update the preset's, e.g.
    ``load_preset("accurate", placement_cfg={"sizes_from_existing": True})`` keeps the preset's ``max_tries``.
    """
    if name not in PRESETS:
        raise ValueError(f"unknown preset {name!r}; choose from {PRESETS}")
    cfg = load_config(InsertionConfig, CONFIG_DIR / "presets" / f"{name}.yaml")
    if not overrides:
        return cfg
    allowed = {f.name for f in fields(InsertionConfig)}
    unknown = sorted(set(overrides) - allowed)
    if unknown:
        raise UnknownConfigKeys(("InsertionConfig",), f"unknown config keys {unknown}; allowed: {sorted(allowed)}")
    for key, value in overrides.items():
        nested = getattr(cfg, key)
        if is_dataclass(nested) and isinstance(value, Mapping):  # on top of the preset's nested config
            overrides[key] = {**{f.name: getattr(nested, f.name) for f in fields(nested)}, **value}
    return replace(cfg, **overrides)

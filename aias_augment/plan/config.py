"""The planning step's config: the fields :func:`~aias_augment.plan.insertion.plan_insertion` and the stage list's
draws (:mod:`aias_augment.core.stages`) read, frozen and checked at construction. The door's flat config
(``pipeline.config.InsertionConfig``) builds it as ``config.plan`` from its effective values (a naive paste turns
placement off)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

from aias_augment.assets.deform import DeformConfig
from aias_augment.core.config import ConfigValueError, checked_config
from aias_augment.plan.placement import PlacementConfig

#: The edge-blend modes of ``core/stages/edge_blend.MODES`` (tests/aias_augment/pipeline/test_config.py).
EdgeBlendMode = Literal["rendered", "hard", "feather"]

#: Bounds of the planning fields (the door's config checks its same-named fields against these too).
PLAN_BOUNDS = {
    # Cost bounds: a range that can never finish an image is refused here, not met as a skip on every image.
    # 64 objects: each needs its own render and placement tries (10000 took 510 s for one image); far more than
    # one photo shows of one category (TraCon: at most 16 cones a photo).
    "min_objects": "[0, 64]",
    "max_objects": "[0, 64]",
    "naive_height_frac_range": "(0, 1] lo<=hi",
    "naive_height_frac_samples": "(0, 1]",
    # The streak's kernel is ~length^2 pixels and the layer grows by it: 200 px is a fast object across a 4K
    # frame, 1e6 made every image a MemoryError.
    "motion_blur_px": "[0, 200] lo<=hi",
    # The layer grows by 3 sigma on each side: 50 px feathers any edge a photo shows.
    "edge_feather_px": "[0, 50] lo<=hi",
    "deform_probability": "[0, 1]",
    "decoys": "[0, 64] lo<=hi",  # as max_objects
    "arrangement_spacing_m": "(0, inf) lo<=hi",
    "arrangement_cluster_radius_m": "(0.35, inf)",
    "family_members": "[1, 65536]",  # family_cache.MAX_MEMBERS
    "family_seed": "[0, inf)",
}
PLAN_ORDERS = ["min_objects <= max_objects"]


def check_plan_fields(cfg, owner: str) -> None:
    """The cross-field rules of the planning fields of ``cfg`` (any config with these fields, named ``owner`` in the
    error)."""
    if not cfg.categories:
        raise ConfigValueError((owner, "categories"), "must not be empty")
    if cfg.family_members is not None and (cfg.family_seed is None or cfg.asset_source != "procedural"):
        raise ConfigValueError(
            (owner, "family_members"),
            f"{cfg.family_members} needs asset_source 'procedural' (got {cfg.asset_source!r}) and a "
            f"family_seed >= 0 (got {cfg.family_seed}): set both, or family_members None",
        )
    if cfg.decoys[1] > 0 and not cfg.decoy_categories:
        raise ConfigValueError((owner, "decoy_categories"), "must not be empty when decoys are drawn")
    if set(cfg.decoy_categories) & set(cfg.categories):
        raise ConfigValueError(
            (owner, "decoy_categories"),
            f"{sorted(set(cfg.decoy_categories) & set(cfg.categories))} are also annotated categories",
        )


@checked_config(PLAN_BOUNDS, orders=PLAN_ORDERS)
@dataclass(frozen=True)
class PlanConfig:
    """What the plan draws: how many objects of which categories and assets, where (``placement``: on the measured
    ground; off: a naive paste's random 2D position and size), how they stand together, decoys, and the stage list's
    per-object parameters. The fields mean what the door's same-named fields do (``pipeline/config.py``)."""

    categories: tuple[str, ...] = ("traffic_cone",)
    min_objects: int = 1
    max_objects: int = 3
    placement: bool = True
    asset_source: Literal["default", "bank", "procedural"] = "default"
    family_members: int | None = None
    family_seed: int | None = None
    deform_probability: float = 0.0
    deform_cfg: DeformConfig = DeformConfig()
    decoy_categories: tuple[str, ...] = ()
    decoys: tuple[int, int] = (0, 0)
    arrangement: Literal["independent", "line", "cluster", "mixed", "row"] = "row"
    arrangement_spacing_m: tuple[float, float] = (1.0, 3.0)
    arrangement_cluster_radius_m: float = 1.2
    naive_height_frac_range: tuple[float, float] = (0.05, 0.4)
    naive_height_frac_samples: tuple[float, ...] = ()
    placement_cfg: PlacementConfig = PlacementConfig()
    # "labels": procedural cones drawn like the image's labelled cones (colour, base, sleeves) when it has some;
    # "variety": the family's own draws everywhere.
    cone_look: Literal["labels", "variety"] = "labels"
    # The stage list's fields (core/stages: each stage's ``enabled`` and ``draw`` read them at plan time).
    motion_blur_px: tuple[float, float] = (0.0, 0.0)
    edge_blend: tuple[EdgeBlendMode, ...] = ()
    edge_feather_px: tuple[float, float] = (0.5, 2.0)

    def __post_init__(self):  # after the checks of every field's type and bounds (checked_config)
        check_plan_fields(self, "PlanConfig")


def plan_config(cfg) -> PlanConfig:
    """The plan's record: ``cfg`` when it is one, else the one a composed config carries (``cfg.plan``, as the door's
    ``InsertionConfig`` does); anything else is a TypeError naming what was given."""
    if isinstance(cfg, PlanConfig):
        return cfg
    record = getattr(cfg, "plan", None)
    if isinstance(record, PlanConfig):
        return record
    raise TypeError(f"the plan needs a PlanConfig or a config with one (.plan), got {type(cfg).__name__}")

"""The apply step's config: the fields :func:`~aias_augment.apply.stages.apply_plan` and its frame steps read
(render, shading, shadows, harmonization, boxes), frozen and checked at construction. The door's flat config
(``pipeline.config.InsertionConfig``) builds it as ``config.apply`` from its effective values (a naive paste turns
placement, lighting, shadow and harmonization off)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

from aias_augment.core.config import checked_config

#: ``harmonize.api.METHODS`` (tests/aias_augment/pipeline/test_config.py checks they agree).
HarmonizeMethod = Literal["none", "reinhard", "camera", "fast", "network"]

#: Bounds of the apply fields (the door's config checks its same-named fields against these too).
APPLY_BOUNDS = {
    # 4: 16 samples a pixel; the render is the frame's size times ssaa (a 4K frame at 4 is 15360 px wide, near
    # the common 16384 GL limit) and costs ~ssaa^2.
    "ssaa": "[1, 4]",
    "contact_shadow_strength": "[0, 1]",
    "contact_shadow_radius": "(0, inf)",
    "box_convention": "[0, 0.45]",
    "coating_f0": "[0, 0.2]",
    "coating_roughness": "[0.05, 1]",
}


@checked_config(APPLY_BOUNDS)
@dataclass(frozen=True)
class ApplyConfig:
    """How a plan is carried out: the stage switches (``placement``: labelled occluders and ground contact;
    ``lighting``: the estimated light and the coating's reflections; ``shadow``; ``harmonize``) and each stage's
    settings. The fields mean what the door's same-named fields do (``pipeline/config.py``)."""

    placement: bool = True
    shadow: bool = True
    lighting: bool = True
    harmonize: bool = True
    harmonize_method: HarmonizeMethod = "camera"
    harmonize_test_time_views: bool = True
    harmonize_colour: Literal["full", "luminance"] = "luminance"
    camera_match: bool = False
    box_convention: tuple[float, float, float, float] = (0.0, 0.0, 0.0, 0.0)
    coating_f0: float = 0.0
    coating_roughness: float = 0.4
    ssaa: int = 2
    shadow_method: Literal["catcher", "projected"] = "catcher"
    contact_shadow_strength: float = 0.15
    contact_shadow_radius: float = 0.25
    render_method: Literal["full", "view_cache", "raycast"] = "full"
    cone_brightness: Literal["labels", "lighting"] = "labels"


def apply_config(cfg) -> ApplyConfig:
    """The apply step's record: ``cfg`` when it is one, else the one a composed config carries (``cfg.apply``, as the
    door's ``InsertionConfig`` does); anything else is a TypeError naming what was given."""
    if isinstance(cfg, ApplyConfig):
        return cfg
    record = getattr(cfg, "apply", None)
    if isinstance(record, ApplyConfig):
        return record
    raise TypeError(f"apply_plan needs an ApplyConfig or a config with one (.apply), got {type(cfg).__name__}")

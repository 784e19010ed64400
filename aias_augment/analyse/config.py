"""The analysis step's config: the fields :func:`~aias_augment.analyse.analysis.analyse_scene` reads, frozen and
checked at construction. The door's flat config (``pipeline.config.InsertionConfig``) builds it as ``config.analyse``
from its effective values (a naive paste turns placement and lighting off)."""

from __future__ import annotations

from dataclasses import dataclass

from aias_augment.analyse.lighting.estimate import LightingConfig
from aias_augment.core.config import ConfigValueError, checked_config
from aias_augment.core.geometry import CAMERA_HEIGHT_PRIOR_M

#: Bounds of the analysis fields (the door's config checks its same-named fields against these too).
ANALYSE_BOUNDS = {
    "analysis_max_width": "[0, inf)",  # and 0 or >= 64 (check_analysis_widths)
    "camera_analysis_width": "[0, inf)",  # and 0 or >= 64 (check_analysis_widths)
    "camera_height_m": "(0, inf)",
    "max_camera_pitch_deg": "[0, 90]",
    "max_camera_roll_deg": "[0, 180]",
    "default_hfov_deg": "(0, 180)",
}


def check_analysis_widths(cfg, owner: str) -> None:
    """The analysis copies' widths of ``cfg`` (any config with these fields, named ``owner`` in the error): 0 (off) or
    at least 64 pixels."""
    for name in ("analysis_max_width", "camera_analysis_width"):
        if 0 < getattr(cfg, name) < 64:
            raise ConfigValueError((owner, name), f"must be 0 (off) or >= 64, got {getattr(cfg, name)}")


@checked_config(ANALYSE_BOUNDS)
@dataclass(frozen=True)
class AnalyseConfig:
    """What the analysis computes: the ground and region only with ``placement``, the estimated light only with
    ``lighting``; ``naive_paste`` says so in the analysis' notes."""

    placement: bool = True
    lighting: bool = True
    naive_paste: bool = False
    # Cheap analysis: the camera (vanishing lines) and the lighting are estimated on a copy at most this many pixels
    # wide (0: the image as given); the camera's copy at least ``camera_analysis_width`` wide (0: the same copy).
    analysis_max_width: int = 0
    camera_analysis_width: int = 0
    # Priors when the scene does not say.
    camera_height_m: float = CAMERA_HEIGHT_PRIOR_M
    estimate_camera: bool = True  # horizon/pitch/roll (and focal when unknown) from vanishing lines
    # Long straight edges off the ground (poles, rails: analyse/thin_structures.py), kept with the placeable region:
    # the placement refuses sites they may stand in front of.
    thin_structures: bool = False
    max_camera_pitch_deg: float = 25.0  # estimates beyond these bounds fall back to the level-camera prior
    max_camera_roll_deg: float = 10.0
    default_hfov_deg: float = 60.0
    lighting_cfg: LightingConfig = LightingConfig()  # thresholds and analysis resolutions of estimate_lighting

    def __post_init__(self):  # after the checks of every field's type and bounds (checked_config)
        check_analysis_widths(self, "AnalyseConfig")

    def key_fields(self) -> dict:
        """The fields that change what the analysis computes (part of the scene cache key). ``naive_paste`` is not
        one: it only adds a note, and a naive paste's placement and lighting are off already."""
        out = {
            k: getattr(self, k)
            for k in (
                "placement",
                "lighting",
                "estimate_camera",
                "camera_height_m",
                "max_camera_pitch_deg",
                "max_camera_roll_deg",
                "default_hfov_deg",
                "lighting_cfg",
            )
        }
        if self.thin_structures:  # only when set: the keys of analyses without them stay what they were
            out["thin_structures"] = True
        if self.analysis_max_width:  # only when set: the keys of full-resolution analyses stay what they were
            out["analysis_max_width"] = self.analysis_max_width
            if self.camera_analysis_width:
                out["camera_analysis_width"] = self.camera_analysis_width
        return out


def analyse_config(cfg) -> AnalyseConfig:
    """The analysis' record: ``cfg`` when it is one, else the one a composed config carries (``cfg.analyse``, as the
    door's ``InsertionConfig`` does); anything else is a TypeError naming what was given."""
    if isinstance(cfg, AnalyseConfig):
        return cfg
    record = getattr(cfg, "analyse", None)
    if isinstance(record, AnalyseConfig):
        return record
    raise TypeError(f"the analysis needs an AnalyseConfig or a config with one (.analyse), got {type(cfg).__name__}")

"""A clip insertion's config (:class:`VideoInsertionConfig`) and its plan (:class:`ClipPlan`): the types the clip
planner (:mod:`aias_augment.pipeline.clip`) and the objects' motion (:mod:`aias_augment.pipeline.clip_motion`) share."""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from aias_augment.assets.asset import Asset
from aias_augment.plan.placement import PlacementConfig
from aias_augment.plan.stabilize import FlowRefineConfig

if TYPE_CHECKING:
    from aias_augment.pipeline.config import InsertionConfig


@dataclass(frozen=True)
class VideoInsertionConfig:
    lookahead_frames: int = 10  # T: the object stands where the camera will be at frame start + T ...
    lateral_offset_m: float = 2.5  # ... shifted this far to the camera's right (negative: left)
    ahead_m: float = 0.0  # ... and this far along that camera's forward axis (a short clip: the object in view)
    contact: str = "lookahead"  # "lookahead" | "sampled" (a ground pixel of the first frame)
    height_m: float | None = None  # object height; None: the asset's own
    local_refit: bool = True  # per-frame local ground refit (needs depths)
    ssaa: int = 1
    shadow: bool = True  # cast shadow from the frame's sun (contact occlusion only without one)
    flow_refine: bool = False  # KLT-track the ground under the contact and slide the object per frame
    # A moving object: metres per frame along its heading (its own x axis on the ground; the yaw draws it), from
    # frame ``start`` on (before it, where it came from). 0: standing.
    speed_m_per_frame: float = 0.0
    # A parked object pulling out: it stands for ``move_after_frames`` frames from ``start``, then speeds up from rest
    # at a constant acceleration, reaching its speed after ``accelerate_frames`` frames. Both 0: it moves at its speed
    # in every frame (before ``start`` too: where it came from).
    move_after_frames: int = 0
    accelerate_frames: int = 0
    # Knocked over: it falls onto its side over this many frames from frame ``topple_start`` (None: drawn in the plan
    # so that the fall ends in the clip), towards a direction drawn in the plan. 0: it stays upright.
    topple_frames: int = 0
    topple_start: int | None = None
    flow_cfg: FlowRefineConfig = FlowRefineConfig()
    placement_cfg: PlacementConfig = PlacementConfig()
    # The image door's preset whose stage settings every frame goes through (coating, shadow method, contact
    # shadow, box convention); ssaa, shadow and render method are this config's, harmonization the clip's own.
    # None: the InsertionConfig defaults.
    stages: InsertionConfig | None = None

    def __post_init__(self):
        if self.contact not in ("lookahead", "sampled"):
            raise ValueError(f"contact must be 'lookahead' or 'sampled', got {self.contact!r}")
        if self.lookahead_frames < 0 or self.ssaa < 1:
            raise ValueError("lookahead_frames must be >= 0 and ssaa >= 1")
        if not np.isfinite(self.speed_m_per_frame):
            raise ValueError(f"speed_m_per_frame must be finite, got {self.speed_m_per_frame}")
        if not (np.isfinite(self.lateral_offset_m) and np.isfinite(self.ahead_m)):
            raise ValueError(
                f"lateral_offset_m and ahead_m must be finite, got {self.lateral_offset_m}, {self.ahead_m}"
            )
        if self.speed_m_per_frame != 0 and self.flow_refine:
            raise ValueError("flow_refine tracks the ground under a standing object: not with speed_m_per_frame")
        if self.move_after_frames < 0 or self.accelerate_frames < 0:
            raise ValueError(
                f"move_after_frames and accelerate_frames must be >= 0, got {self.move_after_frames}, "
                f"{self.accelerate_frames}"
            )
        if self.topple_frames < 0 or (self.topple_start is not None and self.topple_start < 0):
            raise ValueError(
                f"topple_frames and topple_start must be >= 0, got {self.topple_frames}, {self.topple_start}"
            )
        if self.topple_frames and (self.speed_m_per_frame != 0 or self.flow_refine):
            raise ValueError("a toppling object stands where it falls: not with speed_m_per_frame or flow_refine")


@dataclass(frozen=True, eq=False)
class ClipPlan:
    """Everything :func:`apply_clip` does to the frames of one clip, decided once (:func:`plan_clip`): the (scaled)
    asset, its yaw and world pose, per frame its camera pose (None where the object is behind the camera or off the
    frame), the frame's ground and lighting, the object's contact track and the layer stages' parameters."""

    asset: Asset
    yaw_rad: float
    contact_in_world: np.ndarray
    world_from_object: np.ndarray
    cams_from_object: tuple
    grounds: tuple
    lights: tuple
    contact_track_uv: np.ndarray
    contact_visible: np.ndarray
    contact_track_in_world: np.ndarray
    refit_offsets_m: tuple
    layer_params: dict
    modules: dict
    # per frame: the world pose of the object as it stands in that frame, and that frame's asset (a toppling object
    # turns; None: ``asset``)
    worlds_from_object: tuple = ()
    frame_assets: tuple = ()
    # a toppling object's fall: start frame, frames, azimuth of the base edge it tips over, rest angle (radians)
    topple: dict | None = None

    def asset_at(self, i: int) -> Asset:
        return self.frame_assets[i] if self.frame_assets and self.frame_assets[i] is not None else self.asset

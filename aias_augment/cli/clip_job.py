"""What one clip command does (:class:`ClipJob`: the options that decide its output, stored in ``record.json``) and
the inputs it read (:class:`ClipInputs`): the types the clip command's readers, cameras and writers share."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from aias_augment.core.geometry import CAMERA_HEIGHT_PRIOR_M, Intrinsics
from aias_augment.pipeline.clip_objects import ClipRequest


@dataclass(frozen=True)
class ClipJob:
    """Everything that decides the output of one clip (it is stored in ``record.json``)."""

    input: str
    camera: str | None  # None: estimated from the first frame (a static camera only)
    poses: str | None  # None: the clip must come from a static camera (checked), which is then the world
    out: str
    categories: tuple[str, ...] = ("traffic_cone",)
    seed: int = 0
    start: int = 0  # first frame of the input used
    max_frames: int | None = None
    stride: int = 1
    colour: bool = False  # KITTI calib.txt: use P2 (colour camera) instead of P0
    camera_height_m: float = CAMERA_HEIGHT_PRIOR_M
    lookahead_frames: int | None = None  # the object stands beside where the camera is at this frame; None: the last
    lateral_offset_m: float = 2.5
    ahead_m: float = 0.0  # ... and this far ahead of that camera (a short clip: the object and its shadow in view)
    lighting: str = "clip"  # "clip": one sun fused over the clip; "ambient": grey-world ambient only
    flow_refine: bool = False  # KLT stabilisation of the contact (for drifting poses)
    harmonize: str = "fast"  # harmonize.METHODS; "fast": one colour transform for the clip (median over frames)
    preset: str = "balanced"  # the image door's preset whose layer stages (e.g. motion blur) the object gets
    fps: float = 10.0  # frames per second of the clip as read (after --stride): the mp4's rate and the speed's clock
    object_speed_mps: float = 0.0  # the object moves along its heading at this speed (0: it stands)
    # ... after standing this long (seconds), reaching that speed from rest over object_accel_s (a car pulling out)
    object_start_s: float = 0.0
    object_accel_s: float = 0.0
    topple_s: float = 0.0  # each object is knocked over during the clip, falling for this long (0: it stays upright)
    stereo_right: str | None = None  # the right camera's frames: poses by stereo odometry (with a camera, no poses)
    # Objects in the clip, each its own track: object k > 0 stands on the other side of the path from object k - 1
    # and nearer (lookahead scaled by (n - k) / n); on a static camera each stands on its own sampled ground pixel.
    # Objects never meet: one whose box would meet another's in any frame is redrawn (record: "draws",
    # "skipped_objects").
    objects: int = 1
    # The clip's own track labels (MOT or COCO-video; format None: detected), carried into the output with their
    # track ids, occluding inserted objects behind them (aias_augment.pipeline.clip_occluders). MOT rows name no
    # class: they are labels_category.
    labels: str | None = None
    labels_format: str | None = None
    labels_category: str = "object"

    def __post_init__(self):
        if self.stride < 1 or self.start < 0 or (self.max_frames is not None and self.max_frames < 1):
            raise ValueError("need stride >= 1, start >= 0 and max_frames >= 1")
        self.request()  # the door's own checks of what to insert and how
        if self.stereo_right is not None and (self.poses is not None or self.camera is None):
            raise ValueError("stereo_right estimates the poses: it needs a camera and no poses")
        from aias_augment.core.track_labels import FORMATS

        if self.labels_format is not None and self.labels_format not in FORMATS:
            raise ValueError(f"--labels-format must be one of {', '.join(FORMATS)}, got {self.labels_format!r}")
        if self.labels is None and (self.labels_format is not None or self.labels_category != "object"):
            raise ValueError("--labels-format and --labels-category need --labels (the clip's label file)")
        if not self.labels_category.strip():
            raise ValueError("--labels-category must name a class")

    def request(self) -> ClipRequest:
        """What the clip door inserts and how (:class:`~aias_augment.pipeline.clip_objects.ClipRequest`): this job
        without its files."""
        return ClipRequest(
            categories=self.categories,
            seed=self.seed,
            camera_height_m=self.camera_height_m,
            lookahead_frames=self.lookahead_frames,
            lateral_offset_m=self.lateral_offset_m,
            ahead_m=self.ahead_m,
            lighting=self.lighting,
            flow_refine=self.flow_refine,
            harmonize=self.harmonize,
            preset=self.preset,
            fps=self.fps,
            object_speed_mps=self.object_speed_mps,
            object_start_s=self.object_start_s,
            object_accel_s=self.object_accel_s,
            topple_s=self.topple_s,
            objects=self.objects,
            name=self.input,
        )


@dataclass
class ClipInputs:
    """A clip's inputs, read and checked (:mod:`aias_augment.cli.clip_inputs`) before anything is written."""

    frames: list[np.ndarray]
    names: list[str]
    idx: np.ndarray  # index in the input of each frame used
    intrinsics: Intrinsics | None  # --camera's, checked against the frame size
    poses: np.ndarray | None  # (N, 4, 4) cam_from_world of the frames used, from --poses
    labels: list[list] | None = None  # per frame its labelled boxes (core.track_labels.TrackBox), from --labels
    labels_outside: int = 0  # labelled boxes in input frames the clip does not use

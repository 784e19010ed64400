"""Offline augmentation of one posed clip: ``aias-augment --input clip.mp4 --camera calib --poses poses.txt``.

The clip path of the paper: one object pose in the WORLD for the whole clip (:func:`aias_augment.pipeline.clip.
insert_into_clip`), one sun fused over the clip's frames in world coordinates (:func:`aias_augment.analyse.lighting.
estimate_lighting_clip`), every frame rendered through its own K [R | t]. Inputs (read and checked before anything is
written, :mod:`aias_augment.cli.clip_inputs`):

* frames: a video file (anything OpenCV decodes) or a folder of images (sorted by name);
* camera: a KITTI ``calib.txt`` (P0, or P2 with ``colour``), a pyslam/OpenCV ``KITTI*.yaml`` (``Camera.fx`` ...), or
  a plain YAML ``{fx, fy, cx, cy}``;
* poses: KITTI lines (12 numbers, world_from_cam, row-major 3x4) or TUM-style lines (``tx ty tz qx qy qz qw``, with
  or without a leading timestamp); one per frame of the clip (after ``start`` and ``stride``).
* ground: the camera ``camera_height_m`` above level ground (vehicle rigs), the same camera-relative plane for every
  frame (see ``choose_world_contact``).
* labels (optional): the clip's own tracks, a MOTChallenge ``gt.txt`` or a COCO-video json
  (:mod:`aias_augment.core.track_labels`); they go into the output with their track ids (the inserted objects take
  the ids after theirs), hide the inserted objects behind them (:mod:`aias_augment.pipeline.clip_occluders`), and
  carry their visibility under the inserted objects in front of them.

Outputs in ``out``: ``frames/NNNNNN.jpg`` (augmented), ``annotations.json`` (COCO-video: ``videos``, each image's
``video_id`` and ``frame_id``, one ``track_id`` per inserted object with its visible mask as RLE and its amodal box,
the labelled tracks beside them; validated by pycocotools; :mod:`aias_augment.cli.clip_annotations`), ``mot.txt``
(MOTChallenge: frame, id, bb_left, bb_top, w, h, conf, -1, -1, -1, frames and pixels from 1),
``record.json`` (everything needed to replay: seed, asset, world pose, contact, modules used), ``side_by_side.mp4``
(original | augmented with boxes), ``contact_sheet.jpg`` and ``manifest.json`` (the run key and the files, complete
only after the last write; :mod:`aias_augment.cli.clip_output`). Every file is written atomically; a complete clip of
the same run is not redone; a clip in which no object is ever visible writes nothing and is an error.
"""

from __future__ import annotations

import dataclasses
import json
import logging
import math
import os
import sys
import time
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from aias_augment.analyse.ground import prior_ground_plane
from aias_augment.cli.clip_inputs import (
    IMAGE_SUFFIXES,
    VIDEO_SUFFIXES,
    check_pose_count,
    clip_frame_files,
    is_video_input,
    read_camera,
    read_cams_from_world,
    read_clip_frames,
    read_clip_labels,
)
from aias_augment.cli.clip_output import ClipInput, ClipOutput, clip_manifest, files_hash
from aias_augment.cli.manifest import ManifestMismatch, check_out_apart, file_hash, output_lock
from aias_augment.core.errors import AiasError
from aias_augment.core.geometry import CAMERA_HEIGHT_PRIOR_M, Intrinsics
from aias_augment.core.report import skipped, skipped_stages
from aias_augment.core.viz import contact_sheet, draw_boxes

__all__ = [
    "IMAGE_SUFFIXES",
    "VIDEO_SUFFIXES",
    "ClipJob",
    "ClipNotVisible",
    "augment_clip",
    "clip_command",
    "is_video_input",
    "read_camera",
    "read_cams_from_world",
    "read_clip_frames",
]

log = logging.getLogger(__name__)

#: Draws of one object's plan before it is left out for meeting an object already placed in the clip.
COLLISION_ATTEMPTS = 8
COLLISION_STEP_M = 0.5
#: Highest camera the clip command accepts (a mast or a roof; above it an object on the ground is a few pixels).
MAX_CAMERA_HEIGHT_M = 100.0


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
        if self.lighting not in ("clip", "ambient"):
            raise ValueError(f"lighting must be 'clip' or 'ambient', got {self.lighting!r}")
        if self.stride < 1 or self.start < 0 or (self.max_frames is not None and self.max_frames < 1):
            raise ValueError("need stride >= 1, start >= 0 and max_frames >= 1")
        if not self.categories:
            raise ValueError("at least one category")
        from aias_augment.apply.harmonize import METHODS

        if self.harmonize not in METHODS:
            raise ValueError(f"harmonize must be one of {METHODS}, got {self.harmonize!r}")
        from aias_augment.pipeline.config import PRESETS

        if self.preset not in PRESETS:
            raise ValueError(f"preset must be one of {PRESETS}, got {self.preset!r}")
        if not (np.isfinite(self.lateral_offset_m) and np.isfinite(self.ahead_m)):
            raise ValueError(
                f"lateral_offset_m and ahead_m must be finite, got {self.lateral_offset_m}, {self.ahead_m}"
            )
        if not (np.isfinite(self.fps) and self.fps > 0 and np.isfinite(self.object_speed_mps)):
            raise ValueError(f"need fps > 0 and a finite object speed, got {self.fps}, {self.object_speed_mps}")
        if self.object_speed_mps != 0 and self.flow_refine:
            raise ValueError("--flow-refine tracks the ground under a standing object: not with --object-speed")
        if self.objects < 1:
            raise ValueError(f"objects must be >= 1, got {self.objects}")
        if self.stereo_right is not None and (self.poses is not None or self.camera is None):
            raise ValueError("stereo_right estimates the poses: it needs a camera and no poses")
        if not all(np.isfinite(v) and v >= 0 for v in (self.object_start_s, self.object_accel_s)):
            raise ValueError(
                f"object_start_s and object_accel_s must be >= 0, got {self.object_start_s}, {self.object_accel_s}"
            )
        if (self.object_start_s or self.object_accel_s) and not self.object_speed_mps:
            raise ValueError("--object-start and --object-accel need --object-speed")
        if not (np.isfinite(self.topple_s) and self.topple_s >= 0):
            raise ValueError(f"topple_s must be >= 0 seconds, got {self.topple_s}")
        if self.topple_s and (self.object_speed_mps or self.flow_refine):
            raise ValueError(
                "--topple: a toppling object stands where it falls, not with --object-speed or --flow-refine"
            )
        from aias_augment.core.track_labels import FORMATS

        if self.labels_format is not None and self.labels_format not in FORMATS:
            raise ValueError(f"--labels-format must be one of {', '.join(FORMATS)}, got {self.labels_format!r}")
        if self.labels is None and (self.labels_format is not None or self.labels_category != "object"):
            raise ValueError("--labels-format and --labels-category need --labels (the clip's label file)")
        if not self.labels_category.strip():
            raise ValueError("--labels-category must name a class")
        if not (np.isfinite(self.camera_height_m) and 0 < self.camera_height_m <= MAX_CAMERA_HEIGHT_M):
            raise ValueError(
                f"camera_height_m (--camera-height) must be in (0, {MAX_CAMERA_HEIGHT_M:g}] metres above the ground, "
                f"got {self.camera_height_m:g}"
            )


# ------------------------------------------------------------------------------------------------------------- run
class ClipNotVisible(AiasError, RuntimeError):
    """No inserted object is visible in any frame of the clip: nothing was written."""


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


@dataclass
class RenderedClip:
    frames: list[np.ndarray]  # augmented
    intrinsics: Intrinsics
    objects: list  # (category, asset) of each placed object
    results: list  # ClipResult of each placed object
    plans: list
    placed_params: list
    draws: list[int]
    skipped_objects: list[dict]
    notes: dict
    layer_params: list
    labels_visibility: list | None = None  # per frame, each labelled box's fraction left uncovered
    occluders: dict | None = None  # how the labelled objects' masks were made
    sun: dict | None = None  # the clip's sun decision (:func:`clip_sun`); None: ambient light requested or failed


CLIP_FILES = ("annotations.json", "mot.txt", "side_by_side.mp4", "contact_sheet.jpg", "record.json")
_PATH_FIELDS = ("input", "camera", "poses", "stereo_right", "labels")


def _job_dict(job: ClipJob) -> dict:
    return json.loads(json.dumps(dataclasses.asdict(job)))


def read_clip_inputs(job: ClipJob) -> ClipInputs:
    """Frames, camera and poses of ``job``, every problem an :class:`InputError` (cheapest checks first)."""
    all_poses = None if job.poses is None else read_cams_from_world(job.poses)
    frames, names = read_clip_frames(job.input, job.start, job.max_frames, job.stride)
    h, w = frames[0].shape[:2]
    idx = np.arange(job.start, job.start + job.stride * len(frames), job.stride)
    intr = None if job.camera is None else read_camera(job.camera, w, h, colour=job.colour)
    poses = None
    if all_poses is not None:
        check_pose_count(len(all_poses), int(idx[-1]), job.poses, job.input)
        poses = all_poses[idx]
    inputs = ClipInputs(frames, names, idx, intr, poses)
    if job.labels is not None:
        inputs.labels, inputs.labels_outside = read_clip_labels(
            job.labels, job.labels_format, names, idx, job.labels_category
        )
    return inputs


def clip_run_manifest(job: ClipJob, names: list[str]) -> dict:
    """The manifest of ``job``: what decides its output (options, inputs' content hashes) and the files it writes."""
    inputs = []
    for field in _PATH_FIELDS:
        path = getattr(job, field)
        if path is None:
            continue
        p = Path(path)
        sha = files_hash(clip_frame_files(p, job.start, job.max_frames, job.stride)) if p.is_dir() else file_hash(p)
        inputs.append(ClipInput(field, os.path.abspath(p), sha))
    options = {k: v for k, v in _job_dict(job).items() if k not in (*_PATH_FIELDS, "out", "seed", "preset")}
    labels = None if job.labels is None else ""  # its content is hashed in the inputs
    blank = dataclasses.replace(
        job, out="", input="", camera=None, poses=None, stereo_right=None, labels=labels, seed=0
    )
    files = [f"frames/{n}.jpg" for n in names] + list(CLIP_FILES)
    return clip_manifest(blank, job.seed, job.preset, options, inputs, files)


def augment_clip(job: ClipJob, *, overwrite: bool = False) -> dict:
    """Insert ``job.objects`` objects of ``job.categories`` (drawn with the seed) into the clip, each with its own
    track; returns the record (with ``wall_s``, this call's seconds).

    Every input is read and checked before the output folder is touched (:class:`InputError`); a folder holding
    another run is refused (:class:`ManifestMismatch`) unless ``overwrite``; a clip in which no object is ever
    visible raises :class:`ClipNotVisible` before anything is written. See :mod:`aias_augment.cli.clip_output`."""
    t0 = time.perf_counter()
    check_out_apart(job.out, [(_flag(f), getattr(job, f)) for f in _PATH_FIELDS])
    inputs = read_clip_inputs(job)
    out = Path(job.out)
    output = ClipOutput(out, clip_run_manifest(job, inputs.names))
    with output_lock(out):
        if output.done():
            log.info("%s: already done with the same inputs and arguments, nothing to do", out)
            record = json.loads((out / "record.json").read_text())
            return {**record, "wall_s": round(time.perf_counter() - t0, 1)}
        clip = render_clip(job, inputs)
        if not any(b is not None for r in clip.results for b in r.boxes_xywh):
            raise ClipNotVisible(_never_visible(job, inputs, clip))
        for k, r in enumerate(clip.results):
            if all(b is None for b in r.boxes_xywh):
                log.warning("%s: object %d (%s) is visible in no frame", job.input, k + 1, clip.objects[k][0])
        output.begin(overwrite)
        record = write_clip(output, job, inputs, clip)
        output.complete()
    wall_s = round(time.perf_counter() - t0, 1)
    log.info("%s: %d frames, object visible in %d, %.1fs", out, len(inputs.frames), record["visible_frames"], wall_s)
    return {**record, "wall_s": wall_s}


def _flag(field: str) -> str:
    return f"--{field.replace('_', '-')}"


def _never_visible(job: ClipJob, inputs: ClipInputs, clip: RenderedClip) -> str:
    contact = np.append(clip.results[0].contact_in_world, 1.0)
    cams = inputs.poses if inputs.poses is not None else np.eye(4)[None]
    depth = [float((cam @ contact)[2]) for cam in (cams[0], cams[-1])]
    return (
        f"{job.input}: the inserted {clip.objects[0][0]} is visible in none of the {len(inputs.frames)} frames (its "
        f"contact is {depth[0]:.1f} m in front of the first camera, {depth[1]:.1f} m of the last); nothing written to "
        f"{job.out}; check that --poses are this clip's, --camera's K and --camera-height {job.camera_height_m:g}"
    )


def render_clip(job: ClipJob, inputs: ClipInputs) -> RenderedClip:
    """Camera and poses, lighting, plans and the augmented frames of ``job`` (nothing written)."""
    from aias_augment.analyse.lighting.estimate import estimate_lighting_clip
    from aias_augment.core.stages import draw_layer_params
    from aias_augment.cli.clip_cameras import monocular_odometry_clip, static_camera_clip, stereo_odometry_clip
    from aias_augment.pipeline.clip import VideoInsertionConfig, apply_clip_objects
    from aias_augment.pipeline.config import InsertionConfig, load_preset
    from aias_augment.plan.insertion import choose_asset

    frames = inputs.frames
    moving = True  # a camera that goes somewhere: the object stands beside where it will be
    if job.stereo_right is not None:
        intr, poses, camera_note = stereo_odometry_clip(frames, job)
        ground0 = prior_ground_plane(job.camera_height_m)
    elif job.poses is None:
        from aias_augment.scenes.video import static_camera_check

        check = static_camera_check(frames)
        moving = not check.static
        if moving:
            intr, poses, camera_note = monocular_odometry_clip(frames, job, check)
            ground0 = prior_ground_plane(job.camera_height_m)
        else:
            intr, poses, ground0, camera_note = static_camera_clip(frames, job)
    else:
        intr, poses = inputs.intrinsics, inputs.poses
        ground0, camera_note = prior_ground_plane(job.camera_height_m), "given camera and poses"
    rng = np.random.default_rng([job.seed, 0])
    preset = load_preset(job.preset)
    category = job.categories[int(rng.integers(len(job.categories)))]
    # the preset's asset source, as the image door draws (procedural: one seeded family member per object)
    asset = choose_asset(category, rng, InsertionConfig(categories=(category,), asset_source=preset.asset_source))
    lighting, lighting_note = None, "ambient (requested)"
    if job.lighting == "clip":
        try:  # the image door's lighting config and sun decision, at the clip's camera height
            height = ground0.camera_height_m
            height = height if np.isfinite(height) and height > 0 else job.camera_height_m
            lcfg = dataclasses.replace(preset.lighting_cfg, camera_height_m=float(height))
            lighting = estimate_lighting_clip(frames, intr, poses, rng=rng.spawn(1)[0], config=lcfg)
            sun = lighting[0]
            lighting_note = f"one sun fused over {len(frames)} frames ({sun.source}): " + (
                f"sun decided (confidence {sun.confidence:.2f}), cast shadows"
                if sun.dominant_sun
                else "no dominant sun, ambient light and contact shadows only"
            )
        except (ValueError, np.linalg.LinAlgError) as e:  # a clip the estimator cannot read: ambient, said why
            log.warning("clip lighting failed (%s): ambient light only", e)
            lighting_note = skipped(str(e))
    last = len(frames) - 1
    # each object's layer stages from generators of their own: rng untouched
    layer_params = draw_layer_params(preset, job.seed, job.objects)
    cfg = VideoInsertionConfig(
        lookahead_frames=last if job.lookahead_frames is None else min(job.lookahead_frames, last),
        lateral_offset_m=job.lateral_offset_m,
        ahead_m=job.ahead_m,
        contact="lookahead" if moving else "sampled",  # a static camera goes nowhere: a seen ground
        flow_refine=job.flow_refine,
        speed_m_per_frame=job.object_speed_mps / job.fps,
        move_after_frames=round(job.object_start_s * job.fps),
        accelerate_frames=round(job.object_accel_s * job.fps),
        topple_frames=max(1, round(job.topple_s * job.fps)) if job.topple_s else 0,
        stages=preset,
    )

    placed = plan_clip_objects(job, frames, intr, poses, rng, cfg, ground0, lighting, layer_params, (category, asset))
    occluders = None
    if inputs.labels is not None:
        from aias_augment.pipeline.clip_occluders import occluder_depths

        occluders = occluder_depths(frames, intr, placed["plans"], inputs.labels)
    results = apply_clip_objects(frames, intr, placed["plans"], cfg, None if occluders is None else occluders.depths)
    out_frames, harmonize_note = _harmonize(job, results[0].frames, results, len(frames), rng)
    # A grey clip (KITTI image_0/image_l) stays grey: an orange cone in a grey frame would be a give-away.
    grey = all(np.array_equal(f[..., 0], f[..., 1]) and np.array_equal(f[..., 1], f[..., 2]) for f in frames)
    if grey:
        out_frames = [np.repeat(cv2.cvtColor(f, cv2.COLOR_RGB2GRAY)[..., None], 3, axis=2) for f in out_frames]
    notes = {
        **results[0].modules,
        "camera": camera_note,
        "lighting": lighting_note,
        "harmonize": harmonize_note,
        "colour": "grey clip: output converted to grey" if grey else "colour clip",
    }
    clip = RenderedClip(out_frames, intr, results=results, notes=notes, layer_params=layer_params, **placed)
    clip.sun = None if lighting is None else clip_sun(lighting[0], poses[0])
    if occluders is not None:
        from aias_augment.pipeline.clip_occluders import labelled_visibility

        object_z = [  # each inserted object's contact z per frame (its origin stands on its contact)
            [None if p.cams_from_object[i] is None else float(p.cams_from_object[i][2, 3]) for p in placed["plans"]]
            for i in range(len(frames))
        ]
        clip.labels_visibility = [
            labelled_visibility(boxes, occluders.contact_z[i], [r.masks[i] for r in results], object_z[i]).tolist()
            for i, boxes in enumerate(inputs.labels)
        ]
        clip.occluders = {"grabcut_masks": occluders.grabcut, "whole_box_masks": occluders.whole_box}
    return clip


def clip_sun(light, cam_from_world: np.ndarray) -> dict:
    """The clip's sun decision as the record keeps it: decided or not, its confidence and source, the direction
    towards the sun in the world (None without a sun)."""
    d = light.sun_direction_in_cam
    return {
        "dominant_sun": bool(light.dominant_sun),
        "confidence": round(float(light.confidence), 4),
        "source": light.source,
        "direction_in_world": None if d is None else (np.asarray(cam_from_world)[:3, :3].T @ d).round(6).tolist(),
    }


def plan_clip_objects(job, frames, intr, poses, rng, cfg, ground0, lighting, layer_params, first) -> dict:
    """Plans of ``job.objects`` objects, the first ``first`` = (category, asset); objects share the world: a plan
    whose box meets a placed object's in any frame is redrawn (a new yaw, a new sampled pixel, or COLLISION_STEP_M
    further from the path), and after COLLISION_ATTEMPTS it is left out."""
    from aias_augment.pipeline.clip import first_collision, plan_clip
    from aias_augment.pipeline.config import InsertionConfig
    from aias_augment.plan.insertion import choose_asset

    def plan(c, asset, params):
        return plan_clip(
            frames, intr, poses, rng, c, asset=asset, ground_in_cam0=ground0, lighting=lighting, layer_params=params
        )

    objects, placed_params, draws = [first], [layer_params[0]], [1]
    plans = [plan(cfg, first[1], layer_params[0])]
    skipped_objects = []
    for k in range(1, job.objects):
        cat_k = job.categories[int(rng.integers(len(job.categories)))]
        source = (cfg.stages or InsertionConfig()).asset_source  # the image door's asset source
        asset_k = choose_asset(cat_k, rng, InsertionConfig(categories=(cat_k,), asset_source=source))
        for attempt in range(COLLISION_ATTEMPTS):
            cfg_k = dataclasses.replace(
                cfg,
                lookahead_frames=round(cfg.lookahead_frames * (job.objects - k) / job.objects),
                lateral_offset_m=(-1) ** k
                * math.copysign(abs(cfg.lateral_offset_m) + COLLISION_STEP_M * attempt, cfg.lateral_offset_m),
            )
            plan_k = plan(cfg_k, asset_k, layer_params[k])
            hits = [(j, first_collision(plan_k, p)) for j, p in enumerate(plans)]
            hit = next(((j, f) for j, f in hits if f is not None), None)
            if hit is None:
                break
        if hit is not None:
            why = f"meets object {hit[0] + 1} in frame {hit[1]} in all {COLLISION_ATTEMPTS} draws"
            log.warning("%s: object %d left out: %s", job.input, k + 1, why)
            skipped_objects.append({"object": k + 1, "category": cat_k, "reason": why})
            continue
        objects.append((cat_k, asset_k))
        plans.append(plan_k)
        placed_params.append(layer_params[k])
        draws.append(attempt + 1)
    return {
        "objects": objects,
        "plans": plans,
        "placed_params": placed_params,
        "draws": draws,
        "skipped_objects": skipped_objects,
    }


def _harmonize(job: ClipJob, frames: list[np.ndarray], results, n: int, rng) -> tuple[list[np.ndarray], str]:
    if job.harmonize == "none":
        return frames, skipped("--harmonize none")
    from aias_augment.apply.harmonize import harmonize_clip

    union = [
        None
        if all(r.masks[i] is None for r in results)
        else np.maximum.reduce([r.masks[i] for r in results if r.masks[i] is not None])
        for i in range(n)
    ]
    note = (
        f"{job.harmonize}: one colour transform for the clip (median of the per-frame predictions)"
        if job.harmonize == "fast"
        else f"{job.harmonize}, frame by frame"
    )
    return harmonize_clip(frames, union, job.harmonize, rng.spawn(1)[0]), note


def write_clip(output: ClipOutput, job: ClipJob, inputs: ClipInputs, clip: RenderedClip) -> dict:
    """Write the frames, the COCO-video and MOT annotations, the side-by-side video, the contact sheet and the
    record through ``output`` (each file atomically); returns the record."""
    from aias_augment.cli.clip_annotations import clip_annotations, inserted_track_offset
    from aias_augment.core.coco_io import load_coco

    names, idx, intr = inputs.names, inputs.idx, clip.intrinsics
    h, w = inputs.frames[0].shape[:2]
    video = {"name": Path(job.input).name, "width": w, "height": h, "fps": job.fps}
    cats = [c for c, _ in clip.objects]
    ann = clip_annotations(video, names, idx, clip.results, cats, inputs.labels, clip.labels_visibility)
    drawn = []
    for i, (name, img) in enumerate(zip(names, clip.frames)):
        output.write_image(f"frames/{name}.jpg", img)
        drawn.append(draw_boxes(img, ann.boxes[i], ann.labels[i], inserted=ann.inserted[i]))
    output.write_json("annotations.json", ann.coco, check=load_coco)  # pycocotools validates
    output.write_bytes("mot.txt", "".join(line + "\n" for line in ann.mot_lines).encode())
    output.write_with("side_by_side.mp4", lambda p: _write_side_by_side(p, inputs.frames, drawn, job.fps))
    picks = np.unique(np.linspace(0, len(drawn) - 1, min(6, len(drawn))).astype(int))
    output.write_image(
        "contact_sheet.jpg", contact_sheet([drawn[i] for i in picks], cols=3, titles=[names[i] for i in picks])
    )
    res = clip.results[0]
    offset = inserted_track_offset(inputs.labels)
    record = {
        "job": {k: v for k, v in _job_dict(job).items() if k != "out"},  # the folder may move: not part of it
        "category": clip.objects[0][0],
        "asset": clip.objects[0][1].name,
        "asset_source": clip.objects[0][1].source,
        "asset_height_m": float(clip.objects[0][1].height_m),
        "frames": len(names),
        "frame_indices": idx.tolist(),
        "intrinsics": [intr.fx, intr.fy, intr.cx, intr.cy, w, h],
        "world_from_object": res.world_from_object.tolist(),
        "contact_in_world": res.contact_in_world.tolist(),
        "layer_params": clip.layer_params[0],
        "visible_frames": int(sum(b is not None for b in res.boxes_xywh)),
        "objects": [
            {
                "track_id": offset + k + 1,
                "category": cat,
                "asset": a.name,
                "asset_source": a.source,  # procedural: asset_meta["seed"] rebuilds the family member
                "asset_meta": a.meta,
                "asset_height_m": float(a.height_m),
                "world_from_object": r.world_from_object.tolist(),
                "contact_in_world": r.contact_in_world.tolist(),
                "layer_params": clip.placed_params[k],
                "draws": clip.draws[k],
                "topple": clip.plans[k].topple,
                "visible_frames": int(sum(b is not None for b in r.boxes_xywh)),
            }
            for k, ((cat, a), r) in enumerate(zip(clip.objects, clip.results))
        ],
        "skipped_objects": clip.skipped_objects,
        **({} if inputs.labels is None else {"labels": _labels_record(job, inputs, clip)}),
        **({} if clip.sun is None else {"sun": clip.sun}),
        "modules": clip.notes,
        "skipped_stages": skipped_stages(clip.notes),
    }
    output.write_json("record.json", record)
    return record


def _labels_record(job: ClipJob, inputs: ClipInputs, clip: RenderedClip) -> dict:
    from aias_augment.cli.clip_annotations import visibility_table
    from aias_augment.core.track_labels import detect_format

    return {
        "format": job.labels_format or detect_format(job.labels),
        "boxes": sum(len(b) for b in inputs.labels),
        "outside_clip": inputs.labels_outside,
        "occluder_masks": clip.occluders,
        "tracks": visibility_table(inputs.labels, clip.labels_visibility),
    }


def clip_command(a) -> int:
    """``aias-augment`` on a clip (parsed arguments ``a``): 0 done, 1 no object visible, 2 a bad input or
    ``--out``; every error one line on stderr."""
    try:
        job = ClipJob(
            a.input,
            a.camera,
            a.poses,
            a.out,
            tuple(a.categories or ["traffic_cone"]),
            a.seed,
            a.start,
            a.max_frames,
            a.stride,
            a.colour,
            a.camera_height,
            lighting=a.lighting,
            flow_refine=a.flow_refine,
            harmonize=a.harmonize,
            preset=a.preset,
            fps=a.fps,
            object_speed_mps=a.object_speed,
            topple_s=a.topple,
            stereo_right=a.stereo_right,
            object_start_s=a.object_start,
            object_accel_s=a.object_accel,
            objects=a.objects,
            labels=a.labels,
            labels_format=a.labels_format,
            labels_category=a.labels_category,
        )
        record = augment_clip(job, overwrite=a.overwrite)
    except ClipNotVisible as e:
        return _fail(e, 1)
    except (ValueError, ManifestMismatch) as e:  # InputError is a ValueError; OutputBusy a ManifestMismatch
        log.debug("clip refused", exc_info=True)
        return _fail(e, 2)
    except OSError as e:  # an unwritable or full --out, a path through a file
        where = f" ({e.filename})" if e.filename else ""
        return _fail(f"{e.strerror or e}{where}: check that --out is a writable folder with free space", 2)
    print({k: record[k] for k in ("category", "asset", "frames", "visible_frames", "wall_s")})
    return 0


def _fail(e, code: int) -> int:
    print("aias-augment: error: " + " ".join(str(e).split()), file=sys.stderr)
    return code


def _write_side_by_side(path: Path, originals: list[np.ndarray], augmented: list[np.ndarray], fps: float) -> None:
    """Original | augmented, one row per frame, as an mp4."""
    h, w = originals[0].shape[:2]
    scale = min(1.0, 960 / (2 * w))
    size = (int(2 * w * scale) // 2 * 2, int(h * scale) // 2 * 2)
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"mp4v"), fps, size)
    if not writer.isOpened():
        raise OSError(f"cannot open a video writer for {path}")
    try:
        for a, b in zip(originals, augmented):
            pair = cv2.resize(np.concatenate([a, b], 1), size, interpolation=cv2.INTER_AREA)
            writer.write(np.ascontiguousarray(pair[..., ::-1]))
    finally:
        writer.release()

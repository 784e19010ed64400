"""The clip door: several objects into one posed clip, each its own track, planned together so they never meet.

:func:`insert_objects_into_clip` takes the frames, one K, the per-frame ``cam_from_world`` and the ground of the
first frame in its camera (arrays, no files: the CLI ``aias-augment --input clip.mp4 ...`` reads them and writes the
outputs, :mod:`aias_augment.cli.clip`) and returns the augmented frames with every object's plan and per-frame
boxes and masks (:class:`RenderedClip`):

1. one sun fused over the clip's frames in world coordinates (:func:`aias_augment.analyse.lighting.estimate.
   estimate_lighting_clip`, the image door's lighting config at the clip's camera height), or a grey-world ambient;
2. per object a plan (:func:`aias_augment.pipeline.clip.plan_clip`: one world pose, its motion, its layer stages);
   objects share the world: a plan whose box meets a placed object's in any frame is redrawn (a new yaw, a new sampled
   pixel, or :data:`COLLISION_STEP_M` further from the path), and after :data:`COLLISION_ATTEMPTS` it is left out;
3. the clip's labelled tracks (optional) become depth maps that hide the objects behind them
   (:mod:`aias_augment.pipeline.clip_occluders`), and carry their visibility under the objects in front of them;
4. every frame through the image door's stages (:func:`aias_augment.pipeline.clip.apply_clip_objects`), one
   harmonization for the clip (:func:`aias_augment.apply.harmonize.harmonize_clip`), and a grey clip (KITTI
   ``image_0``) made grey again: an orange cone in a grey frame would give itself away.

Every draw comes from the request's seed: the plan from ``default_rng([seed, 0])``, each object's layer stages from
generators of their own (:func:`aias_augment.core.stages.draw_layer_params`).
"""

from __future__ import annotations

import dataclasses
import logging
import math
from dataclasses import dataclass, field

import cv2
import numpy as np

from aias_augment.core.geometry import CAMERA_HEIGHT_PRIOR_M, Intrinsics
from aias_augment.core.report import skipped

__all__ = [
    "COLLISION_ATTEMPTS",
    "COLLISION_STEP_M",
    "MAX_CAMERA_HEIGHT_M",
    "ClipRequest",
    "RenderedClip",
    "clip_sun",
    "insert_objects_into_clip",
    "plan_clip_objects",
]

log = logging.getLogger("aias_augment.cli.clip")  # the clip command's logger: one place to filter its warnings

#: Draws of one object's plan before it is left out for meeting an object already placed in the clip.
COLLISION_ATTEMPTS = 8
COLLISION_STEP_M = 0.5
#: Highest camera the clip door accepts (a mast or a roof; above it an object on the ground is a few pixels).
MAX_CAMERA_HEIGHT_M = 100.0


@dataclass(frozen=True)
class ClipRequest:
    """What to insert into a clip and how (the clip CLI's ``ClipJob`` without its files); checked when built."""

    categories: tuple[str, ...] = ("traffic_cone",)
    seed: int = 0
    camera_height_m: float = CAMERA_HEIGHT_PRIOR_M
    lookahead_frames: int | None = None  # the object stands beside where the camera is at this frame; None: the last
    lateral_offset_m: float = 2.5
    ahead_m: float = 0.0  # ... and this far ahead of that camera (a short clip: the object and its shadow in view)
    lighting: str = "clip"  # "clip": one sun fused over the clip; "ambient": grey-world ambient only
    flow_refine: bool = False  # KLT stabilisation of the contact (for drifting poses)
    harmonize: str = "fast"  # harmonize.METHODS; "fast": one colour transform for the clip (median over frames)
    preset: str = "balanced"  # the image door's preset whose layer stages (e.g. motion blur) the object gets
    fps: float = 10.0  # frames per second of the clip: the clock of the object's speed
    object_speed_mps: float = 0.0  # the object moves along its heading at this speed (0: it stands)
    # ... after standing this long (seconds), reaching that speed from rest over object_accel_s (a car pulling out)
    object_start_s: float = 0.0
    object_accel_s: float = 0.0
    topple_s: float = 0.0  # each object is knocked over during the clip, falling for this long (0: it stays upright)
    # Objects in the clip, each its own track: object k > 0 stands on the other side of the path from object k - 1
    # and nearer (lookahead scaled by (n - k) / n); on a static camera each stands on its own sampled ground pixel.
    objects: int = 1
    name: str = "clip"  # what log lines call the clip (the CLI: its input path)

    def __post_init__(self):
        from aias_augment.apply.harmonize import METHODS
        from aias_augment.pipeline.config import PRESETS

        if self.lighting not in ("clip", "ambient"):
            raise ValueError(f"lighting must be 'clip' or 'ambient', got {self.lighting!r}")
        if not self.categories:
            raise ValueError("at least one category")
        if self.harmonize not in METHODS:
            raise ValueError(f"harmonize must be one of {METHODS}, got {self.harmonize!r}")
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
        self._check_motion()
        if not (np.isfinite(self.camera_height_m) and 0 < self.camera_height_m <= MAX_CAMERA_HEIGHT_M):
            raise ValueError(
                f"camera_height_m (--camera-height) must be in (0, {MAX_CAMERA_HEIGHT_M:g}] metres above the ground, "
                f"got {self.camera_height_m:g}"
            )

    def _check_motion(self) -> None:
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


@dataclass
class RenderedClip:
    frames: list[np.ndarray]  # augmented
    intrinsics: Intrinsics
    objects: list  # (category, asset) of each placed object
    results: list  # ClipInsertion of each placed object
    plans: list
    placed_params: list
    draws: list[int]
    skipped_objects: list[dict]
    notes: dict
    layer_params: list
    labels_visibility: list | None = None  # per frame, each labelled box's fraction left uncovered
    occluders: dict | None = None  # how the labelled objects' masks were made
    sun: dict | None = None  # the clip's sun decision (:func:`clip_sun`); None: ambient light requested or failed
    frame_params: dict = field(default_factory=dict)  # the frame stages' parameters (aias_augment.core.stages)


def insert_objects_into_clip(
    frames: list[np.ndarray],
    intrinsics: Intrinsics,
    cams_from_world: np.ndarray,
    ground_in_cam0,
    request: ClipRequest = ClipRequest(),
    *,
    moving: bool = True,
    camera_note: str = "given camera and poses",
    labels: list[list] | None = None,
) -> RenderedClip:
    """``request.objects`` objects of ``request.categories`` into the clip (see the module docstring).

    frames: N (H, W, 3) uint8 RGB. cams_from_world: (N, 4, 4) OpenCV ``cam_from_world``. ground_in_cam0: the ground
    of the first frame in its camera (camera-relative for every frame of a moving camera). moving: False for a static
    camera (each object on a sampled ground pixel instead of beside the path). camera_note: where K and the poses
    came from, kept in the notes. labels: per frame the clip's labelled boxes (:class:`aias_augment.core.
    track_labels.TrackBox`) or None."""
    from aias_augment.core.stages import apply_frame_stages, draw_frame_params, draw_layer_params
    from aias_augment.pipeline.clip import apply_clip_objects
    from aias_augment.pipeline.config import InsertionConfig, load_preset
    from aias_augment.plan.insertion import choose_asset

    rng = np.random.default_rng([request.seed, 0])
    preset = load_preset(request.preset)
    category = request.categories[int(rng.integers(len(request.categories)))]
    # the preset's asset source, as the image door draws (procedural: one seeded family member per object)
    asset = choose_asset(category, rng, InsertionConfig(categories=(category,), asset_source=preset.asset_source))
    lighting, lighting_note = _clip_lighting(frames, intrinsics, cams_from_world, ground_in_cam0, preset, request)
    # each object's layer stages from generators of their own: rng untouched
    layer_params = draw_layer_params(preset, request.seed, request.objects)
    frame_params = draw_frame_params(preset, request.seed)  # the clip's frame stages: one draw for all its frames
    cfg = _video_config(request, len(frames), moving, preset)
    placed = plan_clip_objects(
        request,
        frames,
        intrinsics,
        cams_from_world,
        rng,
        cfg,
        ground_in_cam0,
        lighting,
        layer_params,
        (category, asset),
    )
    occluders = None
    if labels is not None:
        from aias_augment.pipeline.clip_occluders import occluder_depths

        occluders = occluder_depths(frames, intrinsics, placed["plans"], labels)
    depths = None if occluders is None else occluders.depths
    results = apply_clip_objects(frames, intrinsics, placed["plans"], cfg, depths)
    out_frames, harmonize_note = _harmonize(request.harmonize, results[0].frames, results, len(frames), rng)
    out_frames = [apply_frame_stages(f, frame_params) for f in out_frames]  # after the harmonizer, as in an image
    grey = is_grey_clip(frames)
    if grey:
        out_frames = [np.repeat(cv2.cvtColor(f, cv2.COLOR_RGB2GRAY)[..., None], 3, axis=2) for f in out_frames]
    notes = {
        **results[0].modules,
        "camera": camera_note,
        "lighting": lighting_note,
        "harmonize": harmonize_note,
        "colour": "grey clip: output converted to grey" if grey else "colour clip",
    }
    clip = RenderedClip(out_frames, intrinsics, results=results, notes=notes, layer_params=layer_params, **placed)
    clip.frame_params = frame_params
    clip.sun = None if lighting is None else clip_sun(lighting[0], cams_from_world[0])
    if occluders is not None:
        clip.labels_visibility = _labels_visibility(labels, occluders, placed["plans"], results)
        clip.occluders = {"grabcut_masks": occluders.grabcut, "whole_box_masks": occluders.whole_box}
    return clip


def is_grey_clip(frames) -> bool:
    """Every frame's three channels equal (a grey camera's frames read as RGB)."""
    return all(np.array_equal(f[..., 0], f[..., 1]) and np.array_equal(f[..., 1], f[..., 2]) for f in frames)


def _clip_lighting(frames, intr, poses, ground0, preset, request: ClipRequest):
    """(per-frame lighting or None, its note): one sun fused over the clip with the image door's lighting config at
    the clip's camera height, or ambient when asked for or when the estimator cannot read the clip (said why)."""
    from aias_augment.analyse.lighting.estimate import estimate_lighting_clip

    if request.lighting != "clip":
        return None, "ambient (requested)"
    try:
        height = ground0.camera_height_m
        height = height if np.isfinite(height) and height > 0 else request.camera_height_m
        lcfg = dataclasses.replace(preset.lighting_cfg, camera_height_m=float(height))
        lighting = estimate_lighting_clip(frames, intr, poses, config=lcfg)
    except (ValueError, np.linalg.LinAlgError) as e:  # a clip the estimator cannot read: ambient, said why
        log.warning("clip lighting failed (%s): ambient light only", e)
        return None, skipped(str(e))
    sun = lighting[0]
    note = f"one sun fused over {len(frames)} frames ({sun.source}): " + (
        f"sun decided (confidence {sun.confidence:.2f}), cast shadows"
        if sun.dominant_sun
        else "no dominant sun, ambient light and contact shadows only"
    )
    return lighting, note


def _video_config(request: ClipRequest, n: int, moving: bool, preset):
    from aias_augment.pipeline.clip import VideoInsertionConfig

    last = n - 1
    fps = request.fps
    return VideoInsertionConfig(
        lookahead_frames=last if request.lookahead_frames is None else min(request.lookahead_frames, last),
        lateral_offset_m=request.lateral_offset_m,
        ahead_m=request.ahead_m,
        contact="lookahead" if moving else "sampled",  # a static camera goes nowhere: a seen ground
        flow_refine=request.flow_refine,
        speed_m_per_frame=request.object_speed_mps / fps,
        move_after_frames=round(request.object_start_s * fps),
        accelerate_frames=round(request.object_accel_s * fps),
        topple_frames=max(1, round(request.topple_s * fps)) if request.topple_s else 0,
        stages=preset,
    )


def _labels_visibility(labels, occluders, plans, results) -> list:
    """Per frame, each labelled box's fraction left uncovered by the inserted objects nearer than it."""
    from aias_augment.pipeline.clip_occluders import labelled_visibility

    object_z = [  # each inserted object's contact z per frame (its origin stands on its contact)
        [None if p.cams_from_object[i] is None else float(p.cams_from_object[i][2, 3]) for p in plans]
        for i in range(len(labels))
    ]
    return [
        labelled_visibility(boxes, occluders.contact_z[i], [r.masks[i] for r in results], object_z[i]).tolist()
        for i, boxes in enumerate(labels)
    ]


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


def plan_clip_objects(request, frames, intr, poses, rng, cfg, ground0, lighting, layer_params, first) -> dict:
    """Plans of ``request.objects`` objects, the first ``first`` = (category, asset); objects share the world: a
    plan whose box meets a placed object's in any frame is redrawn (a new yaw, a new sampled pixel, or
    COLLISION_STEP_M further from the path), and after COLLISION_ATTEMPTS it is left out."""
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
    for k in range(1, request.objects):
        cat_k = request.categories[int(rng.integers(len(request.categories)))]
        source = (cfg.stages or InsertionConfig()).asset_source  # the image door's asset source
        asset_k = choose_asset(cat_k, rng, InsertionConfig(categories=(cat_k,), asset_source=source))
        for attempt in range(COLLISION_ATTEMPTS):
            cfg_k = dataclasses.replace(
                cfg,
                lookahead_frames=round(cfg.lookahead_frames * (request.objects - k) / request.objects),
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
            log.warning("%s: object %d left out: %s", request.name, k + 1, why)
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


def _harmonize(method: str, frames: list[np.ndarray], results, n: int, rng) -> tuple[list[np.ndarray], str]:
    if method == "none":
        return frames, skipped("--harmonize none")
    from aias_augment.apply.harmonize import harmonize_clip

    union = [
        None
        if all(r.masks[i] is None for r in results)
        else np.maximum.reduce([r.masks[i] for r in results if r.masks[i] is not None])
        for i in range(n)
    ]
    note = (
        f"{method}: one colour transform for the clip (median of the per-frame predictions)"
        if method == "fast"
        else f"{method}, frame by frame"
    )
    return harmonize_clip(frames, union, method, rng.spawn(1)[0]), note

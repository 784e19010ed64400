"""Offline augmentation of one posed clip: ``aias-augment --input clip.mp4 --camera calib --poses poses.txt``.

The clip path of the paper: one object pose in the WORLD for the whole clip (:func:`aias_augment.pipeline.clip.
insert_into_clip`), one sun fused over the clip's frames in world coordinates (:func:`aias_augment.analyse.lighting.
estimate_lighting_clip`), every frame rendered through its own K [R | t]. Inputs:

* frames: a video file (anything OpenCV decodes) or a folder of images (sorted by name);
* camera: a KITTI ``calib.txt`` (P0, or P2 with ``colour``), a pyslam/OpenCV ``KITTI*.yaml`` (``Camera.fx`` ...), or
  a plain YAML ``{fx, fy, cx, cy}``;
* poses: KITTI lines (12 numbers, world_from_cam, row-major 3x4) or TUM-style lines (``tx ty tz qx qy qz qw``, with
  or without a leading timestamp); one per frame of the clip (after ``start`` and ``stride``).
* ground: the camera ``camera_height_m`` above level ground (vehicle rigs), the same camera-relative plane for every
  frame (see ``choose_world_contact``).

Outputs in ``out``: ``frames/NNNNNN.jpg`` (augmented), ``annotations.json`` (COCO-video: ``videos``, each image's
``video_id`` and ``frame_id``, one ``track_id`` per inserted object with its visible mask as RLE and its amodal box;
validated by pycocotools), ``mot.txt`` (MOTChallenge: frame, id, x, y, w, h, 1, -1, -1, -1, frames from 1),
``record.json`` (everything needed to replay: seed, asset, world pose, contact, modules used), ``side_by_side.mp4`` (original | augmented with boxes) and ``contact_sheet.jpg``. Every file is
written atomically; a finished clip (``record.json`` present with the same arguments) is not redone.
"""

from __future__ import annotations

import dataclasses
import json
import logging
import math
import os
import time
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np
import yaml

from aias_augment.analyse.ground import prior_ground_plane
from aias_augment.apply.annotate import encode_rle
from aias_augment.cli.offline import read_rgb, write_rgb
from aias_augment.core.coco_io import CocoBuilder, atomic_write_json, atomic_write_text
from aias_augment.core.geometry import CAMERA_HEIGHT_PRIOR_M, Intrinsics, invert_rigid
from aias_augment.core.report import skipped, skipped_stages
from aias_augment.core.viz import contact_sheet, draw_boxes

log = logging.getLogger(__name__)

VIDEO_SUFFIXES = (".mp4", ".avi", ".mov", ".mkv", ".webm", ".m4v", ".mpg", ".mpeg")
IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".bmp")
#: Draws of one object's plan before it is left out for meeting an object already placed in the clip.
COLLISION_ATTEMPTS = 8
COLLISION_STEP_M = 0.5


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
        if not (np.isfinite(self.camera_height_m) and self.camera_height_m > 0):
            raise ValueError(f"camera_height_m must be positive, got {self.camera_height_m}")


# ------------------------------------------------------------------------------------------------------------ inputs
def is_video_input(path: str | Path) -> bool:
    return Path(path).suffix.lower() in VIDEO_SUFFIXES


def read_clip_frames(
    path: str | Path, start: int = 0, max_frames: int | None = None, stride: int = 1
) -> tuple[list[np.ndarray], list[str]]:
    """(RGB uint8 frames, names) of a video file or an image folder: frames start, start+stride, ..."""
    p = Path(path)
    if p.is_dir():
        files = sorted(f for f in p.iterdir() if f.suffix.lower() in IMAGE_SUFFIXES)
        files = files[start::stride][:max_frames]
        if not files:
            raise ValueError(f"{p}: no images (from frame {start})")
        frames = [read_rgb(str(f)) for f in files]
        return frames, [f.stem for f in files]
    if not p.is_file():
        raise FileNotFoundError(f"no such video or folder: {p}")
    from aias_augment.scenes.video import read_video

    n = None if max_frames is None else start + max_frames * stride
    frames = read_video(str(p), max_frames=n)[start::stride][:max_frames]
    if not frames:
        raise ValueError(f"{p}: no frames from frame {start}")
    return frames, [f"{start + i * stride:06d}" for i in range(len(frames))]


def read_camera(path: str | Path, width: int, height: int, *, colour: bool = False) -> Intrinsics:
    """Intrinsics from a KITTI calib.txt, a pyslam ``Camera.fx`` yaml, or a plain yaml with fx, fy, cx, cy."""
    p = Path(path)
    if not p.is_file():
        raise FileNotFoundError(f"no such camera file: {p}")
    if p.suffix.lower() in (".yaml", ".yml"):
        text = p.read_text()
        if "Camera.fx" in text:
            from aias_augment.scenes.kitti import read_pyslam_yaml

            v = read_pyslam_yaml(p)
            keys = ("Camera.fx", "Camera.fy", "Camera.cx", "Camera.cy")
        else:
            v = yaml.safe_load(text) or {}
            keys = ("fx", "fy", "cx", "cy")
        missing = [k for k in keys if k not in v]
        if missing:
            raise ValueError(f"{p}: missing {missing} (need fx, fy, cx, cy)")
        return Intrinsics(*(float(v[k]) for k in keys), width, height)
    from aias_augment.scenes.kitti import read_projection_matrices

    mats = read_projection_matrices(p)
    key = "P2" if colour else "P0"
    if key not in mats:
        raise ValueError(f"{p}: no {key} projection matrix (found {sorted(mats)})")
    return Intrinsics.from_matrix(mats[key][:, :3], width, height)


def read_cams_from_world(path: str | Path) -> np.ndarray:
    """(N, 4, 4) OpenCV cam_from_world from KITTI (12 numbers) or TUM (7, or 8 with a timestamp) pose lines."""
    from aias_augment.scenes.kitti import read_kitti_poses
    from aias_augment.scenes.nyu import read_tum_poses

    p = Path(path)
    rows = np.loadtxt(p, dtype=np.float64, ndmin=2, comments="#")
    if rows.shape[1] == 12:
        world_from_cams = read_kitti_poses(p)
    elif rows.shape[1] in (7, 8):
        if rows.shape[1] == 8:  # drop the timestamp column
            tmp = p.with_name(p.name + ".tum7.tmp")
            try:
                np.savetxt(tmp, rows[:, 1:])
                world_from_cams = read_tum_poses(tmp)
            finally:
                tmp.unlink(missing_ok=True)
        else:
            world_from_cams = read_tum_poses(p)
    else:
        raise ValueError(f"{p}: {rows.shape[1]} numbers per line; expected KITTI (12) or TUM (7 or 8)")
    return np.stack([invert_rigid(T) for T in world_from_cams])


# ------------------------------------------------------------------------------------------------------------- run
def _job_dict(job: ClipJob) -> dict:
    return json.loads(json.dumps(dataclasses.asdict(job)))


def augment_clip(job: ClipJob) -> dict:
    """Insert ``job.objects`` objects of ``job.categories`` (drawn with the seed) into the clip, each with its own
    track; returns the record."""
    from aias_augment.analyse.lighting.estimate import estimate_lighting_clip
    from aias_augment.apply.layers import draw_layer_params
    from aias_augment.pipeline.clip import VideoInsertionConfig, apply_clip_objects, first_collision, plan_clip
    from aias_augment.pipeline.config import InsertionConfig, load_preset
    from aias_augment.plan.insertion import choose_asset

    out = Path(job.out)
    record_path = out / "record.json"
    if record_path.exists():
        old = json.loads(record_path.read_text())
        if old.get("job") == _job_dict(job):
            log.info("%s: already done with the same arguments, nothing to do", out)
            return old
    t0 = time.perf_counter()
    frames, names = read_clip_frames(job.input, job.start, job.max_frames, job.stride)
    h, w = frames[0].shape[:2]
    if any(f.shape != frames[0].shape for f in frames):
        raise ValueError(f"{job.input}: frames differ in size")
    idx = np.arange(job.start, job.start + job.stride * len(frames), job.stride)
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
        intr = read_camera(job.camera, w, h, colour=job.colour)
        all_poses = read_cams_from_world(job.poses)
        if idx[-1] >= len(all_poses):
            raise ValueError(f"{job.poses}: {len(all_poses)} poses, but frame {idx[-1]} of {job.input} is used")
        poses = all_poses[idx]
        ground0, camera_note = prior_ground_plane(job.camera_height_m), "given camera and poses"
    rng = np.random.default_rng([job.seed, 0])
    category = job.categories[int(rng.integers(len(job.categories)))]
    asset = choose_asset(category, rng, InsertionConfig(categories=(category,)))
    lighting, lighting_note = None, "ambient (requested)"
    if job.lighting == "clip":
        try:
            lighting = estimate_lighting_clip(frames, intr, poses, rng=rng.spawn(1)[0])
            lighting_note = f"one sun fused over {len(frames)} frames ({lighting[0].source})"
        except (ValueError, np.linalg.LinAlgError) as e:  # a clip the estimator cannot read: ambient, said why
            log.warning("clip lighting failed (%s): ambient light only", e)
            lighting_note = skipped(str(e))
    last = len(frames) - 1
    # each object's layer stages from generators of their own: rng untouched
    layer_params = draw_layer_params(load_preset(job.preset), job.seed, job.objects)
    cfg = VideoInsertionConfig(
        lookahead_frames=last if job.lookahead_frames is None else min(job.lookahead_frames, last),
        lateral_offset_m=job.lateral_offset_m,
        contact="lookahead" if moving else "sampled",  # a static camera goes nowhere: a seen ground
        flow_refine=job.flow_refine,
        speed_m_per_frame=job.object_speed_mps / job.fps,
        move_after_frames=round(job.object_start_s * job.fps),
        accelerate_frames=round(job.object_accel_s * job.fps),
        topple_frames=max(1, round(job.topple_s * job.fps)) if job.topple_s else 0,
    )
    objects = [(category, asset)]
    placed_params, draws = [layer_params[0]], [1]
    plans = [
        plan_clip(
            frames,
            intr,
            poses,
            rng,
            cfg,
            asset=asset,
            ground_in_cam0=ground0,
            lighting=lighting,
            layer_params=layer_params[0],
        )
    ]
    skipped_objects = []
    for k in range(1, job.objects):
        cat_k = job.categories[int(rng.integers(len(job.categories)))]
        asset_k = choose_asset(cat_k, rng, InsertionConfig(categories=(cat_k,)))
        # Objects share the world: a plan whose box meets a placed object's in any frame is redrawn (a new yaw, a
        # new sampled pixel, or COLLISION_STEP_M further from the path), and after COLLISION_ATTEMPTS it is left out.
        for attempt in range(COLLISION_ATTEMPTS):
            cfg_k = dataclasses.replace(
                cfg,
                lookahead_frames=round(cfg.lookahead_frames * (job.objects - k) / job.objects),
                lateral_offset_m=(-1) ** k
                * math.copysign(abs(cfg.lateral_offset_m) + COLLISION_STEP_M * attempt, cfg.lateral_offset_m),
            )
            plan_k = plan_clip(
                frames,
                intr,
                poses,
                rng,
                cfg_k,
                asset=asset_k,
                ground_in_cam0=ground0,
                lighting=lighting,
                layer_params=layer_params[k],
            )
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
    results = apply_clip_objects(frames, intr, plans, cfg)
    res = results[0]
    out_frames = res.frames

    if job.harmonize != "none":
        from aias_augment.apply.harmonize import harmonize_clip

        union = [
            None
            if all(r.masks[i] is None for r in results)
            else np.maximum.reduce([r.masks[i] for r in results if r.masks[i] is not None])
            for i in range(len(frames))
        ]
        out_frames = harmonize_clip(out_frames, union, job.harmonize, rng.spawn(1)[0])
        harmonize_note = (
            f"{job.harmonize}: one colour transform for the clip (median of the per-frame predictions)"
            if job.harmonize == "fast"
            else f"{job.harmonize}, frame by frame"
        )
    else:
        harmonize_note = skipped("--harmonize none")
    # A grey clip (KITTI image_0/image_l) stays grey: an orange cone in a grey frame would be a give-away.
    grey = all(np.array_equal(f[..., 0], f[..., 1]) and np.array_equal(f[..., 1], f[..., 2]) for f in frames)
    if grey:
        out_frames = [np.repeat(cv2.cvtColor(f, cv2.COLOR_RGB2GRAY)[..., None], 3, axis=2) for f in out_frames]
    categories = list(dict.fromkeys(c for c, _ in objects))
    coco = CocoBuilder({c: j + 1 for j, c in enumerate(categories)})
    coco.videos.append({"id": 1, "name": Path(job.input).name, "width": w, "height": h, "fps": job.fps})
    drawn, mot = [], []
    for i, (name, img) in enumerate(zip(names, out_frames)):
        file_name = f"frames/{name}.jpg"
        write_rgb(out / file_name, img)
        image_id = coco.add_image(file_name, w, h, frame_index=int(idx[i]), video_id=1, frame_id=i)
        boxes, labels = [], []
        for track, (r, (cat, _)) in enumerate(zip(results, objects), start=1):
            box = r.boxes_xywh[i]
            if box is None:
                continue
            visible = r.masks[i] > 0.5
            coco.add_box(
                image_id,
                cat,
                box,
                segmentation=encode_rle(visible),
                area=float(visible.sum()),
                inserted=True,
                track_id=track,
                amodal_bbox=[float(v) for v in r.amodal_boxes_xywh[i]],
            )
            mot.append(f"{i + 1},{track},{box[0]:.2f},{box[1]:.2f},{box[2]:.2f},{box[3]:.2f},1,-1,-1,-1")
            boxes.append(box), labels.append(cat)
        drawn.append(draw_boxes(img, boxes, labels, inserted=[True] * len(boxes)))
    coco.write(out / "annotations.json")
    atomic_write_text(out / "mot.txt", "".join(line + "\n" for line in mot))
    _write_side_by_side(out / "side_by_side.mp4", frames, drawn, job.fps)
    picks = np.unique(np.linspace(0, len(drawn) - 1, min(6, len(drawn))).astype(int))
    sheet = contact_sheet([drawn[i] for i in picks], cols=3, titles=[names[i] for i in picks])
    write_rgb(out / "contact_sheet.jpg", sheet)
    notes = {
        **res.modules,
        "camera": camera_note,
        "lighting": lighting_note,
        "harmonize": harmonize_note,
        "colour": "grey clip: output converted to grey" if grey else "colour clip",
    }
    record = {
        "job": _job_dict(job),
        "category": category,
        "asset": asset.name,
        "asset_height_m": float(asset.height_m),
        "frames": len(frames),
        "frame_indices": idx.tolist(),
        "intrinsics": [intr.fx, intr.fy, intr.cx, intr.cy, w, h],
        "world_from_object": res.world_from_object.tolist(),
        "contact_in_world": res.contact_in_world.tolist(),
        "layer_params": layer_params[0],
        "visible_frames": int(sum(b is not None for b in res.boxes_xywh)),
        "objects": [
            {
                "track_id": k + 1,
                "category": cat,
                "asset": a.name,
                "asset_height_m": float(a.height_m),
                "world_from_object": r.world_from_object.tolist(),
                "contact_in_world": r.contact_in_world.tolist(),
                "layer_params": placed_params[k],
                "draws": draws[k],
                "topple": plans[k].topple,
                "visible_frames": int(sum(b is not None for b in r.boxes_xywh)),
            }
            for k, ((cat, a), r) in enumerate(zip(objects, results))
        ],
        "skipped_objects": skipped_objects,
        "modules": notes,
        "skipped_stages": skipped_stages(notes),
        "wall_s": round(time.perf_counter() - t0, 1),
    }
    atomic_write_json(record_path, record)  # last: its presence marks the clip as done
    log.info("%s: %d frames, object visible in %d, %.1fs", out, len(frames), record["visible_frames"], record["wall_s"])
    return record


def stereo_odometry_clip(frames: list[np.ndarray], job: ClipJob):
    """(K, cams_from_world, note) of a stereo clip without poses: the right frames read as the left ones were,
    the baseline from the camera file, the poses by stereo odometry (world = the first left camera)."""
    from aias_augment.scenes.kitti import read_kitti_calib
    from aias_augment.scenes.video import estimate_stereo_motion

    if job.camera is None:
        raise ValueError("--stereo-right needs --camera with both cameras (KITTI P0/P1, or a yaml with Camera.bf)")
    h, w = frames[0].shape[:2]
    intr, baseline = read_kitti_calib(job.camera, w, h, colour=job.colour)
    rights, _ = read_clip_frames(job.stereo_right, job.start, job.max_frames, job.stride)
    if len(rights) != len(frames) or any(r.shape != frames[0].shape for r in rights):
        raise ValueError(f"{job.stereo_right}: {len(rights)} right frames for {len(frames)} left ones, or another size")
    motion = estimate_stereo_motion(frames, rights, intr, baseline, np.random.default_rng([job.seed, 2]))
    failed = [s for s in motion.status if s != "moving"]
    note = f"given camera; poses by stereo odometry (baseline {baseline:.3f} m, {len(frames) - 1 - len(failed)} of {len(frames) - 1} steps measured)"
    if failed:
        log.warning("%s: stereo odometry kept the previous pose in %d steps (%s)", job.input, len(failed), failed[0])
    return intr, motion.cams_from_world, note


def monocular_odometry_clip(frames: list[np.ndarray], job: ClipJob, check):
    """(K, cams_from_world, note) of a moving camera's clip without poses or a right camera: essential-matrix
    odometry, each step's length from the ground at ``job.camera_height_m`` (``scenes.video``, ``ground_height_m``).
    It needs the camera (``--camera``): a focal length guessed from one frame would bend every step."""
    from aias_augment.scenes.video import VideoMotionConfig, estimate_video_motion

    if job.camera is None:
        raise ValueError(
            f"{job.input}: {check.reason()}; a moving camera needs --camera (then its poses are estimated from the "
            "frames, scaled by --camera-height), or --poses, or --stereo-right"
        )
    h, w = frames[0].shape[:2]
    intr = read_camera(job.camera, w, h, colour=job.colour)
    motion = estimate_video_motion(
        frames,
        np.random.default_rng([job.seed, 3]),
        intrinsics=intr,
        cfg=VideoMotionConfig(ground_height_m=job.camera_height_m),
    )
    failed = [s for s in motion.status if s != "moving"]
    steps = motion.meta["ground_steps_m"]
    note = (
        f"given camera; {check.reason()}: poses by monocular odometry, steps scaled by the ground "
        f"{job.camera_height_m} m below ({len(steps)} of {len(frames) - 1} steps measured on the ground, "
        f"median {float(np.median(steps)) if steps else float('nan'):.2f} m)"
    )
    if failed:
        log.warning("%s: monocular odometry kept the previous pose in %d steps (%s)", job.input, len(failed), failed[0])
    return intr, motion.cams_from_world, note


def static_camera_clip(frames: list[np.ndarray], job: ClipJob):
    """(intrinsics, identity poses, ground in the camera, note) of a clip without poses, which must come from a static
    camera (:func:`aias_augment.scenes.video.static_camera_check`; a moving one raises, saying how far it moved).
    K is ``job.camera``'s or estimated from the first frame, the ground from its horizon at ``job.camera_height_m``.
    Its own generator: the insertion's draws are those of a posed clip with the same seed."""
    from aias_augment.analyse.ground import GroundPlane
    from aias_augment.scenes.single_image import estimate_camera_from_image
    from aias_augment.scenes.video import static_camera_check

    check = static_camera_check(frames)
    if not check.static:
        raise ValueError(f"{job.input}: {check.reason()}; not a static camera")
    h, w = frames[0].shape[:2]
    given = None if job.camera is None else read_camera(job.camera, w, h, colour=job.colour)
    cam = estimate_camera_from_image(frames[0], np.random.default_rng([job.seed, 1]), intrinsics=given)
    ground = GroundPlane(cam.ground.normal, job.camera_height_m, cam.ground.source, assumed_scale=True)
    note = (
        f"{check.reason()}: one camera for the clip, K {cam.focal_source}, horizon {cam.horizon_source}, "
        f"camera {job.camera_height_m} m above the ground (assumed)"
    )
    return cam.intrinsics, np.repeat(np.eye(4)[None], len(frames), axis=0), ground, note


def _write_side_by_side(path: Path, originals: list[np.ndarray], augmented: list[np.ndarray], fps: float) -> None:
    """Original | augmented, one row per frame, as an mp4 (written to a temporary name, then renamed)."""
    h, w = originals[0].shape[:2]
    scale = min(1.0, 960 / (2 * w))
    size = (int(2 * w * scale) // 2 * 2, int(h * scale) // 2 * 2)
    tmp = path.with_name(path.stem + ".tmp" + path.suffix)
    writer = cv2.VideoWriter(str(tmp), cv2.VideoWriter_fourcc(*"mp4v"), fps, size)
    if not writer.isOpened():
        raise OSError(f"cannot open a video writer for {path}")
    try:
        for a, b in zip(originals, augmented):
            pair = cv2.resize(np.concatenate([a, b], 1), size, interpolation=cv2.INTER_AREA)
            writer.write(np.ascontiguousarray(pair[..., ::-1]))
    finally:
        writer.release()
    os.replace(tmp, path)

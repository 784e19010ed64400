"""Offline augmentation of one posed clip: ``aias-augment --input clip.mp4 --camera calib --poses poses.txt``.

The command reads and checks the inputs (before anything is written, :mod:`aias_augment.cli.clip_inputs`), finds
the cameras (given, by odometry, or one static camera: :mod:`aias_augment.cli.clip_cameras`), calls the clip door
(:func:`aias_augment.pipeline.clip_objects.insert_objects_into_clip`: the objects planned in the WORLD, one sun fused
over the clip's frames, every frame rendered through its own K [R | t]) and writes its outputs
(:mod:`aias_augment.cli.clip_write`). Inputs:

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
import os
import sys
import time
from pathlib import Path

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
from aias_augment.cli.clip_job import ClipInputs, ClipJob
from aias_augment.cli.clip_output import ClipInput, ClipOutput, clip_manifest, files_hash
from aias_augment.cli.clip_write import job_dict, write_clip
from aias_augment.cli.manifest import ManifestMismatch, check_out_apart, file_hash, output_lock
from aias_augment.core.errors import AiasError
from aias_augment.pipeline.clip_objects import (
    RenderedClip,
    insert_objects_into_clip,
)

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


# ------------------------------------------------------------------------------------------------------------- run
class ClipNotVisible(AiasError, RuntimeError):
    """No inserted object is visible in any frame of the clip: nothing was written."""


CLIP_FILES = ("annotations.json", "mot.txt", "side_by_side.mp4", "contact_sheet.jpg", "record.json")
_PATH_FIELDS = ("input", "camera", "poses", "stereo_right", "labels")


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
    options = {k: v for k, v in job_dict(job).items() if k not in (*_PATH_FIELDS, "out", "seed", "preset")}
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
    """The camera and poses of ``job`` (given, by odometry, or one static camera), then the clip door
    (:func:`~aias_augment.pipeline.clip_objects.insert_objects_into_clip`): nothing written."""
    from aias_augment.cli.clip_cameras import monocular_odometry_clip, static_camera_clip, stereo_odometry_clip

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
    return insert_objects_into_clip(
        frames, intr, poses, ground0, job.request(), moving=moving, camera_note=camera_note, labels=inputs.labels
    )


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

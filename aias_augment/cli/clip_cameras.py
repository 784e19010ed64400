"""Where a clip's cameras come from without ``--poses``: stereo odometry (``--stereo-right``), monocular odometry
scaled by the ground (a moving camera with ``--camera``), or one camera for the clip (a static camera)."""

from __future__ import annotations

import logging
from typing import TYPE_CHECKING

import numpy as np

from aias_augment.cli.clip_inputs import read_camera, read_clip_frames
from aias_augment.core.errors import InputError

if TYPE_CHECKING:
    from aias_augment.cli.clip_job import ClipJob

log = logging.getLogger("aias_augment.cli.clip")


def stereo_odometry_clip(frames: list[np.ndarray], job: ClipJob):
    """(K, cams_from_world, note) of a stereo clip without poses: the right frames read as the left ones were,
    the baseline from the camera file, the poses by stereo odometry (world = the first left camera)."""
    from aias_augment.scenes.kitti import read_kitti_calib
    from aias_augment.scenes.video import estimate_stereo_motion

    if job.camera is None:
        raise InputError("--stereo-right needs --camera with both cameras (KITTI P0/P1, or a yaml with Camera.bf)")
    h, w = frames[0].shape[:2]
    try:
        intr, baseline = read_kitti_calib(job.camera, w, h, colour=job.colour)
    except ValueError as e:
        raise InputError(f"--camera {job.camera}: {e} (--stereo-right needs both cameras)") from None
    rights, _ = read_clip_frames(job.stereo_right, job.start, job.max_frames, job.stride)
    if len(rights) != len(frames) or any(r.shape != frames[0].shape for r in rights):
        raise InputError(
            f"--stereo-right {job.stereo_right}: {len(rights)} right frames for {len(frames)} left ones, or another size"
        )
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
        raise InputError(
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
    from aias_augment.analyse.single_image import estimate_camera_from_image
    from aias_augment.scenes.video import static_camera_check

    check = static_camera_check(frames)
    if not check.static:
        raise InputError(f"{job.input}: {check.reason()}; not a static camera")
    h, w = frames[0].shape[:2]
    given = None if job.camera is None else read_camera(job.camera, w, h, colour=job.colour)
    cam = estimate_camera_from_image(frames[0], np.random.default_rng([job.seed, 1]), intrinsics=given)
    ground = GroundPlane(cam.ground.normal, job.camera_height_m, cam.ground.source, assumed_scale=True)
    note = (
        f"{check.reason()}: one camera for the clip, K {cam.focal_source}, horizon {cam.horizon_source}, "
        f"camera {job.camera_height_m} m above the ground (assumed)"
    )
    return cam.intrinsics, np.repeat(np.eye(4)[None], len(frames), axis=0), ground, note

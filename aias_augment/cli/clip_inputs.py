"""A clip's inputs, read and checked before anything is written: frames, camera, poses.

Every problem is an :class:`~aias_augment.core.errors.InputError` whose one-line message names the file, the value
and what to do. Nothing is written anywhere: pose files are parsed in memory.

Plausible ranges (a value outside them cannot give a usable clip, so it is refused rather than rendered):

* focal lengths ``fx``, ``fy`` between :data:`MIN_FOCAL_PER_WIDTH` and :data:`MAX_FOCAL_PER_WIDTH` times the frame
  width (a horizontal field of view between about 169 and 0.6 degrees), ``fx / fy`` within
  :data:`MAX_PIXEL_ASPECT` of 1;
* the principal point inside the frame grown by half its size on each side (a cropped frame keeps it near);
* rotations orthonormal (KITTI) or unit quaternions within :data:`QUATERNION_NORM_TOL` (TUM), every number finite,
  TUM timestamps strictly increasing (one pose per frame, in frame order).
"""

from __future__ import annotations

import io
import math
import warnings
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from aias_augment.core.config_files import parse_yaml
from aias_augment.core.errors import InputError
from aias_augment.core.geometry import Intrinsics, check_rigid, invert_rigid, make_rigid

VIDEO_SUFFIXES = (".mp4", ".avi", ".mov", ".mkv", ".webm", ".m4v", ".mpg", ".mpeg")
IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".bmp")
MIN_FOCAL_PER_WIDTH = 0.05  # fx = 0.05 w: a 169 degree horizontal field of view
MAX_FOCAL_PER_WIDTH = 100.0  # fx = 100 w: 0.57 degrees, past the longest telephoto lenses
MAX_PIXEL_ASPECT = 4.0  # fx / fy within [1/4, 4]
QUATERNION_NORM_TOL = 1e-2


# ------------------------------------------------------------------------------------------------------------ frames
def is_video_input(path: str | Path) -> bool:
    return Path(path).suffix.lower() in VIDEO_SUFFIXES


def clip_frame_files(path: str | Path, start: int = 0, max_frames: int | None = None, stride: int = 1) -> list[Path]:
    """The image files of a frame folder that a clip uses (sorted by name; frames start, start+stride, ...)."""
    p = Path(path)
    files = sorted(f for f in p.iterdir() if f.is_file() and f.suffix.lower() in IMAGE_SUFFIXES)
    files = files[start::stride][:max_frames]
    stems = [f.stem for f in files]
    twin = next((f for i, f in enumerate(files) if f.stem in stems[:i]), None)
    if twin is not None:
        raise InputError(f"{p}: two frames named {twin.stem} (another suffix); each frame's name must be its own")
    if not files:
        raise InputError(f"{p}: no {'/'.join(IMAGE_SUFFIXES)} images from frame {start}; check --input and --start")
    return files


def read_clip_frames(
    path: str | Path, start: int = 0, max_frames: int | None = None, stride: int = 1
) -> tuple[list[np.ndarray], list[str]]:
    """(RGB uint8 frames, names) of a video file or an image folder: frames start, start+stride, ..., all one size."""
    from aias_augment.cli.offline_job import read_rgb

    p = Path(path)
    if p.is_dir():
        files = clip_frame_files(p, start, max_frames, stride)
        frames, names = [], [f.stem for f in files]
        for f in files:
            try:
                frames.append(read_rgb(str(f)))
            except ValueError as e:
                raise InputError(f"{f}: {e}; replace or remove the frame") from None
    elif p.is_file():
        from aias_augment.scenes.video import read_video

        n = None if max_frames is None else start + max_frames * stride
        try:
            frames = read_video(str(p), max_frames=n)[start::stride][:max_frames]
        except (OSError, ValueError) as e:
            raise InputError(f"{p}: {e}; is it a video OpenCV can decode?") from None
        if not frames:
            raise InputError(f"{p}: no frames from frame {start}; check --start")
        names = [f"{start + i * stride:06d}" for i in range(len(frames))]
    else:
        raise InputError(f"--input {p}: no such video or frame folder")
    odd = next((i for i, f in enumerate(frames) if f.shape != frames[0].shape), None)
    if odd is not None:
        raise InputError(
            f"{p}: frame {names[odd]} is {frames[odd].shape[1]}x{frames[odd].shape[0]}, frame {names[0]} "
            f"{frames[0].shape[1]}x{frames[0].shape[0]}: a clip's frames must all be one size"
        )
    return frames, names


# ------------------------------------------------------------------------------------------------------------ camera
def _read_text(path: Path, what: str) -> str:
    if not path.is_file():
        raise InputError(f"{what} {path}: no such file")
    try:
        return path.read_text(encoding="utf-8")
    except UnicodeDecodeError as e:
        raise InputError(f"{what} {path}: not UTF-8 text (byte {e.start}); save it as UTF-8") from None
    except OSError as e:
        raise InputError(f"{what} {path}: cannot read it ({e.strerror or e})") from None


def read_camera(path: str | Path, width: int, height: int, *, colour: bool = False) -> Intrinsics:
    """Intrinsics from a KITTI calib.txt, a pyslam ``Camera.fx`` yaml, or a plain yaml with fx, fy, cx, cy; checked
    against the frame size (:func:`check_intrinsics`)."""
    p = Path(path)
    text = _read_text(p, "--camera")
    if p.suffix.lower() in (".yaml", ".yml"):
        if "Camera.fx" in text:
            from aias_augment.scenes.kitti import read_pyslam_yaml

            v: object = read_pyslam_yaml(p)
            keys = ("Camera.fx", "Camera.fy", "Camera.cx", "Camera.cy")
        else:
            v = parse_yaml(text, f"--camera {p}") or {}  # bounded: alias expansion (ConfigFileError, an InputError)
            keys = ("fx", "fy", "cx", "cy")
        if not isinstance(v, dict):
            raise InputError(f"--camera {p}: expected a mapping with {', '.join(keys)}, got {type(v).__name__}")
        missing = [k for k in keys if k not in v]
        if missing:
            raise InputError(f"--camera {p}: missing {missing} (need {', '.join(keys)})")
        values = []
        for k in keys:
            try:
                values.append(float(v[k]))
            except (TypeError, ValueError):
                raise InputError(f"--camera {p}: {k} must be a number of pixels, got {v[k]!r}") from None
        fx, fy, cx, cy = values
    else:
        from aias_augment.scenes.kitti import read_projection_matrices

        try:
            mats = read_projection_matrices(p)
        except ValueError as e:
            raise InputError(f"--camera {p}: not a KITTI calib.txt ({e})") from None
        key = "P2" if colour else "P0"
        if key not in mats:
            raise InputError(f"--camera {p}: no {key} projection matrix (found {sorted(mats) or 'none'})")
        K = mats[key][:, :3]
        if not np.isfinite(K).all() or abs(K[0, 1]) > 1e-9 or np.abs(K[2] - (0, 0, 1)).max() > 1e-9:
            raise InputError(f"--camera {p}: {key} does not start with K = [[fx,0,cx],[0,fy,cy],[0,0,1]]")
        fx, fy, cx, cy = float(K[0, 0]), float(K[1, 1]), float(K[0, 2]), float(K[1, 2])
    check_intrinsics(fx, fy, cx, cy, width, height, f"--camera {p}")
    return Intrinsics(fx, fy, cx, cy, width, height)


def check_intrinsics(fx: float, fy: float, cx: float, cy: float, width: int, height: int, source: str) -> None:
    """Refuse a K that cannot belong to a ``width`` x ``height`` frame (the ranges of the module docstring)."""
    lo, hi = MIN_FOCAL_PER_WIDTH * width, MAX_FOCAL_PER_WIDTH * width
    for name, f in (("fx", fx), ("fy", fy)):
        if not (math.isfinite(f) and lo <= f <= hi):
            raise InputError(
                f"{source}: {name} {f:g} px is outside {lo:g}..{hi:g} px, the plausible range for a {width}x{height} "
                "frame (a horizontal field of view of 169 to 0.6 degrees); check that K is in pixels of these frames"
            )
    if not 1 / MAX_PIXEL_ASPECT <= fx / fy <= MAX_PIXEL_ASPECT:
        raise InputError(f"{source}: fx / fy = {fx / fy:g}; pixels that far from square are a wrong K")
    for name, c, size in (("cx", cx, width), ("cy", cy, height)):
        if not (math.isfinite(c) and -size / 2 <= c <= 1.5 * size):
            raise InputError(
                f"{source}: {name} {c:g} px is far outside the {width}x{height} frame (allowed {-size / 2:g}.."
                f"{1.5 * size:g}); check that K is in pixels of these frames"
            )


# ------------------------------------------------------------------------------------------------------------- poses
def read_cams_from_world(path: str | Path) -> np.ndarray:
    """(N, 4, 4) OpenCV cam_from_world from KITTI (12 numbers, world_from_cam row-major 3x4) or TUM
    (``tx ty tz qx qy qz qw``, with or without a leading timestamp) pose lines; ``#`` starts a comment."""
    p = Path(path)
    text = _read_text(p, "--poses")
    fix = "one pose per line: KITTI (12 numbers) or TUM (7, or 8 with a timestamp)"
    try:
        with warnings.catch_warnings():  # "input contained no data": said below, in one line
            warnings.simplefilter("ignore", UserWarning)
            rows = np.loadtxt(io.StringIO(text), dtype=np.float64, ndmin=2, comments="#")
    except ValueError as e:
        raise InputError(f"--poses {p}: {str(e).splitlines()[0]}; {fix}") from None
    if rows.size == 0:
        raise InputError(f"--poses {p}: no poses; {fix}")
    bad = np.flatnonzero(~np.isfinite(rows).all(axis=1))
    if bad.size:
        raise InputError(f"--poses {p}: pose {bad[0] + 1} has a NaN or infinite number; every pose must be finite")
    if rows.shape[1] == 8:
        steps = np.diff(rows[:, 0])
        back = np.flatnonzero(steps <= 0)
        if back.size:
            i = back[0] + 1
            raise InputError(
                f"--poses {p}: timestamp {rows[i, 0]:.9g} of pose {i + 1} does not follow {rows[i - 1, 0]:.9g} of "
                f"pose {i}; TUM poses must be in time order, one per frame (sort the lines by time)"
            )
        rows = rows[:, 1:]
    if rows.shape[1] == 12:
        world_from_cams = np.tile(np.eye(4), (len(rows), 1, 1))
        world_from_cams[:, :3, :] = rows.reshape(-1, 3, 4)
        for i, T in enumerate(world_from_cams):
            try:
                check_rigid(T, f"--poses {p}: pose {i + 1}")
            except ValueError as e:
                raise InputError(f"{e}; KITTI poses are world_from_cam [R | t], row-major") from None
    elif rows.shape[1] == 7:
        norms = np.linalg.norm(rows[:, 3:], axis=1)
        bad = np.flatnonzero(np.abs(norms - 1) > QUATERNION_NORM_TOL)
        if bad.size:
            raise InputError(
                f"--poses {p}: pose {bad[0] + 1} has a quaternion of norm {norms[bad[0]]:g}, not a unit quaternion; "
                "TUM columns are [timestamp] tx ty tz qx qy qz qw"
            )
        world_from_cams = np.stack([make_rigid(Rotation.from_quat(r[3:]).as_matrix(), r[:3]) for r in rows])
    else:
        raise InputError(f"--poses {p}: {rows.shape[1]} numbers per line; {fix}")
    return np.stack([invert_rigid(T) for T in world_from_cams])


def check_pose_count(n_poses: int, last_frame: int, poses: str, frames: str) -> None:
    """One pose per frame of the input: frame ``last_frame`` (0-based, after --start and --stride) needs a pose."""
    if last_frame >= n_poses:
        raise InputError(
            f"--poses {poses}: {n_poses} poses, but frame {last_frame} of {frames} is used ({last_frame + 1} "
            "needed); one pose per frame of the input (check --start, --stride, --max-frames)"
        )


# ------------------------------------------------------------------------------------------------------------ labels
def read_clip_labels(
    path: str | Path, fmt: str | None, names: list[str], idx: np.ndarray, category: str = "object"
) -> tuple[list[list], int]:
    """(per frame of the clip, its labelled boxes; how many labelled boxes lie in input frames the clip does not use)
    from a MOTChallenge or COCO-video file (``fmt`` None: detected, :func:`aias_augment.core.track_labels.
    detect_format`). A MOT row's frame is its input frame (frame 1 = the input's first); a COCO-video image's is the
    frame of --input with its file name when every image names one (a frame folder), else its ``frame_id``
    (0-based in the input). ``category``: the class of MOT rows (MOT files name none)."""
    from aias_augment.core.track_labels import FORMATS, detect_format, read_coco_video, read_mot

    p = Path(path)
    if not p.is_file():
        raise InputError(f"--labels {p}: no such file")
    fmt = fmt or detect_format(p)
    if fmt not in FORMATS:
        raise InputError(f"--labels-format {fmt!r}: use one of {', '.join(FORMATS)}")
    boxes = read_mot(p, category) if fmt == "mot" else read_coco_video(p)
    if fmt == "coco-video" and not all(b.frame_name in set(names) for b in boxes):
        no_frame = next((b for b in boxes if b.frame < 0), None)
        if no_frame is not None:
            raise InputError(
                f"--labels {p}: image {no_frame.frame_name} is no frame of --input and has no frame_id; name the "
                "images as the input's frames or give each its frame_id"
            )
        by_name = None
    else:
        by_name = fmt == "coco-video"
    slot = {n: i for i, n in enumerate(names)} if by_name else {int(f): i for i, f in enumerate(idx)}
    per_frame: list[list] = [[] for _ in names]
    outside = 0
    for b in boxes:
        i = slot.get(b.frame_name if by_name else b.frame)
        if i is None:
            outside += 1
        else:
            per_frame[i].append(b)
    if boxes and outside == len(boxes):
        first, last = (names[0], names[-1]) if by_name else (int(idx[0]), int(idx[-1]))
        raise InputError(
            f"--labels {p}: none of its {len(boxes)} boxes is in the clip's frames {first}..{last}; check that they "
            "are this clip's labels (and --start, --stride, --max-frames)"
        )
    return per_frame, outside

"""A clip's track labels: MOTChallenge and COCO-video files in, MOTChallenge lines out.

Conventions (boxes inside the package are COCO ``[x, y, w, h]`` in pixel-edge coordinates, the top-left pixel's
corner at (0, 0)):

* **MOTChallenge** (``gt.txt``, comma or space separated, one box a line): ``frame, id, bb_left, bb_top, bb_width,
  bb_height[, conf, x, y, z]``; frames count from 1 and the image's top-left pixel is (1, 1) (the devkit's Matlab
  convention, which ``motmetrics.io.loadtxt`` undoes), so ``bb_left = x + 1``. Written with the ten columns, world
  coordinates -1. Ids are positive; a row with id -1 is a detection, not a track, and is refused.
* **COCO-video** (TAO, BDD100K and this package's clip output): ``images`` carry ``video_id`` and ``frame_id``,
  ``annotations`` carry ``track_id`` (TAO/OVIS's ``instance_id`` read as one), ``categories`` name the classes. One
  video per file.

Every problem is an :class:`~aias_augment.core.errors.InputError` naming the file, the line or annotation, and the
fix.
"""

from __future__ import annotations

import io
import json
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from aias_augment.core.errors import InputError

__all__ = ["FORMATS", "TrackBox", "detect_format", "format_number", "mot_line", "read_coco_video", "read_mot"]

FORMATS = ("coco-video", "mot")
#: MOTChallenge pixel coordinates start at 1: MOT = COCO + MOT_ORIGIN_PX.
MOT_ORIGIN_PX = 1.0
MAX_LABEL_BYTES = 256 * 2**20  # a labels file larger than this is not one clip's


@dataclass(frozen=True)
class TrackBox:
    """One labelled box of a track in one frame. ``frame``: the frame's 0-based index in the input (MOT frame - 1,
    COCO-video ``frame_id``); ``frame_name``: the image's file stem (COCO-video) or None (MOT)."""

    frame: int
    track_id: int
    category: str
    box_xywh: tuple[float, float, float, float]  # COCO, pixel-edge coordinates
    conf: float = 1.0
    frame_name: str | None = None


def detect_format(path: str | Path) -> str:
    """``"coco-video"`` for a JSON object (``.json`` or a file starting with ``{``), else ``"mot"``."""
    p = Path(path)
    if p.suffix.lower() == ".json":
        return "coco-video"
    with open(p, "rb") as f:
        head = f.read(4096).lstrip()
    return "coco-video" if head.startswith(b"{") else "mot"


def _read_text(path: Path, flag: str) -> str:
    if not path.is_file():
        raise InputError(f"{flag} {path}: no such file")
    if path.stat().st_size > MAX_LABEL_BYTES:
        raise InputError(f"{flag} {path}: over {MAX_LABEL_BYTES >> 20} MiB; give one clip's labels")
    try:
        return path.read_text(encoding="utf-8")
    except UnicodeDecodeError as e:
        raise InputError(f"{flag} {path}: not UTF-8 text (byte {e.start}); save it as UTF-8") from None


def read_mot(path: str | Path, category: str = "object", flag: str = "--labels") -> list[TrackBox]:
    """The rows of a MOTChallenge file as :class:`TrackBox` (COCO boxes, 0-based frames), each of ``category``."""
    p = Path(path)
    text = _read_text(p, flag)
    fix = "MOTChallenge rows are frame, id, bb_left, bb_top, bb_width, bb_height[, conf, x, y, z]"
    lines = [(n, line) for n, line in enumerate(text.splitlines(), start=1) if line.strip()]
    if not lines:
        raise InputError(f"{flag} {p}: no rows; {fix}")
    try:
        rows = np.loadtxt(io.StringIO(text.replace(",", " ")), dtype=np.float64, ndmin=2)
    except ValueError as e:
        raise InputError(f"{flag} {p}: {str(e).splitlines()[0]}; {fix}") from None
    if rows.shape[1] < 6:
        raise InputError(f"{flag} {p}: {rows.shape[1]} columns; {fix}")
    boxes, seen = [], set()
    for (n, _), r in zip(lines, rows):
        where = f"{flag} {p} line {n}"
        if not np.isfinite(r[:7]).all():
            raise InputError(f"{where}: a NaN or infinite number; every value must be finite")
        frame, track = r[0], r[1]
        if frame != int(frame) or frame < 1:
            raise InputError(f"{where}: frame {frame:g}; MOT frames are whole numbers from 1")
        if track != int(track) or track < 1:
            raise InputError(f"{where}: id {track:g}; track labels need whole ids from 1 (id -1 is a detection)")
        if r[4] <= 0 or r[5] <= 0:
            raise InputError(f"{where}: box {r[4]:g}x{r[5]:g}; width and height must be > 0")
        key = (int(frame), int(track))
        if key in seen:
            raise InputError(f"{where}: track {key[1]} twice in frame {key[0]}; one box per track and frame")
        seen.add(key)
        box = (float(r[2] - MOT_ORIGIN_PX), float(r[3] - MOT_ORIGIN_PX), float(r[4]), float(r[5]))
        conf = float(r[6]) if len(r) > 6 else 1.0
        boxes.append(TrackBox(key[0] - 1, key[1], category, box, conf))
    return boxes


def read_coco_video(path: str | Path, flag: str = "--labels") -> list[TrackBox]:
    """The annotations of a one-video COCO-video file as :class:`TrackBox` (frame: the image's ``frame_id``,
    frame_name: its file stem)."""
    p = Path(path)
    text = _read_text(p, flag)
    try:
        d = json.loads(text)
    except json.JSONDecodeError as e:
        raise InputError(f"{flag} {p}: not JSON ({e.msg}, line {e.lineno}); give a COCO-video file") from None
    except RecursionError:
        raise InputError(f"{flag} {p}: nested too deep for JSON labels; give a COCO-video file") from None
    if not isinstance(d, dict) or not isinstance(d.get("images"), list) or not isinstance(d.get("annotations"), list):
        raise InputError(f"{flag} {p}: no images and annotations lists; give a COCO-video file")
    names = {c.get("id"): str(c.get("name")) for c in d.get("categories", []) if isinstance(c, dict)}
    videos = {im.get("video_id") for im in d["images"] if isinstance(im, dict)}
    if len(videos) > 1:
        raise InputError(f"{flag} {p}: {len(videos)} videos; give a file holding this clip's video only")
    images = {}
    for im in d["images"]:
        if not isinstance(im, dict) or "id" not in im or "file_name" not in im:
            raise InputError(f"{flag} {p}: an image without id or file_name ({str(im)[:60]})")
        fid = im.get("frame_id", im.get("frame_index"))
        if fid is not None and (not isinstance(fid, int) or fid < 0):
            raise InputError(f"{flag} {p}: image {im['id']} has frame_id {fid!r}; frame ids are whole numbers from 0")
        images[im["id"]] = (fid, Path(str(im["file_name"])).stem)
    boxes, seen = [], set()
    for a in d["annotations"]:
        where = f"{flag} {p} annotation {a.get('id', '?') if isinstance(a, dict) else '?'}"
        if not isinstance(a, dict) or a.get("image_id") not in images:
            raise InputError(f"{where}: no image_id of the file's images")
        track = a.get("track_id", a.get("instance_id"))
        if not isinstance(track, int) or track < 1:
            raise InputError(f"{where}: track_id {track!r}; each annotation needs a whole track_id from 1")
        if a.get("category_id") not in names:
            raise InputError(f"{where}: category_id {a.get('category_id')!r} is not in categories")
        box = a.get("bbox")
        ok = isinstance(box, list) and len(box) == 4 and all(isinstance(v, int | float) for v in box)
        if not ok or not all(math.isfinite(v) for v in box) or box[2] <= 0 or box[3] <= 0:
            raise InputError(f"{where}: bbox {box!r}; need [x, y, w, h] with w, h > 0")
        fid, stem = images[a["image_id"]]
        key = (a["image_id"], track)
        if key in seen:
            raise InputError(f"{where}: track {track} twice in image {a['image_id']}; one box per track and frame")
        seen.add(key)
        frame = -1 if fid is None else fid
        xywh = tuple(float(v) for v in box)
        boxes.append(TrackBox(frame, track, names[a["category_id"]], xywh, float(a.get("score", 1.0)), stem))
    return boxes


def format_number(v: float) -> str:
    """``v`` rounded to 1e-4 px, without trailing zeros (``100``, ``10.37``)."""
    return np.format_float_positional(round(float(v), 4) + 0.0, trim="-")  # + 0.0: no "-0"


def mot_line(frame: int, track_id: int, box_xywh, conf: float = 1.0) -> str:
    """A MOTChallenge line (ten columns, world coordinates -1) of the COCO box ``box_xywh`` in the 0-based
    ``frame``."""
    x, y, w, h = (float(v) for v in box_xywh)
    values = (x + MOT_ORIGIN_PX, y + MOT_ORIGIN_PX, w, h, conf)
    return f"{frame + 1},{track_id}," + ",".join(format_number(v) for v in values) + ",-1,-1,-1"

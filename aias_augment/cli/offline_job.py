"""One image of an offline run: :class:`Item` (an input image and what its dataset says about it) and
:func:`process_item`, the job every backend runs (the serial loop and the spawn pool of :mod:`aias_augment.cli.offline`,
the Ray tasks of :mod:`aias_augment.cli.offline_ray`): augment the image with its own generator
``default_rng([seed, index])``, write its image and record atomically, reuse a previous record whose input hash
matches.
"""

from __future__ import annotations

import json
import logging
import math
from dataclasses import asdict, dataclass, field
from pathlib import Path

import cv2
import numpy as np

from aias_augment.adapters.boundary import ImageSkip, nothing_inserted_reason, problem, read_image_checked
from aias_augment.cli.dataset_out import ImageOut
from aias_augment.cli.manifest import TEMP_TAG, item_hash, write_file, write_json
from aias_augment.core.geometry import Intrinsics
from aias_augment.core.image_io import read_image
from aias_augment.pipeline.bounded import insert_bounded
from aias_augment.pipeline.image import InsertionConfig
from aias_augment.pipeline.working import rescale_intrinsics

log = logging.getLogger(__name__)


@dataclass
class Item:
    """One input image with what the scene offers (all optional but the path)."""

    path: str
    bboxes_xywh: list = field(default_factory=list)
    labels: list = field(default_factory=list)
    K: list | None = None  # 3x3 intrinsics
    stereo_right: str | None = None  # rectified right image -> depth by SGBM
    baseline_m: float | None = None
    meta: dict = field(default_factory=dict)
    problems: list = field(default_factory=list)  # input notes (validate.problem dicts): clipped/dropped boxes
    invalid: ImageSkip | None = None  # a label problem: the image is skipped without being read


def read_rgb(path: str) -> np.ndarray:
    """(H, W, 3) uint8 RGB, upright, by the package's reader."""
    return read_image(path)


def write_rgb(path: Path, image: np.ndarray, temp_prefix: str = TEMP_TAG) -> None:
    """Write an RGB image atomically through ``<temp_prefix><name>`` in its folder (the format from the suffix)."""

    def put(tmp: Path) -> None:
        if not cv2.imwrite(str(tmp), image[..., ::-1]):
            raise OSError(f"cannot write {path}")

    write_file(Path(path), temp_prefix, put)


def resolve_yolo_boxes(item: Item, image: np.ndarray, class_names) -> None:
    rows = item.meta.pop("yolo_rows", None)
    if rows is None:
        return
    h, w = image.shape[:2]
    for r in rows:  # validated by parse_yolo_labels: 0 <= c < len(class_names), inside [0, 1]
        c, cx, cy, bw, bh = int(float(r[0])), *map(float, r[1:5])
        x0, y0 = max((cx - bw / 2) * w, 0.0), max((cy - bh / 2) * h, 0.0)
        x1, y1 = min((cx + bw / 2) * w, float(w)), min((cy + bh / 2) * h, float(h))
        if x1 <= x0 or y1 <= y0:
            continue
        item.bboxes_xywh.append([x0, y0, x1 - x0, y1 - y0])
        item.labels.append(class_names[c] if class_names and c < len(class_names) else str(c))


_SCENE_CACHES: dict = {}  # per process: scene-cache folder (or None) -> SceneCache


def _scene_cache(directory: str | None):
    from aias_augment.analyse.cache import SceneCache

    if directory not in _SCENE_CACHES:
        _SCENE_CACHES[directory] = SceneCache(max_items=32, directory=directory)
    return _SCENE_CACHES[directory]


def _bound_size(image: np.ndarray, item: Item, max_pixels: int | None) -> tuple[np.ndarray, float]:
    """Images above ``max_pixels`` are augmented at a bounded size (INTER_AREA, boxes scaled): memory and time stay
    bounded; the record says ``scale`` and ``source_size``."""
    h, w = image.shape[:2]
    if not max_pixels or h * w <= max_pixels:
        return image, 1.0
    s = math.sqrt(max_pixels / (h * w))
    nw, nh = max(1, int(w * s)), max(1, int(h * s))
    sx, sy = nw / w, nh / h
    item.bboxes_xywh = [[b[0] * sx, b[1] * sy, b[2] * sx, b[3] * sy] for b in item.bboxes_xywh]
    if item.K is not None:  # pixel centres move as the resize moves them: (u + 0.5) s - 0.5
        item.K = rescale_intrinsics(Intrinsics.from_matrix(np.asarray(item.K, float), w, h), nw, nh).K.tolist()
    return cv2.resize(image, (nw, nh), interpolation=cv2.INTER_AREA), min(sx, sy)


def _load_record(rec_path: Path, item: Item, input_hash: str | None) -> dict | None:
    """The previous record of this index if it may be reused: same source and input hash, not a skip."""
    if not rec_path.exists():
        return None
    try:
        with open(rec_path) as f:
            rec = json.load(f)
    except ValueError:
        return None
    if "skipped" in rec or rec.get("source") != item.path or rec.get("input_hash") != input_hash:
        return None
    return rec


def _prepared_image(item: Item, class_names, max_pixels: int | None, notes: list):
    """(image, scale, source size (w, h), intrinsics or None, depth or None) of ``item``: the image read and checked
    against its json size, its YOLO boxes resolved, bounded to ``max_pixels`` (noted), its K and stereo depth at
    that size. A problem raises (:class:`ImageSkip` or another error: the caller's counted skip)."""
    image, conv = read_image_checked(item.path)
    notes += conv
    size = item.meta.pop("coco_size", None)
    if size and size[0] and size[1] and tuple(size) != (image.shape[1], image.shape[0]):
        raise ImageSkip(
            "image size mismatch",
            f"the json says {size[0]}x{size[1]}, the file is {image.shape[1]}x{image.shape[0]}",
        )
    item.meta.pop("label_file", None)
    resolve_yolo_boxes(item, image, class_names)
    source_size = [int(image.shape[1]), int(image.shape[0])]
    image, scale = _bound_size(image, item, max_pixels)
    if scale != 1.0:
        notes.append(
            problem(
                "downscaled",
                item.path,
                f"{source_size[0]}x{source_size[1]} augmented at {image.shape[1]}x{image.shape[0]} (--max-megapixels)",
            )
        )
    intr = None
    if item.K is not None:
        intr = Intrinsics.from_matrix(np.asarray(item.K), image.shape[1], image.shape[0])
    depth = None
    if item.stereo_right is not None:
        from aias_augment.scenes.stereo import stereo_depth

        depth = stereo_depth(image, read_rgb(item.stereo_right), intr, item.baseline_m)
    return image, scale, source_size, intr, depth


def _skip_record(e: Exception, index: int, item: Item, input_hash: str, notes: list) -> dict:
    """The record of an image skipped for ``e`` (its kind and line when it is an :class:`ImageSkip`), logged."""
    if isinstance(e, ImageSkip):
        kind, line, msg = e.kind, e.line, str(e)
    else:
        kind, line, msg = "failed", None, f"{type(e).__name__}: {e}"
    log.warning("skipping %s: %s", item.path, msg)
    return {
        "index": index,
        "source": item.path,
        "input_hash": input_hash,
        "skipped": msg,
        "skip_kind": kind,
        "skip_line": line,
        "input_notes": notes,
    }


def process_item(
    index: int,
    item: Item,
    cfg: InsertionConfig,
    seed: int,
    out_dir: str,
    class_names=None,
    scene_cache: str | None = None,
    input_hash: str | None = None,
    max_pixels: int | None = None,
    bank=None,
    temp_prefix: str = TEMP_TAG,
    image_out: ImageOut | None = None,
) -> dict:
    """Augment one image; returns its record (also written to ``records/<index>.json``). ``scene_cache``: a folder
    of scene analyses shared by workers and runs (an image augmented again is not analysed again). A previous
    record is reused only when it is not a skip and its ``input_hash`` matches (failed and changed inputs are
    redone). ``bank``: the asset source of the insertion (e.g. :class:`aias_augment.assets.asset.PathAssets` of the
    user's meshes; picklable, it goes to every worker); None: the default assets. ``temp_prefix``: the run's
    temporary-file prefix (the manifest's), the only names its start-up cleanup removes. ``image_out``: the
    image's name and format (:class:`aias_augment.cli.dataset_out.ImageOut`; None: PNG under ``images/``)."""
    import copy

    item = copy.deepcopy(item)  # resolving labels and bounding the size change it
    out = Path(out_dir)
    rec_path = out / "records" / f"{index:06d}.json"
    input_hash = input_hash or item_hash(item)
    previous = _load_record(rec_path, item, input_hash)
    if previous is not None:
        return previous
    image_out = image_out or ImageOut()
    name = image_out.file_name(index, item.path)
    (out / "images" / name).unlink(missing_ok=True)  # never leave a stale image behind a new record
    import time

    t0 = time.perf_counter()
    rng = np.random.default_rng([seed, index])
    notes = list(item.problems)
    try:
        if item.invalid:
            raise item.invalid
        image, scale, source_size, intr, depth = _prepared_image(item, class_names, max_pixels, notes)
        # above 2 MP: analysed and planned at 2 MP, rendered at the (bounded) output size
        res = insert_bounded(
            image,
            item.bboxes_xywh,
            item.labels,
            rng,
            cfg,
            intrinsics=intr,
            depth=depth,
            meta=item.meta,
            scene_cache=_scene_cache(scene_cache),
            bank=bank,
        )
    except Exception as e:  # counted, logged skip: one bad image never stops the run
        rec = _skip_record(e, index, item, input_hash, notes)
        write_json(rec_path, rec, temp_prefix)
        return rec
    image_out.write(out / "images" / name, res.image, temp_prefix)
    n_keep = int(res.keep_existing.sum())
    rec = {
        "index": index,
        "source": item.path,
        "file_name": name,
        "seed": [seed, index],
        "width": int(res.image.shape[1]),
        "height": int(res.image.shape[0]),
        "boxes": [list(map(float, b)) for b in res.bboxes],
        "labels": [str(lab) for lab in res.labels],
        "inserted": [False] * n_keep + [True] * len(res.inserted_labels),
        "seconds": time.perf_counter() - t0,
        "config": asdict(cfg),
        **res.record.to_dict(),
        "input_hash": input_hash,
        "input_notes": notes,
        "scale": scale,
        "source_size": source_size,
    }
    if not res.inserted_labels:  # counted with its reason in report.json
        rec["nothing_inserted"] = nothing_inserted_reason(res.record.to_dict())
    write_json(rec_path, rec, temp_prefix)
    return rec

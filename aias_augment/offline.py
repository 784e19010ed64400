"""Offline augmentation of a dataset: one record per image (replayable), resumable, any number of workers.

Each image gets its own generator ``default_rng([seed, index])``, so the output does not depend on the number of
workers or on the order in which they finish. Records and images are written atomically; an image whose record
exists is skipped, so a killed run resumes where it stopped. Workers are started with ``spawn`` (an EGL context
must not be inherited through fork).
"""
from __future__ import annotations

import json
import logging
import math
import multiprocessing as mp
import os
from dataclasses import asdict, dataclass, field
from pathlib import Path

import cv2
import numpy as np
from tqdm import tqdm

from .coco_io import CocoBuilder, atomic_write_json
from .geometry import Intrinsics
from .manifest import build_manifest, item_hash, output_lock, prepare_output
from .validate import (IMAGE_SKIP_KINDS, InputError, check_box, check_coco, check_coco_file, check_output_record,
                       nothing_inserted_reason, parse_yolo_labels, problem, read_image_checked)
from .pipeline import InsertionConfig
from .working_resolution import insert_bounded
from .viz import contact_sheet, draw_boxes

log = logging.getLogger(__name__)
IMAGE_SUFFIXES = {".jpg", ".jpeg", ".png", ".bmp"}


@dataclass
class Item:
    """One input image with what the scene offers (all optional but the path)."""

    path: str
    bboxes_xywh: list = field(default_factory=list)
    labels: list = field(default_factory=list)
    K: list | None = None                     # 3x3 intrinsics
    stereo_right: str | None = None           # rectified right image -> depth by SGBM
    baseline_m: float | None = None
    meta: dict = field(default_factory=dict)
    problems: list = field(default_factory=list)   # input notes (validate.problem dicts): clipped/dropped boxes
    invalid: str | None = None                     # "<kind>: <reason>": the image is skipped without being read


def read_rgb(path: str) -> np.ndarray:
    img = cv2.imread(str(path), cv2.IMREAD_COLOR)
    if img is None:
        raise ValueError(f"cannot read image {path}")
    return np.ascontiguousarray(img[..., ::-1])


def write_rgb(path: Path, image: np.ndarray) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(path.stem + ".tmp" + path.suffix)
    if not cv2.imwrite(str(tmp), image[..., ::-1]):
        raise OSError(f"cannot write {path}")
    os.replace(tmp, path)


def items_from_coco(json_path: str, images_dir: str, box_policy: str = "clip") -> list[Item]:
    """COCO json -> items. Duplicate image/annotation/category ids: InputError. Per image (a named skip): a bbox
    that is not 4 finite numbers, an unknown category id. Per box: zero/negative size dropped, outside the image's
    json width/height clipped or dropped (``box_policy``), each counted in ``Item.problems``."""
    try:
        with open(json_path) as f:
            data = json.load(f)
    except (OSError, ValueError) as e:
        raise InputError(f"cannot read COCO json {json_path}: {e}") from None
    check_coco(data, json_path)
    names = {c["id"]: c["name"] for c in data.get("categories", [])}
    anns: dict[int, list] = {}
    ids = {im["id"] for im in data["images"]}
    orphans = 0
    for a in data.get("annotations", []):
        if a.get("image_id") not in ids:
            orphans += 1
            continue
        anns.setdefault(a["image_id"], []).append(a)
    if orphans:
        log.warning("%s: %d annotations refer to no image (ignored)", json_path, orphans)
    items = []
    for im in data["images"]:
        item = Item(str(Path(images_dir) / im["file_name"]), meta={"coco_size": [im.get("width"), im.get("height")]})
        try:
            for a in anns.get(im["id"], []):
                where = f"annotation {a['id']}"
                if a.get("category_id") not in names:
                    raise ValueError(f"unknown category id: {where}: category_id {a.get('category_id')!r} is not "
                                     f"in the categories")
                b = a.get("bbox")
                try:
                    x, y, w, h = (float(v) for v in b)
                except (TypeError, ValueError):
                    raise ValueError(f"garbage label line: {where}: bbox {b!r} is not 4 numbers") from None
                W, H = im.get("width") or math.inf, im.get("height") or math.inf
                try:
                    box = check_box(x, y, w, h, W, H, box_policy, f"{json_path} ({where})", None, item.problems)
                except ValueError as e:
                    raise ValueError(f"{e} ({where})") from None
                if box is not None:
                    item.bboxes_xywh.append(box)
                    item.labels.append(names[a["category_id"]])
        except ValueError as e:
            item.invalid, item.bboxes_xywh, item.labels = str(e), [], []
        items.append(item)
    return items


def coco_categories(json_path: str) -> dict[str, int]:
    """The input's category name -> id, so that output ids are the user's (a name listed twice keeps its first
    id, as :func:`items_from_coco` labels boxes by name)."""
    try:
        with open(json_path) as f:
            cats = json.load(f).get("categories", [])
    except (OSError, ValueError) as e:
        raise InputError(f"cannot read COCO json {json_path}: {e}") from None
    out: dict[str, int] = {}
    for c in cats:
        out.setdefault(c["name"], int(c["id"]))
    return out


def output_categories(input_categories: dict[str, int] | None, class_names, inserted: tuple[str, ...]) -> dict:
    """Output category name -> id: the input's ids as they are (COCO), YOLO class ``i`` as id ``i + 1`` (its names
    when given), then each inserted category the input lacks, in config order, after the largest id. Fixed before
    any image is written, so ids never depend on which image comes first."""
    cats = dict(input_categories or {})
    if not cats and class_names:
        cats = {name: i + 1 for i, name in enumerate(class_names)}
    for name in inserted:
        if name not in cats:
            cats[name] = max(cats.values(), default=0) + 1
    return cats


def image_files(images_dir) -> list[Path]:
    """The images (:data:`IMAGE_SUFFIXES`) directly in ``images_dir``, sorted by name; not a folder: InputError."""
    images_dir = Path(images_dir)
    if not images_dir.is_dir():
        raise InputError(f"{images_dir} is not a folder")
    return [p for p in sorted(images_dir.iterdir()) if p.suffix.lower() in IMAGE_SUFFIXES]


def items_from_images(images_dir: str) -> list[Item]:
    """A folder of unlabelled background images (``aias-augment --images DIR`` alone): items without boxes, so the
    output holds only the inserted objects."""
    return [Item(str(p)) for p in image_files(images_dir)]


def items_from_yolo(images_dir: str, labels_dir: str | None = None, class_names: list[str] | None = None,
                    box_policy: str = "clip") -> list[Item]:
    """YOLO txt: ``class cx cy w h`` normalised; labels in ``labels_dir`` (default: images/ -> labels/). Checked
    here (:func:`aias_augment.validate.parse_yolo_labels`): a garbage line, a class id out of range or a NaN makes
    that image a named skip (file and line); boxes of zero size are dropped, boxes outside the image clipped or
    dropped (``box_policy``), each counted. A missing label file means no objects (YOLO's convention)."""
    images_dir = Path(images_dir)
    labels_dir = Path(labels_dir) if labels_dir else Path(str(images_dir).replace("images", "labels"))
    items = []
    for p in image_files(images_dir):
        lab = labels_dir / (p.stem + ".txt")
        item = Item(str(p), meta={"yolo_rows": []})
        if lab.exists():
            item.meta["label_file"] = str(lab)
            try:
                item.meta["yolo_rows"], item.problems = parse_yolo_labels(lab, class_names, box_policy)
            except ValueError as e:
                item.invalid = str(e)
        items.append(item)
    return items


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


_SCENE_CACHES: dict = {}   # per process: scene-cache folder (or None) -> SceneCache


def _scene_cache(directory: str | None):
    from .insertion.cache import SceneCache
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
    if item.K is not None:
        K = np.asarray(item.K, float).copy()
        K[0] *= sx
        K[1] *= sy
        item.K = K.tolist()
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


def process_item(index: int, item: Item, cfg: InsertionConfig, seed: int, out_dir: str,
                 class_names=None, scene_cache: str | None = None, input_hash: str | None = None,
                 max_pixels: int | None = None, bank=None) -> dict:
    """Augment one image; returns its record (also written to ``records/<index>.json``). ``scene_cache``: a folder
    of scene analyses shared by workers and runs (an image augmented again is not analysed again). A previous
    record is reused only when it is not a skip and its ``input_hash`` matches (failed and changed inputs are
    redone). ``bank``: the asset source of the insertion (e.g. :class:`aias_augment.assets.PathAssets` of the
    user's meshes; picklable, it goes to every worker); None: the default assets."""
    import copy
    item = copy.deepcopy(item)   # resolving labels and bounding the size change it
    out = Path(out_dir)
    rec_path = out / "records" / f"{index:06d}.json"
    input_hash = input_hash or item_hash(item)
    previous = _load_record(rec_path, item, input_hash)
    if previous is not None:
        return previous
    name = f"{index:06d}_{Path(item.path).stem}.png"
    (out / "images" / name).unlink(missing_ok=True)   # never leave a stale image behind a new record
    import time
    t0 = time.perf_counter()
    rng = np.random.default_rng([seed, index])
    notes = list(item.problems)
    try:
        if item.invalid:
            raise ValueError(item.invalid)
        image, conv = read_image_checked(item.path)
        notes += conv
        size = item.meta.pop("coco_size", None)
        if size and size[0] and size[1] and tuple(size) != (image.shape[1], image.shape[0]):
            raise ValueError(f"image size mismatch: the json says {size[0]}x{size[1]}, the file is "
                             f"{image.shape[1]}x{image.shape[0]}")
        item.meta.pop("label_file", None)
        resolve_yolo_boxes(item, image, class_names)
        source_size = [int(image.shape[1]), int(image.shape[0])]
        image, scale = _bound_size(image, item, max_pixels)
        if scale != 1.0:
            notes.append(problem("downscaled", item.path, f"{source_size[0]}x{source_size[1]} augmented at "
                                 f"{image.shape[1]}x{image.shape[0]} (--max-megapixels)"))
        intr = None
        if item.K is not None:
            intr = Intrinsics.from_matrix(np.asarray(item.K), image.shape[1], image.shape[0])
        depth = None
        if item.stereo_right is not None:
            from .stereo import stereo_depth
            depth = stereo_depth(image, read_rgb(item.stereo_right), intr, item.baseline_m)
        # above 2 MP: analysed and planned at 2 MP, rendered at the (bounded) output size
        res = insert_bounded(image, item.bboxes_xywh, item.labels, rng, cfg, intrinsics=intr, depth=depth,
                             meta=item.meta, scene_cache=_scene_cache(scene_cache), bank=bank)
    except Exception as e:  # counted, logged skip: one bad image never stops the run
        msg = str(e)
        kind = msg.split(":", 1)[0] if isinstance(e, ValueError) and ":" in msg else None
        if kind not in IMAGE_SKIP_KINDS:
            kind, msg = "failed", f"{type(e).__name__}: {e}"
        log.warning("skipping %s: %s", item.path, msg)
        rec = {"index": index, "source": item.path, "input_hash": input_hash, "skipped": msg, "skip_kind": kind,
               "input_notes": notes}
        atomic_write_json(rec_path, rec)
        return rec
    write_rgb(out / "images" / name, res.image)
    n_keep = int(res.keep_existing.sum())
    rec = {
        "index": index, "source": item.path, "file_name": name, "seed": [seed, index],
        "width": int(res.image.shape[1]), "height": int(res.image.shape[0]),
        "boxes": [list(map(float, b)) for b in res.bboxes], "labels": [str(lab) for lab in res.labels],
        "inserted": [False] * n_keep + [True] * len(res.inserted_labels),
        "seconds": time.perf_counter() - t0, "config": asdict(cfg), **res.record.to_dict(),
        "input_hash": input_hash, "input_notes": notes, "scale": scale, "source_size": source_size,
    }
    if not res.inserted_labels:   # counted with its reason in report.json
        rec["nothing_inserted"] = nothing_inserted_reason(res.record.to_dict())
    atomic_write_json(rec_path, rec)
    return rec


def _worker(args):
    return process_item(*args)


def run(items: list[Item], cfg: InsertionConfig, seed: int, out_dir: str, workers: int = 1,
        class_names=None, sheet_size: int = 12, scene_cache: str | None = None, *, preset: str | None = None,
        overwrite: bool = False, max_pixels: int | None = None, options: dict | None = None,
        backend: str = "local", ray_address: str | None = None,
        categories: dict[str, int] | None = None, bank=None) -> dict:
    """Augment all items, then write ``annotations.json`` (COCO, validated), ``report.json`` and
    ``contact_sheet.png``.

    ``out_dir/manifest.json`` records what the folder is made from (:mod:`aias_augment.manifest`): the same run
    resumes (failed and changed inputs are redone), another run is refused (ManifestMismatch) unless ``overwrite``.
    No items: InputError. ``max_pixels``: larger images are augmented at a bounded size (recorded).
    ``backend``: "local" (this process or a spawn pool of ``workers``) or "ray" (Ray tasks on ``ray_address`` or a
    local Ray instance of ``workers`` CPUs); outputs are the same bytes either way. ``categories``: the input's
    category name -> id (:func:`coco_categories`), kept in the output (:func:`output_categories`).
    ``bank``: the asset source passed to every insertion (:func:`process_item`); what it holds belongs in
    ``options`` (the manifest), so that a run with other assets is not resumed from this one's records.
    A second run into an ``out_dir`` that a run is writing is refused at start (OutputBusy)."""
    if not items:
        raise InputError("no input images")
    with output_lock(Path(out_dir)):
        return _run(items, cfg, seed, out_dir, workers, class_names, sheet_size, scene_cache, preset=preset,
                    overwrite=overwrite, max_pixels=max_pixels, options=options, backend=backend,
                    ray_address=ray_address, categories=categories, bank=bank)


def _run(items: list[Item], cfg: InsertionConfig, seed: int, out_dir: str, workers: int = 1,
         class_names=None, sheet_size: int = 12, scene_cache: str | None = None, *, preset: str | None = None,
         overwrite: bool = False, max_pixels: int | None = None, options: dict | None = None,
         backend: str = "local", ray_address: str | None = None,
         categories: dict[str, int] | None = None, bank=None) -> dict:
    out = Path(out_dir)
    hashes = [item_hash(it) for it in items]
    out_categories = output_categories(categories, class_names, tuple(cfg.categories))
    manifest = build_manifest(items, cfg, seed, preset, {**(options or {}), "class_names": class_names,
                                                           "max_pixels": max_pixels, "categories": out_categories})
    manifest["inputs"] = [{"path": it.path, "sha256": h} for it, h in zip(items, hashes)]
    prepare_output(out, manifest, overwrite)
    jobs = [(i, it, cfg, seed, str(out), class_names, None if scene_cache is None else str(scene_cache), h,
             max_pixels, bank) for i, (it, h) in enumerate(zip(items, hashes))]
    records = []
    if backend == "ray":   # Ray tasks (aias_augment.offline_ray): the same process_item, the same bytes
        from .offline_ray import run_jobs
        with tqdm(total=len(jobs), desc="aias-augment[ray]", unit="img") as bar:
            records = run_jobs(jobs, workers, ray_address, progress=bar)
    elif backend != "local":
        raise InputError(f"unknown backend {backend!r} (local or ray)")
    elif workers <= 1:
        for j in tqdm(jobs, desc="aias-augment", unit="img"):
            records.append(_worker(j))
    else:
        with mp.get_context("spawn").Pool(workers) as pool:
            for r in tqdm(pool.imap(_worker, jobs), total=len(jobs), desc="aias-augment", unit="img"):
                records.append(r)
    coco = CocoBuilder(out_categories)
    sheet = []
    for rec in records:
        if "skipped" in rec:
            continue
        errs = check_output_record(rec, out)
        if errs:   # a bug upstream: the image is left out and named, never written as a wrong annotation
            log.error("output check failed for %s: %s", rec["source"], "; ".join(errs))
            rec["output_errors"] = errs
            continue
        image_id = coco.add_image(rec["file_name"], rec["width"], rec["height"], source=rec["source"])
        inserted_anns = iter(rec["annotations"])
        for box, lab, ins in zip(rec["boxes"], rec["labels"], rec["inserted"]):
            extra = {}
            if ins:
                a = next(inserted_anns)
                while a["visible_box_xywh"] is None:
                    a = next(inserted_anns)
                extra = {"segmentation": a["rle"], "area": a["area"], "amodal_bbox": a["amodal_box_xywh"],
                         "visibility": a["visibility"]}
            coco.add_box(image_id, lab, box, inserted=ins, **extra)
        if len(sheet) < sheet_size:
            sheet.append(draw_boxes(read_rgb(str(out / "images" / rec["file_name"])), rec["boxes"], rec["labels"],
                                    rec["inserted"]))
    tmp = out / "annotations.json.check"
    coco.write(tmp)
    check_coco_file(tmp, out / "images")
    os.replace(tmp, out / "annotations.json")
    report = build_report(records)
    atomic_write_json(out / "report.json", report)
    if sheet:
        write_rgb(out / "contact_sheet.png", contact_sheet(sheet))
    times = [r["seconds"] for r in records if "seconds" in r]
    summary = {"images": len(records), "written": len(coco.images),
               "skipped": sum("skipped" in r or "output_errors" in r for r in records),
               "inserted": sum(sum(r.get("inserted", [])) for r in records if "output_errors" not in r),
               "nothing_inserted": sum("nothing_inserted" in r for r in records),
               "box_notes": sum(v for k, v in report["notes"].items() if k.startswith("box")),
               "median_seconds_per_image": float(np.median(times)) if times else None}
    atomic_write_json(out / "summary.json", summary)
    return summary


def build_report(records: list[dict]) -> dict:
    """``report.json``: skipped images by kind (file, line, reason), box notes and conversions by kind, images
    where nothing was inserted by reason."""
    from collections import Counter
    skipped: dict[str, list] = {}
    notes: Counter = Counter()
    note_list: list = []
    nothing: dict[str, list] = {}
    for r in records:
        for n in r.get("input_notes", []):
            notes[n["kind"]] += 1
            note_list.append(n)
        if "skipped" in r:
            line = None
            import re
            m = re.search(r":(\d+): ", r["skipped"])
            if m:
                line = int(m.group(1))
            skipped.setdefault(r.get("skip_kind", "failed"), []).append(
                {"file": r["source"], "line": line, "reason": r["skipped"]})
        elif "output_errors" in r:
            skipped.setdefault("output check failed", []).append(
                {"file": r["source"], "line": None, "reason": "; ".join(r["output_errors"])})
        elif "nothing_inserted" in r:
            nothing.setdefault(r["nothing_inserted"], []).append(r["source"])
    return {"images": len(records), "skipped": sum(len(v) for v in skipped.values()),
            "skipped_by_kind": {k: len(v) for k, v in sorted(skipped.items())}, "skips": skipped,
            "notes": dict(sorted(notes.items())), "note_list": note_list,
            "nothing_inserted": {k: len(v) for k, v in nothing.items()}, "nothing_inserted_images": nothing}

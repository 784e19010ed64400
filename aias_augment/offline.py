"""Offline augmentation of a dataset: one record per image (replayable), resumable, any number of workers.

Each image gets its own generator ``default_rng([seed, index])``, so the output does not depend on the number of
workers or on the order in which they finish. Records and images are written atomically; an image whose record
exists is skipped, so a killed run resumes where it stopped. Workers are started with ``spawn`` (an EGL context
must not be inherited through fork).
"""
from __future__ import annotations

import json
import logging
import multiprocessing as mp
import os
from dataclasses import asdict, dataclass, field
from pathlib import Path

import cv2
import numpy as np
from tqdm import tqdm

from .coco_io import CocoBuilder, atomic_write_json
from .geometry import Intrinsics
from .pipeline import InsertionConfig, insert_into_image
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


def items_from_coco(json_path: str, images_dir: str) -> list[Item]:
    with open(json_path) as f:
        data = json.load(f)
    names = {c["id"]: c["name"] for c in data.get("categories", [])}
    anns: dict[int, list] = {}
    for a in data.get("annotations", []):
        anns.setdefault(a["image_id"], []).append(a)
    return [Item(str(Path(images_dir) / im["file_name"]), [a["bbox"] for a in anns.get(im["id"], [])],
                 [names.get(a["category_id"], str(a["category_id"])) for a in anns.get(im["id"], [])])
            for im in data["images"]]


def items_from_yolo(images_dir: str, labels_dir: str | None = None, class_names: list[str] | None = None) -> list[Item]:
    """YOLO txt: ``class cx cy w h`` normalised; labels in ``labels_dir`` (default: images/ -> labels/)."""
    images_dir = Path(images_dir)
    labels_dir = Path(labels_dir) if labels_dir else Path(str(images_dir).replace("images", "labels"))
    items = []
    for p in sorted(images_dir.iterdir()):
        if p.suffix.lower() not in IMAGE_SUFFIXES:
            continue
        lab = labels_dir / (p.stem + ".txt")
        rows = []
        if lab.exists():
            rows = [r.split() for r in lab.read_text().splitlines() if r.strip()]
        items.append(Item(str(p), meta={"yolo_rows": rows}))
    return items


def _resolve_yolo(item: Item, image: np.ndarray, class_names) -> None:
    rows = item.meta.pop("yolo_rows", None)
    if rows is None:
        return
    h, w = image.shape[:2]
    for r in rows:
        c, cx, cy, bw, bh = int(float(r[0])), *map(float, r[1:5])
        item.bboxes_xywh.append([(cx - bw / 2) * w, (cy - bh / 2) * h, bw * w, bh * h])
        item.labels.append(class_names[c] if class_names and c < len(class_names) else str(c))


_SCENE_CACHES: dict = {}   # per process: scene-cache folder (or None) -> SceneCache


def _scene_cache(directory: str | None):
    from .insertion.cache import SceneCache
    if directory not in _SCENE_CACHES:
        _SCENE_CACHES[directory] = SceneCache(max_items=32, directory=directory)
    return _SCENE_CACHES[directory]


def process_item(index: int, item: Item, cfg: InsertionConfig, seed: int, out_dir: str,
                 class_names=None, scene_cache: str | None = None) -> dict:
    """Augment one image; returns its record (also written to ``records/<index>.json``). ``scene_cache``: a folder
    of scene analyses shared by workers and runs (an image augmented again is not analysed again)."""
    out = Path(out_dir)
    rec_path = out / "records" / f"{index:06d}.json"
    if rec_path.exists():
        with open(rec_path) as f:
            return json.load(f)
    import time
    t0 = time.perf_counter()
    rng = np.random.default_rng([seed, index])
    try:
        image = read_rgb(item.path)
        _resolve_yolo(item, image, class_names)
        intr = None
        if item.K is not None:
            intr = Intrinsics.from_matrix(np.asarray(item.K), image.shape[1], image.shape[0])
        depth = None
        if item.stereo_right is not None:
            from .stereo import stereo_depth
            depth = stereo_depth(image, read_rgb(item.stereo_right), intr, item.baseline_m)
        res = insert_into_image(image, item.bboxes_xywh, item.labels, rng, cfg, intrinsics=intr, depth=depth,
                                meta=item.meta, scene_cache=_scene_cache(scene_cache))
    except Exception as e:  # counted, logged skip: one bad image never stops the run
        log.warning("skipping %s: %s: %s", item.path, type(e).__name__, e)
        rec = {"index": index, "source": item.path, "skipped": f"{type(e).__name__}: {e}"}
        atomic_write_json(rec_path, rec)
        return rec
    name = f"{index:06d}_{Path(item.path).stem}.png"
    write_rgb(out / "images" / name, res.image)
    n_keep = int(res.keep_existing.sum())
    rec = {
        "index": index, "source": item.path, "file_name": name, "seed": [seed, index],
        "width": int(res.image.shape[1]), "height": int(res.image.shape[0]),
        "boxes": [list(map(float, b)) for b in res.bboxes], "labels": [str(l) for l in res.labels],
        "inserted": [False] * n_keep + [True] * len(res.inserted_labels),
        "seconds": time.perf_counter() - t0, "config": asdict(cfg), **res.record.to_dict(),
    }
    atomic_write_json(rec_path, rec)
    return rec


def _worker(args):
    return process_item(*args)


def run(items: list[Item], cfg: InsertionConfig, seed: int, out_dir: str, workers: int = 1,
        class_names=None, sheet_size: int = 12, scene_cache: str | None = None) -> dict:
    """Augment all items, then write ``annotations.json`` (COCO, validated) and ``contact_sheet.png``."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    jobs = [(i, it, cfg, seed, str(out), class_names, None if scene_cache is None else str(scene_cache))
            for i, it in enumerate(items)]
    records = []
    if workers <= 1:
        for j in tqdm(jobs, desc="aias-augment", unit="img"):
            records.append(_worker(j))
    else:
        with mp.get_context("spawn").Pool(workers) as pool:
            for r in tqdm(pool.imap(_worker, jobs), total=len(jobs), desc="aias-augment", unit="img"):
                records.append(r)
    coco = CocoBuilder()
    sheet = []
    for rec in records:
        if "skipped" in rec:
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
    coco.write(out / "annotations.json")
    if sheet:
        write_rgb(out / "contact_sheet.png", contact_sheet(sheet))
    times = [r["seconds"] for r in records if "seconds" in r]
    summary = {"images": len(records), "skipped": sum("skipped" in r for r in records),
               "inserted": sum(sum(r.get("inserted", [])) for r in records),
               "median_seconds_per_image": float(np.median(times)) if times else None}
    atomic_write_json(out / "summary.json", summary)
    return summary

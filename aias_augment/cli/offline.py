"""Offline augmentation of a dataset: one record per image (replayable), resumable, any number of workers.

Each image gets its own generator ``default_rng([seed, index])``, so the output does not depend on the number of
workers or on the order in which they finish. Records and images are written atomically; an image whose record
exists is skipped, so a killed run resumes where it stopped. Workers are started with ``spawn`` (an EGL context
must not be inherited through fork). The job of one image, :func:`~aias_augment.cli.offline_job.process_item`, lives in
:mod:`aias_augment.cli.offline_job`, which every backend (here and :mod:`aias_augment.cli.offline_ray`) runs.
"""

from __future__ import annotations

import json
import logging
import math
import multiprocessing as mp
from pathlib import Path

import numpy as np
from tqdm import tqdm

from aias_augment.adapters.boundary import (
    ImageSkip,
    InputError,
    check_box,
    check_coco,
    check_coco_file,
    check_output_record,
    parse_yolo_labels,
)
from aias_augment.cli.dataset_out import DatasetOutput, write_outputs
from aias_augment.cli.dataset_out import planned_outputs as dataset_outputs
from aias_augment.cli.manifest import (
    build_manifest,
    check_out_apart,
    item_hash,
    mark_complete,
    output_lock,
    planned_outputs,
    prepare_output,
    write_file,
    write_json,
)
from aias_augment.cli.offline_job import Item, process_item, read_rgb, resolve_yolo_boxes, write_rgb  # noqa: F401  (public here too)
from aias_augment.cli.offline_ray import run_jobs as run_ray_jobs
from aias_augment.core.coco_io import CocoBuilder
from aias_augment.core.logs import progress_disabled
from aias_augment.core.viz import contact_sheet, draw_boxes
from aias_augment.pipeline.image import InsertionConfig

log = logging.getLogger(__name__)
IMAGE_SUFFIXES = {".jpg", ".jpeg", ".png", ".bmp"}


def items_from_coco(json_path: str, images_dir: str, box_policy: str = "clip") -> list[Item]:
    """COCO json -> items. Duplicate image/annotation/category ids: InputError. Per image (a named skip): a bbox
    that is not 4 finite numbers, an unknown category id. Per box: zero/negative size dropped, outside the image's
    json width/height clipped or dropped (``box_policy``), each counted in ``Item.problems``."""
    try:
        with open(json_path) as f:
            data = json.load(f)
    except (OSError, ValueError, RecursionError) as e:  # RecursionError: nested too deep
        raise InputError(f"cannot read COCO json {json_path}: {str(e) or type(e).__name__}") from None
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
                    raise ImageSkip(
                        "unknown category id", f"category_id {a.get('category_id')!r} is not in the categories", where
                    )
                b = a.get("bbox")
                try:
                    x, y, w, h = (float(v) for v in b)
                except (TypeError, ValueError):
                    raise ImageSkip("garbage label line", f"bbox {b!r} is not 4 numbers", where) from None
                W, H = im.get("width") or math.inf, im.get("height") or math.inf
                try:
                    box = check_box(x, y, w, h, W, H, box_policy, f"{json_path} ({where})", None, item.problems)
                except ImageSkip as e:
                    raise ImageSkip(e.kind, f"{e.reason} ({where})") from None
                if box is not None:
                    item.bboxes_xywh.append(box)
                    item.labels.append(names[a["category_id"]])
        except ImageSkip as e:
            item.invalid, item.bboxes_xywh, item.labels = e, [], []
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


def items_from_yolo(
    images_dir: str, labels_dir: str | None = None, class_names: list[str] | None = None, box_policy: str = "clip"
) -> list[Item]:
    """YOLO txt: ``class cx cy w h`` normalised; labels in ``labels_dir`` (default: images/ -> labels/). Checked
    here (:func:`aias_augment.adapters.boundary.parse_yolo_labels`): a garbage line, a class id out of range or a NaN makes
    that image a named skip (file and line); boxes of zero size are dropped, boxes outside the image clipped or
    dropped (``box_policy``), each counted. A missing label file means no objects (YOLO's convention)."""
    images_dir = Path(images_dir)
    labels_dir = Path(labels_dir) if labels_dir else default_labels_dir(images_dir)
    items = []
    for p in image_files(images_dir):
        lab = labels_dir / (p.stem + ".txt")
        item = Item(str(p), meta={"yolo_rows": []})
        if lab.exists():
            item.meta["label_file"] = str(lab)
            try:
                item.meta["yolo_rows"], item.problems = parse_yolo_labels(lab, class_names, box_policy)
            except ImageSkip as e:
                item.invalid = e
        items.append(item)
    return items


def default_labels_dir(images_dir) -> Path:
    """Where YOLO labels lie by default: the images folder's path with ``images`` replaced by ``labels``."""
    return Path(str(images_dir).replace("images", "labels"))


def named_inputs(args) -> list[tuple[str, str]]:
    """(option, path) of everything an ``aias-augment`` image run reads, from its parsed arguments: the dataset
    (json, images, YOLO images and labels), the config files, the assets and the envmap."""
    named = [
        ("--input", args.input),
        ("--images", args.images),
        ("--yolo", args.yolo),
        ("--yolo labels", default_labels_dir(args.yolo) if args.yolo else None),
        ("--config", args.config),
        ("--box-convention", args.box_convention),
        ("--envmap", args.envmap),
        ("--assets-bank", args.assets_bank),
    ]
    named += [("--assets", spec.partition("=")[2].strip()) for spec in args.assets or ()]
    return [(what, str(path)) for what, path in named if path]


def input_paths(items: list[Item]) -> list[tuple[str, str]]:
    """(what, path) of every file the items are read from and of their folders, for :func:`check_out_apart`."""
    files = [("input image", it.path) for it in items]
    files += [("label file", it.meta["label_file"]) for it in items if it.meta.get("label_file")]
    files += [("right image", it.stereo_right) for it in items if it.stereo_right]
    folders = {str(Path(p).parent) for _, p in files}
    return files + [("the folder of input", f) for f in sorted(folders)]


def _worker(args):
    return process_item(*args)


def run(
    items: list[Item],
    cfg: InsertionConfig,
    seed: int,
    out_dir: str,
    workers: int = 1,
    class_names=None,
    sheet_size: int = 12,
    scene_cache: str | None = None,
    *,
    preset: str | None = None,
    overwrite: bool = False,
    max_pixels: int | None = None,
    options: dict | None = None,
    backend: str = "local",
    ray_address: str | None = None,
    categories: dict[str, int] | None = None,
    bank=None,
    output: DatasetOutput | None = None,
) -> dict:
    """Augment all items, then write ``annotations.json`` (COCO, validated), ``report.json`` and
    ``contact_sheet.png``.

    ``out_dir/manifest.json`` records what the folder is made from (:mod:`aias_augment.cli.manifest`): the same run
    resumes (failed and changed inputs are redone), another run is refused (ManifestMismatch) unless ``overwrite``.
    No items: InputError. ``max_pixels``: larger images are augmented at a bounded size (recorded).
    ``backend``: "local" (this process or a spawn pool of ``workers``) or "ray" (Ray tasks on ``ray_address`` or a
    local Ray instance of ``workers`` CPUs); outputs are the same bytes either way. ``categories``: the input's
    category name -> id (:func:`coco_categories`), kept in the output (:func:`output_categories`).
    ``bank``: the asset source passed to every insertion (:func:`process_item`); what it holds belongs in
    ``options`` (the manifest), so that a run with other assets is not resumed from this one's records.
    ``output``: the layout, image format and labels written (:class:`aias_augment.cli.dataset_out.DatasetOutput`;
    None: COCO, PNG images, the project's category names). A second run into an ``out_dir`` that a run is writing
    is refused at start (OutputBusy). An ``out_dir`` that is, holds or lies inside an input file or its folder is
    refused before anything is written (InputError)."""
    if not items:
        raise InputError("no input images")
    check_out_apart(out_dir, input_paths(items))
    with output_lock(Path(out_dir)):
        return _run(
            items,
            cfg,
            seed,
            out_dir,
            workers,
            class_names,
            sheet_size,
            scene_cache,
            preset=preset,
            overwrite=overwrite,
            max_pixels=max_pixels,
            options=options,
            backend=backend,
            ray_address=ray_address,
            categories=categories,
            bank=bank,
            output=output,
        )


def _run(
    items: list[Item],
    cfg: InsertionConfig,
    seed: int,
    out_dir: str,
    workers: int = 1,
    class_names=None,
    sheet_size: int = 12,
    scene_cache: str | None = None,
    *,
    preset: str | None = None,
    overwrite: bool = False,
    max_pixels: int | None = None,
    options: dict | None = None,
    backend: str = "local",
    ray_address: str | None = None,
    categories: dict[str, int] | None = None,
    bank=None,
    output: DatasetOutput | None = None,
) -> dict:
    out = Path(out_dir)
    hashes = [item_hash(it) for it in items]
    output = output or DatasetOutput()
    sources = [it.path for it in items]
    out_categories = output_categories(categories, class_names, tuple(output.label(c) for c in cfg.categories))
    manifest = build_manifest(
        items,
        cfg,
        seed,
        preset,
        {
            **(options or {}),
            "class_names": class_names,
            "max_pixels": max_pixels,
            "categories": out_categories,
            "output": output.manifest(),
        },
        hashes=hashes,
        outputs=list(dict.fromkeys([*planned_outputs(sources), *dataset_outputs(sources, output)])),
    )
    prepare_output(out, manifest, overwrite)
    temp_prefix = manifest["temp_prefix"]
    jobs = [
        (
            i,
            it,
            cfg,
            seed,
            str(out),
            class_names,
            None if scene_cache is None else str(scene_cache),
            h,
            max_pixels,
            bank,
            temp_prefix,
            output.image,
        )
        for i, (it, h) in enumerate(zip(items, hashes))
    ]
    records = _run_jobs(jobs, workers, backend, ray_address)
    coco, sheet = _coco_and_sheet(records, out, output, out_categories, sheet_size)
    report = build_report(records)
    report["output"] = write_outputs(out, records, output, coco.categories, temp_prefix)
    write_json(out / "report.json", report, temp_prefix)
    if sheet:
        write_rgb(out / "contact_sheet.png", contact_sheet(sheet), temp_prefix)
    summary = _summary(records, coco, report)
    write_json(out / "summary.json", summary, temp_prefix)

    def put_coco(tmp: Path) -> None:  # re-read by pycocotools and checked before it takes its name
        coco.write(tmp)
        check_coco_file(tmp, out / "images")

    write_file(out / "annotations.json", temp_prefix, put_coco)  # the dataset appears last, whole
    mark_complete(out, manifest)
    log.info(
        "%s: %d of %d images written, %d objects inserted (skips and notes in report.json)",
        out,
        summary["written"],
        summary["images"],
        summary["inserted"],
    )
    return summary


def _run_jobs(jobs: list, workers: int, backend: str, ray_address: str | None) -> list[dict]:
    """Each job's record, in the jobs' order: here (``workers`` <= 1), in a spawned pool, or as Ray tasks."""
    records = []
    quiet = progress_disabled(log)
    if backend == "ray":  # Ray tasks (aias_augment.cli.offline_ray): the same process_item, the same bytes
        with tqdm(total=len(jobs), desc="aias-augment[ray]", unit="img", disable=quiet) as bar:
            records = run_ray_jobs(jobs, workers, ray_address, progress=bar)
    elif backend != "local":
        raise InputError(f"unknown backend {backend!r} (local or ray)")
    elif workers <= 1:
        for j in tqdm(jobs, desc="aias-augment", unit="img", disable=quiet):
            records.append(_worker(j))
    else:
        with mp.get_context("spawn").Pool(workers) as pool:
            for r in tqdm(pool.imap(_worker, jobs), total=len(jobs), desc="aias-augment", unit="img", disable=quiet):
                records.append(r)
    return records


def _coco_and_sheet(records: list[dict], out: Path, output: DatasetOutput, out_categories, sheet_size: int):
    """(the COCO builder of the written images, the first ``sheet_size`` images with their boxes drawn): a record
    whose files fail the output check is left out and named (``output_errors``), never written as a wrong
    annotation."""
    coco = CocoBuilder(out_categories)
    sheet = []
    for rec in records:
        if "skipped" in rec:
            continue
        errs = check_output_record(rec, out)
        if errs:  # a bug upstream: the image is left out and named, never written as a wrong annotation
            log.error("output check failed for %s: %s", rec["source"], "; ".join(errs))
            rec["output_errors"] = errs
            continue
        image_id = coco.add_image(rec["file_name"], rec["width"], rec["height"], source=rec["source"])
        inserted_anns = iter(rec["annotations"])
        for box, lab, ins in zip(rec["boxes"], rec["labels"], rec["inserted"]):
            extra = {}
            if ins:
                a = next(inserted_anns)
                while a["visible_box_xywh"] is None or a.get("decoy"):
                    a = next(inserted_anns)
                extra = {
                    "segmentation": a["rle"],
                    "area": a["area"],
                    "amodal_bbox": a["amodal_box_xywh"],
                    "visibility": a["visibility"],
                }
            coco.add_box(image_id, output.label(lab, ins), box, inserted=ins, **extra)
        if len(sheet) < sheet_size:  # named as written (an inserted category under the user's class)
            names = [output.label(lab, ins) for lab, ins in zip(rec["labels"], rec["inserted"])]
            sheet.append(
                draw_boxes(read_rgb(str(out / "images" / rec["file_name"])), rec["boxes"], names, rec["inserted"])
            )
    return coco, sheet


def _summary(records: list[dict], coco, report: dict) -> dict:
    """``summary.json``: images seen, written, skipped, objects inserted, images without one, box notes, and the
    median seconds per image."""
    times = [r["seconds"] for r in records if "seconds" in r]
    summary = {
        "images": len(records),
        "written": len(coco.images),
        "skipped": sum("skipped" in r or "output_errors" in r for r in records),
        "inserted": sum(sum(r.get("inserted", [])) for r in records if "output_errors" not in r),
        "nothing_inserted": sum("nothing_inserted" in r for r in records),
        "box_notes": sum(v for k, v in report["notes"].items() if k.startswith("box")),
        "median_seconds_per_image": float(np.median(times)) if times else None,
    }
    return summary


def build_report(records: list[dict]) -> dict:
    """``report.json``: skipped images by kind (file, line, reason), box notes and conversions by kind, images
    where nothing was inserted (their count, and by reason)."""
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
            skipped.setdefault(r.get("skip_kind", "failed"), []).append(
                {"file": r["source"], "line": r.get("skip_line"), "reason": r["skipped"]}
            )
        elif "output_errors" in r:
            skipped.setdefault("output check failed", []).append(
                {"file": r["source"], "line": None, "reason": "; ".join(r["output_errors"])}
            )
        elif "nothing_inserted" in r:
            nothing.setdefault(r["nothing_inserted"], []).append(r["source"])
    return {
        "images": len(records),
        "skipped": sum(len(v) for v in skipped.values()),
        "skipped_by_kind": {k: len(v) for k, v in sorted(skipped.items())},
        "skips": skipped,
        "notes": dict(sorted(notes.items())),
        "note_list": note_list,
        "nothing_inserted_count": sum(len(v) for v in nothing.values()),
        "nothing_inserted": {k: len(v) for k, v in nothing.items()},
        "nothing_inserted_images": nothing,
    }

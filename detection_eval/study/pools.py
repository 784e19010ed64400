"""Pools of inserted images per arm: generated once through the image door, cached, shared by the seeds."""

from __future__ import annotations

import dataclasses
import json
import logging
import shutil
import time
from pathlib import Path

import cv2
import numpy as np

from aias_augment.core.config import REPO_ROOT
from detection_eval.data import (
    DetectionSet,
    format_yolo_labels,
    load_yolo_dir,
    read_image_rgb,
    write_classes,
    write_yolo_sample,
)
from detection_eval.study.arms import ARM_FLAGS, PER_SEED_ARMS, insertion_config_for_arm
from detection_eval.study.config import StudyConfig, repo_path
from detection_eval.study.pool_runner import PoolCopy, RunnerCopyFailed, RunnerMaker, take_jpeg
from detection_eval.study.splits import pool_backgrounds, real_box_height_fractions

log = logging.getLogger("detection_eval.study")


def closeup_crop(
    image: np.ndarray,
    boxes_xyxy: np.ndarray,
    target_fracs,
    rng: np.random.Generator,
    *,
    min_side_px: int = 128,
    min_visible: float = 0.5,
) -> tuple[np.ndarray, np.ndarray, dict]:
    """Crop ``image`` (no resampling: the crop's pixels are the image's) around its tallest box so that the box's
    height fraction becomes a target drawn from ``target_fracs``: the frame a nearer camera or a longer lens would
    have seen, at the photo's own sharpness (the detector letterboxes every image to its input size anyway).

    The crop keeps the image's aspect, is at least ``min_side_px`` on its short side and holds the tallest box whole;
    other boxes are clipped to it and kept when at least ``min_visible`` of their area is inside. A target at or
    below the current size leaves the image as it is. Returns (crop, boxes in crop pixels, info)."""
    h, w = image.shape[:2]
    boxes = np.asarray(boxes_xyxy, np.float64).reshape(-1, 4)
    info = {"zoom": 1.0, "dropped_boxes": 0}
    if len(boxes) == 0 or len(target_fracs) == 0:
        return image, boxes, info
    k = int(np.argmax(boxes[:, 3] - boxes[:, 1]))
    bx0, by0, bx1, by1 = boxes[k]
    target = float(target_fracs[int(rng.integers(len(target_fracs)))])
    zoom = target / max((by1 - by0) / h, 1e-9)
    zoom = min(zoom, min(h, w) / min_side_px, w / max(bx1 - bx0 + 2.0, 1.0), h / max(by1 - by0 + 2.0, 1.0))
    if zoom <= 1.0 + 1e-6:
        return image, boxes, info
    cw, ch = min(w, int(round(w / zoom))), min(h, int(round(h / zoom)))
    # Origins that keep the tallest box whole, drawn uniformly (integers: the crop is a slice of the image).
    x_lo, x_hi = max(0, int(np.ceil(bx1)) - cw), min(int(np.floor(bx0)), w - cw)
    y_lo, y_hi = max(0, int(np.ceil(by1)) - ch), min(int(np.floor(by0)), h - ch)
    x0 = int(rng.integers(x_lo, x_hi + 1)) if x_hi >= x_lo else max(0, min(w - cw, int(round(bx0))))
    y0 = int(rng.integers(y_lo, y_hi + 1)) if y_hi >= y_lo else max(0, min(h - ch, int(round(by0))))
    crop = image[y0 : y0 + ch, x0 : x0 + cw].copy()
    moved = boxes - [x0, y0, x0, y0]
    clipped = np.c_[np.clip(moved[:, [0, 2]], 0, cw), np.clip(moved[:, [1, 3]], 0, ch)][:, [0, 2, 1, 3]]
    area = np.prod(np.maximum(boxes[:, 2:] - boxes[:, :2], 1e-9), axis=1)
    inside = np.prod(np.maximum(clipped[:, 2:] - clipped[:, :2], 0.0), axis=1)
    keep = inside / area >= min_visible
    keep[k] = True
    info = {"zoom": float(w / cw), "dropped_boxes": int((~keep).sum()), "crop_xywh": [x0, y0, cw, ch]}
    return crop, clipped[keep], info


def generate_arm_set(
    cfg: StudyConfig,
    arm: str,
    train: DetectionSet,
    empty: list[int],
    seed: int | None = None,
    base: DetectionSet | None = None,
) -> Path:
    """Render the arm's pool of ``insertion.pool_size`` inserted copies into a YOLO folder, once for all seeds.
    Resumable: finished copies are listed in ``progress.jsonl`` and kept when a run with the same parameters is
    restarted; ``done.json`` marks a complete pool and is reused while its parameters match. Pipeline copies are
    made by the CLI's offline runner (:mod:`detection_eval.study.pool_runner`)."""
    if ARM_FLAGS[arm].get("closeup_crop"):
        return derive_closeup_pool(cfg, arm, train, empty)
    if ARM_FLAGS[arm].get("mix_pools"):
        return derive_mixed_pool(cfg, arm, train, empty)
    ic = cfg.insertion
    per_seed = arm in PER_SEED_ARMS
    if per_seed and (seed is None or base is None):
        raise ValueError(f"{arm}: its pool is made from the seed's own real instances: pass seed and base")
    out = repo_path(cfg.cache_dir) / arm / (f"seed{seed}/pool" if per_seed else "pool")
    backgrounds = pool_backgrounds(empty, ic.pool_seed, ic.pool_size)
    wanted = {
        "arm": arm,
        "backgrounds": [Path(train.records[i].image_path).name for i in backgrounds],
        "insertion": dataclasses.asdict(ic),
        "flags": ARM_FLAGS[arm],
    }
    if per_seed:  # the instances of this seed's thinned subset only: no real data of other seeds leaks in
        wanted["seed"] = seed
        wanted["sources"] = [Path(r.image_path).name for r in base.records if len(r.labels)]
    wanted = json.loads(json.dumps(wanted))  # as it reads back from json (tuples become lists)
    finished = _resume(out, arm, wanted)
    if finished is None:
        return out
    try:
        make = pool_maker(cfg, arm, train, base, out)
    except RuntimeError as exc:  # no usable instance in the subset: every copy fails with that reason (counted)
        log.warning("%s: %s", arm, exc)

        def make(image, j, stem, _exc=exc):
            raise _exc

    t0, n_new = time.perf_counter(), 0
    with (out / "progress.jsonl").open("a") as plog:
        for j, i in enumerate(backgrounds):
            if j in finished:
                continue
            entry = _make_copy(cfg, arm, train.records[i].image_path, j, make, out)
            plog.write(json.dumps(entry) + "\n")
            plog.flush()
            finished[j] = entry
            n_new += 1
            if n_new % 10 == 0:
                per_image = (time.perf_counter() - t0) / n_new
                log.info("%s: %d/%d pool images, %.1f s/image", arm, len(finished), len(backgrounds), per_image)
    shutil.rmtree(out / "runner", ignore_errors=True)
    _finish_pool(cfg, arm, out, wanted, [finished[j] for j in sorted(finished)])
    return out


def _resume(out: Path, arm: str, wanted: dict) -> dict[int, dict] | None:
    """The copies already made of the pool at ``out`` with parameters ``wanted`` (copy index -> progress entry);
    None when the pool is complete. Copies made with other parameters are dropped."""
    done, progress = out / "done.json", out / "progress.jsonl"
    if done.exists():
        prev = json.loads(done.read_text())
        if all(prev.get(k) == v for k, v in wanted.items()):
            log.info("%s: using cached pool %s (%d images)", arm, out, prev["num_images"])
            return None
        log.info("%s: pool parameters changed, regenerating", arm)
        done.unlink()
        progress.unlink(missing_ok=True)
    params_file = out / "params.json"
    if params_file.exists() and json.loads(params_file.read_text()) != wanted:
        progress.unlink(missing_ok=True)  # a partial pool made with other parameters is not resumed
    out.mkdir(parents=True, exist_ok=True)
    params_file.write_text(json.dumps(wanted))
    finished = {}
    if progress.exists():
        for line in progress.read_text().splitlines():
            try:
                e = json.loads(line)
            except json.JSONDecodeError:  # a line cut by a kill
                continue
            if (out / "images" / e["image"]).exists() or e.get("failed"):
                finished[e["copy"]] = e
    return finished


def pool_background(path: str, max_side_px: int) -> np.ndarray:
    """The background as the pool inserts into it: decoded (orientation as stored) and downscaled (INTER_AREA) so
    that its longer side is at most ``max_side_px``."""
    image = read_image_rgb(path)
    scale = min(1.0, max_side_px / max(image.shape[:2]))
    if scale < 1:
        size = (round(image.shape[1] * scale), round(image.shape[0] * scale))
        image = cv2.resize(image, size, interpolation=cv2.INTER_AREA)
    return image


def _make_copy(cfg: StudyConfig, arm: str, background: str, j: int, make, out: Path) -> dict:
    """Copy ``j`` of the pool on ``background``, written to ``out`` with its labels; returns its progress entry (a
    failure is logged and counted, and nothing is written without its boxes)."""
    image = pool_background(background, cfg.insertion.max_side_px)
    stem = f"{j:04d}_{Path(background).stem}__{arm}"
    t_img = time.perf_counter()
    try:
        copy = make(image, j, stem)
    except Exception as exc:  # logged and counted; the copy is left out, never written without its boxes
        reason = (str(exc) if isinstance(exc, RunnerCopyFailed) else f"{type(exc).__name__}: {exc}")[:200]
        log.warning("%s: insertion failed on %s: %s", arm, background, reason)
        return {"copy": j, "background": Path(background).name, "failed": reason}
    boxes_xyxy = copy.boxes_xyxy
    keep = (boxes_xyxy[:, 2] - boxes_xyxy[:, 0] >= 1) & (boxes_xyxy[:, 3] - boxes_xyxy[:, 1] >= 1)
    boxes_xyxy = boxes_xyxy[keep]
    labels = np.zeros(len(boxes_xyxy), np.int64)
    if copy.jpeg is None:
        write_yolo_sample(out, stem, copy.image, boxes_xyxy, labels)
    else:
        take_jpeg(copy, out / "images" / f"{stem}.jpg")
        (out / "labels").mkdir(parents=True, exist_ok=True)
        (out / "labels" / f"{stem}.txt").write_text(format_yolo_labels(boxes_xyxy, labels, copy.width, copy.height))
    return {
        "copy": j,
        "background": Path(background).name,
        "image": f"{stem}.jpg",
        "boxes": int(keep.sum()),
        "box_heights_frac": [float(x) for x in (boxes_xyxy[:, 3] - boxes_xyxy[:, 1]) / image.shape[0]],
        "seconds": time.perf_counter() - t_img,
        "modules": copy.modules,
    }


def _finish_pool(cfg: StudyConfig, arm: str, out: Path, wanted: dict, entries: list[dict]) -> None:
    """``classes.txt``, ``manifest.json`` (every copy's entry) and ``done.json`` (the parameters, counts, failures)."""
    ok = [e for e in entries if not e.get("failed")]
    write_classes(out, cfg.class_names)
    (out / "manifest.json").write_text(json.dumps(entries, indent=1))
    seconds = [e["seconds"] for e in ok]
    summary = {
        **wanted,
        "code_commit": git_head(),
        "num_images": len(ok),
        "num_boxes": sum(e["boxes"] for e in ok),
        "failures": _failure_counts(entries),
        "seconds_per_image": float(np.median(seconds)) if seconds else None,
    }
    (out / "done.json").write_text(json.dumps(summary, indent=1))
    log.info("%s: pool of %d images, %d inserted boxes", arm, len(ok), summary["num_boxes"])


def _pool_summary(done: dict) -> dict:
    """What a derived pool records of a source pool's ``done.json``: a changed source regenerates it."""
    return {k: done.get(k) for k in ("code_commit", "num_images", "num_boxes")}


def _derived_pool(cfg: StudyConfig, arm: str, key: str, sources) -> tuple[Path, dict, bool]:
    """(folder, parameters, cached) of a pool derived from other pools (``sources`` recorded under ``key``): cached
    when its ``done.json`` matches the parameters; otherwise that marker is removed and the pool is to be made."""
    out = repo_path(cfg.cache_dir) / arm / "pool"
    done = out / "done.json"
    wanted = json.loads(
        json.dumps({"arm": arm, "flags": ARM_FLAGS[arm], "insertion": dataclasses.asdict(cfg.insertion), key: sources})
    )
    if done.exists() and all(json.loads(done.read_text()).get(k) == v for k, v in wanted.items()):
        log.info("%s: using cached pool %s", arm, out)
        return out, wanted, True
    done.unlink(missing_ok=True)
    return out, wanted, False


def _failure_counts(entries: list[dict]) -> dict[str, int]:
    """Failed copies counted by their reason."""
    failures: dict[str, int] = {}
    for e in entries:
        if e.get("failed"):
            failures[e["failed"]] = failures.get(e["failed"], 0) + 1
    return failures


def derive_closeup_pool(cfg: StudyConfig, arm: str, train: DetectionSet, empty: list[int]) -> Path:
    """The ``inserted`` pool's copies, each cropped by :func:`closeup_crop` (copy j with ``default_rng([pool_seed,
    j, 17])``) to a height drawn from the real train boxes: the same insertions, framed closer, so the paired
    difference to ``inserted`` measures the framing alone. No rendering: seconds for the whole pool."""
    src = generate_arm_set(cfg, "inserted", train, empty)
    src_done = json.loads((src / "done.json").read_text())
    out, wanted, cached = _derived_pool(cfg, arm, "source", _pool_summary(src_done))
    if cached:
        return out
    done = out / "done.json"
    out.mkdir(parents=True, exist_ok=True)
    fracs = tuple(f for f in real_box_height_fractions(train) if 0 < f <= 1)
    pool = load_yolo_dir(src, names=cfg.class_names)
    by_name = {Path(r.image_path).name: r for r in pool.records}
    entries = []
    for e in json.loads((src / "manifest.json").read_text()):
        if e.get("failed"):
            entries.append(e)
            continue
        r = by_name[e["image"]]
        image = read_image_rgb(r.image_path)
        crop, boxes, info = closeup_crop(
            image, r.boxes_xyxy, fracs, np.random.default_rng([cfg.insertion.pool_seed, e["copy"], 17])
        )
        stem = Path(e["image"]).stem.replace("__inserted", f"__{arm}")
        write_yolo_sample(out, stem, crop, boxes, np.zeros(len(boxes), np.int64))
        entries.append(
            {
                **e,
                "image": f"{stem}.jpg",
                "boxes": int(len(boxes)),
                "closeup": info,
                "box_heights_frac": [float(x) for x in (boxes[:, 3] - boxes[:, 1]) / crop.shape[0]],
            }
        )
    ok = [e for e in entries if not e.get("failed")]
    write_classes(out, cfg.class_names)
    (out / "manifest.json").write_text(json.dumps(entries, indent=1))
    done.write_text(
        json.dumps(
            {
                **wanted,
                "code_commit": git_head(),
                "num_images": len(ok),
                "num_boxes": sum(e["boxes"] for e in ok),
                "failures": src_done.get("failures", {}),
                "seconds_per_image": src_done.get("seconds_per_image"),
                "median_zoom": float(np.median([e["closeup"]["zoom"] for e in ok])) if ok else None,
            },
            indent=1,
        )
    )
    log.info(
        "%s: %d close-up copies of %s, median zoom %.2f",
        arm,
        len(ok),
        src,
        json.loads(done.read_text())["median_zoom"] or 1.0,
    )
    return out


def mixed_pool_sources(pool_seed: int, n: int, k: int) -> list[int]:
    """Which of ``k`` source pools copy j of a mixed pool comes from: a fair seeded coin per copy
    (``default_rng([pool_seed, 23])``), the same for every amount, so the first n copies of a longer pool are
    those of a shorter one."""
    return [int(x) for x in np.floor(np.random.default_rng([pool_seed, 23]).random(n) * k)]


def derive_mixed_pool(cfg: StudyConfig, arm: str, train: DetectionSet, empty: list[int]) -> Path:
    """Copy j of the mixed pool is copy j of one of the arms in ``ARM_FLAGS[arm]["mix_pools"]``
    (:func:`mixed_pool_sources`): the same backgrounds and draw streams, the kind of insertion chosen per copy.
    The source pools are generated (or reused) first; their images are copied, nothing is rendered."""
    sources = tuple(ARM_FLAGS[arm]["mix_pools"])
    if any(ARM_FLAGS[s] is None or s in PER_SEED_ARMS or ARM_FLAGS[s].get("mix_pools") for s in sources):
        raise ValueError(f"{arm}: mixes only shared offline pools of insertion arms, got {sources}")
    src = {s: generate_arm_set(cfg, s, train, empty) for s in sources}
    summaries = {s: _pool_summary(json.loads((src[s] / "done.json").read_text())) for s in sources}
    out, wanted, cached = _derived_pool(cfg, arm, "sources", summaries)
    if cached:
        return out
    done = out / "done.json"
    manifests = {s: {e["copy"]: e for e in json.loads((src[s] / "manifest.json").read_text())} for s in sources}
    n = cfg.insertion.pool_size
    entries = []
    for j, k in enumerate(mixed_pool_sources(cfg.insertion.pool_seed, n, len(sources))):
        s = sources[k]
        e = manifests[s].get(j)
        if e is None:
            raise RuntimeError(f"{arm}: copy {j} is missing from the {s} pool {src[s]}")
        if e.get("failed"):
            entries.append({**e, "source_arm": s})
            continue
        stem = Path(e["image"]).stem.replace(f"__{s}", f"__{arm}")
        for sub, ext in (("images", ".jpg"), ("labels", ".txt")):  # the source's bytes: no second JPEG encoding
            (out / sub).mkdir(parents=True, exist_ok=True)
            shutil.copyfile(src[s] / sub / f"{Path(e['image']).stem}{ext}", out / sub / f"{stem}{ext}")
        entries.append({**e, "image": f"{stem}.jpg", "source_arm": s})
    ok = [e for e in entries if not e.get("failed")]
    write_classes(out, cfg.class_names)
    (out / "manifest.json").write_text(json.dumps(entries, indent=1))
    failures = _failure_counts(entries)
    done.write_text(
        json.dumps(
            {
                **wanted,
                "code_commit": git_head(),
                "num_images": len(ok),
                "num_boxes": sum(e["boxes"] for e in ok),
                "failures": failures,
                "copies_by_source": {s: sum(1 for e in entries if e["source_arm"] == s) for s in sources},
                "seconds_per_image": None,
            },
            indent=1,
        )
    )
    log.info("%s: %d copies mixed from %s", arm, len(ok), json.loads(done.read_text())["copies_by_source"])
    return out


def git_head() -> str:
    import subprocess

    try:
        return subprocess.run(
            ["git", "rev-parse", "HEAD"], cwd=REPO_ROOT, capture_output=True, text=True, timeout=10
        ).stdout.strip()
    except (OSError, subprocess.SubprocessError):
        return "unknown"


def git_dirty(root: Path = REPO_ROOT) -> bool | None:
    """Whether the checkout at ``root`` has uncommitted changes to tracked files (None when git cannot tell): a run
    made from a dirty tree is not the commit it names."""
    import subprocess

    try:
        res = subprocess.run(
            ["git", "status", "--porcelain", "--untracked-files=no"],
            cwd=root,
            capture_output=True,
            text=True,
            timeout=10,
        )
    except (OSError, subprocess.SubprocessError):
        return None
    return None if res.returncode != 0 else bool(res.stdout.strip())


def run_environment() -> dict:
    """What besides the code decides a training's numbers to the last digit: torch's version, its thread count and
    the CPU kernels it dispatches to, and whether the tree matched its commit."""
    import platform

    import torch

    return {
        "torch": torch.__version__,
        "torch_threads": torch.get_num_threads(),
        "cpu_capability": torch.backends.cpu.get_cpu_capability(),
        "machine": platform.machine(),
        "tree_dirty": git_dirty(),
    }


def pool_maker(cfg: StudyConfig, arm: str, train: DetectionSet, base: DetectionSet | None, out: Path):
    """``make(background, j, stem) -> PoolCopy`` of the arm: the pipeline through the CLI's offline runner (with the
    lifted instances of the seed's subset as its assets for ``lifted``), copy-paste of the subset's real instances,
    or the best of k pipeline insertions under the seed's realism filter. Copy ``j`` draws from
    ``default_rng([pool_seed, j])`` in every arm: paired copies."""
    from aias_augment.pipeline.image import insert_into_image

    flags = ARM_FLAGS[arm]
    ic = cfg.insertion
    bank = None
    if flags.get("copy_paste") or flags.get("lifted"):
        items = [(r.image_path, read_image_rgb(r.image_path), r.boxes_xyxy) for r in base.records if len(r.labels)]
        if flags.get("copy_paste"):
            return _copy_paste_maker(cfg, arm, train, items, out)
        bank = _lifted_bank(arm, ic.categories[0], items, out)
    ins_cfg = insertion_config_for_arm(
        cfg, "inserted" if flags.get("lifted") or flags.get("realism_filter") else arm, train
    )
    if not flags.get("realism_filter"):
        return RunnerMaker(ins_cfg, bank, ic.pool_seed, out)

    def make_insert(image, rng):
        res = insert_into_image(image, np.zeros((0, 4)), [], rng, ins_cfg, bank=bank)
        b = np.asarray(res.bboxes, np.float64).reshape(-1, 4)
        return res.image, np.c_[b[:, :2], b[:, :2] + b[:, 2:]], dict(res.record.modules)

    from aias_augment.evaluation.realism.filter import best_of

    judge = fit_realism_filter(cfg, base, make_insert, out)

    def make_filtered(image, j, stem):
        (new, boxes, modules), info = best_of(
            lambda g: make_insert(image, g),
            lambda r: (r[0], r[1]),
            judge,
            np.random.default_rng([ic.pool_seed, j]),
            int(flags["realism_filter"]),
        )
        return PoolCopy(boxes, {**modules, "realism_filter": info}, new.shape[0], new.shape[1], image=new)

    return make_filtered


def _lifted_bank(arm: str, category: str, items: list, out: Path):
    """The seed's subset's real instances lifted to meshes (:mod:`aias_augment.assets.bank.lift`): the ``lifted``
    arm's assets."""
    from aias_augment.assets.bank.lift import LiftedAssets, lift_instances

    assets, report = lift_instances(items, category, out / "assets")
    log.info(
        "%s: lifted %d instances of %d images (rejected: %s)", arm, report.lifted, len(items), dict(report.rejected)
    )
    if not assets:
        raise RuntimeError(f"no instance of the subset could be lifted: {dict(report.rejected)}")
    return LiftedAssets({category: assets})


def _copy_paste_maker(cfg: StudyConfig, arm: str, train: DetectionSet, items: list, out: Path):
    """``make`` of copy-paste: the subset's real instances cut out (GrabCut from their boxes) and pasted at random
    positions with heights drawn from the real train boxes."""
    from aias_augment.assets.bank.lift import cut_out
    from detection_eval.copy_paste import paste_instances

    cutouts, rejected = [], {}
    for path, image, boxes in items:
        for k, box in enumerate(boxes):
            cut, reason = cut_out(image, box, [b for i, b in enumerate(boxes) if i != k], source=path)
            if cut is None:
                rejected[reason] = rejected.get(reason, 0) + 1
            else:
                cutouts.append(cut)
    (out / "cutouts.json").write_text(json.dumps({"cut": len(cutouts), "rejected": rejected}))
    log.info("%s: %d instances cut out of %d images (rejected: %s)", arm, len(cutouts), len(items), rejected)
    if not cutouts:
        raise RuntimeError(f"no instance of the subset could be cut out: {rejected}")
    fracs = tuple(f for f in real_box_height_fractions(train) if 0 < f <= 1)
    ic = cfg.insertion

    def make_paste(image, j, stem):
        rng = np.random.default_rng([ic.pool_seed, j])
        n = int(rng.integers(ic.min_objects, ic.max_objects + 1))
        new, boxes = paste_instances(image, cutouts, rng, fracs, n)
        modes = {"mode": f"copy-paste of {len(cutouts)} real instances"}
        return PoolCopy(boxes, modes, new.shape[0], new.shape[1], image=new)

    return make_paste


def fit_realism_filter(cfg: StudyConfig, base: DetectionSet, make_insert, out: Path):
    """The seed's realism filter: crops of its thinned subset's real cones (the only real cones the arm may see)
    against crops of cones inserted into its empty roads (up to 60, each with its own stream ``[pool_seed, 99,
    i]``), Lite0 features as in the realism report. Its fit (out-of-fold AUC, threshold) goes to
    ``out/realism_filter.json``."""
    from aias_augment.evaluation.realism.crops import object_crops
    from aias_augment.evaluation.realism.features import Lite0Features
    from aias_augment.evaluation.realism.filter import RealismFilter

    ic = cfg.insertion
    rng = np.random.default_rng([ic.pool_seed, 98])
    real, real_g, ins, ins_g = [], [], [], []

    def shrunk(path):
        image = read_image_rgb(path)
        s = min(1.0, ic.max_side_px / max(image.shape[:2]))
        if s < 1:
            image = cv2.resize(
                image, (round(image.shape[1] * s), round(image.shape[0] * s)), interpolation=cv2.INTER_AREA
            )
        return image, s

    empty = []
    for r in base.records:
        if len(r.labels):
            image, s = shrunk(r.image_path)
            crops, _ = object_crops(image, r.boxes_xyxy * s, rng)
            real += crops
            real_g += [r.image_path] * len(crops)
        else:
            empty.append(r.image_path)
    for i, path in enumerate(empty[:60]):
        image, _ = shrunk(path)
        try:
            new, boxes, _ = make_insert(image, np.random.default_rng([ic.pool_seed, 99, i]))
        except Exception as exc:  # counted in the fit report by the crops it did not give
            log.warning("realism filter: calibration insertion failed on %s: %s", path, exc)
            continue
        crops, _ = object_crops(new, boxes, rng)
        ins += crops
        ins_g += [path] * len(crops)
    judge = RealismFilter.fit(real, real_g, ins, ins_g, Lite0Features(input_size=160), rng)
    (out / "realism_filter.json").write_text(json.dumps(judge.fit_report, indent=1))
    log.info("realism filter: %s", judge.fit_report)
    return judge

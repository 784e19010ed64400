"""One run: its training set (thinned real images plus an arm's pool, or the transform online), training, scoring."""

from __future__ import annotations

import dataclasses
import json
import logging
import math
import time
from pathlib import Path

import numpy as np

from detection_eval.config import load_detector_config, replace_nested
from detection_eval.data import DetectionSet, load_yolo_dir
from detection_eval.study.arms import (
    ARM_FLAGS,
    ONLINE_ARMS,
    PER_SEED_ARMS,
    insertion_config_for_arm,
    run_name,
    uses_pool,
)
from detection_eval.study.config import StudyConfig, repo_path
from detection_eval.study.pools import generate_arm_set, git_head, run_environment
from detection_eval.study.run_table import RUNS_FILE, finished_run, metrics_dir
from detection_eval.study.splits import pool_share, thin_cone_images

log = logging.getLogger("detection_eval.study")


def training_set(
    cfg: StudyConfig, arm: str, seed: int, train: DetectionSet, amount: int | None = None, generate: bool = True
):
    """(training DetectionSet, info dict) for one arm, seed and amount of inserted images."""
    base, empty = thin_cone_images(train, cfg.keep_fraction, seed)
    info = {
        "real_images": len(base),
        "real_cone_images": sum(1 for r in base.records if len(r.labels)),
        "real_boxes": base.num_boxes,
    }
    if ARM_FLAGS[arm] is None or arm in ONLINE_ARMS:
        return base, info
    per_seed = arm in PER_SEED_ARMS
    folder = (
        generate_arm_set(cfg, arm, train, empty, seed, base)
        if generate
        else repo_path(cfg.cache_dir) / arm / (f"seed{seed}/pool" if per_seed else "pool")
    )
    if not (folder / "done.json").exists():
        raise FileNotFoundError(f"{folder}: augmented pool not generated (run --stage generate)")
    gen = json.loads((folder / "done.json").read_text())
    manifest = json.loads((folder / "manifest.json").read_text())
    by_copy = {e["copy"]: e for e in manifest if not e.get("failed")}
    amount = cfg.amounts[0] if amount is None else amount
    share = [j for j in pool_share(cfg.insertion.pool_size, amount, seed) if j in by_copy]
    if not by_copy:  # e.g. a thinned subset none of whose instances can be lifted: say why, train nothing
        reasons = sorted({str(e.get("failed")) for e in manifest})[:3]
        raise ValueError(f"{arm} seed {seed}: its pool {folder} has no image (every copy failed: {reasons})")
    pool = load_yolo_dir(folder, names=cfg.class_names)
    by_name = {Path(r.image_path).name: r for r in pool.records}
    extra = DetectionSet(tuple(by_name[by_copy[j]["image"]] for j in share), pool.category_names)
    info.update(
        {
            "amount": amount,
            "inserted_images": len(extra),
            "inserted_boxes": extra.num_boxes,
            "generation_seconds_per_image": gen["seconds_per_image"],
            "generation_failures": gen["failures"],
        }
    )
    return base + extra, info


_IMAGE_MEMO: dict = {}  # decoded, resized training images shared by all runs of one process


def online_transform(cfg: StudyConfig, train: DetectionSet, scene_cache_dir: Path | None = None):
    """The ``InsertObjects`` albumentations transform (the study's insertion settings, class label 0) as the
    trainer's per-sample transform: each sample gets new insertions with probability ``cfg.online_p``; scene
    analyses are cached by content, so from the second epoch on an image pays no analysis."""
    import albumentations as A

    from aias_augment import InsertObjects
    from detection_eval.online import albumentations_transform

    ins = insertion_config_for_arm(cfg, "inserted", train)
    overrides = {k: getattr(ins, k) for k in ("harmonize_method", "placement_cfg")}
    ic = cfg.insertion
    tf = InsertObjects(
        categories=tuple(ic.categories),
        min_objects=ic.min_objects,
        max_objects=ic.max_objects,
        preset=ic.preset,
        category_ids={c: 0 for c in ic.categories},
        config_overrides=overrides,
        scene_cache=None if scene_cache_dir is None else str(scene_cache_dir),
        scene_cache_items=512,
        p=cfg.online_p,
    )
    compose = A.Compose(
        [tf], bbox_params=A.BboxParams(format="pascal_voc", label_fields=["labels"], min_visibility=0.2), seed=0
    )
    return albumentations_transform(compose)


def run_one(
    cfg: StudyConfig,
    arm: str,
    seed: int,
    train: DetectionSet,
    val: DetectionSet,
    val_cache,
    amount: int | None = None,
    force=False,
    dev: DetectionSet | None = None,
    dev_cache=None,
):
    amount = None if not uses_pool(arm) else (cfg.amounts[0] if amount is None else amount)
    name = run_name(arm, seed, amount)
    result_path = metrics_dir(cfg) / f"{name}.json"
    done = None if force else finished_run(cfg, name)
    if done is not None:
        log.info("%s: result exists (%s or %s), skipping", name, result_path, repo_path(cfg.results_dir) / RUNS_FILE)
        return done
    claim = claim_run(result_path)
    if claim is None:
        log.info("%s: being trained by another process, skipping", name)
        return None
    try:
        return train_and_score(cfg, arm, seed, amount, name, result_path, train, val, val_cache, dev, dev_cache)
    finally:
        claim.unlink(missing_ok=True)


def claim_run(result_path: Path) -> Path | None:
    """An exclusive claim file beside the result, so several study processes (one per core) share one queue of
    runs. A claim whose process is gone is taken over. Returns the claim path, or None when another live process
    holds it."""
    import os

    claim = result_path.with_suffix(".running")
    claim.parent.mkdir(parents=True, exist_ok=True)
    for _ in range(2):
        try:
            fd = os.open(claim, os.O_CREAT | os.O_EXCL | os.O_WRONLY)
        except FileExistsError:
            try:
                pid = int(claim.read_text().strip() or 0)
                os.kill(pid, 0)
                return None  # alive: someone else trains it
            except (ValueError, ProcessLookupError, FileNotFoundError):
                claim.unlink(missing_ok=True)  # stale claim of a killed process
                continue
            except PermissionError:
                return None
        with os.fdopen(fd, "w") as f:
            f.write(str(os.getpid()))
        return claim
    return None


def train_and_score(cfg, arm, seed, amount, name, result_path, train, val, val_cache, dev=None, dev_cache=None):
    from detection_eval.inference import evaluate_dataset
    from detection_eval.train import save_checkpoint, train_detector

    det_cfg = load_detector_config(cfg.detector)
    if cfg.max_iters:
        det_cfg = replace_nested(det_cfg, **{"train.max_iters": cfg.max_iters})
    train_set, info = training_set(cfg, arm, seed, train, amount)
    if uses_pool(arm) and info.get("inserted_images", 0) == 0:
        # Nothing to add (e.g. no instance of the seed's subset could be lifted): the run would repeat the
        # reference arm's; the skip and its reason are kept beside the results.
        log.warning("%s: skipped, its pool holds no image (%s)", name, info.get("generation_failures"))
        result_path.with_suffix(".skip").write_text(json.dumps(info, indent=1))
        return None
    log.info("%s: training on %s", name, info)
    sample_transform = online_transform(cfg, train, repo_path(cfg.cache_dir) / "scenes") if arm in ONLINE_ARMS else None
    synthetic = np.r_[np.zeros(info["real_images"], bool), np.ones(len(train_set) - info["real_images"], bool)]
    res = train_detector(
        det_cfg,
        train_set,
        seed=seed,
        log_fn=lambda m: log.info("%s %s", name, m),
        image_memo=_IMAGE_MEMO,
        sample_transform=sample_transform,
        synthetic_mask=synthetic,
    )
    t0 = time.perf_counter()
    metrics = evaluate_dataset(res.model, val, det_cfg.train.img_size, det_cfg.inference, cached=val_cache)
    eval_seconds = time.perf_counter() - t0
    dev_metrics = (
        None
        if dev is None or not len(dev)
        else evaluate_dataset(res.model, dev, det_cfg.train.img_size, det_cfg.inference, cached=dev_cache)
    )
    weights = repo_path(cfg.runs_dir) / name / "weights.pt"
    row = {
        "arm": arm,
        "seed": seed,
        "amount": amount,
        **info,
        "train_images": len(train_set),
        "iterations": res.iterations,
        "batch_size": det_cfg.train.batch_size,
        "img_size": det_cfg.train.img_size,
        "threads": det_cfg.train.num_threads,
        "train_seconds": res.train_seconds,
        "cache_seconds": res.cache_seconds,
        "train_images_per_second": res.images_per_second,
        "eval_seconds": eval_seconds,
        "final_losses": res.final_losses,
        "metrics": nan_to_none(metrics),
        "dev_metrics": nan_to_none(dev_metrics),
        "weights": str(weights),
        "code_commit": git_head(),
        "environment": run_environment(),  # threads and CPU kernels change the last digits of a run
        "detector": dataclasses.asdict(det_cfg),
    }
    save_checkpoint(weights, res.model, train_set.category_names, {k: v for k, v in row.items() if k != "detector"})
    result_path.parent.mkdir(parents=True, exist_ok=True)
    result_path.write_text(json.dumps(row, indent=1))
    log.info(
        "%s: AP %.4f AP50 %.4f%s (%.0f s train, %.2f img/s)",
        name,
        metrics["AP"],
        metrics["AP50"],
        "" if dev_metrics is None else f" dev AP {dev_metrics['AP']:.4f}",
        res.train_seconds,
        res.images_per_second,
    )
    return row


def nan_to_none(obj):
    if isinstance(obj, float) and math.isnan(obj):
        return None
    if isinstance(obj, dict):
        return {k: nan_to_none(v) for k, v in obj.items()}
    return obj

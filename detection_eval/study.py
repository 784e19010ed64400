"""The downstream study (paper sec. 5.4): does training on inserted cones raise cone detection mAP on TraCon val?

Arms (all share the seeded thinning of the real cones, so seed k of every arm starts from the same images):
- ``original``: TraCon train with the cone images thinned to ``keep_fraction`` (seeded) plus all empty road images.
- ``inserted``: original + copies of empty road images with cones inserted by ``aias_augment`` (full pipeline).
- ``naive_paste``: original + the same copies with cones pasted plainly at random 2D positions and sizes
  (3D Copy-Paste's 'random insertion' baseline).
- ``no_placement`` / ``no_shadow`` / ``no_lighting`` / ``no_harmonize``: the full pipeline with one stage off.

Augmented sets are generated offline once per arm and seed (rendering is slow on CPU) and cached as YOLO-txt folders
under ``cache_dir``; the copy of image i under seed k uses ``default_rng([seed, i])`` in every arm, so arms differ
only in the stage switches. Every run writes its metrics JSON; the summary is a markdown table with mean and 95%
t-interval per arm, paired differences to ``original``, and a plot.

    aias-study --config configs/study/tracon_cones.yaml                       # core: original, inserted, naive paste
    aias-study --config configs/study/tracon_cones_ablations.yaml             # ablation arms
    aias-study --config ... --stage generate | train | summarize              # one stage only
"""
from __future__ import annotations

import argparse
import dataclasses
import json
import logging
import math
import time
from dataclasses import dataclass, field
from pathlib import Path

import cv2
import numpy as np

from aias_augment.config import REPO_ROOT, data_root, load_config

from .config import load_detector_config, replace_nested
from .data import DetectionSet, load_yolo_dir, read_image_rgb, write_classes, write_yolo_sample

log = logging.getLogger("detection_eval.study")

# Stage switches of aias_augment.pipeline.InsertionConfig per arm; None = no insertion.
ARM_FLAGS: dict[str, dict | None] = {
    "original": None,
    "inserted": {},
    "naive_paste": {"naive_paste": True},
    "no_placement": {"placement": False},
    "no_shadow": {"shadow": False},
    "no_lighting": {"lighting": False},
    "no_harmonize": {"harmonize": False},
}


@dataclass(frozen=True)
class InsertionStudyConfig:
    preset: str = "fast"                      # aias_augment configs/presets/<preset>.yaml
    harmonize_method: str = "camera"          # pinned, so every arm and seed uses the same harmonizer
    categories: tuple[str, ...] = ("traffic_cone",)
    min_objects: int = 1
    max_objects: int = 3
    images_per_seed: int | None = None        # empty road images that get an inserted copy (None: all 199)
    max_side_px: int = 640                    # backgrounds are downscaled to this before insertion (we train at 320)


@dataclass(frozen=True)
class StudyConfig:
    dataset: str = "tracon"                   # folder under $AIAS_DATA (or an absolute path)
    class_names: tuple[str, ...] = ("cone",)
    train_split: str = "train"
    val_split: str = "val"
    keep_fraction: float = 0.1                # of the train images that contain cones
    seeds: tuple[int, ...] = (0, 1, 2)
    arms: tuple[str, ...] = ("original", "inserted", "naive_paste")
    detector: str = "lite0_320"               # configs/detector/<name>.yaml
    max_iters: int | None = None              # overrides the detector config: the per-run budget
    insertion: InsertionStudyConfig = field(default_factory=InsertionStudyConfig)
    cache_dir: str = "out/study/cache"
    runs_dir: str = "runs/study"              # weights (not committed)
    results_dir: str = "results/study"        # metrics, table, plot (committed)
    reference_arm: str = "original"

    def __post_init__(self):
        unknown = [a for a in self.arms if a not in ARM_FLAGS]
        if unknown:
            raise ValueError(f"unknown arms {unknown}; known: {list(ARM_FLAGS)}")
        if not 0 < self.keep_fraction <= 1:
            raise ValueError(f"keep_fraction must lie in (0, 1], got {self.keep_fraction}")
        if len(set(self.seeds)) != len(self.seeds) or not self.seeds:
            raise ValueError(f"seeds must be distinct and non-empty, got {self.seeds}")


def _repo_path(p: str) -> Path:
    return Path(p) if Path(p).is_absolute() else REPO_ROOT / p


def dataset_root(cfg: StudyConfig) -> Path:
    p = Path(cfg.dataset)
    return p if p.is_absolute() else data_root() / p


# ------------------------------------------------------------------ training sets

def thin_cone_images(train: DetectionSet, keep_fraction: float, seed: int) -> tuple[DetectionSet, list[int]]:
    """Keep ``round(keep_fraction * n)`` of the images with objects (seeded) and every image without; also return
    the indices of the images without objects (the insertion backgrounds)."""
    with_obj = [i for i, r in enumerate(train.records) if len(r.labels)]
    empty = [i for i, r in enumerate(train.records) if not len(r.labels)]
    n_keep = max(1, round(keep_fraction * len(with_obj)))
    kept = np.random.default_rng([seed, 7]).choice(with_obj, n_keep, replace=False)
    return train.subset(sorted(int(i) for i in kept) + empty), empty


def insertion_backgrounds(empty: list[int], seed: int, n: int | None) -> list[int]:
    order = np.random.default_rng([seed, 11]).permutation(len(empty))
    return [empty[int(i)] for i in order[: (len(empty) if n is None else min(n, len(empty)))]]


def generate_arm_set(cfg: StudyConfig, arm: str, seed: int, train: DetectionSet, background_idx: list[int]) -> Path:
    """Render the inserted copies for (arm, seed) into a YOLO folder; cached: an existing ``done.json`` is reused."""
    from aias_augment.pipeline import load_preset

    out = _repo_path(cfg.cache_dir) / arm / f"seed{seed}"
    done = out / "done.json"
    ic = cfg.insertion
    wanted = {"arm": arm, "seed": seed, "backgrounds": [Path(train.records[i].image_path).name for i in background_idx],
              "insertion": dataclasses.asdict(ic), "flags": ARM_FLAGS[arm]}
    code = {"code_commit": _git_head()}
    if done.exists():
        prev = json.loads(done.read_text())
        if all(prev.get(k) == v for k, v in wanted.items()):
            log.info("%s seed %d: using cached %s (%d images)", arm, seed, out, prev["num_images"])
            return out
        log.info("%s seed %d: cache parameters changed, regenerating", arm, seed)
    ins_cfg = load_preset(ic.preset, categories=tuple(ic.categories), min_objects=ic.min_objects,
                          max_objects=ic.max_objects, harmonize_method=ic.harmonize_method, **ARM_FLAGS[arm])
    t0 = time.perf_counter()
    n_boxes, failures, manifest = 0, {}, []
    for k, i in enumerate(background_idx):
        rec = train.records[i]
        image = read_image_rgb(rec.image_path)
        scale = min(1.0, ic.max_side_px / max(image.shape[:2]))
        if scale < 1:
            image = cv2.resize(image, (round(image.shape[1] * scale), round(image.shape[0] * scale)),
                               interpolation=cv2.INTER_AREA)
        rng = np.random.default_rng([seed, i])       # same draw stream for every arm: paired copies
        try:
            res = _insert(image, rng, ins_cfg)
        except Exception as exc:  # logged and counted; the copy is left out, never written without its boxes
            reason = f"{type(exc).__name__}: {exc}"[:200]
            failures[reason] = failures.get(reason, 0) + 1
            log.warning("%s seed %d: insertion failed on %s: %s", arm, seed, rec.image_path, reason)
            continue
        boxes_xywh = np.asarray(res.bboxes, np.float64).reshape(-1, 4)
        keep = (boxes_xywh[:, 2] >= 1) & (boxes_xywh[:, 3] >= 1)
        boxes_xyxy = np.c_[boxes_xywh[keep, :2], boxes_xywh[keep, :2] + boxes_xywh[keep, 2:]]
        stem = f"{Path(rec.image_path).stem}__{arm}_s{seed}"
        write_yolo_sample(out, stem, res.image, boxes_xyxy, np.zeros(len(boxes_xyxy), np.int64))
        n_boxes += len(boxes_xyxy)
        manifest.append({"background": Path(rec.image_path).name, "image": f"{stem}.jpg", "boxes": int(keep.sum()),
                         "modules": dict(res.record.modules)})
        if (k + 1) % 10 == 0:
            log.info("%s seed %d: %d/%d images, %.1f s/image", arm, seed, k + 1, len(background_idx),
                     (time.perf_counter() - t0) / (k + 1))
    seconds = time.perf_counter() - t0
    write_classes(out, cfg.class_names)
    (out / "manifest.json").write_text(json.dumps(manifest, indent=1))
    done.write_text(json.dumps({**wanted, **code, "num_images": len(manifest), "num_boxes": n_boxes,
                                "failures": failures, "seconds": seconds,
                                "seconds_per_image": seconds / max(len(background_idx), 1)}, indent=1))
    log.info("%s seed %d: %d images, %d inserted boxes in %.0f s", arm, seed, len(manifest), n_boxes, seconds)
    return out


def _git_head() -> str:
    import subprocess
    try:
        return subprocess.run(["git", "rev-parse", "HEAD"], cwd=REPO_ROOT, capture_output=True, text=True,
                              timeout=10).stdout.strip()
    except (OSError, subprocess.SubprocessError):
        return "unknown"


def _insert(image, rng, ins_cfg):
    from aias_augment.pipeline import insert_into_image
    return insert_into_image(image, np.zeros((0, 4)), [], rng, ins_cfg)


def training_set(cfg: StudyConfig, arm: str, seed: int, train: DetectionSet, generate: bool = True):
    """(training DetectionSet, info dict) for one arm and seed."""
    base, empty = thin_cone_images(train, cfg.keep_fraction, seed)
    info = {"real_images": len(base), "real_cone_images": sum(1 for r in base.records if len(r.labels)),
            "real_boxes": base.num_boxes}
    if ARM_FLAGS[arm] is None:
        return base, info
    backgrounds = insertion_backgrounds(empty, seed, cfg.insertion.images_per_seed)
    folder = generate_arm_set(cfg, arm, seed, train, backgrounds) if generate else \
        _repo_path(cfg.cache_dir) / arm / f"seed{seed}"
    if not (folder / "done.json").exists():
        raise FileNotFoundError(f"{folder}: augmented set not generated (run --stage generate)")
    extra = load_yolo_dir(folder, names=cfg.class_names)
    gen = json.loads((folder / "done.json").read_text())
    info.update({"inserted_images": len(extra), "inserted_boxes": extra.num_boxes,
                 "generation_seconds_per_image": gen["seconds_per_image"], "generation_failures": gen["failures"]})
    return base + extra, info


# ------------------------------------------------------------------ runs

_IMAGE_MEMO: dict = {}   # decoded, resized training images shared by all runs of one process


def run_one(cfg: StudyConfig, arm: str, seed: int, train: DetectionSet, val: DetectionSet, val_cache, force=False):
    from .inference import evaluate_dataset
    from .train import save_checkpoint, train_detector

    result_path = _repo_path(cfg.results_dir) / "run_metrics" / f"{arm}_seed{seed}.json"
    if result_path.exists() and not force:
        log.info("%s seed %d: result exists (%s), skipping", arm, seed, result_path)
        return json.loads(result_path.read_text())
    det_cfg = load_detector_config(cfg.detector)
    if cfg.max_iters:
        det_cfg = replace_nested(det_cfg, **{"train.max_iters": cfg.max_iters})
    train_set, info = training_set(cfg, arm, seed, train)
    log.info("%s seed %d: training on %s", arm, seed, info)
    res = train_detector(det_cfg, train_set, seed=seed, log_fn=lambda m: log.info("%s s%d %s", arm, seed, m),
                         image_memo=_IMAGE_MEMO)
    t0 = time.perf_counter()
    metrics = evaluate_dataset(res.model, val, det_cfg.train.img_size, det_cfg.inference, cached=val_cache)
    eval_seconds = time.perf_counter() - t0
    weights = _repo_path(cfg.runs_dir) / arm / f"seed{seed}" / "weights.pt"
    row = {"arm": arm, "seed": seed, **info, "train_images": len(train_set), "iterations": res.iterations,
           "batch_size": det_cfg.train.batch_size, "img_size": det_cfg.train.img_size,
           "train_seconds": res.train_seconds, "cache_seconds": res.cache_seconds,
           "train_images_per_second": res.images_per_second, "eval_seconds": eval_seconds,
           "final_losses": res.final_losses, "metrics": _nan_to_none(metrics), "weights": str(weights),
           "detector": dataclasses.asdict(det_cfg)}
    save_checkpoint(weights, res.model, train_set.category_names, {k: v for k, v in row.items() if k != "detector"})
    result_path.parent.mkdir(parents=True, exist_ok=True)
    result_path.write_text(json.dumps(row, indent=1))
    log.info("%s seed %d: AP %.4f AP50 %.4f (%.0f s train, %.2f img/s)", arm, seed, metrics["AP"], metrics["AP50"],
             res.train_seconds, res.images_per_second)
    return row


def _nan_to_none(obj):
    if isinstance(obj, float) and math.isnan(obj):
        return None
    if isinstance(obj, dict):
        return {k: _nan_to_none(v) for k, v in obj.items()}
    return obj


# ------------------------------------------------------------------ summary

def mean_ci95(values) -> tuple[float, float]:
    """Mean and half-width of the two-sided 95% Student-t interval (nan half-width for fewer than 2 values)."""
    from scipy import stats
    v = np.asarray([x for x in values if x is not None], np.float64)
    if v.size == 0:
        return float("nan"), float("nan")
    if v.size < 2:
        return float(v.mean()), float("nan")
    return float(v.mean()), float(stats.t.ppf(0.975, v.size - 1) * v.std(ddof=1) / math.sqrt(v.size))


METRIC_COLUMNS = (("AP", "AP50:95"), ("AP50", "AP50"), ("AP_small", "AP_S"), ("AP_medium", "AP_M"),
                  ("AP_large", "AP_L"))


def summarize(rows: list[dict], reference: str = "original") -> tuple[str, dict]:
    arms = list(dict.fromkeys(r["arm"] for r in rows))
    by_arm = {a: sorted((r for r in rows if r["arm"] == a), key=lambda r: r["seed"]) for a in arms}
    ref = {r["seed"]: r for r in by_arm.get(reference, [])}
    summary = {}
    fmt = lambda m, h: "n/a" if math.isnan(m) else (f"{m:.3f}" if math.isnan(h) else f"{m:.3f} ± {h:.3f}")
    head = "| arm | seeds | train images (real + inserted) | " + " | ".join(c[1] for c in METRIC_COLUMNS) + \
        f" | ΔAP50:95 vs {reference} (paired) | train s/run | train img/s |"
    lines = [head, "|" + "---|" * (head.count("|") - 1)]
    for a in arms:
        rs = by_arm[a]
        s = {"seeds": [r["seed"] for r in rs]}
        for key, _ in METRIC_COLUMNS:
            s[key] = mean_ci95([r["metrics"][key] for r in rs])
        deltas = [r["metrics"]["AP"] - ref[r["seed"]]["metrics"]["AP"] for r in rs if r["seed"] in ref]
        s["delta_AP"] = mean_ci95(deltas) if a != reference else (float("nan"), float("nan"))
        s["train_seconds"] = float(np.median([r["train_seconds"] for r in rs]))
        s["train_images_per_second"] = float(np.median([r["train_images_per_second"] for r in rs]))
        real = int(np.median([r["real_images"] for r in rs]))
        ins = int(np.median([r.get("inserted_images", 0) for r in rs]))
        summary[a] = s
        lines.append(f"| {a} | {len(rs)} | {real} + {ins} | " +
                     " | ".join(fmt(*s[k]) for k, _ in METRIC_COLUMNS) +
                     f" | {fmt(*s['delta_AP']) if a != reference else '—'} | {s['train_seconds']:.0f} | "
                     f"{s['train_images_per_second']:.2f} |")
    return "\n".join(lines) + "\n", summary


def plot_summary(rows: list[dict], path: Path, reference: str = "original") -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    arms = list(dict.fromkeys(r["arm"] for r in rows))
    fig, axes = plt.subplots(1, 2, figsize=(4 + 1.6 * len(arms), 4))
    for ax, (key, title) in zip(axes, (("AP", "AP50:95"), ("AP50", "AP50"))):
        for x, a in enumerate(arms):
            vals = [r["metrics"][key] for r in rows if r["arm"] == a]
            m, h = mean_ci95(vals)
            ax.scatter([x] * len(vals), vals, color="0.6", s=14, zorder=2)
            ax.errorbar([x], [m], yerr=[[0 if math.isnan(h) else h]] * 2, fmt="o", color="C0" if a == reference
                        else "C1", capsize=6, markersize=7, zorder=3)
        ax.set_xticks(range(len(arms)), arms, rotation=20)
        ax.set_title(f"TraCon val {title} (mean, 95% CI; grey = seeds)")
        ax.grid(axis="y", alpha=0.3)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=120)
    plt.close(fig)


def write_summary(cfg: StudyConfig, config_path: str, command: str) -> str:
    results = _repo_path(cfg.results_dir)
    rows = [json.loads(p.read_text()) for p in sorted((results / "run_metrics").glob("*.json"))]
    rows = [r for r in rows if r["arm"] in ARM_FLAGS]
    if not rows:
        raise FileNotFoundError(f"no run results under {results / 'run_metrics'}")
    order = {a: i for i, a in enumerate(ARM_FLAGS)}
    rows.sort(key=lambda r: (order[r["arm"]], r["seed"]))
    table, summary = summarize(rows, cfg.reference_arm)
    plot_summary(rows, results / "ap_by_arm.png", cfg.reference_arm)
    r0 = rows[0]
    gen = {}
    for a in dict.fromkeys(r["arm"] for r in rows):
        per_image = [r["generation_seconds_per_image"] for r in rows if r["arm"] == a and
                     "generation_seconds_per_image" in r]
        if per_image:
            gen[a] = float(np.median(per_image))
    note = (f"Detector: `{r0['detector']['model']['backbone']}` (width {r0['detector']['model']['width']}), "
            f"{r0['img_size']} px, {r0['iterations']} iterations x batch {r0['batch_size']} per run, 1 CPU thread. "
            f"Evaluated on TraCon val ({r0['metrics']['num_images']} images, {r0['metrics']['num_gt']} cones) with "
            f"pycocotools. Mean ± half-width of the 95% Student-t interval over seeds.\n")
    if gen:
        note += "Offline generation, median seconds per inserted image: " + \
            ", ".join(f"{a} {s:.1f}" for a, s in gen.items()) + ".\n"
    md = f"# Detection study: TraCon cones\n\nCommand: `{command}` (config `{config_path}`)\n\n{note}\n{table}\n" \
         f"![AP by arm](ap_by_arm.png)\n"
    (results / "table.md").write_text(md)
    (results / "summary.json").write_text(json.dumps(_nan_to_none(
        {a: {k: (list(v) if isinstance(v, tuple) else v) for k, v in s.items()} for a, s in summary.items()}),
        indent=1))
    return md


# ------------------------------------------------------------------ entry point

def load_study_config(path: str | Path) -> StudyConfig:
    p = Path(path)
    if not p.exists() and not p.suffix:
        p = REPO_ROOT / "configs" / "study" / f"{path}.yaml"
    return load_config(StudyConfig, p)


def available_arms(arms) -> list[str]:
    """Arms whose insertion interface exists; the rest are skipped with a logged reason."""
    try:
        from aias_augment.pipeline import insert_into_image, load_preset  # noqa: F401
        return list(arms)
    except ImportError as exc:
        skipped = [a for a in arms if ARM_FLAGS[a] is not None]
        if skipped:
            log.warning("skipping arms %s: aias_augment.pipeline is not available (%s)", skipped, exc)
        return [a for a in arms if ARM_FLAGS[a] is None]


def main(argv: list[str] | None = None) -> None:
    import shlex
    import sys

    import torch

    p = argparse.ArgumentParser(prog="aias-study", description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--config", default="configs/study/tracon_cones.yaml")
    p.add_argument("--stage", choices=("all", "generate", "train", "summarize"), default="all")
    p.add_argument("--arms", nargs="*", help="subset of the config's arms")
    p.add_argument("--seeds", nargs="*", type=int, help="subset of the config's seeds")
    p.add_argument("--force", action="store_true", help="re-run runs whose results exist")
    args = p.parse_args(argv)
    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(levelname)s %(name)s: %(message)s")
    torch.set_num_threads(1)
    cfg = load_study_config(args.config)
    arms = available_arms(args.arms or cfg.arms)
    seeds = args.seeds if args.seeds is not None else list(cfg.seeds)
    command = "aias-study " + " ".join(shlex.quote(a) for a in (sys.argv[1:] if argv is None else argv))
    root = dataset_root(cfg)
    if args.stage in ("all", "generate", "train"):
        train = load_yolo_dir(root, cfg.train_split, cfg.class_names)
        log.info("train: %d images, %d boxes", len(train), train.num_boxes)
    if args.stage == "generate":
        for seed in seeds:
            for arm in arms:
                if ARM_FLAGS[arm] is not None:
                    training_set(cfg, arm, seed, train)
        return
    if args.stage in ("all", "train"):
        from .loader import cache_dataset
        val = load_yolo_dir(root, cfg.val_split, cfg.class_names)
        det_cfg = load_detector_config(cfg.detector)
        val_cache = cache_dataset(val, det_cfg.train.img_size)
        for seed in seeds:
            for arm in arms:
                run_one(cfg, arm, seed, train, val, val_cache, force=args.force)
    print(write_summary(cfg, str(args.config), command))


if __name__ == "__main__":
    main()

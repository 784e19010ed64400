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

from aias_augment.core.config import CONFIG_DIR, REPO_ROOT, data_root, load_config

from .config import load_detector_config, replace_nested
from .data import DetectionSet, load_yolo_dir, read_image_rgb, write_classes, write_yolo_sample

log = logging.getLogger("detection_eval.study")

# Stage switches of aias_augment.pipeline.image.InsertionConfig per arm; None = no insertion.
ARM_FLAGS: dict[str, dict | None] = {
    "original": None,
    "inserted": {},
    "naive_paste": {"naive_paste": True},
    "no_placement": {"placement": False},
    "no_shadow": {"shadow": False},
    "no_lighting": {"lighting": False},
    "no_harmonize": {"harmonize": False},
    "inserted_online": {},
    "inserted_procedural": {"asset_source": "procedural"},  # a new seeded procedural cone per object
    # The inserted image cropped, without resampling, around its largest object so that object's box height matches
    # a height drawn from the real train boxes (see closeup_crop): a level road camera ~1.65 m up cannot see a cone
    # standing on the ground taller than ~0.3 of the frame, while a third of TraCon's real cones are.
    "inserted_closeup": {"closeup_crop": True},
    # Placement fitted to the photo (issue 15's matched-background protocol: TraCon's close-ups got cones half the
    # size of their own and a third cut by the frame): box heights from the photo's own cones, objects in frame.
    "inserted_scene_sizes": {"placement_cfg": {"sizes_from_existing": True}},
    "inserted_in_frame": {"placement_cfg": {"min_in_image_frac": 1.0}},
    "inserted_scene_sizes_in_frame": {"placement_cfg": {"sizes_from_existing": True, "min_in_image_frac": 1.0}},
    # The photo's unknown metric scale (a single photo's camera height is a prior) drawn per image so that the real
    # boxes' sizes stand on its visible ground (PlacementConfig.scene_scale_from_sizes): ground contact, perspective
    # and shadows as in ``inserted``, sizes as in ``naive_paste``.
    "inserted_scene_scale": {"placement_cfg": {"scene_scale_from_sizes": True}},
    # Its ablation: the assumed camera height kept, so sizes are what that height lets the visible ground host.
    "inserted_fixed_scale": {"placement_cfg": {"scene_scale_from_sizes": False}},
    # The seed's thinned subset's own real instances (aias_augment.assets.bank.lift): pasted at random positions and sizes
    # (Simple Copy-Paste, masks from the boxes by GrabCut), or lifted into 3D and inserted by the full pipeline
    # (placed on the ground, lit, shadowed, harmonized: the pipeline with the data's own appearance).
    "copy_paste": {"copy_paste": True},
    "lifted": {"lifted": True},
}
# Flags the study applies itself (not insertion-config overrides).
STUDY_FLAGS = ("closeup_crop", "copy_paste", "lifted")
# Arms whose pool is made per seed from that seed's thinned real subset (no other seed's real images leak in).
PER_SEED_ARMS = ("copy_paste", "lifted")
# Arms whose insertions happen inside the training loop (``InsertObjects`` on each sample, new draws every epoch)
# instead of coming from the offline pool.
ONLINE_ARMS = ("inserted_online",)


@dataclass(frozen=True)
class InsertionStudyConfig:
    preset: str = "fast"  # aias_augment configs/presets/<preset>.yaml
    harmonize_method: str = "camera"  # pinned, so every arm and seed uses the same harmonizer
    categories: tuple[str, ...] = ("traffic_cone",)
    min_objects: int = 1
    max_objects: int = 3
    pool_size: int = 200  # inserted images generated once per arm (backgrounds cycle when larger
    # than the 199 empty road images); every run draws its share from it
    pool_seed: int = 0  # copy j uses default_rng([pool_seed, j]) in every arm: paired copies
    max_side_px: int = 640  # backgrounds are downscaled to this before insertion (we train at 320)
    match_real_sizes: bool = True  # target box heights drawn from the labelled train boxes' heights (as a
    # fraction of image height): inserted objects cover the real sizes

    def __post_init__(self):
        if self.pool_size < 1:
            raise ValueError(f"pool_size must be >= 1, got {self.pool_size}")


@dataclass(frozen=True)
class StudyConfig:
    dataset: str = "tracon"  # folder under $AIAS_DATA (or an absolute path)
    class_names: tuple[str, ...] = ("cone",)
    train_split: str = "train"
    val_split: str = "val"
    keep_fraction: float = 0.1  # of the train images that contain cones
    seeds: tuple[int, ...] = (0, 1, 2, 3, 4)
    arms: tuple[str, ...] = ("original", "inserted", "naive_paste")
    amounts: tuple[int, ...] = (200,)  # inserted images added per run (an axis: a gain may need enough cones)
    detector: str = "lite0_320"  # configs/detector/<name>.yaml
    max_iters: int | None = None  # overrides the detector config: the per-run budget
    insertion: InsertionStudyConfig = field(default_factory=InsertionStudyConfig)
    cache_dir: str = "out/study/cache"
    runs_dir: str = "runs/study"  # weights (not committed)
    results_dir: str = "results/study"  # metrics, table, plot (committed)
    reference_arm: str = "original"
    # A development split carved out of train before anything else (fixed draw, seed ``dev_seed``): no arm trains on
    # it, every run is scored on it beside val, and settings are chosen on it, never on val.
    dev_cone_images: int = 0
    dev_empty_images: int = 0
    dev_seed: int = 0
    online_p: float = 0.5  # inserted_online: probability that a training sample gets insertions

    def __post_init__(self):
        unknown = [a for a in self.arms if a not in ARM_FLAGS]
        if unknown:
            raise ValueError(f"unknown arms {unknown}; known: {list(ARM_FLAGS)}")
        if not 0 < self.keep_fraction <= 1:
            raise ValueError(f"keep_fraction must lie in (0, 1], got {self.keep_fraction}")
        if len(set(self.seeds)) != len(self.seeds) or not self.seeds:
            raise ValueError(f"seeds must be distinct and non-empty, got {self.seeds}")
        if not self.amounts or any(a < 1 or a > self.insertion.pool_size for a in self.amounts):
            raise ValueError(
                f"amounts must lie in [1, insertion.pool_size={self.insertion.pool_size}], got {self.amounts}"
            )


def _repo_path(p: str) -> Path:
    return Path(p) if Path(p).is_absolute() else REPO_ROOT / p


def dataset_root(cfg: StudyConfig) -> Path:
    p = Path(cfg.dataset)
    return p if p.is_absolute() else data_root() / p


# ------------------------------------------------------------------ training sets


def split_dev(train: DetectionSet, n_cone: int, n_empty: int, seed: int) -> tuple[DetectionSet, DetectionSet]:
    """(rest, dev): ``n_cone`` images with objects and ``n_empty`` without, drawn once with ``default_rng([seed,
    3])``, moved out of ``train`` into a development set that no arm trains on (its empty roads are no insertion
    backgrounds either)."""
    with_obj = [i for i, r in enumerate(train.records) if len(r.labels)]
    empty = [i for i, r in enumerate(train.records) if not len(r.labels)]
    if n_cone > len(with_obj) or n_empty > len(empty) or n_cone < 0 or n_empty < 0:
        raise ValueError(f"dev split of {n_cone} + {n_empty} images asked of {len(with_obj)} + {len(empty)}")
    rng = np.random.default_rng([seed, 3])
    dev = set(int(i) for i in rng.choice(with_obj, n_cone, replace=False)) | set(
        int(i) for i in rng.choice(empty, n_empty, replace=False)
    )
    rest = [i for i in range(len(train)) if i not in dev]
    return train.subset(rest), train.subset(sorted(dev))


def thin_cone_images(train: DetectionSet, keep_fraction: float, seed: int) -> tuple[DetectionSet, list[int]]:
    """Keep ``round(keep_fraction * n)`` of the images with objects (seeded) and every image without; also return
    the indices of the images without objects (the insertion backgrounds)."""
    with_obj = [i for i, r in enumerate(train.records) if len(r.labels)]
    empty = [i for i, r in enumerate(train.records) if not len(r.labels)]
    n_keep = max(1, round(keep_fraction * len(with_obj)))
    kept = np.random.default_rng([seed, 7]).choice(with_obj, n_keep, replace=False)
    return train.subset(sorted(int(i) for i in kept) + empty), empty


def pool_backgrounds(empty: list[int], pool_seed: int, n: int) -> list[int]:
    """Background of each of the ``n`` pool copies: a seeded order of the empty images, cycled when ``n`` exceeds
    them (copy j and copy j + len(empty) share a background, with different draws)."""
    order = np.random.default_rng([pool_seed, 11]).permutation(len(empty))
    return [empty[int(order[j % len(empty)])] for j in range(n)]


def pool_share(pool_size: int, amount: int, seed: int) -> list[int]:
    """Which pool copies a run with ``seed`` uses: ``amount`` of them, a seeded subset (all when amount == size)."""
    return sorted(int(j) for j in np.random.default_rng([seed, 13]).permutation(pool_size)[:amount])


def real_box_height_fractions(train: DetectionSet) -> tuple[float, ...]:
    """Box height / image height of every labelled box (the class's size distribution in the user's data)."""
    return tuple(
        float((r.boxes_xyxy[i, 3] - r.boxes_xyxy[i, 1]) / r.height) for r in train.records for i in range(len(r.labels))
    )


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


def insertion_config_for_arm(cfg: StudyConfig, arm: str, train: DetectionSet):
    from aias_augment.pipeline.image import load_preset

    ic = cfg.insertion
    flags = {k: v for k, v in ARM_FLAGS[arm].items() if k not in STUDY_FLAGS}
    placement_flags = flags.pop("placement_cfg", {})  # fields of the placement config, on top of the preset's
    overrides = dict(
        categories=tuple(ic.categories),
        min_objects=ic.min_objects,
        max_objects=ic.max_objects,
        harmonize_method=ic.harmonize_method,
        **flags,
    )
    base = load_preset(ic.preset).placement_cfg
    if ic.match_real_sizes:
        fracs = tuple(f for f in real_box_height_fractions(train) if 0 < f <= 1)
        overrides["placement_cfg"] = dataclasses.replace(base, box_height_frac_samples=fracs)
        if ARM_FLAGS[arm].get("naive_paste") or ARM_FLAGS[arm].get("placement") is False:
            # random 2D positions (naive paste, no placement) draw their sizes from the same distribution
            overrides["naive_height_frac_samples"] = fracs
    if placement_flags:
        overrides["placement_cfg"] = dataclasses.replace(overrides.get("placement_cfg", base), **placement_flags)
    return load_preset(ic.preset, **overrides)


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
    restarted; ``done.json`` marks a complete pool and is reused while its parameters match."""
    if ARM_FLAGS[arm].get("closeup_crop"):
        return derive_closeup_pool(cfg, arm, train, empty)
    ic = cfg.insertion
    per_seed = arm in PER_SEED_ARMS
    if per_seed and (seed is None or base is None):
        raise ValueError(f"{arm}: its pool is made from the seed's own real instances: pass seed and base")
    out = _repo_path(cfg.cache_dir) / arm / (f"seed{seed}/pool" if per_seed else "pool")
    done, progress = out / "done.json", out / "progress.jsonl"
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
    if done.exists():
        prev = json.loads(done.read_text())
        if all(prev.get(k) == v for k, v in wanted.items()):
            log.info("%s: using cached pool %s (%d images)", arm, out, prev["num_images"])
            return out
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
    try:
        make = _pool_maker(cfg, arm, train, base, out)
    except RuntimeError as exc:  # no usable instance in the subset: every copy fails with that reason (counted)
        log.warning("%s: %s", arm, exc)

        def make(image, rng, _exc=exc):
            raise _exc

    t0, n_new = time.perf_counter(), 0
    with progress.open("a") as plog:
        for j, i in enumerate(backgrounds):
            if j in finished:
                continue
            rec = train.records[i]
            image = read_image_rgb(rec.image_path)
            scale = min(1.0, ic.max_side_px / max(image.shape[:2]))
            if scale < 1:
                image = cv2.resize(
                    image, (round(image.shape[1] * scale), round(image.shape[0] * scale)), interpolation=cv2.INTER_AREA
                )
            rng = np.random.default_rng([ic.pool_seed, j])  # same draw stream for every arm: paired copies
            t_img = time.perf_counter()
            try:
                new_image, boxes_xyxy, modules = make(image, rng)
            except Exception as exc:  # logged and counted; the copy is left out, never written without its boxes
                reason = f"{type(exc).__name__}: {exc}"[:200]
                log.warning("%s: insertion failed on %s: %s", arm, rec.image_path, reason)
                entry = {"copy": j, "background": Path(rec.image_path).name, "failed": reason}
            else:
                keep = (boxes_xyxy[:, 2] - boxes_xyxy[:, 0] >= 1) & (boxes_xyxy[:, 3] - boxes_xyxy[:, 1] >= 1)
                boxes_xyxy = boxes_xyxy[keep]
                stem = f"{j:04d}_{Path(rec.image_path).stem}__{arm}"
                write_yolo_sample(out, stem, new_image, boxes_xyxy, np.zeros(len(boxes_xyxy), np.int64))
                entry = {
                    "copy": j,
                    "background": Path(rec.image_path).name,
                    "image": f"{stem}.jpg",
                    "boxes": int(keep.sum()),
                    "box_heights_frac": [float(x) for x in (boxes_xyxy[:, 3] - boxes_xyxy[:, 1]) / image.shape[0]],
                    "seconds": time.perf_counter() - t_img,
                    "modules": modules,
                }
            plog.write(json.dumps(entry) + "\n")
            plog.flush()
            finished[j] = entry
            n_new += 1
            if n_new % 10 == 0:
                log.info(
                    "%s: %d/%d pool images, %.1f s/image",
                    arm,
                    len(finished),
                    len(backgrounds),
                    (time.perf_counter() - t0) / n_new,
                )
    entries = [finished[j] for j in sorted(finished)]
    ok = [e for e in entries if not e.get("failed")]
    failures: dict[str, int] = {}
    for e in entries:
        if e.get("failed"):
            failures[e["failed"]] = failures.get(e["failed"], 0) + 1
    write_classes(out, cfg.class_names)
    (out / "manifest.json").write_text(json.dumps(entries, indent=1))
    seconds = [e["seconds"] for e in ok]
    done.write_text(
        json.dumps(
            {
                **wanted,
                "code_commit": _git_head(),
                "num_images": len(ok),
                "num_boxes": sum(e["boxes"] for e in ok),
                "failures": failures,
                "seconds_per_image": float(np.median(seconds)) if seconds else None,
            },
            indent=1,
        )
    )
    log.info("%s: pool of %d images, %d inserted boxes", arm, len(ok), sum(e["boxes"] for e in ok))
    return out


def derive_closeup_pool(cfg: StudyConfig, arm: str, train: DetectionSet, empty: list[int]) -> Path:
    """The ``inserted`` pool's copies, each cropped by :func:`closeup_crop` (copy j with ``default_rng([pool_seed,
    j, 17])``) to a height drawn from the real train boxes: the same insertions, framed closer, so the paired
    difference to ``inserted`` measures the framing alone. No rendering: seconds for the whole pool."""
    src = generate_arm_set(cfg, "inserted", train, empty)
    src_done = json.loads((src / "done.json").read_text())
    out = _repo_path(cfg.cache_dir) / arm / "pool"
    done = out / "done.json"
    wanted = json.loads(
        json.dumps(
            {
                "arm": arm,
                "flags": ARM_FLAGS[arm],
                "insertion": dataclasses.asdict(cfg.insertion),
                "source": {k: src_done.get(k) for k in ("code_commit", "num_images", "num_boxes")},
            }
        )
    )
    if done.exists() and all(json.loads(done.read_text()).get(k) == v for k, v in wanted.items()):
        log.info("%s: using cached pool %s", arm, out)
        return out
    done.unlink(missing_ok=True)
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
                "code_commit": _git_head(),
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


def _git_head() -> str:
    import subprocess

    try:
        return subprocess.run(
            ["git", "rev-parse", "HEAD"], cwd=REPO_ROOT, capture_output=True, text=True, timeout=10
        ).stdout.strip()
    except (OSError, subprocess.SubprocessError):
        return "unknown"


def _pool_maker(cfg: StudyConfig, arm: str, train: DetectionSet, base: DetectionSet | None, out: Path):
    """``make(background, rng) -> (image, boxes_xyxy, modules)`` of the arm: the pipeline (with the lifted instances
    of the seed's subset as its assets for ``lifted``), or copy-paste of the subset's real instances."""
    from aias_augment.pipeline.image import insert_into_image

    flags = ARM_FLAGS[arm]
    if flags.get("copy_paste") or flags.get("lifted"):
        from aias_augment.assets.bank.lift import LiftedAssets, cut_out, lift_instances

        items = [(r.image_path, read_image_rgb(r.image_path), r.boxes_xyxy) for r in base.records if len(r.labels)]
        category = cfg.insertion.categories[0]
        if flags.get("lifted"):
            assets, report = lift_instances(items, category, out / "assets")
            log.info(
                "%s: lifted %d instances of %d images (rejected: %s)",
                arm,
                report.lifted,
                len(items),
                dict(report.rejected),
            )
            if not assets:
                raise RuntimeError(f"no instance of the subset could be lifted: {dict(report.rejected)}")
            bank = LiftedAssets({category: assets})
        else:
            from .copy_paste import paste_instances

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

            def make_paste(image, rng):
                n = int(rng.integers(ic.min_objects, ic.max_objects + 1))
                new, boxes = paste_instances(image, cutouts, rng, fracs, n)
                return new, boxes, {"mode": f"copy-paste of {len(cutouts)} real instances"}

            return make_paste
    else:
        bank = None
    ins_cfg = insertion_config_for_arm(cfg, "inserted" if flags.get("lifted") else arm, train)

    def make_insert(image, rng):
        res = insert_into_image(image, np.zeros((0, 4)), [], rng, ins_cfg, bank=bank)
        b = np.asarray(res.bboxes, np.float64).reshape(-1, 4)
        return res.image, np.c_[b[:, :2], b[:, :2] + b[:, 2:]], dict(res.record.modules)

    return make_insert


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
        else _repo_path(cfg.cache_dir) / arm / (f"seed{seed}/pool" if per_seed else "pool")
    )
    if not (folder / "done.json").exists():
        raise FileNotFoundError(f"{folder}: augmented pool not generated (run --stage generate)")
    gen = json.loads((folder / "done.json").read_text())
    manifest = json.loads((folder / "manifest.json").read_text())
    by_copy = {e["copy"]: e for e in manifest if not e.get("failed")}
    amount = cfg.amounts[0] if amount is None else amount
    share = [j for j in pool_share(cfg.insertion.pool_size, amount, seed) if j in by_copy]
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


# ------------------------------------------------------------------ runs

_IMAGE_MEMO: dict = {}  # decoded, resized training images shared by all runs of one process


def run_name(arm: str, seed: int, amount: int | None) -> str:
    return f"{arm}_seed{seed}" if amount is None else f"{arm}_n{amount}_seed{seed}"


def uses_pool(arm: str) -> bool:
    return ARM_FLAGS[arm] is not None and arm not in ONLINE_ARMS


def online_transform(cfg: StudyConfig, train: DetectionSet, scene_cache_dir: Path | None = None):
    """The ``InsertObjects`` albumentations transform (the study's insertion settings, class label 0) as the
    trainer's per-sample transform: each sample gets new insertions with probability ``cfg.online_p``; scene
    analyses are cached by content, so from the second epoch on an image pays no analysis."""
    import albumentations as A

    from aias_augment import InsertObjects

    from .online import albumentations_transform

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
    result_path = _repo_path(cfg.results_dir) / "run_metrics" / f"{name}.json"
    if result_path.exists() and not force:
        log.info("%s: result exists (%s), skipping", name, result_path)
        return json.loads(result_path.read_text())
    claim = claim_run(result_path)
    if claim is None:
        log.info("%s: being trained by another process, skipping", name)
        return None
    try:
        return _train_and_score(cfg, arm, seed, amount, name, result_path, train, val, val_cache, dev, dev_cache)
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


def _train_and_score(cfg, arm, seed, amount, name, result_path, train, val, val_cache, dev=None, dev_cache=None):
    from .inference import evaluate_dataset
    from .train import save_checkpoint, train_detector

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
    sample_transform = (
        online_transform(cfg, train, _repo_path(cfg.cache_dir) / "scenes") if arm in ONLINE_ARMS else None
    )
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
    weights = _repo_path(cfg.runs_dir) / name / "weights.pt"
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
        "metrics": _nan_to_none(metrics),
        "dev_metrics": _nan_to_none(dev_metrics),
        "weights": str(weights),
        "code_commit": _git_head(),
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


METRIC_COLUMNS = (
    ("AP", "AP50:95"),
    ("AP50", "AP50"),
    ("AP_small", "AP_S"),
    ("AP_medium", "AP_M"),
    ("AP_large", "AP_L"),
)


def group_of(row: dict) -> str:
    """Table row label: the arm, with its amount of inserted images when it has one."""
    return row["arm"] if row.get("amount") is None else f"{row['arm']} n={row['amount']}"


def paired_deltas(rows: list[dict], group: str, other: str, key: str = "AP", split: str = "metrics") -> list[float]:
    """``group`` minus ``other`` per seed, over the seeds both have (same seed = same thinned real subset);
    ``split`` "metrics" (val) or "dev_metrics"."""
    a = {r["seed"]: (r.get(split) or {}).get(key) for r in rows if group_of(r) == group}
    b = {r["seed"]: (r.get(split) or {}).get(key) for r in rows if group_of(r) == other}
    return [a[s] - b[s] for s in sorted(a) if s in b and a[s] is not None and b[s] is not None]


def summarize(rows: list[dict], reference: str = "original") -> tuple[str, dict]:
    """Markdown table: per arm (and amount) mean ± 95 % t-interval over seeds of each metric, and the paired
    differences of AP50:95 to ``reference`` and, for inserted arms, to ``naive_paste`` at the same amount."""
    groups = list(dict.fromkeys(group_of(r) for r in rows))
    summary = {}
    fmt = lambda m, h: "n/a" if math.isnan(m) else (f"{m:.3f}" if math.isnan(h) else f"{m:.3f} ± {h:.3f}")
    head = (
        "| arm | seeds | train images (real + inserted) | "
        + " | ".join(c[1] for c in METRIC_COLUMNS)
        + f" | ΔAP50:95 vs {reference} (paired) | ΔAP50:95 vs naive_paste (paired) | dev AP50:95 | "
        f"dev ΔAP50:95 vs {reference} | train s/run | train img/s |"
    )
    lines = [head, "|" + "---|" * (head.count("|") - 1)]
    for g in groups:
        rs = sorted((r for r in rows if group_of(r) == g), key=lambda r: r["seed"])
        arm, amount = rs[0]["arm"], rs[0].get("amount")
        s = {"arm": arm, "amount": amount, "seeds": [r["seed"] for r in rs]}
        for key, _ in METRIC_COLUMNS:
            s[key] = mean_ci95([r["metrics"][key] for r in rs])
        s["delta_AP"] = (
            mean_ci95(paired_deltas(rows, g, reference)) if arm != reference else (float("nan"), float("nan"))
        )
        naive = f"naive_paste n={amount}"
        s["delta_AP_vs_naive"] = (
            mean_ci95(paired_deltas(rows, g, naive))
            if arm not in (reference, "naive_paste") and naive in groups
            else (float("nan"), float("nan"))
        )
        s["dev_AP"] = mean_ci95([(r.get("dev_metrics") or {}).get("AP") for r in rs])
        s["dev_delta_AP"] = (
            mean_ci95(paired_deltas(rows, g, reference, split="dev_metrics"))
            if arm != reference
            else (float("nan"), float("nan"))
        )
        s["train_seconds"] = float(np.median([r["train_seconds"] for r in rs]))
        s["train_images_per_second"] = float(np.median([r["train_images_per_second"] for r in rs]))
        real = int(np.median([r["real_images"] for r in rs]))
        ins = int(np.median([r.get("inserted_images", 0) for r in rs]))
        summary[g] = s
        dn = fmt(*s["delta_AP_vs_naive"]) if not math.isnan(s["delta_AP_vs_naive"][0]) else "—"
        lines.append(
            f"| {g} | {len(rs)} | {real} + {ins} | "
            + " | ".join(fmt(*s[k]) for k, _ in METRIC_COLUMNS)
            + f" | {fmt(*s['delta_AP']) if arm != reference else '—'} | {dn} | {fmt(*s['dev_AP'])} | "
            f"{fmt(*s['dev_delta_AP']) if arm != reference else '—'} | {s['train_seconds']:.0f} | "
            f"{s['train_images_per_second']:.2f} |"
        )
    return "\n".join(lines) + "\n", summary


def plot_summary(rows: list[dict], path: Path, reference: str = "original") -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    groups = list(dict.fromkeys(group_of(r) for r in rows))
    fig, axes = plt.subplots(1, 2, figsize=(4 + 1.6 * len(groups), 4))
    for ax, (key, title) in zip(axes, (("AP", "AP50:95"), ("AP50", "AP50"))):
        for x, g in enumerate(groups):
            vals = [r["metrics"][key] for r in rows if group_of(r) == g]
            m, h = mean_ci95(vals)
            ax.scatter([x] * len(vals), vals, color="0.6", s=14, zorder=2)
            ax.errorbar(
                [x],
                [m],
                yerr=[[0 if math.isnan(h) else h]] * 2,
                fmt="o",
                color="C0" if g == reference else "C1",
                capsize=6,
                markersize=7,
                zorder=3,
            )
        ax.set_xticks(range(len(groups)), groups, rotation=20)
        ax.set_title(f"TraCon val {title} (mean, 95% CI; grey = seeds)")
        ax.grid(axis="y", alpha=0.3)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=120)
    plt.close(fig)


def plot_amounts(rows: list[dict], path: Path, reference: str = "original") -> bool:
    """Paired ΔAP50:95 to ``reference`` (mean, 95 % CI, seeds as dots) against the number of inserted images, one
    line per pool arm with at least two amounts or sharing an amount with one that has; False when nothing to draw."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    arms = list(dict.fromkeys(r["arm"] for r in rows if r.get("amount") is not None))
    if len({r["amount"] for r in rows if r.get("amount") is not None}) < 2:
        return False
    fig, ax = plt.subplots(figsize=(7, 4.2))
    for k, arm in enumerate(arms):
        amounts = sorted({r["amount"] for r in rows if r["arm"] == arm and r.get("amount") is not None})
        pts = []
        for a in amounts:
            d = paired_deltas(rows, f"{arm} n={a}", reference)
            if d:
                m, h = mean_ci95(d)
                pts.append((a, m, 0.0 if math.isnan(h) else h, d))
        if not pts:
            continue
        off = 1.0 + 0.03 * (k - (len(arms) - 1) / 2)  # a small multiplicative offset so the bars do not overlap
        xs = [a * off for a, *_ in pts]
        ax.errorbar(
            xs,
            [m for _, m, _, _ in pts],
            yerr=[h for *_, h, _ in pts],
            fmt="o-",
            capsize=5,
            color=f"C{k}",
            label=f"{arm} (seeds: {', '.join(str(len(d)) for *_, d in pts)})",
        )
        for x, (_, _, _, d) in zip(xs, pts):
            ax.scatter([x] * len(d), d, color=f"C{k}", s=10, alpha=0.35)
    ax.axhline(0, color="0.3", lw=1)
    ax.set_xscale("log")
    ticks = sorted({r["amount"] for r in rows if r.get("amount") is not None})
    ax.set_xticks(ticks, [str(t) for t in ticks])
    ax.minorticks_off()
    ax.set_xlabel("inserted images per run (beside the real subset's 219 images)")
    ax.set_ylabel(f"paired ΔAP50:95 vs {reference}")
    ax.set_title("TraCon val: gain by amount of inserted data (mean, 95% CI)")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return True


def plot_size_histograms(cfg: StudyConfig, train: DetectionSet, val: DetectionSet, path: Path) -> dict:
    """Box height / image height of real train, real val and each arm's pool; returns their medians."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    series = {"real train": real_box_height_fractions(train), "real val": real_box_height_fractions(val)}
    for arm in ARM_FLAGS:  # every pool generated so far (the other study configs' arms too; per-seed pools pooled)
        arm_dir = _repo_path(cfg.cache_dir) / arm
        files = (
            sorted(arm_dir.glob("seed*/pool/manifest.json"))
            if arm in PER_SEED_ARMS
            else [arm_dir / "pool" / "manifest.json"]
        )
        heights = [
            h for mf in files if mf.exists() for e in json.loads(mf.read_text()) for h in e.get("box_heights_frac", [])
        ]
        if uses_pool(arm) and heights:
            series[f"{arm} pool"] = heights
    fig, ax = plt.subplots(figsize=(7, 4))
    bins = np.linspace(0, 1, 41)
    for k, (name, v) in enumerate(series.items()):
        if len(v):
            ax.hist(
                v,
                bins=bins,
                density=True,
                histtype="step",
                lw=1.8,
                color=f"C{k}",
                label=f"{name} (n={len(v)}, median {np.median(v):.2f})",
            )
    ax.set_xlabel("box height / image height")
    ax.set_ylabel("density")
    ax.set_title("Object sizes: real cones vs inserted")
    ax.legend(fontsize=8)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return {k: float(np.median(v)) for k, v in series.items() if len(v)}


def write_summary(
    cfg: StudyConfig, config_path: str, command: str, train: DetectionSet | None = None, val: DetectionSet | None = None
) -> str:
    results = _repo_path(cfg.results_dir)
    rows = [json.loads(p.read_text()) for p in sorted((results / "run_metrics").glob("*.json"))]
    rows = [r for r in rows if r["arm"] in ARM_FLAGS]
    if not rows:
        raise FileNotFoundError(f"no run results under {results / 'run_metrics'}")
    order = {a: i for i, a in enumerate(ARM_FLAGS)}
    rows.sort(key=lambda r: (order[r["arm"]], r.get("amount") or 0, r["seed"]))
    table, summary = summarize(rows, cfg.reference_arm)
    plot_summary(rows, results / "ap_by_arm.png", cfg.reference_arm)
    r0 = rows[0]
    gen = {}
    for a in dict.fromkeys(r["arm"] for r in rows):
        per_image = [
            r["generation_seconds_per_image"]
            for r in rows
            if r["arm"] == a and r.get("generation_seconds_per_image") is not None
        ]
        if per_image:
            gen[a] = float(np.median(per_image))
    note = (
        f"Detector: `{r0['detector']['model']['backbone']}` (width {r0['detector']['model']['width']}), "
        f"{r0['img_size']} px, {r0['iterations']} iterations x batch {r0['batch_size']} per run, "
        f"{r0.get('threads', 1)} CPU thread(s) per run. Evaluated on TraCon val ({r0['metrics']['num_images']} "
        f"images, {r0['metrics']['num_gt']} cones) with pycocotools. Mean ± half-width of the 95% Student-t "
        f"interval over seeds; Δ columns are paired by seed (seed k of every arm trains on the same thinned "
        f"real subset, redrawn per seed, so its variance is inside the interval).\n"
    )
    if gen:
        note += (
            "Offline generation, median seconds per inserted image: "
            + ", ".join(f"{a} {s:.1f}" for a, s in gen.items())
            + ".\n"
        )
    total = sum(r["train_seconds"] + r.get("eval_seconds", 0.0) for r in rows)
    note += (
        f"Training and evaluation time summed over the {len(rows)} runs: {total / 60:.0f} min of one CPU "
        f"thread each (wall time about half of that with one process per core, see the README).\n"
    )
    md = (
        f"# Detection study: TraCon cones\n\nReproduce: `aias-study --config {config_path}` (generate, train, "
        f"summarize); this table was written by `{command}`.\n\n{note}\n{table}\n"
        f"![AP by arm](ap_by_arm.png)\n"
    )
    if plot_amounts(rows, results / "ap_by_amount.png", cfg.reference_arm):
        md += "\n![gain by amount of inserted data](ap_by_amount.png)\n"
    if train is not None and val is not None:
        medians = plot_size_histograms(cfg, train, val, results / "size_histograms.png")
        md += (
            "\nObject sizes (median box height / image height): "
            + ", ".join(f"{k} {v:.3f}" for k, v in medians.items())
            + "\n\n![sizes](size_histograms.png)\n"
        )
    (results / "table.md").write_text(md)
    (results / "summary.json").write_text(
        json.dumps(
            _nan_to_none(
                {a: {k: (list(v) if isinstance(v, tuple) else v) for k, v in s.items()} for a, s in summary.items()}
            ),
            indent=1,
        )
    )
    return md


# ------------------------------------------------------------------ entry point


def load_study_config(path: str | Path) -> StudyConfig:
    p = Path(path)
    if not p.exists() and not p.suffix:
        p = CONFIG_DIR / "study" / f"{path}.yaml"
    return load_config(StudyConfig, p)


def available_arms(arms) -> list[str]:
    """Arms whose insertion interface exists; the rest are skipped with a logged reason."""
    try:
        from aias_augment.pipeline.image import insert_into_image, load_preset  # noqa: F401

        return list(arms)
    except ImportError as exc:
        skipped = [a for a in arms if ARM_FLAGS[a] is not None]
        if skipped:
            log.warning("skipping arms %s: aias_augment.pipeline.image is not available (%s)", skipped, exc)
        return [a for a in arms if ARM_FLAGS[a] is None]


def main(argv: list[str] | None = None) -> None:
    import shlex
    import sys

    import torch

    p = argparse.ArgumentParser(
        prog="aias-study", description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    p.add_argument("--config", default="configs/study/tracon_cones.yaml")
    p.add_argument("--stage", choices=("all", "generate", "train", "summarize"), default="all")
    p.add_argument("--arms", nargs="*", help="subset of the config's arms")
    p.add_argument("--seeds", nargs="*", type=int, help="subset of the config's seeds")
    p.add_argument("--amounts", nargs="*", type=int, help="subset of the config's amounts")
    p.add_argument("--force", action="store_true", help="re-run runs whose results exist")
    args = p.parse_args(argv)
    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(levelname)s %(name)s: %(message)s")
    torch.set_num_threads(1)
    cfg = load_study_config(args.config)
    arms = available_arms(args.arms or cfg.arms)
    seeds = args.seeds if args.seeds is not None else list(cfg.seeds)
    amounts = args.amounts if args.amounts is not None else list(cfg.amounts)
    command = "aias-study " + " ".join(shlex.quote(a) for a in (sys.argv[1:] if argv is None else argv))
    root = dataset_root(cfg)
    train = load_yolo_dir(root, cfg.train_split, cfg.class_names)
    val = load_yolo_dir(root, cfg.val_split, cfg.class_names)
    train, dev = split_dev(train, cfg.dev_cone_images, cfg.dev_empty_images, cfg.dev_seed)
    log.info(
        "train: %d images, %d boxes; dev: %d images, %d boxes", len(train), train.num_boxes, len(dev), dev.num_boxes
    )
    if args.stage == "generate":
        _, empty = thin_cone_images(train, cfg.keep_fraction, seeds[0])
        for arm in arms:
            if uses_pool(arm) and arm not in PER_SEED_ARMS:
                generate_arm_set(cfg, arm, train, empty)
            elif uses_pool(arm):
                for seed in seeds:
                    base, empty = thin_cone_images(train, cfg.keep_fraction, seed)
                    generate_arm_set(cfg, arm, train, empty, seed, base)
        return
    if args.stage in ("all", "train"):
        from .loader import cache_dataset

        det_cfg = load_detector_config(cfg.detector)
        val_cache = cache_dataset(val, det_cfg.train.img_size)
        dev_cache = cache_dataset(dev, det_cfg.train.img_size) if len(dev) else None
        for seed in seeds:
            for arm in arms:
                for amount in amounts if uses_pool(arm) else [None]:
                    run_one(
                        cfg, arm, seed, train, val, val_cache, amount, force=args.force, dev=dev, dev_cache=dev_cache
                    )
    print(write_summary(cfg, str(args.config), command, train, val))


if __name__ == "__main__":
    main()

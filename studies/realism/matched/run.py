"""Realism with matched backgrounds: cones inserted into TraCon's own road-scene cone photos, compared with
the real cones of other road-scene cone photos, so the crops around inserted and real cones differ by the object,
not by the scene.

    # 1. insert cones into half B of the road-scene cone photos, every arm, 3 draws per photo (resumable, ~6 min)
    taskset -c 0 python -m studies.realism.matched generate --n 106 --copies 3
    # 2. the report: studies/realism/matched/result/report.md, report.json, contact_sheet.jpg (~6 min with the CNN)
    taskset -c 0 python -m studies.realism.matched report --n 106 --cnn-sets floor inserted no_placement \
        naive_paste control
    # replication with the halves' roles swapped, and crop variants (--isolated, --context 0, --min-box-height 48,
    # --scene-scale 0.67 1.5) into subfolders of studies/realism/matched/result/ (each report.md has its command)
    taskset -c 0 python -m studies.realism.matched generate --n 106 --copies 3 --swap \
        --cache-dir out/realism/matched_swap

Photos: TraCon train + val images with cones that are road scenes (not stock shots on white:
``eval_realism.is_stock_photo``), downscaled to the study's ``max_side_px`` (640), split by a seeded permutation
into two disjoint halves. Half A gives the real reference (crops of its real cones); half B gives the backgrounds:
each arm inserts 1-3 cones into each B photo with the study's ablation insertion config
(``detection_eval.study.arms.insertion_config_for_arm``, studies/detection/lite0_320/ablations.yaml), the photo's real
cone boxes passed as existing boxes; copy j uses ``default_rng([pool_seed, 7, j])`` in every arm (paired). Only the
inserted boxes are cropped. No photo contributes to both classes of a test, so nothing leaks across folds.
Floor: the real cones of the B photos against A (what a perfect inserter would score). Control: the full arm's crop
windows cut from the B photos before insertion (same scene, no inserted cone).

Crops and metrics as ``studies/realism/arms/run.py report`` (CropConfig, 25 % context, box 20-48 px, 64 px, JPEG q85;
Lite0-KID/FID; logistic-regression two-sample AUC, 5 folds grouped by photo, photo-bootstrap interval; CNN
optional), plus a KID interval by bootstrap over photos, paired across the B-photo sets
(``aias_augment.evaluation.realism.bootstrap``).
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import logging
import shlex
import sys
import time
from pathlib import Path

import cv2
import numpy as np

from aias_augment.evaluation.realism.appearance import box_colour_stats
from aias_augment.evaluation.realism.bootstrap import kid_photo_bootstrap
from aias_augment.evaluation.realism.crops import CropConfig, context_window, object_crops
from studies._shared.pictures import write_jpeg
from studies.realism.arms.run import (
    CropSet,
    cached_features,
    colour_summary,
    contact_sheet,
    evaluate,
    fmt_ci,
    fmt_folds,
    is_stock_photo,
    study_cfg,
)

REPO = Path(__file__).resolve().parents[3]
log = logging.getLogger("eval_realism_matched")
ARMS = ("inserted", "no_shadow", "no_lighting", "no_harmonize", "no_placement", "naive_paste")
PAPER_ORDER = ("inserted", "no_shadow", "no_lighting", "no_placement")  # full > w/o shadow > w/o HDR > w/o placement
FLOOR = "floor: real cones of the B photos"
CONTROL = "control: full arm's windows, B photos before insertion (no inserted cone)"
REF = "real cones of the A photos (reference)"
SPLIT_SEED = 21
COPY_STRIDE = 1000  # copy id = photo index + COPY_STRIDE * k (k-th insertion draw into that photo)


# ------------------------------------------------------------------ photos


@dataclasses.dataclass(frozen=True)
class Photo:
    key: str  # "<split>/<file stem>": the group for folds and bootstraps
    path: str
    boxes_xyxy: np.ndarray  # real cones, in the downscaled image's pixels
    scale: float  # downscale factor applied to the file


def downscaled(path: str, max_side: int) -> tuple[np.ndarray, float]:
    from detection_eval.data import read_image_rgb

    img = read_image_rgb(path)
    s = min(1.0, max_side / max(img.shape[:2]))
    if s < 1:
        img = cv2.resize(img, (round(img.shape[1] * s), round(img.shape[0] * s)), interpolation=cv2.INTER_AREA)
    return img, s


def road_photo_halves(cfg, seed: int = 0, swap: bool = False) -> tuple[list[Photo], list[Photo]]:
    """Road-scene cone photos of TraCon train + val, split into halves A (reference) and B (backgrounds) by a seeded
    permutation of the photos (sorted by key first, so the split does not depend on listing order); ``swap``: the
    halves exchanged (the replication with roles reversed)."""
    from detection_eval.data import load_yolo_dir
    from detection_eval.study.config import dataset_root

    root = dataset_root(cfg)
    photos = []
    for split in (cfg.train_split, cfg.val_split):
        for rec in load_yolo_dir(root, split, cfg.class_names).records:
            if not len(rec.labels):
                continue
            img, s = downscaled(rec.image_path, cfg.insertion.max_side_px)
            if is_stock_photo(img):
                continue
            photos.append(Photo(f"{split}/{Path(rec.image_path).stem}", rec.image_path, rec.boxes_xyxy * s, s))
    photos.sort(key=lambda p: p.key)
    order = np.random.default_rng([seed, SPLIT_SEED]).permutation(len(photos))
    half = len(photos) // 2
    a, b = [photos[i] for i in order[:half]], [photos[i] for i in order[half:]]
    return (b, a) if swap else (a, b)


# ------------------------------------------------------------------ generation


def _arm_dir(cache_dir: str, arm: str) -> Path:
    return REPO / cache_dir / arm


def cmd_generate(args) -> None:
    from aias_augment.pipeline.image import insert_into_image
    from detection_eval.data import load_yolo_dir, write_yolo_sample
    from detection_eval.study.arms import ARM_FLAGS, insertion_config_for_arm
    from detection_eval.study.config import dataset_root

    cfg = study_cfg(args.cache_dir, args.n)
    train = load_yolo_dir(dataset_root(cfg), cfg.train_split, cfg.class_names)
    _, half_b = road_photo_halves(cfg, swap=args.swap)
    photos = half_b[: args.n]
    log.info("%d B photos (of %d)", len(photos), len(half_b))
    for arm in args.arms:
        out = _arm_dir(args.cache_dir, arm)
        ins_cfg = insertion_config_for_arm(cfg, arm, train)  # the study's insertion config for this arm
        if args.arrangement:
            ins_cfg = dataclasses.replace(ins_cfg, arrangement=args.arrangement)
        params = json.loads(
            json.dumps(
                {
                    "arm": arm,
                    "insertion": dataclasses.asdict(cfg.insertion),
                    "flags": ARM_FLAGS[arm],
                    "split_seed": SPLIT_SEED,
                    **({"swap": True} if args.swap else {}),
                    **({"first_draw": args.first_draw} if args.first_draw else {}),
                }
            )
        )
        progress = out / "progress.jsonl"
        if (out / "params.json").exists() and json.loads((out / "params.json").read_text()) != params:
            raise SystemExit(f"{out}: made with other parameters; use another --cache-dir")
        out.mkdir(parents=True, exist_ok=True)
        (out / "params.json").write_text(json.dumps(params))
        done = {}
        if progress.exists():
            for line in progress.read_text().splitlines():
                try:
                    e = json.loads(line)
                except json.JSONDecodeError:
                    continue
                done[e["copy"]] = e
        t0, n_new = time.perf_counter(), 0
        with progress.open("a") as plog:
            draws = range(args.first_draw, args.first_draw + args.copies)
            for k, j in ((k, j) for k in draws for j in range(len(photos))):
                ph, copy = photos[j], j + COPY_STRIDE * k
                if copy in done:
                    continue
                img, _ = downscaled(ph.path, cfg.insertion.max_side_px)
                existing = np.c_[ph.boxes_xyxy[:, :2], ph.boxes_xyxy[:, 2:] - ph.boxes_xyxy[:, :2]]
                # same stream in every arm; copy k > 0 of a photo: another draw
                rng = np.random.default_rng([cfg.insertion.pool_seed, 7, j] + ([k] if k else []))
                t_img = time.perf_counter()
                entry = {"copy": copy, "photo": ph.key}
                try:
                    res = insert_into_image(img, existing, ["cone"] * len(existing), rng, ins_cfg)
                except Exception as exc:  # counted; the copy is left out
                    entry["failed"] = f"{type(exc).__name__}: {exc}"[:200]
                    log.warning("%s: insertion failed on %s: %s", arm, ph.key, entry["failed"])
                else:
                    b = np.asarray(res.inserted_bboxes, np.float64).reshape(-1, 4)
                    b = b[(b[:, 2] >= 1) & (b[:, 3] >= 1)]
                    xyxy = np.c_[b[:, :2], b[:, :2] + b[:, 2:]]
                    stem = f"{j:04d}{f'k{k}' if k else ''}_{ph.key.replace('/', '-')}__{arm}"
                    write_yolo_sample(out, stem, res.image, xyxy, np.zeros(len(xyxy), np.int64))
                    entry.update(
                        image=f"{stem}.jpg",
                        boxes=xyxy.tolist(),
                        existing_visibility=[float(v) for v in res.record.existing_visibility],
                        seconds=time.perf_counter() - t_img,
                    )
                plog.write(json.dumps(entry) + "\n")
                plog.flush()
                n_new += 1
                if n_new % 20 == 0:
                    log.info("%s: %d new, %.1f s/image", arm, n_new, (time.perf_counter() - t0) / n_new)
        log.info("%s: %d new copies in %.0f s", arm, n_new, time.perf_counter() - t0)


def separable_sheet(arm, arm_f, ref, ref_f, n: int, path: Path, seed: int) -> None:
    """Four rows of ``n`` crops by the out-of-fold score of the study's classifier (the logistic regression of
    ``logistic_two_sample``: standardised Lite0 features, L2, folds grouped by photo): the inserted crops it finds
    most and least inserted-looking, then the real crops it finds least and most real-looking. What the classifier
    keys on, for the eye."""
    from sklearn.linear_model import LogisticRegression
    from sklearn.pipeline import make_pipeline
    from sklearn.preprocessing import StandardScaler

    from aias_augment.evaluation.realism.two_sample import grouped_folds

    X = np.concatenate([arm_f, ref_f]).astype(np.float64)
    y = np.r_[np.zeros(len(arm_f), bool), np.ones(len(ref_f), bool)]
    g = np.r_[[f"a:{x}" for x in arm.groups], [f"r:{x}" for x in ref.groups]]
    folds = grouped_folds(g, 5, np.random.default_rng([seed, 6]), y)
    score = np.zeros(len(y))
    for k in range(5):
        clf = make_pipeline(StandardScaler(), LogisticRegression(C=0.1, max_iter=2000, class_weight="balanced"))
        clf.fit(X[folds != k], y[folds != k])
        score[folds == k] = clf.decision_function(X[folds == k])
    a, r = np.argsort(score[: len(arm_f)]), np.argsort(score[len(arm_f) :])

    def strip(crops, idx):
        return np.concatenate([cv2.resize(crops[i], (96, 96), interpolation=cv2.INTER_NEAREST) for i in idx], 1)

    rows = [strip(arm.crops, a[:n]), strip(arm.crops, a[-n:]), strip(ref.crops, r[:n]), strip(ref.crops, r[-n:])]
    path.parent.mkdir(parents=True, exist_ok=True)
    write_jpeg(path, cv2.cvtColor(np.concatenate(rows, 0), cv2.COLOR_RGB2BGR))


def _arm_entries(cache_dir: str, arm: str) -> dict:
    p = _arm_dir(cache_dir, arm) / "progress.jsonl"
    if not p.exists():
        return {}
    out = {}
    for line in p.read_text().splitlines():
        try:
            e = json.loads(line)
        except json.JSONDecodeError:
            continue
        if not e.get("failed") and (_arm_dir(cache_dir, arm) / "images" / e["image"]).exists():
            out[e["copy"]] = e
    return out


# ------------------------------------------------------------------ crops


@dataclasses.dataclass
class MatchedCropSet(CropSet):
    crowded: list = dataclasses.field(default_factory=list)  # another cone (>= 1/4 of its box) inside the window
    at_bottom: list = dataclasses.field(default_factory=list)  # the box touches the image's bottom edge (cut off)
    box_h: list = dataclasses.field(default_factory=list)  # source box height, px (in the 640 px photo)
    rel_h: list = dataclasses.field(default_factory=list)  # box height / median height of the photo's real cones

    def summary(self) -> dict:
        return {
            "another_cone_in_window": float(np.mean(self.crowded)),
            "touches_bottom_edge": float(np.mean(self.at_bottom)),
            "box_height_px_quartiles": np.percentile(self.box_h, [25, 50, 75]).tolist(),
            "height_vs_photo_real_cones_quartiles": np.percentile(self.rel_h, [25, 50, 75]).tolist(),
        }


def another_cone_in_window(window_xyxy, others_xyxy, min_inside: float = 0.25) -> bool:
    """Whether at least ``min_inside`` of some other box's area lies inside the crop window."""
    o = np.asarray(others_xyxy, np.float64).reshape(-1, 4)
    if not len(o):
        return False
    iw = np.clip(np.minimum(o[:, 2], window_xyxy[2]) - np.maximum(o[:, 0], window_xyxy[0]), 0, None)
    ih = np.clip(np.minimum(o[:, 3], window_xyxy[3]) - np.maximum(o[:, 1], window_xyxy[1]), 0, None)
    area = np.maximum((o[:, 2] - o[:, 0]) * (o[:, 3] - o[:, 1]), 1e-9)  # eps: degenerate box
    return bool(np.any(iw * ih / area >= min_inside))


def crops_of(
    name: str,
    items,
    rng: np.random.Generator,
    cfg: CropConfig,
    isolated: bool = False,
    min_box_height: float = 0.0,
    scene_scale: tuple[float, float] | None = None,
) -> MatchedCropSet:
    """Crops of (photo key, image, boxes_xyxy to crop, other boxes_xyxy in the image, the photo's real cone boxes)
    items, in order (same items and rng -> same windows). ``isolated``: keep only crops whose window holds no other
    cone; ``min_box_height``: only boxes at least this tall (px); ``scene_scale`` (lo, hi): only boxes not cut by the
    bottom edge whose height is lo..hi times the median of the photo's real cones. The filters apply after the crops
    are drawn, so the kept windows are the same as without them."""
    cs = MatchedCropSet(name)
    for key, img, boxes, others, real in items:
        boxes = np.asarray(boxes, np.float64).reshape(-1, 4)
        others = np.asarray(others, np.float64).reshape(-1, 4)
        real = np.asarray(real, np.float64).reshape(-1, 4)
        if not len(boxes):
            continue
        real_h = float(np.median(real[:, 3] - real[:, 1])) if len(real) else float("nan")
        crops, kept = object_crops(img, boxes, rng, cfg)
        stats = box_colour_stats(img, boxes[kept])
        for crop, i, st in zip(crops, kept, stats):
            rest = np.concatenate([boxes[np.arange(len(boxes)) != i], others])
            crowded = another_cone_in_window(context_window(boxes[i], img.shape[:2], cfg.context), rest)
            h = float(boxes[i, 3] - boxes[i, 1])
            at_bottom = bool(boxes[i, 3] >= img.shape[0] - 1.5)
            if (isolated and crowded) or h < min_box_height:
                continue
            if scene_scale is not None and (at_bottom or not scene_scale[0] <= h / real_h <= scene_scale[1]):
                continue
            cs.crops.append(crop)
            cs.groups.append(key)
            cs.road.append(True)
            cs.stats.append(st)
            cs.crowded.append(crowded)
            cs.at_bottom.append(at_bottom)
            cs.box_h.append(h)
            cs.rel_h.append(h / real_h)
    return cs


def cmd_report(args) -> None:
    from aias_augment.evaluation.realism.features import Lite0Features
    from detection_eval.data import read_image_rgb

    t_start = time.perf_counter()
    seed = 0
    ccfg = CropConfig(context=args.context)
    cfg = study_cfg(args.cache_dir, args.n)
    half_a, half_b = road_photo_halves(cfg, swap=args.swap)
    photos_b = half_b[: args.n]
    max_side = cfg.insertion.max_side_px
    entries = {arm: _arm_entries(args.cache_dir, arm) for arm in args.arms}
    entries = {a: e for a, e in entries.items() if e}
    common = sorted(set.intersection(*[set(e) for e in entries.values()]) if entries else set())
    common = [c for c in common if c % COPY_STRIDE < len(photos_b)]
    log.info("arms %s; %d paired copies", list(entries), len(common))

    iso, mh = args.isolated, args.min_box_height
    sc = tuple(args.scene_scale) if args.scene_scale else None
    ref = crops_of(
        REF,
        ((p.key, downscaled(p.path, max_side)[0], p.boxes_xyxy, (), p.boxes_xyxy) for p in half_a),
        np.random.default_rng([seed, 1]),
        ccfg,
        iso,
        mh,
        sc,
    )
    used_b = [photos_b[j] for j in sorted({c % COPY_STRIDE for c in common})]
    floor = crops_of(
        FLOOR,
        ((p.key, downscaled(p.path, max_side)[0], p.boxes_xyxy, (), p.boxes_xyxy) for p in used_b),
        np.random.default_rng([seed, 2]),
        ccfg,
        iso,
        mh,
        sc,
    )
    sets = []
    for arm, ent in entries.items():
        items = (
            (
                photos_b[c % COPY_STRIDE].key,
                read_image_rgb(str(_arm_dir(args.cache_dir, arm) / "images" / ent[c]["image"])),
                ent[c]["boxes"],
                photos_b[c % COPY_STRIDE].boxes_xyxy,
                photos_b[c % COPY_STRIDE].boxes_xyxy,
            )
            for c in common
        )
        sets.append(crops_of(arm, items, np.random.default_rng([seed, 3]), ccfg, iso, mh, sc))
    if "inserted" in entries:
        # the full arm's windows and the same "another cone" decision (its real and other inserted boxes)
        items = (
            (
                photos_b[c % COPY_STRIDE].key,
                downscaled(photos_b[c % COPY_STRIDE].path, max_side)[0],
                entries["inserted"][c]["boxes"],
                photos_b[c % COPY_STRIDE].boxes_xyxy,
                photos_b[c % COPY_STRIDE].boxes_xyxy,
            )
            for c in common
        )
        sets.append(crops_of(CONTROL, items, np.random.default_rng([seed, 3]), ccfg, iso, mh, sc))
    log.info(
        "crops: ref %d (%d photos), floor %d, %s",
        len(ref.crops),
        len(half_a),
        len(floor.crops),
        ", ".join(f"{s.name} {len(s.crops)}" for s in sets),
    )

    feat = cached_features(
        Lite0Features(input_size=args.feature_size), args.feature_size, REPO / args.cache_dir / "features"
    )

    ref_f = feat(ref.crops)
    all_sets = [floor] + sets
    feats = {s.name: feat(s.crops) for s in all_sets}
    log.info("features done (%.0f s)", time.perf_counter() - t_start)
    fid_n = min(len(s.crops) for s in all_sets)
    rng = np.random.default_rng([seed, 4])
    cnn_sets = set(args.cnn_sets or [])
    results = {}
    for cs in all_sets:
        t0 = time.perf_counter()
        use_cnn = (
            cs.name in cnn_sets
            or (cs is floor and "floor" in cnn_sets)
            or (cs.name == CONTROL and "control" in cnn_sets)
        )
        res = evaluate(cs, ref, feats[cs.name], ref_f, fid_n, rng, cnn=use_cnn, road_only=False, epochs=args.epochs)
        res.update(cs.summary())
        res["seconds"] = time.perf_counter() - t0
        results[cs.name] = res
        log.info(
            "%s: KID %.4f FID %.1f AUC(logreg) %s AUC(cnn) %s",
            cs.name,
            res["kid_crops"][0],
            res["fid_crops"],
            fmt_ci(res["auc_logreg_lite0"]),
            fmt_ci(res.get("auc_cnn")),
        )
    # KID with a photo-bootstrap interval; the B-photo sets share their draws (paired differences)
    reps = kid_photo_bootstrap(
        {s.name: (feats[s.name], s.groups) for s in all_sets},
        ref_f,
        ref.groups,
        np.random.default_rng([seed, 5]),
        n_boot=args.n_boot,
    )
    for name, r in reps.items():
        results[name]["kid_boot_ci95"] = [float(np.nanpercentile(r, 2.5)), float(np.nanpercentile(r, 97.5))]
    if args.separable and "inserted" in feats:
        inserted = next(c for c in all_sets if c.name == "inserted")
        separable_sheet(inserted, feats["inserted"], ref, ref_f, args.separable, Path(args.out) / "separable.jpg", seed)
    paired = {}
    names = [s.name for s in all_sets]
    for i, a in enumerate(names):
        for b in names[i + 1 :]:
            d = reps[a] - reps[b]
            paired[f"{a} - {b}"] = {
                "mean": float(np.nanmean(d)),
                "ci95": [float(np.nanpercentile(d, 2.5)), float(np.nanpercentile(d, 97.5))],
            }
    out = REPO / args.out
    out.mkdir(parents=True, exist_ok=True)
    contact_sheet([ref, floor] + sets, out / "contact_sheet.jpg", rng=np.random.default_rng(5))
    command = "python -m studies.realism.matched " + " ".join(shlex.quote(a) for a in sys.argv[1:])
    report = {
        "command": command,
        "cache_dir": args.cache_dir,
        "crop_config": dataclasses.asdict(ccfg),
        "fid_n": fid_n,
        "n_boot": args.n_boot,
        "split_seed": SPLIT_SEED,
        "photos": {
            "A": len(half_a),
            "B": len(half_b),
            "B_used": len(used_b),
            "copies": len(common),
            "draws_per_photo": max(c // COPY_STRIDE for c in common) + 1,
            "swap": bool(args.swap),
            "A_keys": [p.key for p in half_a],
            "B_used_keys": [p.key for p in used_b],
        },
        "isolated": bool(iso),
        "min_box_height": mh,
        "scene_scale": sc,
        "reference": {
            "name": ref.name,
            "crops": len(ref.crops),
            "photos": len(set(ref.groups)),
            "colour": colour_summary(ref.stats),
            **ref.summary(),
        },
        "failures": {
            arm: sum(
                1
                for line in (_arm_dir(args.cache_dir, arm) / "progress.jsonl").read_text().splitlines()
                if '"failed"' in line
            )
            for arm in entries
        },
        "arms": results,
        "kid_paired_differences": paired,
        "seconds": time.perf_counter() - t_start,
    }
    (out / "report.json").write_text(json.dumps(report, indent=1))
    (out / "report.md").write_text(render_markdown(report, args))
    print((out / "report.md").read_text())


# ------------------------------------------------------------------ markdown


def _kid(r: dict) -> str:
    lo, hi = r["kid_boot_ci95"]
    return f"{r['kid_crops'][0]:.3f} [{lo:.3f}, {hi:.3f}]"


def _reading(rep: dict) -> list[str]:
    a = rep["arms"]
    if "inserted" not in a:
        return []
    kid = {k: a[k]["kid_crops"][0] for k in a}
    auc = {k: a[k]["auc_logreg_lite0"]["auc"] for k in a}
    full = "inserted"
    met = lambda ok: "**met**" if ok else "**missed**"  # noqa: E731
    lines = [
        "",
        "## Reading",
        "",
        f"- Targets, full pipeline in the matched protocol: Lite0-KID {kid[full]:.3f} "
        f"(target <= 0.03: {met(kid[full] <= 0.03)}), logistic AUC {auc[full]:.3f} (target <= 0.70: "
        f"{met(auc[full] <= 0.70)})"
        + (f", CNN AUC {a[full]['auc_cnn']['auc']:.3f}" if "auc_cnn" in a[full] else "")
        + f". Floor (real vs real): KID {kid[FLOOR]:.3f}, AUC {auc[FLOOR]:.3f}.",
    ]
    if CONTROL in a:
        lines.append(
            f"- Control (the full arm's windows without the inserted cone, same photos): KID "
            f"{kid[CONTROL]:.3f}, AUC {auc[CONTROL]:.3f}."
        )
    order = sorted([k for k in a if k not in (FLOOR, CONTROL)], key=lambda k: kid[k])
    lines.append(
        "- Arms by KID (best first): "
        + ", ".join(f"{k} {_kid(a[k])}" for k in order)
        + "; by AUC: "
        + ", ".join(f"{k} {fmt_ci(a[k]['auc_logreg_lite0'])}" for k in sorted(order, key=lambda k: auc[k]))
        + "."
    )
    pd = rep["kid_paired_differences"]
    diffs = []
    for k in order:
        if k == full:
            continue
        d = pd.get(f"{full} - {k}") or pd.get(f"{k} - {full}")
        sign = 1 if f"{full} - {k}" in pd else -1
        lo, hi = sorted(sign * np.asarray(d["ci95"]))
        diffs.append(f"{k} {sign * d['mean']:+.3f} [{lo:+.3f}, {hi:+.3f}]")
    paper = [k for k in PAPER_ORDER if k in a]
    steps = []
    for lo_arm, hi_arm in zip(paper, paper[1:]):
        key = f"{lo_arm} - {hi_arm}" if f"{lo_arm} - {hi_arm}" in pd else f"{hi_arm} - {lo_arm}"
        sign = 1 if key.startswith(lo_arm + " - ") else -1
        ci = sorted(sign * np.asarray(pd[key]["ci95"]))
        verdict = (
            "agrees, resolved"
            if ci[1] < 0
            else "reversed, resolved"
            if ci[0] > 0
            else ("agrees" if sign * pd[key]["mean"] < 0 else "reversed") + ", not resolved"
        )
        steps.append(f"{lo_arm} vs {hi_arm}: {sign * pd[key]['mean']:+.3f} [{ci[0]:+.3f}, {ci[1]:+.3f}] ({verdict})")
    lines.append(
        "- The paper's ordering (full better than without shadow, better than without HDR lighting, better "
        "than without placement), step by step as paired KID differences (first minus second; negative "
        "agrees): " + "; ".join(steps) + "."
    )
    lines.append(
        "- Paired KID differences, full minus arm (photo bootstrap over the same B photos; negative = "
        "full closer to real): " + "; ".join(diffs) + "."
    )
    return lines


def _paragraph(text: str) -> list[str]:
    """A markdown paragraph and its blank line, or nothing for empty text."""
    return [text.strip(), ""] if text.strip() else []


def render_markdown(rep: dict, args) -> str:
    ph = rep["photos"]
    lines = [
        "# Realism with matched backgrounds: real vs inserted cones in TraCon road-scene cone photos",
        "",
        f"Written by `{rep['command']}` ({rep['seconds'] / 60:.0f} min on one CPU core) after "
        f"`python -m studies.realism.matched generate --n {ph['B_used']}"
        + (f" --copies {ph['draws_per_photo']}" if ph.get("draws_per_photo", 1) > 1 else "")
        + (" --swap" if ph.get("swap") else "")
        + (
            f" --cache-dir {rep['cache_dir']}"
            if rep.get("cache_dir", "out/realism/matched") != "out/realism/matched"
            else ""
        )
        + "` (6 arms, about 0.25 s per image; every command under `taskset -c 0`). Code: `studies/realism/matched/run.py`, `aias_augment/realism/` "
        "(KID bootstrap: `bootstrap.py`).",
        "",
        f"Photos: the {ph['A'] + ph['B']} TraCon train + val cone photos that are road scenes (not stock shots "
        "on white), downscaled to 640 px, split by photo (seeded) into half A "
        f"({ph['A']} photos: the real reference, {rep['reference']['crops']} cone crops) and half B "
        f"({ph['B']} photos; {ph['B_used']} used: the backgrounds)"
        + (" (halves swapped: the replication with roles reversed)" if ph.get("swap") else "")
        + f". Each arm inserts 1-3 cones into every B photo ({ph.get('draws_per_photo', 1)} draw(s) per photo) with the study's ablation insertion config, the photo's real cones passed as existing boxes "
        "(copy j: same random stream in every arm); only the inserted cones are cropped. No photo is on both "
        "sides of any comparison, so no fold can learn a photo from one class and test it on the other. "
        "Floor: the real cones of the same B photos against A. Control: the full arm's crop windows on the B "
        "photos before insertion.",
        "",
        f"Crops as `eval_realism.py report`: {100 * rep['crop_config']['context']:.0f} % context, box 20-48 px "
        "(log-uniform), 64x64, JPEG q85. Lite0-KID: unbiased cubic-kernel MMD^2 on EfficientNet-Lite0 "
        f"features (input {args.feature_size} px), [95 % interval by bootstrap over photos of both sides, "
        f"{rep['n_boot']} replicates]; Lite0-FID on {rep['fid_n']} crops per set (mean of 5 draws). AUC: "
        "logistic regression on Lite0 features, real vs set, 5 folds grouped by photo, pooled out-of-fold "
        "[photo-bootstrap 95 %] and fold mean ± t-interval; a cross-validated AUC between two samples of one "
        "distribution is not exactly 0.5 (it tends to fall below; see studies/realism/arms/result/report.md): read the "
        "floor's values as 'indistinguishable' and only distances from them as signal. CNN: `cnn_two_sample` from scratch, "
        + f"{args.epochs} epochs; '—' = not run.",
        "",
        *_paragraph(
            (
                "Only crops whose window holds no other cone (real or inserted, >= 1/4 of its box inside) are "
                "kept in every set (`--isolated`). "
                if rep.get("isolated")
                else ""
            )
            + (
                f"Only boxes at least {rep['min_box_height']:.0f} px tall (in the 640 px photo) are kept in every "
                "set (`--min-box-height`): every crop is then shrunk, none enlarged. "
                if rep.get("min_box_height")
                else ""
            )
            + (
                "Only boxes not cut by the photo's bottom edge and {:.2f}-{:.2f} times the median height of the same "
                "photo's real cones are kept in every set (`--scene-scale`): inserted cones the size of the "
                "scene's own.".format(*rep["scene_scale"])
                if rep.get("scene_scale")
                else ""
            )
        ),
        "| set | crops (photos) | Lite0-KID [photo bootstrap 95 %] | Lite0-FID | "
        "AUC logreg (pooled) | AUC logreg (fold mean) | AUC CNN (pooled) | AUC CNN (fold mean) |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for name, r in rep["arms"].items():
        lines.append(
            f"| {name} | {r['crops']} ({r['photos']}) | "
            f"{_kid(r)} | {r['fid_crops']:.1f} | "
            f"{fmt_ci(r['auc_logreg_lite0'])} | {fmt_folds(r['auc_logreg_lite0'])} | "
            f"{fmt_ci(r.get('auc_cnn'))} | {fmt_folds(r.get('auc_cnn'))} |"
        )
    lines += [
        "",
        "Where the cropped boxes sit: another cone (real or inserted, >= 1/4 of its box) inside the crop "
        "window; box touching the photo's bottom edge (cut off by the frame); source box height in the 640 px "
        "photo; box height over the median height of the same photo's real cones (1 = the size of the cones "
        "already in the scene). Quartiles.",
        "",
        "| set | another cone in window | touches bottom edge | box height px | height / photo's real cones |",
        "|---|---|---|---|---|",
    ]
    geo = [(rep["reference"]["name"], rep["reference"])] + list(rep["arms"].items())
    for name, r in geo:
        if "touches_bottom_edge" not in r:
            continue
        bh, rh = r["box_height_px_quartiles"], r["height_vs_photo_real_cones_quartiles"]
        lines.append(
            f"| {name} | {100 * r['another_cone_in_window']:.0f} % | {100 * r['touches_bottom_edge']:.0f} % | "
            f"{bh[1]:.0f} [{bh[0]:.0f}, {bh[2]:.0f}] | {rh[1]:.2f} [{rh[0]:.2f}, {rh[2]:.2f}] |"
        )
    lines += [
        "",
        "Colour inside the boxes (means over boxes; as in studies/realism/arms/result/report.md).",
        "",
        "| set | mean brightness | saturated orange | clipped in box | clipped in ring | boxes clipped where "
        "the scene is not |",
        "|---|---|---|---|---|---|",
    ]
    for name, c in [(rep["reference"]["name"], rep["reference"]["colour"])] + [
        (n, r["colour"]) for n, r in rep["arms"].items()
    ]:
        lines.append(
            f"| {name} | {c['mean_brightness']:.0f} | {100 * c['saturated_orange_fraction']:.0f} % | "
            f"{100 * c['clipped_fraction']:.1f} % | {100 * c['clipped_fraction_ring']:.1f} % | "
            f"{100 * c['boxes_clipped_where_ring_is_not']:.0f} % |"
        )
    lines += _reading(rep)
    notes = REPO / args.out / "notes.md"
    if notes.exists():
        lines += ["", notes.read_text().strip()]
    lines += ["", "![contact sheet: real A, floor (real B), then each arm and the control](contact_sheet.jpg)", ""]
    return "\n".join(lines) + "\n"


def cmd_render(args) -> None:
    out = REPO / args.out
    rep = json.loads((out / "report.json").read_text())
    (out / "report.md").write_text(render_markdown(rep, args))
    print((out / "report.md").read_text())


def main(argv=None) -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = p.add_subparsers(dest="cmd", required=True)
    g = sub.add_parser("generate")
    g.add_argument("--n", type=int, default=100, help="B photos to insert into (the first n of half B)")
    g.add_argument("--arms", nargs="+", default=list(ARMS))
    g.add_argument("--cache-dir", default="out/realism/matched")
    g.add_argument("--copies", type=int, default=1, help="insertion draws per B photo (different seeds)")
    g.add_argument(
        "--first-draw",
        type=int,
        default=0,
        help="the first draw's index: --first-draw 3 --copies 3 makes draws 3-5 (other seeds, the same policy)",
    )
    g.add_argument("--swap", action="store_true", help="halves exchanged (insert into A, reference B)")
    g.add_argument(
        "--arrangement",
        choices=("independent", "line", "cluster", "mixed", "row"),
        help="how one photo's inserted cones stand together (InsertionConfig.arrangement), instead of the config's",
    )
    r = sub.add_parser("report")
    r.add_argument("--n", type=int, default=100)
    r.add_argument("--arms", nargs="+", default=list(ARMS))
    r.add_argument("--cache-dir", default="out/realism/matched")
    r.add_argument("--swap", action="store_true", help="halves exchanged (insert into A, reference B)")
    r.add_argument("--cnn-sets", nargs="*", help="run the CNN test on these sets ('floor', 'control', arm names)")
    r.add_argument("--epochs", type=int, default=8)
    r.add_argument("--n-boot", type=int, default=1000)
    r.add_argument("--feature-size", type=int, default=160)
    r.add_argument("--context", type=float, default=0.25)
    r.add_argument("--isolated", action="store_true", help="only crops whose window holds no other cone")
    r.add_argument(
        "--scene-scale",
        nargs=2,
        type=float,
        metavar=("LO", "HI"),
        help="only boxes not cut by the bottom edge, LO..HI times the photo's real cones' median height",
    )
    r.add_argument(
        "--min-box-height",
        type=float,
        default=0.0,
        help="only boxes at least this tall (px, in the 640 px photo), in every set",
    )
    r.add_argument("--out", default="studies/realism/matched/result")
    r.add_argument(
        "--separable",
        type=int,
        default=0,
        help="write separable.jpg: this many crops per row, the inserted and the real ones the classifier finds most "
        "and least alike the other set",
    )
    m = sub.add_parser("render", help="rewrite report.md from report.json")
    m.add_argument("--out", default="studies/realism/matched/result")
    m.add_argument("--epochs", type=int, default=8)
    m.add_argument("--feature-size", type=int, default=160)
    args = p.parse_args(argv)
    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(levelname)s %(name)s: %(message)s")
    import torch

    torch.set_num_threads(1)
    {"generate": cmd_generate, "report": cmd_report, "render": cmd_render}[args.cmd](args)


if __name__ == "__main__":
    main()

"""What tells inserted cones from real ones? The two-sample AUC with one cue taken away at a time (issue 15).

    taskset -c 0 python -m studies.realism.arms generate --n 40 --arms inserted naive_paste   # the pools, once
    taskset -c 0 python -m studies.realism.cues --out studies/realism/cues/result

The crops are the realism report's (``studies/realism/arms/run.py``: the same windows with 25 % context, 64x64, JPEG
q85, the same seeds), and the box of each crop is kept so that the object and its surroundings can be told apart.
Each view removes one cue from every set alike (real train = reference, real val = floor, inserted, naive paste),
then the report's classifier (logistic regression on EfficientNet-Lite0 features, 5 folds grouped by photo, 95 %
interval by bootstrap over photos) is run again:

- ``as is``: the report's AUC;
- ``grey``: luma only (no hue, no saturation);
- ``grey, normalised``: luma standardised per crop (no colour, no brightness, no contrast);
- ``object only``: everything outside the box set to mid-grey (the object's own pixels and silhouette);
- ``surroundings only``: the box inpainted from its border (Telea) - the object removed, its context kept;
- ``object only, grey, normalised``: what is left is shape and shading pattern.

A cue matters when taking it away brings the AUC down toward the floor. Writes ``<out>/cues.json`` and
``<out>/cues.md`` (with the command) and ``<out>/cues_sheet.jpg`` (one row of crops per view and set).
"""

from __future__ import annotations

import argparse
import json
import logging
import shlex
import sys
import time
from pathlib import Path

import cv2
import numpy as np

from aias_augment.evaluation.realism.crops import CropConfig, context_window, normalise_crop
from aias_augment.evaluation.realism.two_sample import logistic_two_sample
from studies._shared.pictures import write_jpeg

REPO = Path(__file__).resolve().parents[3]
log = logging.getLogger("realism_cues")
VIEWS = ("as is", "grey", "grey, normalised", "object only", "surroundings only", "object only, grey, normalised")


def crops_with_boxes(records, rng: np.random.Generator, cfg: CropConfig, copies: set | None = None):
    """The report's crops (``object_crops``: the same draws of ``rng``) with each box in crop pixels."""
    from detection_eval.data import read_image_rgb

    crops, boxes, groups = [], [], []
    lo, hi = np.log(cfg.target_height_range_px[0]), np.log(cfg.target_height_range_px[1])
    for rec in records:
        stem = Path(rec.image_path).name
        if (copies is not None and int(stem[:4]) not in copies) or not len(rec.labels):
            continue
        img = read_image_rgb(rec.image_path)
        for b in np.asarray(rec.boxes_xyxy, np.float64).reshape(-1, 4):
            t = float(np.exp(rng.uniform(lo, hi)))
            if b[2] - b[0] < cfg.min_box_px or b[3] - b[1] < cfg.min_box_px:
                continue
            x0, y0, x1, y1 = context_window(b, img.shape[:2], cfg.context)
            crops.append(normalise_crop(np.ascontiguousarray(img[y0:y1, x0:x1]), b[3] - b[1], t, cfg))
            s = cfg.out_size / (x1 - x0)
            boxes.append(np.clip((b - [x0, y0, x0, y0]) * s, 0, cfg.out_size))
            groups.append(stem)
    return crops, boxes, groups


def _box_mask(box, size: int, grow: int = 1) -> np.ndarray:
    m = np.zeros((size, size), np.uint8)
    x0, y0, x1, y1 = box
    m[
        max(0, int(np.floor(y0)) - grow) : min(size, int(np.ceil(y1)) + grow),
        max(0, int(np.floor(x0)) - grow) : min(size, int(np.ceil(x1)) + grow),
    ] = 1
    return m


def _grey(img: np.ndarray) -> np.ndarray:
    return np.repeat(cv2.cvtColor(img, cv2.COLOR_RGB2GRAY)[..., None], 3, axis=2)


def _normalised(grey3: np.ndarray, mask: np.ndarray | None = None) -> np.ndarray:
    y = grey3[..., 0].astype(np.float32)
    sel = y[mask > 0] if mask is not None and mask.any() else y.ravel()
    z = (y - sel.mean()) / max(float(sel.std()), 1.0) * 40.0 + 128.0
    if mask is not None:
        z = np.where(mask > 0, z, 128.0)
    return np.repeat(np.clip(z, 0, 255).astype(np.uint8)[..., None], 3, axis=2)


def view(img: np.ndarray, box, name: str) -> np.ndarray:
    """One crop with a cue taken away (see the module docstring)."""
    size = img.shape[0]
    if name == "as is":
        return img
    if name == "grey":
        return _grey(img)
    if name == "grey, normalised":
        return _normalised(_grey(img))
    m = _box_mask(box, size)
    if name == "object only":
        return np.where(m[..., None] > 0, img, 128).astype(np.uint8)
    if name == "surroundings only":
        return cv2.inpaint(np.ascontiguousarray(img), m, 3, cv2.INPAINT_TELEA)
    if name == "object only, grey, normalised":
        return _normalised(_grey(img), m)
    raise ValueError(f"unknown view {name!r}")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--cache-dir", default="out/realism/cache", help="eval_realism.py generate's pools")
    ap.add_argument("--arms", nargs="+", default=["inserted", "naive_paste"])
    ap.add_argument("--feature-size", type=int, default=160)
    ap.add_argument("--out", default="studies/realism/cues/result")
    args = ap.parse_args(argv)
    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(message)s")
    from aias_augment.evaluation.realism.features import Lite0Features
    from detection_eval.data import load_yolo_dir
    from detection_eval.study.config import dataset_root
    from studies.realism.arms.run import pool_copies, study_cfg

    t0 = time.perf_counter()
    ccfg = CropConfig()
    cfg = study_cfg(args.cache_dir, 1)
    root = dataset_root(cfg)
    seed = 0  # the report's seeds: reference [0, 1], floor [0, 2], arms [0, 3]
    sets = {
        "real TraCon train (reference)": crops_with_boxes(
            load_yolo_dir(root, cfg.train_split, cfg.class_names).records, np.random.default_rng([seed, 1]), ccfg
        ),
        "real TraCon val (floor)": crops_with_boxes(
            load_yolo_dir(root, cfg.val_split, cfg.class_names).records, np.random.default_rng([seed, 2]), ccfg
        ),
    }
    folders = {a: REPO / args.cache_dir / a / "pool" for a in args.arms}
    missing = [a for a, f in folders.items() if not (f / "done.json").exists()]
    if missing:
        raise SystemExit(
            f"no pool for {missing} under {args.cache_dir}: run studies/realism/arms/run.py generate first"
        )
    common = set.intersection(*[pool_copies(f) for f in folders.values()])
    for a, f in folders.items():
        sets[a] = crops_with_boxes(
            load_yolo_dir(f, names=cfg.class_names).records, np.random.default_rng([seed, 3]), ccfg, copies=common
        )
    log.info("crops: %s", {k: len(v[0]) for k, v in sets.items()})
    extractor = Lite0Features(input_size=args.feature_size)
    ref_name = "real TraCon train (reference)"
    results = {}
    sheet_rows = []
    for vname in VIEWS:
        feats = {k: extractor([view(c, b, vname) for c, b in zip(cr, bx)]) for k, (cr, bx, _) in sets.items()}
        results[vname] = {}
        for k, (cr, bx, gr) in sets.items():
            if k == ref_name:
                continue
            X = np.concatenate([feats[k], feats[ref_name]])
            y = np.r_[np.zeros(len(cr), bool), np.ones(len(sets[ref_name][0]), bool)]
            groups = np.r_[[f"a:{g}" for g in gr], [f"r:{g}" for g in sets[ref_name][2]]]
            res = logistic_two_sample(X, y, groups, np.random.default_rng([seed, 4])).to_dict()
            results[vname][k] = res
            log.info("%-32s %-28s AUC %.3f [%.3f, %.3f]", vname, k, res["auc"], *res["ci95"])
        rng = np.random.default_rng(7)
        for k, (cr, bx, _) in sets.items():
            idx = rng.choice(len(cr), min(8, len(cr)), replace=False)
            sheet_rows.append(np.concatenate([view(cr[i], bx[i], vname) for i in idx], axis=1))
    out = REPO / args.out
    out.mkdir(parents=True, exist_ok=True)
    width = max(r.shape[1] for r in sheet_rows)
    sheet = np.concatenate(
        [np.pad(r, ((0, 2), (0, width - r.shape[1]), (0, 0)), constant_values=255) for r in sheet_rows]
    )
    write_jpeg(out / "cues_sheet.jpg", sheet[..., ::-1])
    command = "python -m studies.realism.cues " + " ".join(shlex.quote(a) for a in (argv or sys.argv[1:]))
    rep = {
        "command": command,
        "crops": {k: len(v[0]) for k, v in sets.items()},
        "photos": {k: len(set(v[2])) for k, v in sets.items()},
        "auc": results,
        "seconds": time.perf_counter() - t0,
    }
    (out / "cues.json").write_text(json.dumps(rep, indent=1))
    names = [k for k in sets if k != ref_name]
    lines = [
        "# What separates inserted cones from real ones: the two-sample AUC with one cue taken away",
        "",
        f"Command: `{command}` ({rep['seconds']:.0f} s). Reference: real TraCon train, {rep['crops'][ref_name]} "
        f"crops. Classifier: logistic regression on EfficientNet-Lite0 features, 5 folds grouped by photo, 95 % "
        "interval by bootstrap over photos (0.5 = indistinguishable). Rows of `cues_sheet.jpg`: per view, "
        "8 crops of each set in the order " + ", ".join(sets) + ".",
        "",
        "| view | " + " | ".join(f"{n} ({rep['crops'][n]} crops)" for n in names) + " |",
        "|---|" + "---|" * len(names),
    ]
    for vname in VIEWS:
        lines.append(
            f"| {vname} | "
            + " | ".join(
                f"{results[vname][n]['auc']:.3f} [{results[vname][n]['ci95'][0]:.3f}, {results[vname][n]['ci95'][1]:.3f}]"
                for n in names
            )
            + " |"
        )
    (out / "cues.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

"""The labelled objects' own cast shadows as a direct-sun cue (issue 53), measured on the development photos only.

Under a direct sun an object standing on the ground casts a dark, sharp-edged shadow attached to its base on one
side: the shadow is lit by the sky alone, so its linear luminance is ~0.1-0.6 of the sunlit ground beside it (and
bluer). Under an overcast sky there is only a faint, symmetric contact darkening right under the base (a few per
cent, ``studies/lighting/contact_shadows``). For each labelled box, in a ground window around the box's base (all
labelled boxes left out), the pixels darker than ``DARK_RATIO`` of the window's median ground that are connected to
the base are the candidate shadow; the photo's cue is the deepest such shadow over its boxes
(``shadow_depth`` = 1 - its median luminance over the ground's).

    python -m studies.lighting.object_shadows     # result/dev.json: cue alone and combined rules, 5-fold x 5 seeds

Only the ``dev`` rows of ``sun_asymmetric/result/split.csv`` with ``uncertain == 0`` are read; the held-out rows are
never opened here.
"""

from __future__ import annotations

import argparse
import csv
import json
import time
from pathlib import Path

import cv2
import numpy as np

from aias_augment.analyse.lighting.sun_evidence import asymmetric_threshold, wilson_interval
from aias_augment.core.config import data_root
from aias_augment.core.srgb import srgb_to_linear

ANALYSIS_SIDE = 640  # px, the long side the pipeline analyses TraCon photos at
MIN_BOX_HEIGHT = 16  # px at ANALYSIS_SIDE: smaller boxes have too few ground pixels to tell
DARK_RATIO = 0.5  # a pixel is shadow when its linear luminance is below this share of the window's median ground
SIDE, BELOW, ABOVE = 1.5, 1.0, 0.35  # ground window: box widths each side; box heights below and above its bottom
RING = 0.06  # the base: pixels within this share of the box height of the box's lower third, outside every box
SHIPPED_T = 0.97149  # the evidence model's shipped threshold (checkpoints/sun_evidence.json)
MIN_PRECISION = 0.90
_EPS = 1e-4
_LUMA = np.array([0.2126, 0.7152, 0.0722], np.float32)
SPLIT = Path("studies/lighting/sun_asymmetric/result/split.csv")
ESTIMATES = Path("studies/lighting/sun_asymmetric/result/estimates.csv")
OUT = Path("studies/lighting/object_shadows/result")

CUE_KEYS = ("boxes", "shadow_depth", "shadow_ratio", "shadow_area", "asymmetry", "sharpness", "blue_shift")
NO_CUE = {k: 0.0 for k in CUE_KEYS} | {"shadow_ratio": 1.0}


def _box_shadow(lin: np.ndarray, lum: np.ndarray, grad: np.ndarray, boxes_mask: np.ndarray, box) -> dict | None:
    """The dark region attached to one box's base (see the module docstring) and its description; None where the box
    is too small or its window holds too little ground. Also returns the window and masks, for the pictures."""
    H, W = lum.shape
    x0, y0, x1, y1 = (float(v) for v in box)
    w, h = x1 - x0, y1 - y0
    if h < MIN_BOX_HEIGHT or w < 2:
        return None
    c0, c1 = max(int(x0 - SIDE * w), 0), min(int(np.ceil(x1 + SIDE * w)), W)
    r0, r1 = max(int(y1 - ABOVE * h), 0), min(int(np.ceil(y1 + BELOW * h)), H)
    if r1 - r0 < 4 or c1 - c0 < 4:
        return None
    win = (slice(r0, r1), slice(c0, c1))
    ground = ~boxes_mask[win]
    if ground.sum() < 30:
        return None
    L = lum[win]
    ref = float(np.median(L[ground]))
    if ref <= _EPS:
        return None
    dark = ground & (L < DARK_RATIO * ref)
    d = max(int(round(RING * h)), 2)
    base = np.zeros_like(ground)
    bx0, bx1, by0, by1 = int(x0) - c0, int(np.ceil(x1)) - c0, int(y1 - h / 3) - r0, int(np.ceil(y1)) - r0
    base[max(by0 - d, 0) : max(by1 + d, 0), max(bx0 - d, 0) : max(bx1 + d, 0)] = True
    base &= ground
    _, lab = cv2.connectedComponents(dark.astype(np.uint8), connectivity=8)
    touching = np.unique(lab[base & dark])
    shadow = np.isin(lab, touching[touching > 0])
    out = dict(NO_CUE) | {"window": win, "shadow": shadow, "base": base}
    lit = ground & ~dark & (L >= ref)
    if shadow.sum() < 4 or lit.sum() < 4:
        return out
    ratio = float(np.median(L[shadow])) / ref
    cols = np.nonzero(shadow)[1] + c0
    left, right = float(np.sum(cols < 0.5 * (x0 + x1))), float(np.sum(cols >= 0.5 * (x0 + x1)))
    edge = shadow & ~cv2.erode(shadow.astype(np.uint8), np.ones((3, 3), np.uint8)).astype(bool)
    rgb = lin[win]
    log_br = np.log((rgb[..., 2] + _EPS) / (rgb[..., 0] + _EPS))
    return out | {
        "shadow_depth": 1.0 - ratio,
        "shadow_ratio": ratio,
        "shadow_area": float(shadow.sum()) / (w * h),
        "asymmetry": abs(left - right) / (left + right),
        "sharpness": float(np.median(grad[win][edge])) / max(-np.log(max(ratio, _EPS)), _EPS),
        "blue_shift": float(np.median(log_br[shadow]) - np.median(log_br[lit])),
    }


def _analysis_copy(image_rgb_uint8: np.ndarray, boxes_xyxy_px) -> tuple[np.ndarray, np.ndarray]:
    """The photo at <= ANALYSIS_SIDE px and its boxes scaled alike."""
    img = np.asarray(image_rgb_uint8)
    if img.ndim != 3 or img.shape[2] != 3 or img.dtype != np.uint8:
        raise ValueError(f"object_shadow_cue: need an (H, W, 3) uint8 RGB image, got {img.shape} {img.dtype}")
    boxes = np.asarray(boxes_xyxy_px, float).reshape(-1, 4)
    s = min(1.0, ANALYSIS_SIDE / max(img.shape[:2]))
    if s < 1:
        img = cv2.resize(img, None, fx=s, fy=s, interpolation=cv2.INTER_AREA)
        boxes = boxes * s
    return img, boxes


def _box_shadows(img: np.ndarray, boxes: np.ndarray) -> list[dict]:
    """:func:`_box_shadow` of every measurable box of an analysis copy."""
    lin = srgb_to_linear(img).astype(np.float32)
    lum = lin @ _LUMA
    log_l = np.log(lum + _EPS)
    grad = np.hypot(cv2.Sobel(log_l, cv2.CV_32F, 1, 0), cv2.Sobel(log_l, cv2.CV_32F, 0, 1)) / 8.0
    mask = np.zeros(lum.shape, bool)
    for x0, y0, x1, y1 in np.round(boxes).astype(int):
        mask[max(y0, 0) : max(y1, 0), max(x0, 0) : max(x1, 0)] = True
    return [c for b in boxes if (c := _box_shadow(lin, lum, grad, mask, b)) is not None]


def object_shadow_cue(image_rgb_uint8: np.ndarray, boxes_xyxy_px) -> dict[str, float]:
    """The object-shadow cue of one photo: (H, W, 3) uint8 RGB and its labelled boxes (N, 4) xyxy in its pixels ->
    ``boxes`` (how many could be measured) and, for the box with the deepest attached shadow: ``shadow_depth``
    (1 - ``shadow_ratio``), ``shadow_ratio`` (the shadow's median linear luminance over the window's median ground),
    ``shadow_area`` (its pixels over the box's area), ``asymmetry`` (|left - right| / total about the box's centre),
    ``sharpness`` (median |grad log L| on its edge over its log step, 1/px, about one over the edge's width) and
    ``blue_shift`` (log B/R, shadow minus lit ground). :data:`NO_CUE` where no box has an attached shadow."""
    cues = _box_shadows(*_analysis_copy(image_rgb_uint8, boxes_xyxy_px))
    if not cues:
        return dict(NO_CUE)
    best = max(cues, key=lambda c: c["shadow_depth"])
    return {"boxes": float(len(cues))} | {k: float(best[k]) for k in CUE_KEYS[1:]}


# --- the dev evaluation -------------------------------------------------------------------------------------------


def label_path(photo: str) -> Path:
    """The YOLO label file of a TraCon photo (relative to the data root)."""
    return data_root() / Path(photo.replace("/images/", "/labels/")).with_suffix(".txt")


def labelled_boxes(photo: str, width: int, height: int) -> np.ndarray:
    """The labelled boxes of a TraCon photo, (N, 4) xyxy px; (0, 4) for other photos or an empty label file."""
    p = label_path(photo)
    if not photo.startswith("tracon/") or not p.is_file() or p.stat().st_size == 0:
        return np.zeros((0, 4))
    cx, cy, w, h = np.loadtxt(p, ndmin=2)[:, 1:5].T
    return np.stack([(cx - w / 2) * width, (cy - h / 2) * height, (cx + w / 2) * width, (cy + h / 2) * height], 1)


def dev_rows() -> list[dict]:
    """The scored development photos with their label, the evidence probability and whether a sun is possible."""
    split = {(r["set"], r["index"]): r for r in csv.DictReader(SPLIT.open())}
    rows = []
    for r in csv.DictReader(ESTIMATES.open()):
        s = split[(r["set"], r["index"])]
        if s["part"] != "dev" or s["uncertain"] != "0":
            continue
        rows.append(
            {
                "set": r["set"],
                "index": int(r["index"]),
                "photo": r["photo"],
                "direct_sun": int(s["direct_sun"]),
                "evidence": float(r["balanced_probability"]),
                "possible": int(r["balanced_sun_possible"]),
            }
        )
    return rows


def auc(score: np.ndarray, y: np.ndarray) -> float:
    """ROC AUC by the rank statistic (ties count half)."""
    pos, neg = score[y == 1], score[y == 0]
    return float(np.mean((pos[:, None] > neg[None]) + 0.5 * (pos[:, None] == neg[None])))


def folds(n: int, k: int, seed: int, y: np.ndarray) -> np.ndarray:
    """Stratified fold index of each of n photos (seeded permutation within each class)."""
    rng = np.random.default_rng(seed)
    f = np.empty(n, int)
    for c in (0, 1):
        idx = rng.permutation(np.nonzero(y == c)[0])
        f[idx] = np.arange(len(idx)) % k
    return f


def pr(pred: np.ndarray, y: np.ndarray) -> dict:
    """Decided, true suns, precision and recall with 95 % Wilson intervals."""
    tp, n_pred, n_pos = int(np.sum(pred & (y == 1))), int(pred.sum()), int(y.sum())
    return {
        "decided": n_pred,
        "true_suns": tp,
        "sunny": n_pos,
        "precision": tp / n_pred if n_pred else None,
        "precision_ci": wilson_interval(tp, n_pred) if n_pred else None,
        "recall": tp / n_pos,
        "recall_ci": wilson_interval(tp, n_pos),
    }


def logit(p: np.ndarray) -> np.ndarray:
    q = np.clip(p, 1e-4, 1 - 1e-4)
    return np.log(q / (1 - q))


def fit_logistic(X: np.ndarray, y: np.ndarray, l2: float = 1.0, iters: int = 50) -> np.ndarray:
    """Weights (intercept first) of an L2-regularised logistic regression by Newton steps (intercept not penalised)."""
    A = np.c_[np.ones(len(X)), X]
    w = np.zeros(A.shape[1])
    pen = np.r_[0.0, np.full(X.shape[1], l2)]
    for _ in range(iters):
        p = 1 / (1 + np.exp(-A @ w))
        g = A.T @ (p - y) + pen * w
        Hm = A.T @ (A * (p * (1 - p))[:, None]) + np.diag(pen + 1e-9)
        w -= np.linalg.solve(Hm, g)
    return w


def cv_scores(score_fn, n: int, y: np.ndarray, k: int, seeds: list[int]) -> list[np.ndarray]:
    """Out-of-fold scores per seed: ``score_fn(train_idx, test_idx) -> scores of test_idx``."""
    out = []
    for seed in seeds:
        f, s = folds(n, k, seed, y), np.empty(n)
        for j in range(k):
            s[f == j] = score_fn(np.nonzero(f != j)[0], np.nonzero(f == j)[0])
        out.append(s)
    return out


def summarise(per_seed: list[dict]) -> dict:
    """The median-recall seed's counts (with intervals) and the range of precision and recall over seeds."""
    order = sorted(range(len(per_seed)), key=lambda i: (per_seed[i]["recall"], per_seed[i]["precision"] or 0))
    mid = per_seed[order[len(order) // 2]]
    prec = [p["precision"] for p in per_seed if p["precision"] is not None]
    return mid | {
        "decided_true_per_seed": [[p["decided"], p["true_suns"]] for p in per_seed],
        "precision_range_over_seeds": [min(prec), max(prec)] if prec else None,
        "recall_range_over_seeds": [min(p["recall"] for p in per_seed), max(p["recall"] for p in per_seed)],
    }


def evaluate(rows: list[dict], k: int, seeds: list[int]) -> dict:
    """(a) the cue alone on the photos with labelled boxes, (b) combined rules over every scored dev photo."""
    y = np.array([r["direct_sun"] for r in rows])
    ev = np.array([r["evidence"] for r in rows])
    possible = np.array([r["possible"] for r in rows]).astype(bool)
    has = np.array([r["cue"]["boxes"] > 0 for r in rows])
    cones = np.array([r["cones"] > 0 for r in rows])
    depth = np.array([r["cue"]["shadow_depth"] for r in rows])
    n = len(rows)
    rep: dict = {
        "photos": n,
        "sunny": int(y.sum()),
        "with_cones": int(cones.sum()),
        "sunny_with_cones": int(y[cones].sum()),
    }
    rep["with_measured_box"] = int(has.sum())
    rep["evidence_shipped_t"] = pr(possible & (ev >= SHIPPED_T), y)
    rep["evidence_shipped_t_on_cone_photos"] = pr((possible & (ev >= SHIPPED_T))[cones], y[cones])
    rep["upper_bound_recall"] = {
        "note": "every sunny photo with cones caught plus the evidence model's suns elsewhere at the shipped t",
        "recall": float(np.sum(y & (cones | (possible & (ev >= SHIPPED_T)))) / y.sum()),
    }
    # (a) the cue alone, photos with labelled cones
    yc, cue_rows = y[cones], [r["cue"] for r in rows if r["cones"] > 0]
    rep["cue_alone_auc"] = {key: auc(np.array([c[key] for c in cue_rows]), yc) for key in CUE_KEYS}
    rep["evidence_auc_on_cone_photos"] = auc(ev[cones], yc)
    dc = depth[cones]
    per_t = {f"{t:.2f}": pr(dc >= t, yc) for t in (0.5, 0.6, 0.7, 0.8, 0.9)}
    rep["cue_alone_at_depth"] = per_t
    nested = []
    for seed in seeds:
        f, pred = folds(len(yc), k, seed, yc), np.zeros(len(yc), bool)
        for j in range(k):
            tr = f != j
            t = asymmetric_threshold(np.clip(dc[tr], 0, 1), yc[tr], MIN_PRECISION)
            pred[f == j] = dc[f == j] >= t
        nested.append(pr(pred, yc))
    rep["cue_alone_nested_cv"] = summarise(nested)

    # (b1) rule: sun if possible and (evidence >= shipped t or (cones and depth >= t_c)), t_c chosen on train folds
    def rule(t_c: float, idx: np.ndarray) -> np.ndarray:
        return possible[idx] & ((ev[idx] >= SHIPPED_T) | (cones[idx] & (depth[idx] >= t_c)))

    grid = np.unique(np.r_[depth[cones], 1.01])
    per_seed_rule, chosen = [], []
    for seed in seeds:
        f, pred = folds(n, k, seed, y), np.zeros(n, bool)
        for j in range(k):
            tr = np.nonzero(f != j)[0]
            best = (-1.0, 1.01)
            for t_c in grid[::-1]:
                p_ = rule(t_c, tr)
                tp = int(np.sum(p_ & (y[tr] == 1)))
                if p_.sum() and tp / p_.sum() >= MIN_PRECISION and tp / y[tr].sum() > best[0]:
                    best = (tp / y[tr].sum(), float(t_c))
            chosen.append(best[1])
            te = np.nonzero(f == j)[0]
            pred[te] = rule(best[1], te)
        per_seed_rule.append(pr(pred, y))
    rep["rule_or_nested_cv"] = summarise(per_seed_rule) | {"t_c_chosen_in_folds": [min(chosen), max(chosen)]}
    rep["rule_or_full_dev"] = {f"{t:.2f}": pr(rule(t, np.arange(n)), y) for t in (0.6, 0.7, 0.8, 0.9)}

    # (b2) logistic on [logit evidence, cones, cones * depth]; out-of-fold probability, then the asymmetric threshold
    X = np.c_[logit(ev), cones.astype(float), cones * depth]

    def logistic_fold(tr: np.ndarray, te: np.ndarray) -> np.ndarray:
        mu, sd = X[tr].mean(0), X[tr].std(0) + 1e-9
        w = fit_logistic((X[tr] - mu) / sd, y[tr])
        return 1 / (1 + np.exp(-(w[0] + ((X[te] - mu) / sd) @ w[1:])))

    oof = cv_scores(logistic_fold, n, y, k, seeds)
    base_oof = cv_scores(
        lambda tr, te: (
            1 / (1 + np.exp(-(np.c_[np.ones(len(te)), logit(ev[te])] @ fit_logistic(logit(ev[tr])[:, None], y[tr]))))
        ),
        n,
        y,
        k,
        seeds,
    )
    for name, scores in (("logistic_evidence_plus_cue", oof), ("logistic_evidence_only", base_oof)):
        per_seed, ts = [], []
        for s in scores:
            s = np.where(possible, s, 0.0)
            t = asymmetric_threshold(s, y, MIN_PRECISION)
            ts.append(t)
            per_seed.append(pr(s >= t, y) | {"auc": auc(s, y), "auc_cone_photos": auc(s[cones], y[cones])})
        rep[name] = summarise(per_seed) | {
            "threshold_range": [min(ts), max(ts)],
            "auc_mean": float(np.mean([p["auc"] for p in per_seed])),
            "auc_cone_photos_mean": float(np.mean([p["auc_cone_photos"] for p in per_seed])),
            "note": "threshold chosen on the pooled out-of-fold probabilities (optimistic)",
        }
    w_full = fit_logistic((X - X.mean(0)) / (X.std(0) + 1e-9), y)
    rep["logistic_full_dev_weights"] = dict(
        zip(["intercept", "logit_evidence", "cones", "cones_x_depth"], w_full.tolist())
    )
    return rep


PICTURES = {"sunny_more21.jpg": ("more", 21), "overcast_benchmark2.jpg": ("benchmark", 2)}


def picture(img: np.ndarray, boxes: np.ndarray, title: str) -> np.ndarray:
    """What the cue measures on one photo (BGR, <= ANALYSIS_SIDE px): windows yellow, labelled boxes green, the base
    band light green, the dark regions attached to a base magenta."""
    img, boxes = _analysis_copy(img, boxes)
    out = img.copy()
    for c in _box_shadows(img, boxes):
        sub = out[c["window"]]
        sub[c["base"]] = (0.6 * sub[c["base"]] + 0.4 * np.array([120, 255, 120])).astype(np.uint8)
        sub[c["shadow"]] = (0.35 * sub[c["shadow"]] + 0.65 * np.array([255, 0, 255])).astype(np.uint8)
        r, q = c["window"]
        cv2.rectangle(out, (q.start, r.start), (q.stop - 1, r.stop - 1), (255, 255, 0), 1)
    for x0, y0, x1, y1 in np.round(boxes).astype(int):
        cv2.rectangle(out, (x0, y0), (x1, y1), (0, 200, 0), 1)
    out = cv2.cvtColor(np.hstack([img, out]), cv2.COLOR_RGB2BGR)
    if out.shape[1] > 1200:
        out = cv2.resize(out, None, fx=1200 / out.shape[1], fy=1200 / out.shape[1], interpolation=cv2.INTER_AREA)
    bar = np.full((22, out.shape[1], 3), 255, np.uint8)
    cv2.putText(bar, title, (4, 16), cv2.FONT_HERSHEY_SIMPLEX, 0.45, (0, 0, 0), 1, cv2.LINE_AA)
    return np.vstack([bar, out])


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--folds", type=int, default=5)
    ap.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2, 3, 4])
    ap.add_argument("--out", type=Path, default=OUT)
    a = ap.parse_args(argv)
    t0 = time.time()
    rows = dev_rows()
    for r in rows:
        img = cv2.cvtColor(cv2.imread(str(data_root() / r["photo"])), cv2.COLOR_BGR2RGB)
        boxes = labelled_boxes(r["photo"], img.shape[1], img.shape[0])
        r["cones"] = len(boxes)
        r["cue"] = object_shadow_cue(img, boxes) if len(boxes) else dict(NO_CUE)
        if (key := (r["set"], r["index"])) in PICTURES.values():
            name = next(k for k, v in PICTURES.items() if v == key)
            c = r["cue"]
            title = (
                f"{r['photo'].split('/')[-1]} direct_sun={r['direct_sun']} evidence p={r['evidence']:.2f} "
                f"shadow_depth={c['shadow_depth']:.2f} area={c['shadow_area']:.2f} blue_shift={c['blue_shift']:.2f}"
            )
            a.out.mkdir(parents=True, exist_ok=True)
            cv2.imwrite(str(a.out / name), picture(img, boxes, title), [cv2.IMWRITE_JPEG_QUALITY, 80])
    rep = evaluate(rows, a.folds, a.seeds)
    rep["per_photo"] = [
        {k: r[k] for k in ("set", "index", "direct_sun", "evidence", "cones")}
        | {k: round(v, 4) for k, v in r["cue"].items()}
        for r in rows
    ]
    rep["seconds"] = round(time.time() - t0, 1)
    a.out.mkdir(parents=True, exist_ok=True)
    (a.out / "dev.json").write_text(json.dumps(rep, indent=1))
    print(json.dumps({k: v for k, v in rep.items() if k != "per_photo"}, indent=1))
    return 0

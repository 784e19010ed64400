"""Direct sun from a photo's own labelled traffic cones: does a cone's shading, highlights and cast shadow tell a
sunny photo from an overcast one better than the three colour traces of ``sun_evidence``?

    python -m studies.lighting.sun_labelled_cues --part dev     # result/cues_dev.csv, dev_report.json, cues.jpg

Cues are measured per labelled cone box (TraCon YOLO labels) on the photo as the pipeline sees it (<= 640 px), then
aggregated per photo as the median over its usable cones (:func:`photo_cone_cues`). Photos without labels or without
a usable cone (box side < 15 px) get NaN. The three existing features and the shipped model's probability come from
``sun_asymmetric/result/estimates.csv`` (not recomputed). Only the part named by ``--part`` is read.
"""

from __future__ import annotations

import argparse
import csv
import json
import sys
import time
from pathlib import Path

import cv2
import numpy as np

from aias_augment.core.config import data_root
from aias_augment.core.srgb import srgb_to_linear

HERE = Path(__file__).resolve().parent
OUT = HERE / "result"
SPLIT = HERE.parent / "sun_asymmetric/result/split.csv"
ESTIMATES = HERE.parent / "sun_asymmetric/result/estimates.csv"
BASE = ("sky_blue", "shadow_blue", "clipped")
# primary cues, one per physical idea, fixed before any score was looked at; the others are secondary candidates
PRIMARY = ("side_ratio", "cone_clip", "ground_ratio")
SECONDARY = ("side_blue", "cone_spread", "ground_blue")
CUES = PRIMARY + SECONDARY
# the direction each cue was expected to point to direct sun (before any score): AUCs are reported in it
SIGN = {"side_ratio": 1, "cone_clip": 1, "ground_ratio": -1, "side_blue": 1, "cone_spread": 1, "ground_blue": 1}
MIN_BOX_PX = 15
MAX_SIDE = 640
_LUM = np.array([0.2126, 0.7152, 0.0722], np.float32)
_EPS = 1e-3
_CLIP = 0.98
N_SECTORS = 8


# ----------------------------------------------------------------------------------------------- the cue functions
def cone_mask(rgb01: np.ndarray, box: tuple[int, int, int, int]) -> np.ndarray | None:
    """Boolean mask (box-sized) of the cone's coloured body: pixels of saturation >= 0.3 and value >= 0.05 whose hue
    is within 25 deg of the circular median hue of the saturated pixels of the box's central vertical band (the middle
    30 % of its width, rows 20-95 %): the band is mostly cone, so the cone's own colour is found whatever it is
    (orange, red, yellow, blue). White stripes, highlights and grey background drop out. None where the band has
    < 15 saturated pixels (a white or black cone)."""
    x0, y0, x1, y1 = box
    crop = rgb01[y0:y1, x0:x1]
    h, w = crop.shape[:2]
    mx, mn = crop.max(-1), crop.min(-1)
    sat = (mx - mn) / np.maximum(mx, 1e-6)
    hsv = cv2.cvtColor((crop * 255).astype(np.uint8), cv2.COLOR_RGB2HSV_FULL)
    hue = hsv[..., 0].astype(np.float32) * (2 * np.pi / 256)
    coloured = (sat >= 0.3) & (mx >= 0.05)
    band = np.zeros_like(coloured)
    band[int(0.2 * h) : int(np.ceil(0.95 * h)), int(0.35 * w) : int(np.ceil(0.65 * w))] = True
    ref = coloured & band
    if ref.sum() < 15:
        return None
    ang = hue[ref]
    mean_dir = np.arctan2(np.sin(ang).mean(), np.cos(ang).mean())
    d = np.abs(np.angle(np.exp(1j * (ang - mean_dir))))  # refine: median of the hues around the mean direction
    ref_hue = mean_dir + float(np.median(np.angle(np.exp(1j * (ang - mean_dir)))[d < np.pi / 2]))
    dist = np.abs(np.angle(np.exp(1j * (hue - ref_hue))))
    return coloured & (dist <= np.radians(25))


def cone_cues(img: np.ndarray, lin: np.ndarray, box_xyxy, other_boxes=(), detail: bool = False) -> dict | None:
    """The six cues of one cone box (x0, y0, x1, y1 px) on an (H, W, 3) uint8 RGB photo and its linear copy ``lin``.
    None where the box is < :data:`MIN_BOX_PX` on a side. Cues that cannot be measured are NaN.

    - ``side_ratio``: rows 30-90 % of the box height; per row the cone mask's leftmost and rightmost pixel; the left
      third and right third of that span collected over rows (>= 15 px each); |log(median linear luminance of one
      side / the other)|. Direct sun lights one flank: 2-6x (0.7-1.8); overcast: near 0.
    - ``side_blue``: median log(B/R) of the darker side minus that of the brighter side (sky-lit shade is bluer).
    - ``cone_spread``: log(q90 / q10) of linear luminance over the cone mask in rows 30-90 %.
    - ``cone_clip``: share of clipped pixels (a channel >= 0.98) within the cone's hull (per row between the mask's
      extremes, rows 5-100 %): specular highlights and sunlit retro-reflective stripes.
    - ``ground_ratio``: an elliptic ring around the base (centre: box centre column, 95 % of its height; radius
      0.55-1.5 box widths horizontally, half that vertically: the ground seen obliquely), minus every labelled box,
      split in 8 angular sectors; sectors with >= 12 px count, >= 4 needed; log(median luminance of the darkest
      sector / the brightest). A sharp cast shadow beside the base: strongly negative.
    - ``ground_blue``: median log(B/R) of the darkest sector minus that of the brightest.
    """
    H, W = img.shape[:2]
    x0, y0, x1, y1 = (int(round(v)) for v in box_xyxy)
    x0, y0, x1, y1 = max(x0, 0), max(y0, 0), min(x1, W), min(y1, H)
    w, h = x1 - x0, y1 - y0
    if min(w, h) < MIN_BOX_PX:
        return None
    nan = float("nan")
    out = dict.fromkeys(CUES, nan)
    rgb01 = img.astype(np.float32) / 255.0
    lum = lin @ _LUM
    log_br = np.log((lin[..., 2] + _EPS) / (lin[..., 0] + _EPS))
    dbg = {"box": (x0, y0, x1, y1)}

    mask = cone_mask(rgb01, (x0, y0, x1, y1))
    if mask is not None:
        bl, bbr = lum[y0:y1, x0:x1], log_br[y0:y1, x0:x1]
        left, right = np.zeros_like(mask), np.zeros_like(mask)
        hull = np.zeros_like(mask)
        for r in range(int(0.05 * h), h):
            xs = np.flatnonzero(mask[r])
            if len(xs) < 6:
                continue
            xl, xr = xs[0], xs[-1]
            hull[r, xl : xr + 1] = True
            if 0.3 * h <= r < 0.9 * h:
                third = (xr - xl) / 3
                left[r] = mask[r] & (np.arange(w) < xl + third)
                right[r] = mask[r] & (np.arange(w) > xr - third)
        if left.sum() >= 15 and right.sum() >= 15:
            ml, mr = np.median(bl[left]), np.median(bl[right])
            out["side_ratio"] = float(abs(np.log((ml + _EPS) / (mr + _EPS))))
            dark, bright = (left, right) if ml < mr else (right, left)
            out["side_blue"] = float(np.median(bbr[dark]) - np.median(bbr[bright]))
        mid = mask.copy()
        mid[: int(0.3 * h)] = False
        mid[int(0.9 * h) :] = False
        if mid.sum() >= 30:
            q10, q90 = np.quantile(bl[mid], [0.1, 0.9])
            out["cone_spread"] = float(np.log((q90 + _EPS) / (q10 + _EPS)))
        if hull.sum() >= 30:
            out["cone_clip"] = float(np.mean(rgb01[y0:y1, x0:x1].max(-1)[hull] >= _CLIP))
        dbg.update(mask=mask, left=left, right=right, hull=hull)

    # ground ring around the base
    cx, yb = 0.5 * (x0 + x1), y0 + 0.95 * h
    rx_out, ry_out = 1.5 * w, 0.75 * w
    gx0, gx1 = int(max(cx - rx_out, 0)), int(min(cx + rx_out + 1, W))
    gy0, gy1 = int(max(yb - ry_out, 0)), int(min(yb + ry_out + 1, H))
    if gx1 > gx0 and gy1 > gy0:
        yy, xx = np.mgrid[gy0:gy1, gx0:gx1]
        u, v = (xx - cx) / w, (yy - yb) / (0.5 * w)
        r = np.hypot(u, v)
        ring = (r >= 0.55) & (r <= 1.5)
        for bx in [(x0, y0, x1, y1), *other_boxes]:
            bx0, by0, bx1, by1 = (int(round(c)) for c in bx)
            ring &= ~((xx >= bx0) & (xx < bx1) & (yy >= by0) & (yy < by1))
        sector = ((np.arctan2(v, u) + np.pi) / (2 * np.pi) * N_SECTORS).astype(int) % N_SECTORS
        gl, gbr = lum[gy0:gy1, gx0:gx1], log_br[gy0:gy1, gx0:gx1]
        meds, blues, secs = [], [], []
        for s in range(N_SECTORS):
            m = ring & (sector == s)
            if m.sum() >= 12:
                meds.append(np.median(gl[m]))
                blues.append(np.median(gbr[m]))
                secs.append(s)
        if len(meds) >= 4:
            i_d, i_b = int(np.argmin(meds)), int(np.argmax(meds))
            out["ground_ratio"] = float(np.log((meds[i_d] + _EPS) / (meds[i_b] + _EPS)))
            out["ground_blue"] = float(blues[i_d] - blues[i_b])
            dbg.update(ring=(gx0, gy0, ring, sector), dark_sector=secs[i_d], bright_sector=secs[i_b])
    if detail:
        out["_detail"] = dbg
    return out


def label_boxes(photo: str, shape: tuple[int, int]) -> np.ndarray:
    """(N, 4) xyxy px boxes of the photo's TraCon labels at the analysed size; (0, 4) where it has none."""
    parts = photo.split("/")
    if parts[0] != "tracon":
        return np.zeros((0, 4))
    lab_path = data_root() / "tracon/labels" / parts[2] / (Path(parts[3]).stem + ".txt")
    if not lab_path.exists() or lab_path.stat().st_size == 0:
        return np.zeros((0, 4))
    lab = np.loadtxt(lab_path, ndmin=2)
    H, W = shape
    cx, cy, bw, bh = lab[:, 1] * W, lab[:, 2] * H, lab[:, 3] * W, lab[:, 4] * H
    return np.c_[cx - bw / 2, cy - bh / 2, cx + bw / 2, cy + bh / 2]


def photo_cone_cues(img: np.ndarray, boxes_xyxy: np.ndarray, skip_truncated: bool = False) -> dict[str, float]:
    """Per photo: each cue the median over the usable cones (NaN where none measured it), and ``n_cones`` used.
    ``img`` (H, W, 3) uint8 RGB at the analysed size (<= 640 px), ``boxes_xyxy`` (N, 4) px. ``skip_truncated``: also
    skip boxes within 2 px of the photo's border (a cut cone)."""
    lin = srgb_to_linear(img)
    H, W = img.shape[:2]
    per = []
    for k, b in enumerate(boxes_xyxy):
        if skip_truncated and (b[0] < 2 or b[1] < 2 or b[2] > W - 2 or b[3] > H - 2):
            continue
        c = cone_cues(img, lin, b, [o for j, o in enumerate(boxes_xyxy) if j != k])
        if c is not None:
            per.append(c)
    res = {}
    for name in CUES:
        v = np.array([c[name] for c in per], float)
        res[name] = float(np.nanmedian(v)) if np.isfinite(v).any() else float("nan")
    res["n_cones"] = len(per)
    return res


# ------------------------------------------------------------------------------------------------------- the data
def load_photo(photo: str) -> np.ndarray:
    img = cv2.cvtColor(cv2.imread(str(data_root() / photo)), cv2.COLOR_BGR2RGB)
    if photo.startswith("tracon"):
        s = min(1.0, MAX_SIDE / max(img.shape[:2]))
        if s < 1:
            img = cv2.resize(img, None, fx=s, fy=s, interpolation=cv2.INTER_AREA)
    return img


def part_rows(part: str) -> list[dict]:
    """Scored (certain) rows of ``part`` with the three features and the shipped probability from estimates.csv."""
    est = {r["photo"]: r for r in csv.DictReader(open(ESTIMATES)) if r["part"] == part}
    rows = []
    for r in csv.DictReader(open(SPLIT)):
        if r["part"] != part or int(r["uncertain"]):
            continue
        e = est[r["photo"]]
        p = float(e["balanced_probability"]) if int(e["balanced_sun_possible"]) else 0.0
        rows.append(
            {
                "photo": r["photo"],
                "direct_sun": int(r["direct_sun"]),
                **{f: float(e[f]) for f in BASE},
                "balanced_probability": float(e["balanced_probability"]),
                "shipped_p": p,
            }
        )
    return rows


def measure(rows: list[dict], skip_truncated: bool = False) -> tuple[list[dict], list[float]]:
    times = []
    for r in rows:
        img = load_photo(r["photo"])
        boxes = label_boxes(r["photo"], img.shape[:2])
        r["n_boxes"] = len(boxes)
        if len(boxes):
            t0 = time.perf_counter()
            r.update(photo_cone_cues(img, boxes, skip_truncated))
            times.append(time.perf_counter() - t0)
        else:
            r.update({c: float("nan") for c in CUES}, n_cones=0)
    return rows, times


# -------------------------------------------------------------------------------------------------- the evaluation
def auc(score: np.ndarray, y: np.ndarray) -> float:
    from sklearn.metrics import roc_auc_score

    ok = np.isfinite(score)
    if len(set(y[ok])) < 2:
        return float("nan")
    return float(roc_auc_score(y[ok], score[ok]))


def best_recall(p: np.ndarray, y: np.ndarray, min_precision: float = 0.9) -> float:
    """Highest recall of ``p >= t`` over thresholds t with precision >= min_precision (0 where none)."""
    best = 0.0
    for t in np.unique(p):
        pred = p >= t
        if y[pred].mean() >= min_precision:
            best = max(best, y[pred].sum() / y.sum())
    return float(best)


def choose_t(p: np.ndarray, y: np.ndarray, min_precision: float = 0.9) -> float:
    from aias_augment.analyse.lighting.sun_evidence import asymmetric_threshold

    return asymmetric_threshold(p, y, min_precision)


def design(rows: list[dict], cues: tuple[str, ...], indicator: bool) -> np.ndarray:
    X = np.array([[r[f] for f in BASE + cues] for r in rows], float)
    if indicator:
        X = np.c_[X, [float(r["n_cones"] > 0) for r in rows]]
    return X


def fit_predict(Xtr, ytr, Xte):
    """Median imputation (training rows' medians), standardisation and logistic regression (L2, C=1)."""
    from sklearn.impute import SimpleImputer
    from sklearn.linear_model import LogisticRegression
    from sklearn.pipeline import make_pipeline
    from sklearn.preprocessing import StandardScaler

    m = make_pipeline(SimpleImputer(strategy="median"), StandardScaler(), LogisticRegression(C=1.0, max_iter=1000))
    m.fit(Xtr, ytr)
    return m.predict_proba(Xte)[:, 1]


def cv_scores(X: np.ndarray, y: np.ndarray, seeds=range(5), k: int = 5) -> dict:
    """5-fold stratified CV over ``seeds``: out-of-fold AUC, the pooled-OOF best recall at precision >= 0.9, and the
    nested version: t chosen on inner 5-fold OOF probabilities of the training folds, applied to the test fold,
    decisions pooled over folds -> precision and recall."""
    from sklearn.model_selection import StratifiedKFold

    aucs, pooled, n_rec, n_prec, n_dec = [], [], [], [], []
    for s in seeds:
        oof = np.zeros(len(y))
        dec = np.zeros(len(y), bool)
        for tr, te in StratifiedKFold(k, shuffle=True, random_state=s).split(X, y):
            oof[te] = fit_predict(X[tr], y[tr], X[te])
            inner = np.zeros(len(tr))
            for itr, ite in StratifiedKFold(k, shuffle=True, random_state=100 + s).split(X[tr], y[tr]):
                inner[ite] = fit_predict(X[tr][itr], y[tr][itr], X[tr][ite])
            dec[te] = oof[te] >= choose_t(inner, y[tr])
        aucs.append(auc(oof, y))
        pooled.append(best_recall(oof, y))
        tp = int(np.sum(dec & (y == 1)))
        n_dec.append(int(dec.sum()))
        n_prec.append(tp / dec.sum() if dec.sum() else float("nan"))
        n_rec.append(tp / y.sum())
    r3 = lambda v: round(float(np.nanmean(v)), 3)  # noqa: E731
    return {
        "oof_auc": r3(aucs),
        "oof_auc_range": [round(min(aucs), 3), round(max(aucs), 3)],
        "pooled_recall_at_p90": r3(pooled),
        "nested_recall": r3(n_rec),
        "nested_precision": r3(n_prec),
        "nested_decided_sun": r3(n_dec),
    }


def auc_ci(score: np.ndarray, y: np.ndarray, n: int = 2000, seed: int = 0) -> list[float]:
    """95 % percentile bootstrap interval of the AUC over the photos that have the score."""
    ok = np.isfinite(score)
    s, t = score[ok], y[ok]
    rng = np.random.default_rng(seed)
    v = []
    for _ in range(n):
        i = rng.integers(0, len(s), len(s))
        if 0 < t[i].sum() < len(i):
            v.append(auc(s[i], t[i]))
    return [round(float(q), 3) for q in np.quantile(v, [0.025, 0.975])]


def evaluate(rows: list[dict]) -> dict:
    y = np.array([r["direct_sun"] for r in rows])
    has = np.array([r["n_cones"] > 0 for r in rows])
    rep = {
        "photos": len(rows),
        "sunny": int(y.sum()),
        "with_usable_cone": int(has.sum()),
        "sunny_with_usable_cone": int(y[has].sum()),
        "sunny_share_with_cone": round(float(y[has].mean()), 3),
        "sunny_share_without_cone": round(float(y[~has].mean()), 3),
    }
    feat = {}
    for f in BASE + CUES + ("balanced_probability", "shipped_p"):
        v = np.array([r[f] for r in rows], float)
        ok = np.isfinite(v)
        sv = SIGN.get(f, 1) * v
        feat[f] = {
            "photos": int(ok.sum()),
            "expected_sign": SIGN.get(f, 1),
            "auc_all_with_it": round(auc(sv, y), 3),
            "auc_all_with_it_95": auc_ci(sv, y),
            "auc_on_cone_photos": round(auc(np.where(has, sv, np.nan), y), 3),
            "sunny_median_iqr": [round(float(q), 3) for q in np.nanquantile(v[ok & (y == 1)], [0.5, 0.25, 0.75])],
            "not_median_iqr": [round(float(q), 3) for q in np.nanquantile(v[ok & (y == 0)], [0.5, 0.25, 0.75])],
        }
    rep["per_feature"] = feat
    models = {
        "base3": ((), False),
        "base3+cone_indicator": ((), True),
        "base3+primary3": (PRIMARY, False),
        "base3+indicator+primary3": (PRIMARY, True),
        "base3+side_ratio": (("side_ratio",), False),
        "base3+cone_clip": (("cone_clip",), False),
        "base3+ground_ratio": (("ground_ratio",), False),
        "base3+indicator+all6": (CUES, True),
        # post hoc: the best single cue by dev AUC (a secondary one), chosen after seeing the scores above
        "posthoc_base3+ground_blue": (("ground_blue",), False),
        "posthoc_base3+indicator+ground_blue": (("ground_blue",), True),
    }
    rep["cv_all_photos"] = {name: cv_scores(design(rows, c, i), y) for name, (c, i) in models.items()}
    sub = [r for r, h in zip(rows, has) if h]
    ys = y[has]
    rep["cv_cone_photos_only"] = {
        name: cv_scores(design(sub, c, False), ys)
        for name, c in (("base3", ()), ("base3+primary3", PRIMARY), ("posthoc_base3+ground_blue", ("ground_blue",)))
        if c is not None
    }
    Xc = np.array([[r[f] for f in PRIMARY] for r in sub], float)
    rep["cv_cone_photos_only"]["primary3_alone"] = cv_scores(Xc, ys)
    return rep


# ------------------------------------------------------------------------------------------------------ the picture
def picture(rows: list[dict], path: Path, n_each: int = 4, seed: int = 0) -> list[str]:
    """Crops around the largest usable cone of n_each sunny and n_each not-sunny cone photos (seeded draw)."""
    rng = np.random.default_rng(seed)
    chosen = []
    for lab in (1, 0):
        cand = [r for r in rows if r["n_cones"] > 0 and r["direct_sun"] == lab]
        chosen += [cand[i] for i in sorted(rng.choice(len(cand), min(n_each, len(cand)), replace=False))]
    tiles = []
    tw, th = 300, 300
    for r in chosen:
        img = load_photo(r["photo"])
        boxes = label_boxes(r["photo"], img.shape[:2])
        areas = (boxes[:, 2] - boxes[:, 0]) * (boxes[:, 3] - boxes[:, 1])
        lin = srgb_to_linear(img)
        c = None
        for k in np.argsort(-areas):
            c = cone_cues(img, lin, boxes[k], [o for j, o in enumerate(boxes) if j != k], detail=True)
            if c is not None:
                break
        vis = img.copy()
        d = c["_detail"]
        x0, y0, x1, y1 = d["box"]
        if "ring" in d:
            gx0, gy0, ring, sector = d["ring"]
            sub = vis[gy0 : gy0 + ring.shape[0], gx0 : gx0 + ring.shape[1]]
            col = np.zeros_like(sub)
            col[ring] = (255, 255, 0)
            col[ring & (sector == d["dark_sector"])] = (0, 0, 255)
            col[ring & (sector == d["bright_sector"])] = (255, 255, 255)
            sub[ring] = (0.55 * sub[ring] + 0.45 * col[ring]).astype(np.uint8)
        if "left" in d:
            crop = vis[y0:y1, x0:x1]
            for m, colr in ((d["left"], (0, 255, 0)), (d["right"], (255, 0, 255))):
                crop[m] = (0.5 * crop[m] + 0.5 * np.array(colr)).astype(np.uint8)
        cv2.rectangle(vis, (x0, y0), (x1 - 1, y1 - 1), (255, 0, 0), 1)
        w = x1 - x0
        cx0, cx1 = max(int(0.5 * (x0 + x1) - 1.7 * w), 0), min(int(0.5 * (x0 + x1) + 1.7 * w), img.shape[1])
        cy0, cy1 = max(y0 - int(0.15 * (y1 - y0)), 0), min(int(y0 + 0.95 * (y1 - y0) + 0.9 * w), img.shape[0])
        crop = vis[cy0:cy1, cx0:cx1]
        s = min(tw / crop.shape[1], (th - 64) / crop.shape[0])
        crop = cv2.resize(crop, None, fx=s, fy=s, interpolation=cv2.INTER_AREA if s < 1 else cv2.INTER_LINEAR)
        tile = np.full((th, tw, 3), 30, np.uint8)
        tile[: crop.shape[0], : crop.shape[1]] = crop
        lines = [
            f"{'SUN' if r['direct_sun'] else 'no sun'}  {Path(r['photo']).name[:22]}",
            f"side {c['side_ratio']:.2f}  clip {c['cone_clip']:.2f}",
            f"ground {c['ground_ratio']:.2f}  p_shipped {r['shipped_p']:.2f}",
        ]
        for i, t in enumerate(lines):
            cv2.putText(tile, t, (4, th - 46 + 17 * i), cv2.FONT_HERSHEY_SIMPLEX, 0.45, (255, 255, 255), 1, cv2.LINE_AA)
        tiles.append(tile)
    while len(tiles) % 4:
        tiles.append(np.full((th, tw, 3), 30, np.uint8))
    grid = np.vstack([np.hstack(tiles[i : i + 4]) for i in range(0, len(tiles), 4)])
    cv2.imwrite(str(path), cv2.cvtColor(grid, cv2.COLOR_RGB2BGR), [cv2.IMWRITE_JPEG_QUALITY, 88])
    return [r["photo"] for r in chosen]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--part", choices=("dev", "heldout"), required=True)
    ap.add_argument("--out", type=Path, default=OUT)
    ap.add_argument("--skip-truncated", action="store_true", help="also skip cone boxes cut by the photo border")
    ap.add_argument("--no-picture", action="store_true")
    a = ap.parse_args(argv)
    a.out.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    rows, times = measure(part_rows(a.part), a.skip_truncated)
    with open(a.out / f"cues_{a.part}.csv", "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows([{k: (round(v, 5) if isinstance(v, float) else v) for k, v in r.items()} for r in rows])
    rep = {
        "command": "python -m studies.lighting.sun_labelled_cues " + " ".join(argv or sys.argv[1:]),
        "part": a.part,
        "skip_truncated": a.skip_truncated,
        "primary_cues": PRIMARY,
        "secondary_cues": SECONDARY,
        "cue_ms_per_photo_median": round(1000 * float(np.median(times)), 1),
        "cue_ms_per_photo_max": round(1000 * float(np.max(times)), 1),
        **evaluate(rows),
    }
    if a.part == "dev" and not a.no_picture:
        rep["picture_photos"] = picture(rows, a.out / "cues.jpg")
    rep["seconds"] = round(time.perf_counter() - t0, 1)
    (a.out / f"{a.part}_report.json").write_text(json.dumps(rep, indent=1))
    print(json.dumps(rep, indent=1))
    return 0

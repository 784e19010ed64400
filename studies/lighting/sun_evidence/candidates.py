#!/usr/bin/env python
"""Would a cast-shadow edge cue add to the direct-sun evidence? Cross-validated on the benchmark's train half only.

Candidates, measured on the same 320 px copy as :mod:`aias_augment.analyse.lighting.sun_evidence`, bottom half:

- ``edge_share``: of the sharp log-luminance edges (gradient > 0.15 per px after a 1 px blur), the share whose two
  sides 3 px apart differ by more than 2x in luminance with the bright side unclipped (a cast shadow's boundary);
- ``edge_blue``: the median log(B/R) of the dark side minus the bright side over those edges (skylight in the shadow);
- ``edge_shadow``: the share of sharp edges that are both (> 2x and > 0.1 bluer on the dark side);
- ``bottom_range``: log(p95 / p5) of the bottom half's luminance (direct sun spreads it).

Each is added to the shipped three features; 6-fold out-of-fold log loss, ROC AUC, precision and recall at 0.5,
averaged over 5 fold seeds, on the 48 train-half photos. The test half is not touched.

    python -m studies.lighting.sun_evidence.candidates
"""

from __future__ import annotations

import csv

import cv2
import numpy as np

from aias_augment.analyse.lighting.sun_evidence import FEATURE_SIDE, FEATURES, sun_evidence_features
from aias_augment.core.config import data_root
from studies.lighting.sun_benchmark.run import precision_recall, split_halves


def edge_features(img: np.ndarray) -> dict[str, float]:
    s = FEATURE_SIDE / max(img.shape[:2])
    if s < 1:
        img = cv2.resize(img, None, fx=s, fy=s, interpolation=cv2.INTER_AREA)
    x = img.astype(np.float32) / 255.0
    lin = np.where(x <= 0.04045, x / 12.92, ((x + 0.055) / 1.055) ** 2.4)
    lum = lin @ np.array([0.2126, 0.7152, 0.0722], np.float32)
    L = cv2.GaussianBlur(np.log(lum + 1e-3), (0, 0), 1.0)
    br = cv2.GaussianBlur(np.log((lin[..., 2] + 1e-3) / (lin[..., 0] + 1e-3)), (0, 0), 1.0)
    gx = cv2.Sobel(L, cv2.CV_32F, 1, 0, ksize=3) / 8
    gy = cv2.Sobel(L, cv2.CV_32F, 0, 1, ksize=3) / 8
    g = np.hypot(gx, gy)
    h, (H, W) = img.shape[0], L.shape
    bl = lum[h // 2 :]
    out = {"bottom_range": float(np.log((np.quantile(bl, 0.95) + 1e-3) / (np.quantile(bl, 0.05) + 1e-3)))}
    ys, xs = np.nonzero(g[h // 2 :] > 0.15)
    ys = ys + h // 2
    if not len(ys):
        return {**out, "edge_share": 0.0, "edge_blue": 0.0, "edge_shadow": 0.0}
    nx, ny = gx[ys, xs] / g[ys, xs], gy[ys, xs] / g[ys, xs]
    xa, ya = np.clip(np.round(xs - 3 * nx).astype(int), 0, W - 1), np.clip(np.round(ys - 3 * ny).astype(int), 0, H - 1)
    xb, yb = np.clip(np.round(xs + 3 * nx).astype(int), 0, W - 1), np.clip(np.round(ys + 3 * ny).astype(int), 0, H - 1)
    d_lum, d_blue = L[yb, xb] - L[ya, xa], br[ya, xa] - br[yb, xb]  # a: the darker side (against the gradient)
    strong = (d_lum > np.log(2.0)) & (x[yb, xb].max(-1) < 0.98)
    return {
        **out,
        "edge_share": float(strong.mean()),
        "edge_blue": float(np.median(d_blue[strong])) if strong.sum() > 10 else 0.0,
        "edge_shadow": float(np.mean(strong & (d_blue > 0.1))),
    }


def main() -> int:
    from sklearn.linear_model import LogisticRegression
    from sklearn.metrics import log_loss, roc_auc_score
    from sklearn.model_selection import StratifiedKFold, cross_val_predict

    rows = list(csv.DictReader(open("studies/lighting/sun_benchmark/labels/labels.csv")))
    train, _ = split_halves(len(rows), 0)
    feats = []
    for i in train:
        img = cv2.cvtColor(cv2.imread(str(data_root() / rows[i]["photo"])), cv2.COLOR_BGR2RGB)
        feats.append({**sun_evidence_features(img), **edge_features(img)})
    y = np.array([int(rows[i]["direct_sun"]) for i in train])
    names = list(feats[0])
    X = np.array([[f[k] for k in names] for f in feats])
    print("| features | out-of-fold log loss | ROC AUC | precision | recall |\n|---|---|---|---|---|")
    for extra in (
        [],
        ["edge_share"],
        ["edge_blue"],
        ["edge_shadow"],
        ["bottom_range"],
        ["edge_shadow", "bottom_range"],
    ):
        cols = [names.index(k) for k in (*FEATURES, *extra)]
        Z = (X[:, cols] - X[:, cols].mean(0)) / X[:, cols].std(0)
        scores = []
        for seed in range(5):
            cv = StratifiedKFold(6, shuffle=True, random_state=seed)
            p = cross_val_predict(LogisticRegression(C=1.0), Z, y, cv=cv, method="predict_proba")[:, 1]
            scores.append([log_loss(y, p), roc_auc_score(y, p), *precision_recall(p >= 0.5, y == 1)])
        m = np.mean(scores, axis=0)
        print(
            f"| shipped three{' + ' + ' + '.join(extra) if extra else ''} | " + " | ".join(f"{v:.3f}" for v in m) + " |"
        )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

"""Direct sun from the photo's shadow edges: whether sharp illumination edges on the ground tell direct sun better
than the three colour traces of ``sun_evidence`` (development photos only).

A cast shadow's edge under direct sun is a step in brightness of 2x or more whose every channel steps the same way
and whose red steps more than its blue (the lit side has the warm sun, the shadow only the blue sky); a material
edge need not do either. On a 320 px copy (as ``sun_evidence``): log luminance smoothed (sigma 1 px), its gradient's
local maxima above 0.15 per px in the lower two thirds, each sampled 3 px to either side along the gradient in
linear RGB. Per photo:

- ``strong_frac``: edges stepping >= 2x in luminance (lit side unclipped), per pixel of the lower two thirds;
- ``edge_frac``: those that also step up in every channel (log ratio > 0.2) and more in red than blue (> 0.05);
- ``edge_share``: ``edge_frac`` / ``strong_frac``; ``edge_step``: their median log step; ``edge_rb``: the median
  red-minus-blue log step of the strong edges.

Fixed before any score. Scored as ``sun_labelled_cues`` scores: ROC AUC per feature, and logistic regressions with
the three traces (5-fold stratified CV x 5 seeds: out-of-fold AUC and the recall at precision >= 0.90).

    python -m studies.lighting.sun_shadow_edges      # result/edges_dev.csv, report.json, edges.jpg; ~20 s
"""

from __future__ import annotations

import argparse
import csv
import json
from pathlib import Path

import cv2
import numpy as np
from scipy import ndimage

from aias_augment.core.srgb import srgb_to_linear
from studies._shared.pictures import write_jpeg
from studies.lighting.sun_asymmetric.run import load_photo
from studies.lighting.sun_labelled_cues.run import part_rows

OUT = Path(__file__).parent / "result"
FEATURES = ("strong_frac", "edge_frac", "edge_share", "edge_step", "edge_rb")
BASE = ("sky_blue", "shadow_blue", "clipped")
LUMA = np.array([0.2126, 0.7152, 0.0722])


def shadow_edges(img: np.ndarray) -> tuple[dict, np.ndarray, np.ndarray]:
    """The features (module docstring) of one RGB uint8 photo, its 320 px copy and the mask of illumination edges."""
    s = 320 / max(img.shape[:2])
    if s < 1:
        img = cv2.resize(img, None, fx=s, fy=s, interpolation=cv2.INTER_AREA)
    lin = srgb_to_linear(img).astype(np.float64)
    level = ndimage.gaussian_filter(np.log(lin @ LUMA + 1e-3), 1.0)
    gy, gx = np.gradient(level)
    mag = np.hypot(gx, gy)
    h, w = level.shape
    region = np.broadcast_to(np.arange(h)[:, None] >= h // 3, (h, w))
    edge = region & (mag > 0.15) & (mag >= ndimage.maximum_filter(mag, 3))
    ys, xs = np.nonzero(edge)
    mask = np.zeros((h, w), bool)
    if len(ys) < 10:
        return dict.fromkeys(FEATURES, 0.0), img, mask
    ny, nx = gy[ys, xs] / mag[ys, xs], gx[ys, xs] / mag[ys, xs]

    def at(plane, k):
        return ndimage.map_coordinates(plane, [ys + k * ny, xs + k * nx], order=1, mode="nearest")

    lit = np.stack([at(lin[..., c], 3.0) for c in range(3)], -1)
    dark = np.stack([at(lin[..., c], -3.0) for c in range(3)], -1)
    steps = np.log((lit + 1e-4) / (dark + 1e-4))
    step = np.log((lit @ LUMA + 1e-4) / (dark @ LUMA + 1e-4))
    strong = (step > np.log(2.0)) & (at(img.max(-1) / 255.0, 3.0) < 0.98)
    illum = strong & (steps.min(-1) > 0.2) & (steps[:, 0] - steps[:, 2] > 0.05)
    mask[ys[illum], xs[illum]] = True
    n = region.sum()
    return (
        {
            "strong_frac": float(strong.sum() / n),
            "edge_frac": float(illum.sum() / n),
            "edge_share": float(illum.sum() / max(strong.sum(), 1)),
            "edge_step": float(np.median(step[illum])) if illum.any() else 0.0,
            "edge_rb": float(np.median((steps[:, 0] - steps[:, 2])[strong])) if strong.any() else 0.0,
        },
        img,
        mask,
    )


def cross_validated(rows: list[dict], keys: tuple[str, ...], seeds: int = 5) -> dict:
    from sklearn.linear_model import LogisticRegression
    from sklearn.metrics import roc_auc_score
    from sklearn.model_selection import StratifiedKFold
    from sklearn.pipeline import make_pipeline
    from sklearn.preprocessing import StandardScaler

    x = np.array([[r[k] for k in keys] for r in rows])
    y = np.array([r["direct_sun"] for r in rows])
    aucs, recalls = [], []
    for seed in range(seeds):
        oof = np.zeros(len(y))
        for tr, te in StratifiedKFold(5, shuffle=True, random_state=seed).split(x, y):
            m = make_pipeline(StandardScaler(), LogisticRegression(C=1.0, max_iter=1000)).fit(x[tr], y[tr])
            oof[te] = m.predict_proba(x[te])[:, 1]
        aucs.append(roc_auc_score(y, oof))
        ok = [((oof >= t) & (y == 1)).sum() / y.sum() for t in np.unique(oof) if y[oof >= t].mean() >= 0.9]
        recalls.append(max(ok, default=0.0))
    return {
        "oof_auc": float(np.mean(aucs)),
        "oof_auc_range": [float(min(aucs)), float(max(aucs))],
        "recall_at_precision_0.9": float(np.mean(recalls)),
    }


def picture(rows: list[dict], path: Path, rng: np.random.Generator) -> None:
    tiles = []
    for label in (1, 0):
        pick = [r for r in rows if r["direct_sun"] == label]
        for r in [pick[i] for i in rng.choice(len(pick), 4, replace=False)]:
            _, small, mask = shadow_edges(load_photo(r["photo"]))
            bgr = cv2.cvtColor(small, cv2.COLOR_RGB2BGR)
            bgr[cv2.dilate(mask.astype(np.uint8), np.ones((2, 2), np.uint8)) > 0] = (255, 0, 255)
            cv2.putText(
                bgr, f"sun {label} f {r['edge_frac']:.3f}", (4, 14), cv2.FONT_HERSHEY_SIMPLEX, 0.45, (255, 255, 255), 1
            )
            tiles.append(cv2.resize(bgr, (320, int(320 * bgr.shape[0] / bgr.shape[1]))))
    hgt = max(t.shape[0] for t in tiles)
    tiles = [np.pad(t, ((0, hgt - t.shape[0]), (0, 0), (0, 0))) for t in tiles]
    write_jpeg(path, np.vstack([np.hstack(tiles[:4]), np.hstack(tiles[4:])]))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--out", type=Path, default=OUT)
    a = ap.parse_args(argv)
    from sklearn.metrics import roc_auc_score

    a.out.mkdir(parents=True, exist_ok=True)
    rows = part_rows("dev")
    for r in rows:
        r.update(shadow_edges(load_photo(r["photo"]))[0])
    with open(a.out / "edges_dev.csv", "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=["photo", "direct_sun", *BASE, *FEATURES])
        w.writeheader()
        w.writerows([{k: (round(r[k], 5) if isinstance(r[k], float) else r[k]) for k in w.fieldnames} for r in rows])
    y = [r["direct_sun"] for r in rows]
    models = {
        "base3": BASE,
        "base3 + edge_frac": (*BASE, "edge_frac"),
        "base3 + edge_frac + edge_rb": (*BASE, "edge_frac", "edge_rb"),
        "base3 + all five": (*BASE, *FEATURES),
        "edges alone (strong_frac, edge_frac, edge_rb)": ("strong_frac", "edge_frac", "edge_rb"),
    }
    report = {
        "photos": len(rows),
        "sunny": int(sum(y)),
        "auc": {k: float(roc_auc_score(y, [r[k] for r in rows])) for k in (*FEATURES, *BASE)},
        "models": {name: cross_validated(rows, keys) for name, keys in models.items()},
    }
    (a.out / "report.json").write_text(json.dumps(report, indent=1) + "\n")
    picture(rows, a.out / "edges.jpg", np.random.default_rng(53))
    print(json.dumps(report, indent=1))
    return 0

"""Fit the direct-sun evidence model on the train half of the labelled lighting benchmark; score the test half.

The labels are ``studies/lighting/sun_benchmark/labels/labels.csv`` (97 photos labelled by eye, ``direct_sun``); the split is
the benchmark's seeded half (``studies/lighting/sun_benchmark/run.py``: the first half of ``default_rng(seed).permutation``
trains). On train: a logistic regression of the standardised features of
:mod:`aias_augment.analyse.lighting.sun_evidence` (scikit-learn, L2, C = 1), and the threshold that maximises F0.5 on
its out-of-fold probabilities (6 folds): a shadow under an overcast sky looks worse than a missing one, so
precision weighs double. The test half is scored once: precision, recall, ROC AUC, Brier score, a reliability
diagram, beside the decision the recorded image-cue estimate made on the same photos (``estimates.csv``).

    python -m studies.lighting.sun_evidence --model checkpoints/sun_evidence.json --out studies/lighting/sun_evidence/result

The shipped threshold is then set by ``python -m studies.lighting.sun_asymmetric`` (an asymmetric cost, chosen on its
development photos): rerun its ``score`` step and copy its threshold into the model after refitting.
"""

import argparse
import csv
import json
import sys
import time
from pathlib import Path

import cv2
import numpy as np

from aias_augment.analyse.lighting.sun_evidence import FEATURES, SunEvidenceModel, sun_evidence_features
from aias_augment.core.config import data_root
from studies._shared.pictures import save_figure_jpeg
from studies.lighting.sun_benchmark.run import precision_recall, split_halves


def f_beta(p: float, r: float, beta: float) -> float:
    b2 = beta * beta
    return (1 + b2) * p * r / max(b2 * p + r, 1e-9)


def reliability(prob: np.ndarray, truth: np.ndarray, bins: int = 5) -> list[dict]:
    edges = np.linspace(0, 1, bins + 1)
    out = []
    for lo, hi in zip(edges[:-1], edges[1:]):
        m = (prob >= lo) & ((prob < hi) | (hi == 1.0))
        out.append(
            {
                "bin": [round(float(lo), 1), round(float(hi), 1)],
                "photos": int(m.sum()),
                "mean_probability": None if not m.any() else round(float(prob[m].mean()), 3),
                "direct_sun_share": None if not m.any() else round(float(truth[m].mean()), 3),
            }
        )
    return out


def main(argv=None) -> int:
    from sklearn.linear_model import LogisticRegression
    from sklearn.metrics import brier_score_loss, roc_auc_score
    from sklearn.model_selection import StratifiedKFold, cross_val_predict

    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--labels", type=Path, default=Path("studies/lighting/sun_benchmark/labels/labels.csv"))
    ap.add_argument("--estimates", type=Path, default=Path("studies/lighting/sun_evidence/result/estimates_cues.csv"))
    ap.add_argument("--model", type=Path, default=Path("checkpoints/sun_evidence.json"))
    ap.add_argument("--out", type=Path, default=Path("studies/lighting/sun_evidence/result"))
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument(
        "--extra-labels",
        type=Path,
        default=None,
        help="more labelled photos outside the benchmark (labels_extra.csv): added to the train half only",
    )
    a = ap.parse_args(argv)
    rows = list(csv.DictReader(open(a.labels)))
    n_bench = len(rows)
    extra = [] if a.extra_labels is None else list(csv.DictReader(open(a.extra_labels)))
    rows += extra
    root = data_root()
    t0 = time.perf_counter()
    for r in rows:
        img = cv2.cvtColor(cv2.imread(str(root / r["photo"])), cv2.COLOR_BGR2RGB)
        r.update({k: round(v, 5) for k, v in sun_evidence_features(img).items()})
    seconds_per_photo = (time.perf_counter() - t0) / len(rows)
    X = np.array([[float(r[k]) for k in FEATURES] for r in rows])
    y = np.array([int(r["direct_sun"]) for r in rows])
    train, test = split_halves(n_bench, a.seed)
    train = np.r_[train, np.arange(n_bench, len(rows))].astype(int)  # extra photos train, never score

    mean, scale = X[train].mean(axis=0), X[train].std(axis=0)
    Z = (X - mean) / scale
    oof = cross_val_predict(
        LogisticRegression(C=1.0),
        Z[train],
        y[train],
        cv=StratifiedKFold(6, shuffle=True, random_state=a.seed),
        method="predict_proba",
    )[:, 1]
    bench = train < n_bench  # the benchmark's own train half among the training rows
    candidates = np.unique(np.clip(oof, 0.02, 0.98))
    threshold = max(candidates, key=lambda t: (f_beta(*precision_recall(oof >= t, y[train] == 1), 0.5), -t))
    clf = LogisticRegression(C=1.0).fit(Z[train], y[train])
    model = SunEvidenceModel(
        FEATURES,
        tuple(float(v) for v in mean),
        tuple(float(v) for v in scale),
        tuple(float(v) for v in clf.coef_[0]),
        float(clf.intercept_[0]),
        float(threshold),
        {
            "command": "python -m studies.lighting.sun_evidence "
            + " ".join(argv if argv is not None else sys.argv[1:]),
            "labels": str(a.labels),
            "extra_labels": None if a.extra_labels is None else str(a.extra_labels),
            "train_photos": len(train),
            "split_seed": a.seed,
            "threshold": "max F0.5 on 6-fold out-of-fold probabilities of the train half",
        },
    )
    a.model.parent.mkdir(parents=True, exist_ok=True)
    a.model.write_text(json.dumps(model.to_dict(), indent=1) + "\n")

    prob = np.array([model.probability(dict(zip(FEATURES, x))) for x in X])
    truth = y == 1
    p_test, r_test = precision_recall(prob[test] >= threshold, truth[test])
    report = {
        "command": model.provenance["command"],
        "photos": n_bench,
        "extra_train_photos": len(rows) - n_bench,
        "train": len(train),
        "test": len(test),
        "seconds_per_photo": round(seconds_per_photo, 4),
        "coefficients": dict(zip(FEATURES, (round(v, 3) for v in model.coef))),
        "threshold": round(float(threshold), 3),
        "benchmark_train_half_out_of_fold": {
            "precision": round(precision_recall(oof[bench] >= threshold, y[train][bench] == 1)[0], 3),
            "recall": round(precision_recall(oof[bench] >= threshold, y[train][bench] == 1)[1], 3),
            "roc_auc": round(float(roc_auc_score(y[train][bench], oof[bench])), 3),
        },
        "train_out_of_fold": {
            "precision": round(precision_recall(oof >= threshold, y[train] == 1)[0], 3),
            "recall": round(precision_recall(oof >= threshold, y[train] == 1)[1], 3),
            "roc_auc": round(float(roc_auc_score(y[train], oof)), 3),
        },
        "test_evidence": {
            "precision": round(p_test, 3),
            "recall": round(r_test, 3),
            "roc_auc": round(float(roc_auc_score(y[test], prob[test])), 3),
            "brier": round(float(brier_score_loss(y[test], prob[test])), 3),
            "reliability": reliability(prob[test], truth[test]),
        },
    }
    if a.estimates.exists():  # the recorded image-cue decision on the same photos, for comparison
        est = {r["index"]: r for r in csv.DictReader(open(a.estimates))}
        for preset in ("fast", "balanced"):
            if f"{preset}_sun" not in next(iter(est.values())):
                continue
            old = np.array([int(est[r["index"]][f"{preset}_sun"]) for r in rows[:n_bench]], bool)
            conf = np.array([float(est[r["index"]][f"{preset}_confidence"]) for r in rows[:n_bench]])
            po, ro = precision_recall(old[test], truth[test])
            report[f"test_recorded_{preset}"] = {
                "precision": round(po, 3),
                "recall": round(ro, 3),
                "confidence_roc_auc": round(float(roc_auc_score(y[test], conf[test])), 3),
                "brier_of_confidence": round(float(brier_score_loss(y[test], conf[test])), 3),
            }
    a.out.mkdir(parents=True, exist_ok=True)
    for i, r in enumerate(rows):
        r["split"] = "extra" if i >= n_bench else "train" if i in set(train.tolist()) else "test"
        r["probability"] = round(float(prob[i]), 4)
    with open(a.out / "features.csv", "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    (a.out / "report.json").write_text(json.dumps(report, indent=1) + "\n")

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(9, 4))
    pts = [(b["mean_probability"], b["direct_sun_share"], b["photos"]) for b in report["test_evidence"]["reliability"]]
    pts = [p for p in pts if p[2]]
    axes[0].plot([p[0] for p in pts], [p[1] for p in pts], "o-", label="evidence model (test half)")
    for p in pts:
        axes[0].annotate(str(p[2]), (p[0], p[1]), textcoords="offset points", xytext=(4, -10), fontsize=8)
    axes[0].plot([0, 1], [0, 1], "k:", label="calibrated")
    axes[0].set_xlabel("predicted probability of direct sun (bin mean)")
    axes[0].set_ylabel("share labelled direct sun")
    axes[0].legend(fontsize=8)
    for lab, c in ((1, "tab:orange"), (0, "tab:blue")):
        m = y[test] == lab
        axes[1].scatter(
            X[test][m, 0], X[test][m, 1], c=c, label="direct sun" if lab else "no direct sun", s=18, alpha=0.8
        )
    axes[1].set_xlabel("sky_blue")
    axes[1].set_ylabel("shadow_blue")
    axes[1].legend(fontsize=8)
    axes[1].set_title("test half")
    fig.tight_layout()
    save_figure_jpeg(fig, a.out / "reliability.jpg", dpi=120)
    print(
        json.dumps(
            {k: v for k, v in report.items() if k != "test_evidence"}
            | {"test": {k: v for k, v in report["test_evidence"].items() if k != "reliability"}},
            indent=1,
        )
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())

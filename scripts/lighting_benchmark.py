"""The dominant-sun decision against labels made by eye (``results/lighting/benchmark/labels.csv``: 97 photos,
TraCon train, KITTI 06 colour, DGP; ``direct_sun`` 1 where the scene is lit by direct sunlight, from its cast
shadows, sunlit surfaces and sky; made from the sheets of ``scripts/lighting_label_sheets.py``).

Each photo is analysed as the pipeline does (``analyse_scene``, TraCon photos at <= 640 px like the study) with the
fast and the balanced preset. Reported: precision and recall of ``dominant_sun``, agreement of the two presets, the
reliability of the recorded confidence (label frequency per confidence bin, a diagram), and a confidence threshold
chosen on a seeded half of the photos (train) and scored on the other (test).

    python scripts/lighting_benchmark.py --out results/lighting/benchmark
"""

import argparse
import csv
import json
import sys
import time
from pathlib import Path

import cv2
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from aias_augment.analyse.analysis import analyse_scene  # noqa: E402
from aias_augment.core.config import data_root  # noqa: E402
from aias_augment.core.frame import Frame  # noqa: E402
from aias_augment.pipeline.config import load_preset  # noqa: E402

PRESETS = ("fast", "balanced")


def precision_recall(pred: np.ndarray, truth: np.ndarray) -> tuple[float, float]:
    tp = float(np.sum(pred & truth))
    return tp / max(float(pred.sum()), 1.0), tp / max(float(truth.sum()), 1.0)


def split_halves(n: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """The benchmark's seeded split of ``n`` photos: (train, test) sorted indices, the first half of a permutation
    training (what thresholds and models are chosen on) and the rest scored."""
    perm = np.random.default_rng(seed).permutation(n)
    return np.sort(perm[: n // 2]), np.sort(perm[n // 2 :])


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--labels", type=Path, default=Path("results/lighting/benchmark/labels.csv"))
    ap.add_argument("--out", type=Path, default=Path("results/lighting/benchmark"))
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument(
        "--sun-decision", choices=("evidence", "cues"), default="evidence", help="LightingConfig.sun_decision"
    )
    a = ap.parse_args(argv)
    rows = list(csv.DictReader(open(a.labels)))
    root = data_root()
    t0 = time.perf_counter()
    for r in rows:
        img = cv2.cvtColor(cv2.imread(str(root / r["photo"])), cv2.COLOR_BGR2RGB)
        if r["photo"].startswith("tracon"):
            s = min(1.0, 640 / max(img.shape[:2]))
            if s < 1:
                img = cv2.resize(img, None, fx=s, fy=s, interpolation=cv2.INTER_AREA)
        for preset in PRESETS:
            cfg = load_preset(preset, lighting_cfg={"sun_decision": a.sun_decision})
            est = analyse_scene(Frame(img, None), cfg).lighting
            r[f"{preset}_sun"] = int(est.dominant_sun)
            r[f"{preset}_confidence"] = round(float(est.confidence), 4)
            r[f"{preset}_source"] = est.source
        print(
            f"[{len(rows)}] {r['index']} {r['photo']} label {r['direct_sun']} "
            f"fast {r['fast_sun']} {r['fast_confidence']} balanced {r['balanced_sun']} {r['balanced_confidence']}",
            flush=True,
        )
    truth = np.array([int(r["direct_sun"]) for r in rows], bool)
    train, test = split_halves(len(rows), a.seed)
    report = {
        "command": "python scripts/lighting_benchmark.py " + " ".join(argv or sys.argv[1:]),
        "photos": len(rows),
        "direct_sun_labels": int(truth.sum()),
        "seconds": round(time.perf_counter() - t0),
    }
    for preset in PRESETS:
        sun = np.array([r[f"{preset}_sun"] for r in rows], bool)
        conf = np.array([r[f"{preset}_confidence"] for r in rows], float)
        p, rec = precision_recall(sun[test], truth[test])
        # the threshold: the decision kept only where the confidence reaches t, t chosen on train (max F1)
        best = max(
            (2 * pr * rc / max(pr + rc, 1e-9), t)
            for t in np.unique(np.r_[0.0, conf[train]])
            for pr, rc in [precision_recall(sun[train] & (conf[train] >= t), truth[train])]
        )
        pt, rt = precision_recall(sun[test] & (conf[test] >= best[1]), truth[test])
        bins = np.linspace(0, 1, 6)
        rel = []
        for lo, hi in zip(bins[:-1], bins[1:]):
            m = (conf >= lo) & ((conf < hi) | (hi == 1.0))
            rel.append(
                {
                    "bin": [round(lo, 1), round(hi, 1)],
                    "photos": int(m.sum()),
                    "direct_sun_share": None if not m.any() else round(float(truth[m].mean()), 3),
                }
            )
        report[preset] = {
            "test": {"precision": round(p, 3), "recall": round(rec, 3), "photos": len(test)},
            "threshold_from_train": round(float(best[1]), 4),
            "test_with_threshold": {"precision": round(pt, 3), "recall": round(rt, 3)},
            "all_photos": dict(zip(("precision", "recall"), (round(v, 3) for v in precision_recall(sun, truth)))),
            "reliability": rel,
        }
    agree = np.mean([r["fast_sun"] == r["balanced_sun"] for r in rows])
    report["fast_balanced_agreement"] = round(float(agree), 3)
    a.out.mkdir(parents=True, exist_ok=True)
    with open(a.out / "estimates.csv", "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    (a.out / "report.json").write_text(json.dumps(report, indent=1))
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(4.5, 4))
    for preset in PRESETS:
        pts = [(np.mean(b["bin"]), b["direct_sun_share"]) for b in report[preset]["reliability"] if b["photos"]]
        ax.plot(*zip(*pts), "o-", label=preset)
    ax.plot([0, 1], [0, 1], "k:", label="calibrated")
    ax.set_xlabel("recorded confidence (bin centre)")
    ax.set_ylabel("share of photos labelled direct sun")
    ax.legend()
    fig.tight_layout()
    fig.savefig(a.out / "reliability.png", dpi=120)
    print(json.dumps({k: v for k, v in report.items() if k in PRESETS or k == "fast_balanced_agreement"}, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())

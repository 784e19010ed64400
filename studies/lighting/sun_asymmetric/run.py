"""The sun decision under an asymmetric cost: a false sun (a hard black shadow under an overcast sky) costs far more
than a missed one, so the threshold on the evidence model's probability is chosen on a development part of the
labelled photos to maximise recall subject to precision >= ``--min-precision``, and scored once on a held-out part.

The labelled photos (by eye, from the numbered sheets of ``lighting_label_sheets.py``): the benchmark's 97
(``labels.csv``), its 64 extra TraCon photos (``labels_extra.csv``) and 64 more (``labels_more.csv``, with an
``uncertain`` column: photos whose label could not be told are kept in the files and left out of every score).

    python -m studies.lighting.sun_asymmetric split      # studies/lighting/sun_asymmetric/result/split.csv (seeded, before analysis)
    python -m studies.lighting.sun_asymmetric analyse    # estimates.csv: every photo through analyse_scene, both presets
    python -m studies.lighting.sun_asymmetric score      # report.json: threshold on dev, held-out scored once

Split: the photos the evidence model was fitted on (the benchmark's train half) are development photos; the others
are split in two by a seeded permutation (``--seed``). Analysis: each photo as the pipeline sees it (TraCon photos
at <= 640 px, like the study), fast and balanced, with ``sun_threshold`` near 0 so that every photo where a sun is
possible (outdoor, sun above the horizon) records the direction the preset would give it; the decision at any
threshold is then ``possible and probability >= threshold``, computed from the CSV
(``aias_augment.analyse.lighting.sun_evidence.decide_direct_sun``).
"""

import argparse
import csv
import json
import sys
import time
from pathlib import Path

import cv2
import numpy as np

from aias_augment.analyse.lighting.sun_evidence import (
    asymmetric_threshold,
    sun_evidence_features,
    wilson_interval,
)
from aias_augment.core.config import data_root
from studies.lighting.sun_benchmark.run import split_halves

BENCH = Path("studies/lighting/sun_benchmark/labels")  # the labels made by eye
OUT = Path("studies/lighting/sun_asymmetric/result")
PRESETS = ("fast", "balanced")
LABEL_FILES = (("benchmark", "labels.csv"), ("extra", "labels_extra.csv"), ("more", "labels_more.csv"))
FORCED_THRESHOLD = 1e-9  # every photo where a sun is possible gets one: its direction is recorded


def labelled_rows(bench: Path = BENCH) -> list[dict]:
    """Every labelled photo: set, index in its file, photo, direct_sun, uncertain (0 where the file has no column)."""
    rows = []
    for name, fname in LABEL_FILES:
        for r in csv.DictReader(open(bench / fname)):
            rows.append(
                {
                    "set": name,
                    "index": int(r["index"]),
                    "photo": r["photo"],
                    "direct_sun": int(r["direct_sun"]),
                    "uncertain": int(r.get("uncertain") or 0),
                }
            )
    return rows


def split_rows(rows: list[dict], seed: int) -> list[dict]:
    """``part`` per row: "dev" for the model's training photos (the benchmark's train half) and the first half of a
    seeded permutation of the rest, "heldout" for the other half."""
    n_bench = sum(r["set"] == "benchmark" for r in rows)
    fitted = {int(i) for i in split_halves(n_bench, 0)[0]}
    rest = [k for k, r in enumerate(rows) if not (r["set"] == "benchmark" and r["index"] in fitted)]
    perm = np.random.default_rng(seed).permutation(len(rest))
    dev = {rest[i] for i in perm[: len(rest) // 2]}
    return [{**r, "part": "dev" if (k in dev or k not in rest) else "heldout"} for k, r in enumerate(rows)]


def read_split(path: Path = OUT / "split.csv") -> list[dict]:
    rows = list(csv.DictReader(open(path)))
    for r in rows:
        for k in ("index", "direct_sun", "uncertain"):
            r[k] = int(r[k])
    return rows


def load_photo(photo: str) -> np.ndarray:
    img = cv2.cvtColor(cv2.imread(str(data_root() / photo)), cv2.COLOR_BGR2RGB)
    if photo.startswith("tracon"):
        s = min(1.0, 640 / max(img.shape[:2]))
        if s < 1:
            img = cv2.resize(img, None, fx=s, fy=s, interpolation=cv2.INTER_AREA)
    return img


def analyse(rows: list[dict]) -> list[dict]:
    """Per photo and preset: the evidence probability, whether a sun is possible, its direction in the camera."""
    from aias_augment.analyse.analysis import analyse_scene
    from aias_augment.core.frame import Frame
    from aias_augment.pipeline.config import load_preset

    cfgs = {p: load_preset(p, lighting_cfg={"sun_threshold": FORCED_THRESHOLD}) for p in PRESETS}
    out = []
    for k, r in enumerate(rows):
        img = load_photo(r["photo"])
        e = {**r, **{f: round(v, 5) for f, v in sun_evidence_features(img).items()}}
        for preset, cfg in cfgs.items():
            est = analyse_scene(Frame(img, None), cfg).lighting
            e[f"{preset}_probability"] = round(float(est.confidence), 5)
            e[f"{preset}_source"] = est.source
            e[f"{preset}_sun_possible"] = int(est.dominant_sun)
            d = est.sun_direction_in_cam if est.dominant_sun else np.full(3, np.nan)
            for axis, v in zip("xyz", d):
                e[f"{preset}_sun_{axis}"] = round(float(v), 5)
        out.append(e)
        print(f"[{k + 1}/{len(rows)}] {r['photo']} label {r['direct_sun']} p {e['balanced_probability']}", flush=True)
    return out


def read_estimates(path: Path = OUT / "estimates.csv") -> list[dict]:
    rows = list(csv.DictReader(open(path)))
    for r in rows:
        for k, v in r.items():
            if k.endswith(("_probability", "_sun_x", "_sun_y", "_sun_z")) or k in (
                "sky_blue",
                "shadow_blue",
                "clipped",
            ):
                r[k] = float(v)
            elif k in ("index", "direct_sun", "uncertain") or k.endswith("_sun_possible"):
                r[k] = int(v)
    return rows


def decisions(rows: list[dict], preset: str, threshold: float) -> np.ndarray:
    """The pipeline's decision at ``threshold``: a sun is possible and the probability reaches the threshold."""
    return np.array([bool(r[f"{preset}_sun_possible"]) and r[f"{preset}_probability"] >= threshold for r in rows])


def scores(pred: np.ndarray, truth: np.ndarray) -> dict:
    tp, n_pred, n_true = int(np.sum(pred & truth)), int(pred.sum()), int(truth.sum())
    return {
        "photos": int(len(truth)),
        "sunny": n_true,
        "decided_sun": n_pred,
        "true_suns": tp,
        "precision": round(tp / max(n_pred, 1), 3),
        "precision_95": [round(v, 3) for v in wilson_interval(tp, n_pred)],
        "recall": round(tp / max(n_true, 1), 3),
        "recall_95": [round(v, 3) for v in wilson_interval(tp, n_true)],
    }


def sun_angle_deg(r: dict) -> float:
    """Angle between the fast and the balanced sun directions of one photo (nan where either has none)."""
    a = np.array([r[f"fast_sun_{k}"] for k in "xyz"])
    b = np.array([r[f"balanced_sun_{k}"] for k in "xyz"])
    return float(np.degrees(np.arccos(np.clip(a @ b, -1.0, 1.0))))


def direction_agreement(rows: list[dict], max_deg: float = 30.0) -> dict:
    """Fast vs balanced sun direction on labelled sunny photos (certain labels): the share within ``max_deg``."""
    ang = np.array([sun_angle_deg(r) for r in rows if r["direct_sun"] and not r["uncertain"]])
    ok = np.isfinite(ang)
    within = int(np.sum(ang[ok] <= max_deg))
    return {
        "sunny_photos": int(len(ang)),
        "with_a_direction": int(ok.sum()),
        f"within_{max_deg:.0f}_deg": within,
        "share": round(within / max(int(ok.sum()), 1), 3),
        "share_95": [round(v, 3) for v in wilson_interval(within, int(ok.sum()))],
        "median_deg": round(float(np.median(ang[ok])), 1) if ok.any() else None,
    }


def score(rows: list[dict], min_precision: float, threshold: float | None = None) -> dict:
    """Threshold chosen on the dev part (unless given), both parts scored, the presets compared."""
    scored = [r for r in rows if not r["uncertain"]]
    dev = [r for r in scored if r["part"] == "dev"]
    held = [r for r in scored if r["part"] == "heldout"]
    p_dev = np.array([r["balanced_probability"] if r["balanced_sun_possible"] else 0.0 for r in dev])
    y_dev = np.array([r["direct_sun"] for r in dev], bool)
    t = asymmetric_threshold(p_dev, y_dev, min_precision) if threshold is None else threshold
    report = {
        "labelled": len(rows),
        "uncertain": len(rows) - len(scored),
        "min_precision_on_dev": min_precision,
        "threshold": round(t, 5),
    }
    for preset in PRESETS:
        report[preset] = {
            part: scores(decisions(sub, preset, t), np.array([r["direct_sun"] for r in sub], bool))
            for part, sub in (("dev", dev), ("heldout", held))
        }
    report["presets_decide_alike"] = int(np.sum(decisions(rows, "fast", t) == decisions(rows, "balanced", t)))
    report["direction_fast_vs_balanced"] = direction_agreement(rows)
    return report


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("step", choices=("split", "analyse", "score"))
    ap.add_argument("--out", type=Path, default=OUT)
    ap.add_argument("--seed", type=int, default=53)
    ap.add_argument("--estimates", type=Path, default=OUT / "estimates.csv", help="what score reads")
    ap.add_argument("--min-precision", type=float, default=0.90)
    ap.add_argument("--threshold", type=float, default=None, help="score this threshold instead of choosing one")
    a = ap.parse_args(argv)
    a.out.mkdir(parents=True, exist_ok=True)
    if a.step == "split":
        rows = split_rows(labelled_rows(), a.seed)
        with open(a.out / "split.csv", "w", newline="") as f:
            w = csv.DictWriter(f, fieldnames=list(rows[0]))
            w.writeheader()
            w.writerows(rows)
        n = {p: sum(r["part"] == p and not r["uncertain"] for r in rows) for p in ("dev", "heldout")}
        print(len(rows), "photos,", sum(r["uncertain"] for r in rows), "uncertain; scored", n)
    elif a.step == "analyse":
        t0 = time.perf_counter()
        rows = analyse(read_split(a.out / "split.csv"))
        with open(a.out / "estimates.csv", "w", newline="") as f:
            w = csv.DictWriter(f, fieldnames=list(rows[0]))
            w.writeheader()
            w.writerows(rows)
        print(f"{len(rows)} photos in {time.perf_counter() - t0:.0f} s")
    else:
        report = score(read_estimates(a.estimates), a.min_precision, a.threshold)
        report["command"] = "python -m studies.lighting.sun_asymmetric " + " ".join(argv or sys.argv[1:])
        (a.out / "report.json").write_text(json.dumps(report, indent=1))
        print(json.dumps(report, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())

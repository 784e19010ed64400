"""The dominant-sun decision against labels made by eye (``studies/lighting/sun_benchmark/labels/labels.csv``: 97 photos,
TraCon train, KITTI 06 colour, DGP; ``direct_sun`` 1 where the scene is lit by direct sunlight, from its cast
shadows, sunlit surfaces and sky; made from the sheets of ``studies/lighting/sun_benchmark/label_sheets.py``).

Each photo is analysed as the pipeline does (``analyse_scene``, TraCon photos at <= 640 px like the study) with the
fast and the balanced preset. Reported: precision and recall of ``dominant_sun``, agreement of the two presets, the
reliability of the recorded confidence (label frequency per confidence bin, a diagram), and a confidence threshold
chosen on a seeded half of the photos (train) and scored on the other (test).

Cast-shadow directions in the image (``shadow_directions.csv``): where a photo shows an occluder's shadow, a line
from the occluder's base along the shadow's axis, read by eye off a 0.05 grid (``lighting_label_sheets.py
--shadow-grids``); for the KITTI 06 colour frames the line follows from the sun's azimuth that the road's real shadow
bands give (``studies/lighting/kitti_cast_shadow/result/kitti_cast_shadow.json``, truth), drawn with the KITTI calibration 8 m ahead. The
pipeline's line starts at the same base pixel, lifted onto the analysis' ground and moved away from its sun: the
direction the shadow it draws takes in the image, for the sun the record holds; a photo whose record has no sun gets
no hard shadow and is counted as such.

    python -m studies.lighting.sun_benchmark --out studies/lighting/sun_benchmark/result
"""

import argparse
import csv
import json
import sys
import time
from pathlib import Path

import cv2
import numpy as np

from aias_augment.analyse.analysis import analyse_scene
from aias_augment.core.config import data_root
from aias_augment.core.frame import Frame
from aias_augment.core.geometry import project_points
from aias_augment.pipeline.config import load_preset
from studies._shared.pictures import save_figure_jpeg

PRESETS = ("fast", "balanced")


def precision_recall(pred: np.ndarray, truth: np.ndarray) -> tuple[float, float]:
    tp = float(np.sum(pred & truth))
    return tp / max(float(pred.sum()), 1.0), tp / max(float(truth.sum()), 1.0)


def split_halves(n: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """The benchmark's seeded split of ``n`` photos: (train, test) sorted indices, the first half of a permutation
    training (what thresholds and models are chosen on) and the rest scored."""
    perm = np.random.default_rng(seed).permutation(n)
    return np.sort(perm[: n // 2]), np.sort(perm[n // 2 :])


def shadow_image_angle(K: np.ndarray, normal: np.ndarray, d: float, sun_in_cam, base_uv) -> float | None:
    """Image angle (deg, atan2(dv, du)) of a cast shadow starting at pixel ``base_uv`` on the plane
    ``normal . p + d = 0``, for the sun direction ``sun_in_cam``: the base lifted onto the plane and moved away from the
    sun's horizontal part. None where the base is not on the plane in front of the camera or the sun is overhead."""
    ray = np.linalg.solve(K, np.array([base_uv[0], base_uv[1], 1.0]))
    den = float(normal @ ray)
    if abs(den) < 1e-9 or -d / den <= 0:
        return None
    x0 = ray * (-d / den)
    s = np.asarray(sun_in_cam, float)
    h = s - (s @ normal) * normal
    if np.linalg.norm(h) < 1e-6:
        return None
    x1 = x0 - h / np.linalg.norm(h) * 0.05 * np.linalg.norm(x0)
    uv, _ = project_points(np.stack([x0, x1]), K)
    if not np.all(np.isfinite(uv)):
        return None
    du, dv = uv[1] - uv[0]
    return float(np.degrees(np.arctan2(dv, du)))


def angle_error(a: float, b: float) -> float:
    return float(abs((a - b + 180.0) % 360.0 - 180.0))


def kitti_shadow_lines(truth_json: Path, photos: dict[str, str]) -> list[dict]:
    """Label rows for the KITTI 06 colour frames from the sun azimuths of their real shadow bands (camera ground
    frame, from forward, right positive): the shadow of a point 8 m ahead on the road, drawn with the KITTI
    calibration and camera height."""
    from studies.lighting.kitti_shadow_depth.run import KITTI_CAMERA_HEIGHT_M, KITTI_K

    fx, fy, cx, cy = KITTI_K
    K = np.array([[fx, 0, cx], [0, fy, cy], [0, 0, 1.0]])
    truth = json.loads(truth_json.read_text())["truth"]["per_colour_frame"]
    rows = []
    for frame, t in sorted(truth.items()):
        photo = f"kitti06_color_snippet/kitti06-{frame}-color.png"
        if photo not in photos:
            continue
        a = np.radians(t["azimuth_deg"])
        sun = np.array([np.sin(a), 0.0, np.cos(a)])  # horizontal; only its ground part matters
        h, w = cv2.imread(str(data_root() / photo)).shape[:2]
        x0 = np.array([0.0, KITTI_CAMERA_HEIGHT_M, 8.0])
        uv, _ = project_points(np.stack([x0, x0 - 1.5 * sun]), K)
        rows.append(
            {
                "index": photos[photo],
                "base_x": uv[0, 0] / w,
                "base_y": uv[0, 1] / h,
                "tip_x": uv[1, 0] / w,
                "tip_y": uv[1, 1] / h,
                "note": f"road shadow bands, sun azimuth {t['azimuth_deg']:.0f} deg (kitti_cast_shadow.json)",
            }
        )
    return rows


def shadow_direction_row(img: np.ndarray, analysis, line: dict, row: dict, preset: str) -> dict:
    """The labelled shadow line of one photo against the one the pipeline draws (None without a recorded sun)."""
    h, w = img.shape[:2]
    base = (float(line["base_x"]) * w, float(line["base_y"]) * h)
    dx = (float(line["tip_x"]) - float(line["base_x"])) * w
    dy = (float(line["tip_y"]) - float(line["base_y"])) * h
    truth = float(np.degrees(np.arctan2(dy, dx)))
    g, sun = analysis.ground, analysis.lighting.sun_direction_in_cam
    drawn = None if sun is None else shadow_image_angle(analysis.intrinsics.K, g.normal, g.d, sun, base)
    return {
        "index": row["index"],
        "photo": row["photo"],
        "preset": preset,
        "source": "kitti_shadow_bands" if "kitti_cast_shadow" in line["note"] else "eye",
        "truth_deg": round(truth, 1),
        "recorded_sun": int(analysis.lighting.dominant_sun),
        "confidence": round(float(analysis.lighting.confidence), 3),
        "drawn_deg": None if drawn is None else round(drawn, 1),
        "error_deg": None if drawn is None else round(angle_error(drawn, truth), 1),
        "base_uv": [round(base[0], 1), round(base[1], 1)],
    }


def direction_summary(rows: list[dict], key: str) -> dict:
    e = np.array([r[key] for r in rows if r[key] is not None], float)
    return {
        "photos": len(rows),
        "shadow_drawn": int(e.size),
        "median_deg": None if not e.size else round(float(np.median(e)), 1),
        "p90_deg": None if not e.size else round(float(np.percentile(e, 90)), 1),
        "within_35_deg": int(np.sum(e <= 35)),
    }


def direction_sheet(rows: list[dict], out: Path) -> None:
    """Each labelled photo (balanced preset) with the labelled shadow line (green) and the pipeline's (red: the
    recorded sun, none where the record has no sun)."""
    tiles = []
    for r in rows:
        img = cv2.imread(str(data_root() / r["photo"]))
        if r["photo"].startswith("tracon"):
            s = min(1.0, 640 / max(img.shape[:2]))
            img = cv2.resize(img, None, fx=s, fy=s, interpolation=cv2.INTER_AREA) if s < 1 else img
        L = 0.12 * max(img.shape[:2])
        b = np.array(r["base_uv"])
        for ang, col in ((r["truth_deg"], (0, 200, 0)), (r["drawn_deg"], (0, 0, 255))):
            if ang is None:
                continue
            tip = b + L * np.array([np.cos(np.radians(ang)), np.sin(np.radians(ang))])
            cv2.arrowedLine(img, tuple(int(v) for v in b), tuple(int(v) for v in tip), col, 3, tipLength=0.2)
        s = min(380 / img.shape[1], 300 / img.shape[0])
        img = cv2.resize(img, None, fx=s, fy=s, interpolation=cv2.INTER_AREA)
        tile = np.full((300, 380, 3), 255, np.uint8)
        tile[: img.shape[0], : img.shape[1]] = img
        label = f"{r['index']}: " + (f"error {r['error_deg']:.0f} deg" if r["recorded_sun"] else "no sun: no shadow")
        cv2.putText(tile, label, (6, 22), cv2.FONT_HERSHEY_SIMPLEX, 0.6, (0, 0, 0), 3)
        cv2.putText(tile, label, (6, 22), cv2.FONT_HERSHEY_SIMPLEX, 0.6, (255, 255, 255), 1)
        tiles.append(tile)
    if not tiles:
        return
    cols = 4
    tiles += [np.full_like(tiles[0], 255)] * (-len(tiles) % cols)
    sheet = np.vstack([np.hstack(tiles[i : i + cols]) for i in range(0, len(tiles), cols)])
    cv2.imwrite(str(out), sheet)


def worst_sheet(rows: list[dict], test: np.ndarray, out: Path, preset: str = "balanced", n: int = 10) -> list[dict]:
    """The ``n`` photos the sun decision gets most wrong (largest gap between the recorded confidence and the
    label), each titled with its index, half, label, confidence and the decision; returns those rows."""
    from aias_augment.core.viz import contact_sheet

    in_test = np.zeros(len(rows), bool)
    in_test[test] = True
    gap = [abs(float(r[f"{preset}_confidence"]) - int(r["direct_sun"])) for r in rows]
    worst = [int(i) for i in np.argsort(gap, kind="stable")[::-1][:n]]
    images, titles, picked = [], [], []
    for i in worst:
        r = rows[i]
        img = cv2.cvtColor(cv2.imread(str(data_root() / r["photo"])), cv2.COLOR_BGR2RGB)
        s = 480 / img.shape[1]
        images.append(cv2.resize(img, None, fx=s, fy=s, interpolation=cv2.INTER_AREA))
        label = "sun" if int(r["direct_sun"]) else "none"
        decided = "sun" if int(r[f"{preset}_sun"]) else "none"
        half = "test" if in_test[i] else "train"
        titles.append(f"{r['index']} {half}: label {label}, p {float(r[f'{preset}_confidence']):.2f}: {decided}")
        picked.append({"index": r["index"], "photo": r["photo"], "half": half, "confidence_gap": round(gap[i], 3)})
    cv2.imwrite(str(out), cv2.cvtColor(contact_sheet(images, cols=4, cell_width=400, titles=titles), cv2.COLOR_RGB2BGR))
    return picked


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--labels", type=Path, default=Path("studies/lighting/sun_benchmark/labels/labels.csv"))
    ap.add_argument("--out", type=Path, default=Path("studies/lighting/sun_benchmark/result"))
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument(
        "--shadow-labels", type=Path, default=Path("studies/lighting/sun_benchmark/labels/shadow_directions.csv")
    )
    ap.add_argument(
        "--kitti-truth", type=Path, default=Path("studies/lighting/kitti_cast_shadow/result/kitti_cast_shadow.json")
    )
    ap.add_argument(
        "--sun-decision", choices=("evidence", "cues"), default="evidence", help="LightingConfig.sun_decision"
    )
    a = ap.parse_args(argv)
    rows = list(csv.DictReader(open(a.labels)))
    root = data_root()
    lines = {
        r["index"]: r for r in csv.DictReader(open(a.shadow_labels)) if r["base_x"]
    }  # photos whose shadow axis was readable
    lines.update({r["index"]: r for r in kitti_shadow_lines(a.kitti_truth, {r["photo"]: r["index"] for r in rows})})
    directions = []
    t0 = time.perf_counter()
    for r in rows:
        img = cv2.cvtColor(cv2.imread(str(root / r["photo"])), cv2.COLOR_BGR2RGB)
        if r["photo"].startswith("tracon"):
            s = min(1.0, 640 / max(img.shape[:2]))
            if s < 1:
                img = cv2.resize(img, None, fx=s, fy=s, interpolation=cv2.INTER_AREA)
        for preset in PRESETS:
            cfg = load_preset(preset, lighting_cfg={"sun_decision": a.sun_decision})
            analysis = analyse_scene(Frame(img, None), cfg)
            est = analysis.lighting
            r[f"{preset}_sun"] = int(est.dominant_sun)
            if r["index"] in lines:
                directions.append(shadow_direction_row(img, analysis, lines[r["index"]], r, preset))
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
        "command": "python -m studies.lighting.sun_benchmark " + " ".join(argv or sys.argv[1:]),
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
    report["shadow_direction"] = {
        preset: direction_summary([d for d in directions if d["preset"] == preset], "error_deg") for preset in PRESETS
    }
    agree = np.mean([r["fast_sun"] == r["balanced_sun"] for r in rows])
    report["fast_balanced_agreement"] = round(float(agree), 3)
    a.out.mkdir(parents=True, exist_ok=True)
    with open(a.out / "estimates.csv", "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    (a.out / "report.json").write_text(json.dumps(report, indent=1))
    (a.out / "shadow_direction_rows.json").write_text(json.dumps(directions, indent=1))
    direction_sheet([d for d in directions if d["preset"] == "balanced"], a.out / "shadow_directions.jpg")
    report["worst_ten"] = worst_sheet(rows, test, a.out / "worst_ten.jpg")
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
    save_figure_jpeg(fig, a.out / "reliability.jpg", dpi=120)
    print(
        json.dumps(
            {k: v for k, v in report.items() if k in PRESETS or k in ("fast_balanced_agreement", "shadow_direction")},
            indent=1,
        )
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())

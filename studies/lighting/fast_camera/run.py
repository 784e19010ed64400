"""Fast preset's analysis copies vs balanced: sun direction and camera roll on the labelled sunny photos.

For every certain sunny photo of ``studies/lighting/sun_asymmetric/result/estimates.csv`` (loaded as that study loads it), the
fast preset is run with each variant of ``--widths`` (``analysis_max_width,camera_analysis_width,min_input_width``)
with the sun threshold near 0 (every possible sun gives its direction); its sun direction is compared with the
balanced direction recorded there, its roll with balanced's roll (the camera estimate on the whole photo, as balanced
runs it), on all photos and on each half (sorted by name: even places "dev", odd "heldout"; ``--half`` runs one).
Then the time of ``analyse_scene`` and of a whole ``insert_into_image`` call on 640x480 roads, the variants
interleaved in one process (``--repeats 0``: none).

    taskset -c 1 nice .venv/bin/python -m studies.lighting.fast_camera --widths 160,640,320 160,640,640 --repeats 3
"""

import argparse
import json
import sys
import time
from pathlib import Path

import cv2
import numpy as np

from aias_augment.analyse.analysis import ANALYSIS_SEED, analyse_scene, scene_geometry
from aias_augment.core.frame import Frame
from aias_augment.pipeline.config import load_preset
from studies.lighting.sun_asymmetric.run import FORCED_THRESHOLD, OUT, load_photo, read_estimates


def roll_deg(ground) -> float:
    return float(np.degrees(ground.pitch_roll_rad()[1])) if ground is not None else float("nan")


def variant(spec: str, **lighting):
    """The fast preset with ``analysis_max_width,camera_analysis_width,min_input_width`` (e.g. ``160,640,320``)."""
    amw, cam, light = (int(v) for v in spec.split(","))
    lighting["min_input_width"] = light
    return load_preset("fast", analysis_max_width=amw, camera_analysis_width=cam, lighting_cfg=lighting)


def angle_deg(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.degrees(np.arccos(np.clip(a @ b, -1.0, 1.0))))


def sunny_rows() -> list[dict]:
    """The labelled photos with direct sun (the uncertain ones left out), as ``../sun_asymmetric``'s estimates list
    them with each preset's direction."""
    return [r for r in read_estimates(OUT / "estimates.csv") if r["direct_sun"] and not r["uncertain"]]


def halves(rows: list[dict]) -> dict[str, list[dict]]:
    """The photos sorted by name and split by the parity of their place: "dev" (even) chooses a variant,
    "heldout" (odd) only reports the chosen one (and the default) once."""
    ordered = sorted(rows, key=lambda r: r["photo"])
    return {"dev": ordered[0::2], "heldout": ordered[1::2]}


def summary(ang: np.ndarray, droll: np.ndarray) -> dict:
    a, d = np.asarray(ang, float), np.asarray(droll, float)
    ok = np.isfinite(a)
    return {
        "sunny_photos": len(a),
        "with_a_direction": int(ok.sum()),
        "within_30_deg": int(np.sum(a[ok] <= 30)),
        "share": round(float(np.mean(a[ok] <= 30)), 3),
        "median_deg": round(float(np.median(a[ok])), 1),
        "roll_diff_median_deg": round(float(np.nanmedian(d)), 2),
        "roll_diff_p90_deg": round(float(np.nanpercentile(d, 90)), 2),
        "roll_diff_max_deg": round(float(np.nanmax(d)), 2),
        "roll_within_2_deg": int(np.sum(d <= 2)),
    }


def measure(rows: list[dict], widths: list[str], part: dict[str, str]) -> dict:
    """Per variant: the agreement on ``rows``, on each of their halves (``part``: photo -> "dev" | "heldout"), per photo."""
    cfgs = {w: variant(w, sun_threshold=FORCED_THRESHOLD) for w in widths}
    bal = load_preset("balanced")
    ang = {w: [] for w in widths}
    droll = {w: [] for w in widths}
    for k, r in enumerate(rows):
        img = load_photo(r["photo"])
        _, g_bal = scene_geometry(img, None, None, np.random.default_rng(ANALYSIS_SEED), bal, {}, need_ground=True)
        b_sun = np.array([r[f"balanced_sun_{a}"] for a in "xyz"])
        for w, cfg in cfgs.items():
            a = analyse_scene(Frame(img, None), cfg)
            f_sun = a.lighting.sun_direction_in_cam if a.lighting.dominant_sun else np.full(3, np.nan)
            ang[w].append(angle_deg(np.asarray(f_sun, float), b_sun))
            droll[w].append(abs(roll_deg(a.ground) - roll_deg(g_bal)))
        print(
            f"[{k + 1}/{len(rows)}] {r['photo']} "
            + " ".join(f"{w}:{ang[w][-1]:.1f}/{droll[w][-1]:.1f}" for w in widths),
            flush=True,
        )
    out = {}
    for w in widths:
        a, d = np.array(ang[w]), np.array(droll[w])
        out[w] = summary(a, d) | {
            p: summary(a[sel], d[sel])
            for p in ("dev", "heldout")
            if (sel := np.array([part[r["photo"]] == p for r in rows])).any()
        }
        out[w]["per_photo"] = {r["photo"]: [round(x, 2), round(y, 2)] for r, x, y in zip(rows, a, d)}
    return out


def timing(images: list[np.ndarray], widths: list[str], repeats: int) -> dict:
    """Per variant, interleaved (image by image, variant by variant, ``repeats`` rounds): ``analyse_scene`` alone and a
    whole first-sight ``insert_into_image`` call (no scene cache: every call analyses the photo; one warm-up call per
    variant and image first, for the asset and view caches). Wall and CPU ms (``time.process_time``); medians over
    every image and round."""
    from aias_augment.pipeline.image import insert_into_image

    cfgs = {w: variant(w) for w in widths}
    for img in images:
        for cfg in cfgs.values():
            insert_into_image(img, rng=np.random.default_rng(0), cfg=cfg)
    keys = ("analysis", "first_sight", "analysis_cpu", "first_sight_cpu")
    t = {w: {k: [] for k in keys} for w in widths}
    for _ in range(repeats):
        for img in images:
            for w, cfg in cfgs.items():  # interleaved: drift in the machine's load touches every variant alike
                t0, c0 = time.perf_counter(), time.process_time()
                analyse_scene(Frame(img, None), cfg)
                t1, c1 = time.perf_counter(), time.process_time()
                insert_into_image(img, rng=np.random.default_rng(0), cfg=cfg)
                t[w]["analysis"].append(1000 * (t1 - t0))
                t[w]["analysis_cpu"].append(1000 * (c1 - c0))
                t[w]["first_sight"].append(1000 * (time.perf_counter() - t1))
                t[w]["first_sight_cpu"].append(1000 * (time.process_time() - c1))
    return {w: {f"{k}_median_ms": round(float(np.median(v)), 1) for k, v in d.items()} for w, d in t.items()}


def timing_images(n: int) -> list[np.ndarray]:
    """The 640x480 TraCon roads of the first-sight benchmark (``benchmarks.bench_first_sight``): the ``n`` after its
    warm-up rotation."""
    from benchmarks.bench_regression_guard import ROTATION, tracon_files

    return [
        cv2.resize(cv2.cvtColor(cv2.imread(str(f)), cv2.COLOR_BGR2RGB), (640, 480), interpolation=cv2.INTER_AREA)
        for f in tracon_files(ROTATION + n)[ROTATION:]
    ]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument(
        "--widths",
        nargs="+",
        default=["160,0,320", "160,640,320", "640,0,320"],
        help="analysis_max_width,camera_analysis_width,lighting min_input_width",
    )
    ap.add_argument("--repeats", type=int, default=7, help="timing runs per variant (0: no timing)")
    ap.add_argument("--timing-images", type=int, default=12, help="640x480 roads timed")
    ap.add_argument("--timing-only", action="store_true", help="the timing alone (the agreement left out)")
    ap.add_argument("--limit", type=int, default=0, help="first N sunny photos only (0: all)")
    ap.add_argument(
        "--half",
        choices=("all", "dev", "heldout"),
        default="all",
        help="the photos by sorted name: even places (dev, to choose a variant), odd (heldout), or all",
    )
    ap.add_argument("--out", type=Path, default=Path("studies/lighting/fast_camera/result/report.json"))
    a = ap.parse_args(argv)
    rows = sunny_rows()
    split = halves(rows)
    part = {r["photo"]: p for p, rs in split.items() for r in rs}
    rows = rows if a.half == "all" else split[a.half]
    rows = rows[: a.limit] if a.limit else rows
    report = {"timing_640x480": None, "agreement": measure(rows, a.widths, part) if not a.timing_only else None}
    if a.repeats:
        report["timing_images"] = f"{a.timing_images} TraCon training roads at 640x480 (benchmarks.bench_first_sight's)"
        report["timing_640x480"] = timing(timing_images(a.timing_images), a.widths, a.repeats)
    a.out.parent.mkdir(parents=True, exist_ok=True)
    a.out.write_text(json.dumps(report, indent=1))
    print(json.dumps(report, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())

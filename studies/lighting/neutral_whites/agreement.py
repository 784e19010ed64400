#!/usr/bin/env python
"""How closely can an inserted white match a photo's own whites, when the photo's whites disagree among themselves?

On TraCon train photos with labelled cones, the colour (R/G, B/G) of white cone sleeves is measured from the labels
(``eval_neutral_whites.real_white_rgb``, optionally eroded away from the orange) and compared three ways:

- **real vs real** (the floor): one labelled cone against the median of the photo's other cones, in photos with at
  least two measurable cones. No inserted object can agree with "the real whites" more often than they agree with
  each other under the same measurement.
- **light estimate vs real**: the light's colour the pipeline takes from the photo's grey surfaces
  (``achromatic_light_colour``) against the median real sleeve.
- **inserted vs real**: white parts of cones inserted with the preset's defaults (harmonized), raw and divided by
  the rendered albedo's own colour (the procedural paint is an off-white, 0.96/0.96/0.95 sRGB, and silver bands are
  bluish: what a neutral object would show).

Photos are split by a hash of their name into a choice half and a report half; the measurement's erosion is chosen
on the choice half (the setting under which real cones agree most often, the selection not pulled toward grey), the
report half is reported once.

    python -m studies.lighting.neutral_whites.agreement --photos 240 --out studies/lighting/neutral_whites/result
"""

from __future__ import annotations

import argparse
import json
import time
import zlib
from dataclasses import replace
from pathlib import Path

import cv2
import numpy as np

from aias_augment.analyse.analysis import analyse_scene
from aias_augment.analyse.lighting.estimate import achromatic_light_colour
from aias_augment.apply.render import render_object, srgb_to_linear
from aias_augment.apply.stages import apply_plan
from aias_augment.core.frame import Frame
from aias_augment.pipeline.config import load_preset
from aias_augment.plan.insertion import plan_insertion
from studies._shared.cone_whites import chroma, labelled_cone_photos

BAND = (0.94, 1.06)
ERODE = (0, 1, 2)  # the measurement settings compared on the choice half


def sleeve_rgb(img: np.ndarray, box: np.ndarray, erode: int) -> np.ndarray | None:
    """Median linear RGB of one labelled cone's white sleeve: HSV S < 0.25, V in [0.55, 0.97] in the middle half of
    the box's width and its upper 85 %, the mask eroded ``erode`` times (3 x 3) away from the orange."""
    x0, y0, x1, y1 = np.asarray(box).astype(int)
    w, h = x1 - x0, y1 - y0
    if w < 6 or h < 12:
        return None
    hsv = cv2.cvtColor(img, cv2.COLOR_RGB2HSV).astype(np.float32)
    sl = (slice(max(y0, 0), max(y0 + int(0.85 * h), 0)), slice(max(x0 + w // 4, 0), max(x1 - w // 4, 0)))
    s, v = hsv[sl][..., 1] / 255.0, hsv[sl][..., 2] / 255.0
    m = ((s < 0.25) & (v > 0.55) & (v < 0.97)).astype(np.uint8)
    if erode:
        m = cv2.erode(m, np.ones((3, 3), np.uint8), iterations=erode)
    px = img[sl][m.astype(bool)]
    if len(px) < 20:
        return None
    return np.median(srgb_to_linear(px.astype(np.float32) / 255.0), axis=0)


def inserted_white_and_albedo(out: np.ndarray, plan, analysis) -> tuple[np.ndarray, np.ndarray] | None:
    """Mean linear RGB of the inserted objects' white parts (albedo bright and unsaturated, eroded, unclipped) and
    the mean rendered albedo over the same pixels."""
    wh = np.zeros(out.shape[:2], bool)
    albedo = np.zeros(out.shape[:2] + (3,), np.float64)
    for obj in plan.objects:
        L = render_object(obj.asset, obj.placement.cam_from_object_matrix, analysis.intrinsics, ssaa=1)
        a = L.albedo_linear
        w = (L.alpha > 0.99) & (a.min(-1) > 0.5) & ((a.max(-1) - a.min(-1)) / np.maximum(a.max(-1), 1e-6) < 0.15)
        w = cv2.erode(w.astype(np.uint8), np.ones((3, 3), np.uint8)).astype(bool)
        albedo[w] = a[w]
        wh |= w
    wh &= out.max(-1) < 250
    if wh.sum() < 10:
        return None
    return srgb_to_linear(out[wh].astype(np.float32) / 255.0).mean(0), albedo[wh].mean(0)


def half(stem: str) -> str:
    return "choice" if zlib.crc32(stem.encode()) % 2 == 0 else "report"


def measure(a) -> list[dict]:
    cfg = load_preset(a.preset)
    if a.max_sun_sky_chroma is not None:
        cfg = replace(cfg, lighting_cfg=replace(cfg.lighting_cfg, max_sun_sky_chroma=a.max_sun_sky_chroma))
    rows, t0 = [], time.perf_counter()
    for stem, img, boxes in labelled_cone_photos(a.seed):
        if len(rows) >= a.photos:
            break
        row = {"photo": stem, "half": half(stem)}
        if a.half not in ("both", row["half"]):
            continue
        lin = srgb_to_linear(img.astype(np.float32) / 255.0)
        est = achromatic_light_colour(lin)
        for e in ERODE:
            cones = [c for c in (sleeve_rgb(img, b, e) for b in boxes) if c is not None][:6]
            if not cones:
                continue
            ref = np.median(np.array(cones), axis=0)
            row[f"ref_e{e}"] = chroma(ref).tolist()
            if len(cones) >= 2:
                row[f"floor_e{e}"] = (chroma(cones[0]) / chroma(np.median(np.array(cones[1:]), axis=0))).tolist()
            if est is not None:
                row[f"estimate_e{e}"] = (chroma(est) / chroma(ref)).tolist()
        if "ref_e0" not in row:
            continue
        frame = Frame(img, None)
        an = analyse_scene(frame, cfg)
        if an.region is not None:
            plan = plan_insertion(
                an, cfg, np.random.default_rng([a.seed, len(rows)]), n_objects=3, existing_boxes_xyxy=boxes
            )
            if plan.objects:
                got = inserted_white_and_albedo(apply_plan(frame, an, plan, cfg).image, plan, an)
                if got is not None:
                    row["inserted"] = chroma(got[0]).tolist()
                    row["albedo"] = chroma(got[1]).tolist()
        rows.append(row)
        print(f"[{len(rows)}/{a.photos} {time.perf_counter() - t0:.0f}s] {stem}", flush=True)
    return rows


def ratios(rows: list[dict], what: str, e: int) -> np.ndarray:
    """(n, 2) ratios to the real sleeves (measured with erosion ``e``) of ``what``."""
    out = []
    for r in rows:
        if what in ("floor", "estimate"):
            v = r.get(f"{what}_e{e}")
        elif "inserted" in r and f"ref_e{e}" in r:
            c = np.array(r["inserted"]) / (np.array(r["albedo"]) if what == "inserted_neutral" else 1.0)
            v = (c / np.array(r[f"ref_e{e}"])).tolist()
        else:
            v = None
        if v is not None:
            out.append(v)
    return np.array(out).reshape(-1, 2)


def within(v: np.ndarray) -> float:
    return float(np.mean(np.all((v >= BAND[0]) & (v <= BAND[1]), axis=1))) if len(v) else float("nan")


def interval(v: np.ndarray, rng: np.random.Generator) -> tuple[float, float]:
    ok = np.all((v >= BAND[0]) & (v <= BAND[1]), axis=1).astype(float)
    bs = [ok[rng.integers(0, len(ok), len(ok))].mean() for _ in range(4000)]
    return tuple(float(x) for x in np.percentile(bs, [2.5, 97.5]))


def report(rows: list[dict], a) -> int:
    out = Path(a.out)
    choice = [r for r in rows if r["half"] == "choice"]
    test = [r for r in rows if r["half"] == "report"]
    # the measurement setting: the erosion under which real cones agree most often on the choice half
    floors = {e: within(ratios(choice, "floor", e)) for e in ERODE}
    e_star = max(ERODE, key=lambda e: floors[e])
    rng = np.random.default_rng(0)
    what = {
        "floor": "real vs real (one cone vs the others' median)",
        "estimate": "light estimate (grey surfaces) vs real",
        "inserted": "inserted whites vs real",
        "inserted_neutral": "inserted whites / their albedo's colour vs real",
    }
    summary = {"erode_chosen": e_star, "floor_within_choice_half": floors}
    lines = [
        "# Inserted whites against a photo's own whites, and how much those agree among themselves\n",
        f"`python -m studies.lighting.neutral_whites.agreement --photos {a.photos} --seed {a.seed} --preset {a.preset} --out "
        f"{a.out}"
        + (f" --half {a.half}" if a.half != "both" else "")
        + (f" --max-sun-sky-chroma {a.max_sun_sky_chroma}" if a.max_sun_sky_chroma is not None else "")
        + f"`: {len(rows)} TraCon train photos with labelled cones (val not looked at), split by a hash of the "
        f"name into a choice half ({len(choice)}) and a report half ({len(test)}). Ratios (R/G, B/G) against the "
        f"median white sleeve of the photo's labelled cones; 'within' = both in {BAND[0]}-{BAND[1]}, with a 95 % "
        f"photo-bootstrap interval. Inserted cones: the {a.preset} preset's defaults, harmonized.\n",
        f"Measurement chosen on the choice half: the sleeve mask eroded {e_star}x (real-vs-real within: "
        + ", ".join(f"erosion {e} {100 * floors[e]:.0f} %" for e in ERODE)
        + ").\n",
        "| half | comparison | photos | within 0.94-1.06 [95 %] | median R/G | median B/G | median deviation |",
        "|---|---|---|---|---|---|---|",
    ]
    for name, part in (("report", test), ("choice", choice)):
        for key, label in what.items():
            v = ratios(part, key, e_star)
            if not len(v):
                continue
            lo, hi = interval(v, rng)
            dev = float(np.median(np.abs(np.log(v)).max(axis=1)))
            summary[f"{name}/{key}"] = {"n": len(v), "within": within(v), "ci95": [lo, hi], "median_deviation": dev}
            lines.append(
                f"| {name} | {label} | {len(v)} | {100 * within(v):.0f} % [{100 * lo:.0f}, {100 * hi:.0f}] | "
                f"{np.median(v[:, 0]):.3f} | {np.median(v[:, 1]):.3f} | {dev:.3f} |"
            )
    (out / "agreement.json").write_text(json.dumps(summary, indent=1))
    (out / "agreement.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))
    return 0


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--photos", type=int, default=240)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--preset", default="balanced")
    ap.add_argument("--out", default="studies/lighting/neutral_whites/result")
    ap.add_argument("--half", choices=("both", "choice", "report"), default="both", help="measure one half only")
    ap.add_argument("--max-sun-sky-chroma", type=float, default=None, help="LightingConfig override (a choice)")
    ap.add_argument("--from-rows", action="store_true", help="only summarize OUT/agreement_rows.json again")
    a = ap.parse_args(argv)
    out = Path(a.out)
    if a.from_rows:
        return report(json.loads((out / "agreement_rows.json").read_text()), a)
    rows = measure(a)
    out.mkdir(parents=True, exist_ok=True)
    (out / "agreement_rows.json").write_text(json.dumps(rows))
    return report(rows, a)


if __name__ == "__main__":
    raise SystemExit(main())

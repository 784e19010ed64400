#!/usr/bin/env python
"""Contact shadows of inserted objects against the real ones beside them.

TraCon train photos that hold labelled cones (the seeded draw of ``eval_neutral_whites.py``); 1-3 cones inserted
with a preset's defaults (the real boxes passed as existing boxes) and the contact-shadow strength swept. For every
base (a real cone's box, an inserted cone's visible box), fully inside the photo and at least 30 px tall: the
darkening next to it, the median luminance of a band just below its bottom (0-8 % of its height below, its width
plus 15 % each side) over that of a band farther down (25-45 % below), other objects' boxes left out of both. The
same ratio at an inserted cone's place in the photo before insertion is the scene's own gradient there (no object).

Choosing: the strength whose inserted ratios' median matches the real cones' median is chosen on a seeded half of
the photos (train) and reported on the other half (test), once.

    python -m studies.lighting.contact_shadows --photos 60 --out studies/lighting/contact_shadows/result
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
import time
from pathlib import Path

import cv2
import numpy as np

from aias_augment.analyse.analysis import analyse_scene
from aias_augment.apply.stages import apply_plan
from aias_augment.core.frame import Frame
from aias_augment.pipeline.config import load_preset
from aias_augment.plan.insertion import plan_insertion
from studies._shared.cone_whites import labelled_cone_photos

NEAR, FAR, SIDE = (0.0, 0.08), (0.25, 0.45), 0.15
STRENGTHS = (0.0, 0.15, 0.3, 0.45, 0.6)


def luminance(img: np.ndarray) -> np.ndarray:
    return cv2.cvtColor(img, cv2.COLOR_RGB2GRAY).astype(np.float32)


def band_ratio(lum: np.ndarray, box, others: np.ndarray) -> float | None:
    """Near-band median over far-band median below ``box`` (xyxy), ``others`` (H, W) bool left out; None where a
    band leaves the photo or has under 20 pixels."""
    H, W = lum.shape
    x0, y0, x1, y1 = box
    w, h = x1 - x0, y1 - y0
    if h < 30 or y0 < 0 or x0 < 0 or x1 > W:
        return None
    c0, c1 = int(round(x0 - SIDE * w)), int(round(x1 + SIDE * w))
    if c0 < 0 or c1 > W:
        return None
    vals = []
    for lo, hi in (NEAR, FAR):
        r0, r1 = int(round(y1 + lo * h)), int(round(y1 + hi * h))
        if r1 > H or r1 <= r0:
            return None
        m = ~others[r0:r1, c0:c1]
        if m.sum() < 20:
            return None
        vals.append(float(np.median(lum[r0:r1, c0:c1][m])))
    return vals[0] / max(vals[1], 1.0)


def boxes_mask(shape, boxes) -> np.ndarray:
    m = np.zeros(shape, bool)
    for x0, y0, x1, y1 in np.round(np.asarray(boxes, float)).astype(int).reshape(-1, 4):
        m[max(y0, 0) : max(y1, 0), max(x0, 0) : max(x1, 0)] = True
    return m


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--photos", type=int, default=60)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--preset", default="fast")
    ap.add_argument("--out", type=Path, default=Path("studies/lighting/contact_shadows/result"))
    a = ap.parse_args(argv)
    base = load_preset(a.preset)
    rows, t0 = [], time.perf_counter()
    for stem, img, boxes in labelled_cone_photos(a.seed):
        if len(rows) >= a.photos:
            break
        H, W = img.shape[:2]
        lum = luminance(img)
        real = []
        for k, b in enumerate(boxes):
            r = band_ratio(lum, b, boxes_mask((H, W), np.delete(boxes, k, axis=0)))
            if r is not None:
                real.append(r)
        frame = Frame(img, None)
        an = analyse_scene(frame, base)
        if an.region is None:
            continue
        plan = plan_insertion(
            an, base, np.random.default_rng([a.seed, len(rows)]), n_objects=3, existing_boxes_xyxy=boxes
        )
        if not plan.objects:
            continue
        row = {"photo": stem, "real": real, "sun": bool(an.lighting.dominant_sun), "inserted": {}, "before": []}
        for s in STRENGTHS:
            cfg = dataclasses.replace(base, contact_shadow_strength=s)
            res = apply_plan(frame, an, plan, cfg)
            ins = [x.visible_box_xywh for x in res.annotations if not x.decoy and x.visible_box_xywh is not None]
            ins = [(x, y, x + w, y + h) for x, y, w, h in ins]
            everything = np.r_[np.asarray(boxes).reshape(-1, 4), np.asarray(ins, float).reshape(-1, 4)]
            vals, before = [], []
            out_lum = luminance(res.image)
            for k, b in enumerate(ins):
                others = boxes_mask((H, W), np.delete(everything, len(boxes) + k, axis=0))
                r = band_ratio(out_lum, b, others)
                if r is not None:
                    vals.append(r)
                    before.append(band_ratio(lum, b, others))
            row["inserted"][str(s)] = vals
            if s == STRENGTHS[0]:
                row["before"] = before
        rows.append(row)
        print(
            f"[{len(rows)}/{a.photos} {time.perf_counter() - t0:.0f}s] {stem}: real {np.round(real, 3).tolist()} "
            f"inserted@0.6 {np.round(row['inserted']['0.6'], 3).tolist()}",
            flush=True,
        )
    a.out.mkdir(parents=True, exist_ok=True)
    (a.out / "rows.json").write_text(json.dumps(rows, indent=1))
    perm = np.random.default_rng(a.seed).permutation(len(rows))
    halves = {
        "train": [rows[i] for i in np.sort(perm[: len(rows) // 2])],
        "test": [rows[i] for i in np.sort(perm[len(rows) // 2 :])],
    }

    def pooled(rs, key, s=None):
        return np.array([v for r in rs for v in (r[key] if s is None else r[key][str(s)])], float)

    summary = {
        "command": "python -m studies.lighting.contact_shadows " + " ".join(argv or sys.argv[1:]),
        "photos": len(rows),
        "preset": a.preset,
    }
    for name, rs in halves.items():
        summary[name] = {
            "photos": len(rs),
            "real_bases": int(pooled(rs, "real").size),
            "real_median": float(np.median(pooled(rs, "real"))),
            "before_median": float(np.median([v for r in rs for v in r["before"] if v is not None])),
            "inserted_median": {str(s): float(np.median(pooled(rs, "inserted", s))) for s in STRENGTHS},
            "inserted_bases": int(pooled(rs, "inserted", STRENGTHS[0]).size),
        }
    train = summary["train"]
    chosen = min(STRENGTHS, key=lambda s: abs(np.log(train["inserted_median"][str(s)] / train["real_median"])))
    summary["chosen_strength_on_train"] = chosen
    test = summary["test"]
    summary["test_at_chosen"] = {
        "real_median": test["real_median"],
        "inserted_median": test["inserted_median"][str(chosen)],
    }
    summary["seconds"] = round(time.perf_counter() - t0)
    (a.out / "summary.json").write_text(json.dumps(summary, indent=1))
    lines = [
        "| half | photos | real bases | real near/far (median) | scene alone at the inserted places | "
        + " | ".join(f"inserted, strength {s}" for s in STRENGTHS)
        + " |",
        "|---" * (5 + len(STRENGTHS)) + "|",
    ]
    for name in ("train", "test"):
        h = summary[name]
        lines.append(
            f"| {name} | {h['photos']} | {h['real_bases']} | {h['real_median']:.3f} | {h['before_median']:.3f} | "
            + " | ".join(f"{h['inserted_median'][str(s)]:.3f}" for s in STRENGTHS)
            + " |"
        )
    (a.out / "table.md").write_text("\n".join(lines) + f"\n\nChosen on train: strength {chosen}.\n")
    print("\n".join(lines), f"\nchosen on train: {chosen}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

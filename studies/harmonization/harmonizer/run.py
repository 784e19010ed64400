#!/usr/bin/env python
"""Evaluate harmonizers on held-out pairs built from any folder of real images with YOLO or COCO boxes.

Each image is resized to cover 640x480 and centre-cropped; each labelled object (GrabCut mask from its box) is
perturbed in colour, exposure, noise and blur (the training perturbation ranges), and every method tries to restore
it. Reports MSE, fMSE and PSNR (0..255 scale, iHarmony4 definitions) and the median time of one ``harmonize`` call
on a 640x480 image, per method.

  nice -n 10 .venv/bin/python -m studies.harmonization.harmonizer --images $AIAS_DATA/tracon/images/val \
      --labels $AIAS_DATA/tracon/labels/val --out studies/harmonization/harmonizer/result
"""

from __future__ import annotations

import argparse
import json
import logging
import platform
import shlex
import sys
import time
from pathlib import Path

import cv2
import numpy as np

from aias_augment.apply.harmonize import harmonize
from aias_augment.apply.harmonize.metrics import fmse, mse, psnr
from aias_augment.apply.harmonize.pairs import (
    PerturbRanges,
    apply_perturbation,
    cover_resize,
    grabcut_mask,
    labelled_images,
    load_boxes,
    read_image_rgb,
    sample_perturbation,
)
from aias_augment.apply.harmonize.regions import context_box, mask_box
from studies._shared.pictures import write_jpeg

log = logging.getLogger("eval_harmonization")
METHOD_ORDER = ("none", "reinhard", "camera", "fast", "network")
LABELS = {
    "none": "raw composite",
    "reinhard": "Reinhard colour transfer",
    "camera": "camera-pipeline matching",
    "fast": "fast harmonizer",
    "network": "network (coarse-to-fine)",
}


def build_pairs(images: Path, labels: Path, size_wh, max_images, max_objects, min_box_px, rng):
    pairs, skipped = [], {"small_or_cut": 0, "grabcut": 0}
    for path, boxes in labelled_images(images, labels):
        if max_images and len({p["image"] for p in pairs}) >= max_images:
            break
        img = read_image_rgb(path)
        boxes = load_boxes(path, boxes, labels, img.shape[:2])
        if not boxes:
            continue
        view, s, ox, oy = cover_resize(img, size_wh)
        n = 0
        for x0, y0, x1, y1 in boxes:
            if n >= max_objects:
                break
            bx = np.array([x0 * s - ox, y0 * s - oy, x1 * s - ox, y1 * s - oy])
            cl = np.clip(bx, 0, [size_wh[0], size_wh[1], size_wh[0], size_wh[1]])
            area, vis = (bx[2] - bx[0]) * (bx[3] - bx[1]), max(cl[2] - cl[0], 0) * max(cl[3] - cl[1], 0)
            box = tuple(int(round(v)) for v in cl)
            if vis < 0.5 * area or min(box[2] - box[0], box[3] - box[1]) < min_box_px:
                skipped["small_or_cut"] += 1
                continue
            mask = grabcut_mask(view, box)
            if mask is None:
                skipped["grabcut"] += 1
                continue
            p = sample_perturbation(PerturbRanges(), rng)
            comp = apply_perturbation(view, mask.astype(np.float32), p, rng)
            pairs.append(
                {"image": path.name, "box": box, "target": view, "composite": comp, "mask": mask, "perturbation": p}
            )
            n += 1
    return pairs, skipped


def side_by_side(pairs, outputs, methods, path: Path, n: int = 5, tile: int = 160):
    rows = []
    for i in np.linspace(0, len(pairs) - 1, min(n, len(pairs))).astype(int):
        pr = pairs[i]
        x0, y0, x1, y1 = context_box(mask_box(pr["mask"]), pr["mask"].shape, 2.0)
        cells = [pr["target"]] + [outputs[m][i] for m in methods]
        rows.append(
            np.concatenate([cv2.resize(c[y0:y1, x0:x1], (tile, tile), interpolation=cv2.INTER_AREA) for c in cells], 1)
        )
    grid = np.concatenate(rows, 0)
    head = np.full((24, grid.shape[1], 3), 255, np.uint8)
    for j, name in enumerate(["target (real)"] + [("composite" if m == "none" else m) for m in methods]):
        cv2.putText(head, name, (j * tile + 4, 17), cv2.FONT_HERSHEY_SIMPLEX, 0.5, (0, 0, 0), 1, cv2.LINE_AA)
    write_jpeg(path, cv2.cvtColor(np.concatenate([head, grid], 0), cv2.COLOR_RGB2BGR))


def network_stage_table(pairs, checkpoint, base_fmse):
    """fMSE of the network stopped after each of its stages, with one view and with the test-time views."""
    from aias_augment.apply.harmonize.api import checkpoint_path
    from aias_augment.apply.harmonize.color import to_float, to_uint8
    from aias_augment.apply.harmonize.network import STAGES, load_generator, run_network, up_to_stage

    gen = load_generator(checkpoint_path("network", checkpoint))
    names = STAGES if gen.global_stage is not None else STAGES[1:]
    rows = []
    for i, last in enumerate(names):
        g = up_to_stage(gen, last)
        row = {"stages": " + ".join(names[: i + 1])}
        for key, tta in (("single", False), ("tta", True)):
            scores, times = [], []
            for p in pairs:
                t = time.perf_counter()
                out = run_network(g, to_float(p["composite"]), p["mask"].astype(bool), tta)
                times.append(time.perf_counter() - t)
                scores.append(fmse(to_uint8(out), p["target"], p["mask"]))
            f = float(np.mean(scores))
            row[f"fmse_{key}"], row[f"reduction_{key}"] = f, (1 - f / base_fmse) if base_fmse else float("nan")
            row[f"time_ms_{key}"] = float(1000 * np.median(times))
        log.info("network up to %s: fMSE %.1f (1 view) %.1f (6 views)", last, row["fmse_single"], row["fmse_tta"])
        rows.append(row)
    return rows


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--images", required=True, type=Path)
    ap.add_argument("--labels", required=True, type=Path, help="YOLO label folder or COCO json")
    ap.add_argument("--out", type=Path, default=Path("studies/harmonization/harmonizer/result"))
    ap.add_argument("--methods", nargs="+", default=list(METHOD_ORDER), choices=METHOD_ORDER)
    ap.add_argument("--network-checkpoint", default=None)
    ap.add_argument("--fast-checkpoint", default=None)
    ap.add_argument("--size", default="640x480", help="evaluation image size WxH")
    ap.add_argument("--max-images", type=int, default=0, help="0 = all")
    ap.add_argument("--max-objects-per-image", type=int, default=2)
    ap.add_argument("--min-box-px", type=int, default=16)
    ap.add_argument("--threads", type=int, default=1, help="torch threads for the learnt methods")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument(
        "--single-view",
        action="store_true",
        help="learnt methods predict from one view instead of averaging the 6 test-time views",
    )
    ap.add_argument(
        "--network-stages",
        action="store_true",
        help="also score the network stopped after each stage, with one view and with the test-time views",
    )
    args = ap.parse_args(argv)
    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(message)s")
    import torch

    torch.set_num_threads(args.threads)
    size_wh = tuple(int(v) for v in args.size.lower().split("x"))
    t0 = time.perf_counter()
    pairs, skipped = build_pairs(
        args.images,
        args.labels,
        size_wh,
        args.max_images,
        args.max_objects_per_image,
        args.min_box_px,
        np.random.default_rng(args.seed),
    )
    if not pairs:
        raise SystemExit("no evaluation pairs could be built")
    log.info(
        "%d pairs from %d images (skipped %s) in %.1fs",
        len(pairs),
        len({p["image"] for p in pairs}),
        skipped,
        time.perf_counter() - t0,
    )
    ckpt = {"network": args.network_checkpoint, "fast": args.fast_checkpoint}
    methods = [m for m in METHOD_ORDER if m in args.methods]
    per_method, outputs = {}, {}
    views = not args.single_view
    for m in methods:
        harmonize(
            pairs[0]["composite"],
            pairs[0]["mask"].astype(np.float32),
            m,
            np.random.default_rng(0),
            checkpoint=ckpt.get(m),
            test_time_views=views,
        )  # warm-up/load
        rows, outs = [], []
        for i, pr in enumerate(pairs):
            t = time.perf_counter()
            out = harmonize(
                pr["composite"],
                pr["mask"].astype(np.float32),
                m,
                np.random.default_rng(args.seed + i),
                ckpt.get(m),
                test_time_views=views,
            )
            dt = time.perf_counter() - t
            rows.append((mse(out, pr["target"]), fmse(out, pr["target"], pr["mask"]), psnr(out, pr["target"]), dt))
            outs.append(out)
        a = np.array(rows)
        per_method[m] = {
            "mse": float(a[:, 0].mean()),
            "fmse": float(a[:, 1].mean()),
            "psnr": float(np.mean(np.minimum(a[:, 2], 100.0))),
            "time_ms_median": float(1000 * np.median(a[:, 3])),
            "time_ms_p90": float(1000 * np.percentile(a[:, 3], 90)),
        }
        outputs[m] = outs
        log.info(
            "%-9s MSE %7.1f fMSE %7.1f PSNR %5.2f  %.1f ms",
            m,
            *[per_method[m][k] for k in ("mse", "fmse", "psnr", "time_ms_median")],
        )
    base = per_method.get("none", {}).get("fmse")
    for m, r in per_method.items():
        r["fmse_reduction_vs_composite"] = None if not base else float(1 - r["fmse"] / base)
    stages = network_stage_table(pairs, ckpt["network"], base) if args.network_stages else None

    args.out.mkdir(parents=True, exist_ok=True)
    command = " ".join(shlex.quote(a) for a in ["python", "studies/harmonization/harmonizer/run.py", *sys.argv[1:]])
    meta = {
        "command": command,
        "pairs": len(pairs),
        "images": len({p["image"] for p in pairs}),
        "skipped": skipped,
        "size_wh": size_wh,
        "torch_threads": args.threads,
        "seed": args.seed,
        "learnt_methods_views": 6 if views else 1,
        "machine": f"{platform.processor() or platform.machine()}, shared 2-core CPU",
        "checkpoints": ckpt,
        "eval_wall_s": round(time.perf_counter() - t0, 1),
    }
    (args.out / "eval.json").write_text(
        json.dumps({"meta": meta, "methods": per_method, **({"network_stages": stages} if stages else {})}, indent=2)
    )
    lines = [
        "# Harmonization on held-out pairs",
        "",
        f"Command: `{command}`",
        "",
        f"{len(pairs)} pairs from {meta['images']} images ({size_wh[0]}x{size_wh[1]}), skipped {skipped}; "
        f"torch threads {args.threads}; learnt methods average {meta['learnt_methods_views']} view(s); "
        f"time = median of all {len(pairs)} calls of `harmonize()` per method.",
        "",
        "| method | MSE | fMSE | PSNR (dB) | fMSE vs composite | time / 640x480 image (ms, median / p90) |",
        "|---|---:|---:|---:|---:|---:|",
    ]
    for m, r in per_method.items():
        red = "" if r["fmse_reduction_vs_composite"] is None else f"{-100 * r['fmse_reduction_vs_composite']:+.1f}%"
        lines.append(
            f"| {LABELS[m]} | {r['mse']:.1f} | {r['fmse']:.1f} | {r['psnr']:.2f} | {red} | "
            f"{r['time_ms_median']:.1f} / {r['time_ms_p90']:.1f} |"
        )
    if stages:
        lines += [
            "",
            "Network stopped after each stage (later stages set to their identity), one view vs the 6 "
            "test-time views (time: median ms of `run_network` per image):",
            "",
            "| stages | fMSE (1 view) | vs composite | ms | fMSE (6 views) | vs composite | ms |",
            "|---|---:|---:|---:|---:|---:|---:|",
        ]
        for r in stages:
            lines.append(
                f"| {r['stages']} | {r['fmse_single']:.1f} | {-100 * r['reduction_single']:+.1f}% | "
                f"{r['time_ms_single']:.0f} | {r['fmse_tta']:.1f} | {-100 * r['reduction_tta']:+.1f}% | "
                f"{r['time_ms_tta']:.0f} |"
            )
    lines += ["", "![side by side](side_by_side.jpg)", ""]
    (args.out / "eval.md").write_text("\n".join(lines))
    side_by_side(pairs, outputs, methods, args.out / "side_by_side.jpg")
    print("\n".join(lines))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

"""Learning curves of the detector: train once, record the loss terms every iteration and TraCon val AP every
``--eval-every`` iterations (the weights a run returns), write ``curve.json``; ``--plot`` draws several runs,
``--table`` lists them.

    # one run: TraCon train thinned to 10 % of its cone images (seeded as in the study), 450 iterations
    python -m studies.detection.detector --config lite0_320_c --iters 450 --keep-fraction 0.1 --seed 0 \
        --out studies/detection/detector/result/curves/c_thin10_s0
    # a variant: any config field by its dotted name (values parsed as YAML)
    python -m studies.detection.detector ... --set model.frozen_blocks=0 model.backbone_bn=frozen
    # the table and a plot of several runs
    python -m studies.detection.detector --table studies/detection/detector/result/curves/*/curve.json \
        --out studies/detection/detector/result/curves.md
    python -m studies.detection.detector --plot studies/detection/detector/result/curves/d*/curve.json \
        --out studies/detection/detector/result/curves_d.jpg

Evaluation time is excluded from the reported training time. Use one thread per run (``--threads``) and at most two
runs side by side on the 2-core machine.
"""

from __future__ import annotations

import argparse
import json
import logging
import sys
import time
from pathlib import Path

import yaml

from detection_eval.config import load_detector_config, replace_nested


def parse_overrides(items: list[str]) -> dict:
    out = {}
    for item in items:
        key, sep, value = item.partition("=")
        if not sep:
            raise SystemExit(f"--set expects key=value, got {item!r}")
        v = yaml.safe_load(value)
        out[key] = tuple(v) if isinstance(v, list) else v
    return out


def run(args) -> None:
    import torch

    from aias_augment.core.config import data_root
    from detection_eval.data import load_yolo_dir
    from detection_eval.inference import evaluate_dataset
    from detection_eval.loader import cache_dataset
    from detection_eval.study.splits import thin_cone_images
    from detection_eval.train import train_detector

    torch.set_num_threads(args.threads)
    overrides = parse_overrides(args.set or [])
    cfg = load_detector_config(args.config)
    cfg = replace_nested(cfg, **{"train.max_iters": args.iters, "train.num_threads": args.threads, **overrides})
    root = Path(args.data) if args.data else data_root() / "tracon"
    train = load_yolo_dir(root, "train", ("cone",))
    val = load_yolo_dir(root, "val", ("cone",))
    if args.keep_fraction < 1:
        train, _ = thin_cone_images(train, args.keep_fraction, args.seed)
    val_cache = cache_dataset(val, cfg.train.img_size)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    losses, evals = [], []
    t_start = time.perf_counter()

    def on_iteration(it, model, step_losses):
        losses.append({"iter": it, **step_losses})
        if (it + 1) % args.eval_every == 0 or it + 1 == cfg.train.max_iters:
            m = evaluate_dataset(model, val, cfg.train.img_size, cfg.inference, cached=val_cache)
            evals.append(
                {
                    "iter": it + 1,
                    "AP": m["AP"],
                    "AP50": m["AP50"],
                    "AP_small": m["AP_small"],
                    "AP_medium": m["AP_medium"],
                    "AP_large": m["AP_large"],
                }
            )
            logging.info("iter %d: val AP %.4f AP50 %.4f", it + 1, m["AP"], m["AP50"])

    res = train_detector(cfg, train, seed=args.seed, log_fn=logging.info, on_iteration=on_iteration)
    final_raw = None
    if res.raw_model is not None:  # the optimised weights beside the EMA ones: does EMA help at this schedule?
        m = evaluate_dataset(res.raw_model, val, cfg.train.img_size, cfg.inference, cached=val_cache)
        final_raw = {
            "iter": res.iterations,
            "AP": m["AP"],
            "AP50": m["AP50"],
            "AP_small": m["AP_small"],
            "AP_medium": m["AP_medium"],
            "AP_large": m["AP_large"],
        }
        logging.info("raw (non-EMA) weights: val AP %.4f AP50 %.4f", m["AP"], m["AP50"])
    row = {
        "name": args.name or out.name,
        "config": args.config,
        "overrides": {k: list(v) if isinstance(v, tuple) else v for k, v in overrides.items()},
        "seed": args.seed,
        "keep_fraction": args.keep_fraction,
        "train_images": len(train),
        "train_boxes": train.num_boxes,
        "iterations": res.iterations,
        "batch_size": cfg.train.batch_size,
        "threads": args.threads,
        "train_seconds": res.train_seconds,
        "train_images_per_second": res.images_per_second,
        "wall_seconds": time.perf_counter() - t_start,
        "final": evals[-1],
        "final_raw": final_raw,
        "evals": evals,
        "losses": losses,
        "command": "python -m studies.detection.detector " + " ".join(sys.argv[1:]),
    }
    (out / "curve.json").write_text(json.dumps(row, indent=1))
    logging.info(
        "done: AP %.4f in %.0f s train (%.2f img/s)", evals[-1]["AP"], res.train_seconds, res.images_per_second
    )


def smooth(values, k: int = 15):
    import numpy as np

    v = np.asarray(values, float)
    if len(v) < k:
        return v
    return np.convolve(np.pad(v, (k // 2, k - 1 - k // 2), mode="edge"), np.ones(k) / k, mode="valid")


def plot(paths: list[str], out: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    runs = [json.loads(Path(p).read_text()) for p in paths]
    fig, axes = plt.subplots(1, 5, figsize=(25, 4.5))
    for i, r in enumerate(runs):
        c = f"C{i % 10}"
        label = f"{r['name']} ({r['final']['AP']:.3f})"
        it = [x["iter"] for x in r["losses"]]
        axes[0].plot([e["iter"] for e in r["evals"]], [e["AP"] for e in r["evals"]], "o-", color=c, label=label)
        if r.get("final_raw"):  # the optimised weights beside the EMA ones
            axes[0].plot([r["final_raw"]["iter"]], [r["final_raw"]["AP"]], "x", color=c, ms=9, mew=2)
        axes[1].plot(it, smooth([x["obj"] for x in r["losses"]]), color=c)
        pos = [x for x in r["losses"] if x["num_fg"] > 0]  # IoU and class terms exist only with positives
        for ax, key in zip(axes[2:4], ("iou", "cls")):
            ax.plot([x["iter"] for x in pos], smooth([x[key] for x in pos]), color=c)
        axes[4].plot(it, smooth([float(x["num_fg"] == 0) for x in r["losses"]], 25), color=c)
    axes[0].set_title("TraCon val AP50:95 (returned weights: EMA if on; x = raw)", fontsize=10)
    axes[0].legend(fontsize=7)
    for ax, key in zip(
        axes[1:4], ("objectness loss", "IoU loss (batches with positives)", "class loss (batches with positives)")
    ):
        ax.set_title(f"train {key}, smoothed", fontsize=10)
        ax.set_yscale("log")
    axes[4].set_title("share of batches without any positive (smoothed)", fontsize=10)
    for ax in axes:
        ax.set_xlabel("iteration")
        ax.grid(alpha=0.3)
    fig.tight_layout()
    Path(out).parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=min(110, 1600 / max(fig.get_size_inches())), pil_kwargs={"quality": 90})
    print(f"wrote {out}")


def table(paths: list[str]) -> str:
    """Markdown rows: variant, data, seed, AP and AP50 (EMA weights; raw weights in brackets), train s, img/s."""
    rows = [
        "| variant | data | seed | AP50:95 | AP50 | AP50:95 raw weights | train s | train img/s | threads | command |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    for path in paths:
        r = json.loads(Path(path).read_text())
        data = "all" if r["keep_fraction"] >= 1 else f"thinned {r['keep_fraction']:.0%}"
        raw = f"{r['final_raw']['AP']:.3f}" if r.get("final_raw") else "—"
        rows.append(
            f"| {r['name']} | {data} | {r['seed']} | {r['final']['AP']:.3f} | {r['final']['AP50']:.3f} | "
            f"{raw} | {r['train_seconds']:.0f} | {r['train_images_per_second']:.2f} | {r['threads']} | "
            f"`{r['command']}` |"
        )
    return "\n".join(rows)


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--config", default="lite0_320")
    p.add_argument("--set", nargs="*", help="config overrides, dotted.key=value")
    p.add_argument("--data", default=None, help="YOLO dataset root with train/ and val/ splits (default: TraCon)")
    p.add_argument("--keep-fraction", type=float, default=0.1)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--iters", type=int, default=450)
    p.add_argument("--eval-every", type=int, default=50)
    p.add_argument("--threads", type=int, default=1)
    p.add_argument("--name", default=None)
    p.add_argument("--plot", nargs="*", help="curve.json files to draw (then --out is the JPEG)")
    p.add_argument("--table", nargs="*", help="curve.json files to list as a markdown table (--out: its file)")
    p.add_argument("--out", default=None)
    args = p.parse_args()
    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(message)s")
    if args.table:
        text = table(args.table)
        if args.out:
            Path(args.out).write_text(text + "\n")
        print(text)
    elif not args.out:
        p.error("--out is required")
    elif args.plot:
        plot(args.plot, args.out)
    else:
        run(args)
    return 0

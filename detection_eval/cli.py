"""``detection-eval``: train, evaluate saved weights on any COCO json / YOLO-txt set, predict on a folder.

detection-eval --weights runs/x/weights.pt --data $AIAS_DATA/tracon --split val      # evaluate (default)
detection-eval eval --weights W --data instances.json [--image-root DIR]
detection-eval train --config lite0_320 --data $AIAS_DATA/tracon --split train --names cone --out runs/x
detection-eval predict --weights W --images DIR --out out/pred [--score 0.3]
"""

from __future__ import annotations

import argparse
import json
import logging
import math
import sys
from pathlib import Path

import torch

from aias_augment.core.arg_parser import OneLineArgumentParser
from aias_augment.core.config import ConfigError
from aias_augment.core.logs import add_logging_args, configure_logging

from .config import load_detector_config, replace_nested
from .data import DetectionSet, load_dataset
from .evaluate import format_metrics
from .inference import evaluate_dataset
from .predict import add_predict_args, cmd_predict
from .train import load_checkpoint, save_checkpoint, train_detector

COMMANDS = ("eval", "train", "predict")


def align_categories(dataset: DetectionSet, model_names: list[str]) -> DetectionSet:
    """Relabel ``dataset`` into the model's label order by category name. A one-class model on a one-class set is
    matched whatever the names (``cone`` vs ``traffic_cone``); otherwise unknown names raise."""
    names = list(dataset.category_names)
    if names == model_names:
        return dataset
    if len(names) == 1 and len(model_names) == 1:
        logging.getLogger(__name__).warning("matching dataset class %r to model class %r", names[0], model_names[0])
        return DetectionSet(dataset.records, tuple(model_names), dataset.category_ids, dataset.skipped)
    missing = [n for n in names if n not in model_names]
    if missing:
        raise ValueError(f"dataset categories {missing} are not among the model's {model_names}")
    import dataclasses

    import numpy as np

    remap = np.array([model_names.index(n) for n in names])
    records = tuple(dataclasses.replace(r, labels=remap[r.labels]) for r in dataset.records)
    ids = [0] * len(model_names)
    for n, cid in zip(names, dataset.category_ids):
        ids[model_names.index(n)] = cid
    free = iter(i for i in range(max(ids) + 1, max(ids) + 1 + len(model_names)))
    ids = [cid if cid else next(free) for cid in ids]
    return DetectionSet(records, tuple(model_names), tuple(ids), dataset.skipped)


def _json_safe(obj):
    if isinstance(obj, float) and math.isnan(obj):
        return None
    if isinstance(obj, dict):
        return {k: _json_safe(v) for k, v in obj.items()}
    return obj


def cmd_eval(args) -> dict:
    model, names, meta = load_checkpoint(args.weights)
    dataset = align_categories(
        load_dataset(args.data, args.split, tuple(args.names) if args.names else None, args.image_root), names
    )
    img_size = args.img_size or model.cfg.train.img_size
    cfg = model.cfg.inference
    metrics = evaluate_dataset(model, dataset, img_size, cfg)
    print(format_metrics(metrics))
    if args.out:
        Path(args.out).parent.mkdir(parents=True, exist_ok=True)
        Path(args.out).write_text(
            json.dumps(
                _json_safe(
                    {
                        "weights": str(args.weights),
                        "data": str(args.data),
                        "split": args.split,
                        "img_size": img_size,
                        **metrics,
                    }
                ),
                indent=2,
            )
        )
    return metrics


def cmd_train(args) -> None:
    cfg = load_detector_config(args.config)
    if args.iters:
        cfg = replace_nested(cfg, **{"train.max_iters": args.iters})
    dataset = load_dataset(args.data, args.split, tuple(args.names) if args.names else None)
    result = train_detector(cfg, dataset, seed=args.seed, log_fn=None if args.quiet else print)
    out = Path(args.out)
    meta = {
        "data": str(args.data),
        "split": args.split,
        "seed": args.seed,
        "train_seconds": result.train_seconds,
        "images_per_second": result.images_per_second,
        "iterations": result.iterations,
    }
    save_checkpoint(out / "weights.pt", result.model, dataset.category_names, meta)
    print(
        f"saved {out / 'weights.pt'}: {result.iterations} iterations in {result.train_seconds:.0f} s "
        f"({result.images_per_second:.2f} train images/s)"
    )
    if args.val:
        val = load_dataset(args.val, args.val_split, tuple(args.names) if args.names else None)
        metrics = evaluate_dataset(result.model, val, cfg.train.img_size, cfg.inference)
        print(format_metrics(metrics))
        (out / "val_metrics.json").write_text(json.dumps(_json_safe(metrics), indent=2))


def main(argv: list[str] | None = None) -> None:
    argv = _default_to_eval(list(sys.argv[1:] if argv is None else argv))
    p = OneLineArgumentParser(
        prog="detection-eval", description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    sub = p.add_subparsers(dest="command", required=True)
    e = sub.add_parser("eval", help="COCO metrics of saved weights on a COCO json or YOLO-txt folder")
    e.add_argument("--weights", required=True)
    e.add_argument("--data", required=True, help="COCO .json or YOLO folder (images/, labels/)")
    e.add_argument("--split", default=None, help="YOLO split subfolder, e.g. val")
    e.add_argument("--names", nargs="*", help="YOLO class names (else classes.txt or class_<i>)")
    e.add_argument("--image-root", default=None, help="COCO: folder of the images (default: beside the json)")
    e.add_argument(
        "--img-size", type=_int_in(32, 4096), default=None, help="default: the training size stored with the weights"
    )
    e.add_argument("--out", default=None, help="write the metrics as JSON here")
    t = sub.add_parser("train", help="train a detector on one dataset")
    t.add_argument("--config", default="lite0_320", help="configs/detector/<name>.yaml or a path")
    t.add_argument("--data", required=True)
    t.add_argument("--split", default=None)
    t.add_argument("--names", nargs="*")
    t.add_argument("--val", default=None)
    t.add_argument("--val-split", default=None)
    t.add_argument("--iters", type=_int_in(1, 10**9), default=None, help="default: the config's max_iters")
    t.add_argument("--seed", type=_int_in(0, 2**32 - 1), default=0)
    t.add_argument("--out", required=True)
    add_predict_args(sub.add_parser("predict", help="draw the detections of saved weights on a folder of images"))
    add_logging_args(p, subcommands=sub.choices.values())
    args = p.parse_args(argv)
    configure_logging(args)
    torch.set_num_threads(1)
    try:
        {"eval": cmd_eval, "train": cmd_train, "predict": cmd_predict}[args.command](args)
    except (ValueError, OSError, ConfigError) as e:  # bad weights, data or config: one line (DEBUG: the traceback)
        logging.getLogger(__name__).debug("detection-eval %s failed", args.command, exc_info=True)
        p.exit(2, f"detection-eval {args.command}: error: {' '.join(str(e).split())}\n")


def _int_in(lo: int, hi: int):
    """An argparse type: a whole number in [lo, hi]."""

    def parse(text: str) -> int:
        try:
            v = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{text!r} is not a whole number") from None
        if not lo <= v <= hi:
            raise argparse.ArgumentTypeError(f"{v} is outside [{lo}, {hi}]")
        return v

    return parse


def _default_to_eval(argv: list[str]) -> list[str]:
    """``detection-eval --weights W --data D`` evaluates: insert ``eval`` after any leading logging flags unless a
    subcommand or a help flag comes there."""
    i = 0
    while i < len(argv) and (argv[i] == "--quiet" or argv[i].startswith("--log-level")):
        i += 1 if argv[i] == "--quiet" or "=" in argv[i] else 2
    if i >= len(argv) or argv[i] in (*COMMANDS, "-h", "--help"):
        return argv
    return [*argv[:i], "eval", *argv[i:]]


if __name__ == "__main__":
    main()

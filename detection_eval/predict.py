"""Predict on a folder of images: writes each image with its boxes drawn, plus ``detections.json`` (COCO-style
results with file names).

    detection-eval predict --weights runs/x/weights.pt --images DIR --out out/pred [--score 0.3]
    python -m detection_eval.predict ...   (same arguments)
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import logging
from pathlib import Path

import cv2
import numpy as np
import torch

from aias_augment.core.arg_parser import OneLineArgumentParser
from aias_augment.core.logs import add_logging_args, configure_logging

from .data import IMAGE_SUFFIXES, read_image_rgb
from .inference import predict_images
from .train import load_checkpoint

log = logging.getLogger(__name__)


def draw_detections(image_rgb: np.ndarray, det: dict, names: list[str]) -> np.ndarray:
    """Copy of the image with boxes and 'name score' captions."""
    out = cv2.cvtColor(image_rgb, cv2.COLOR_RGB2BGR)
    thick = max(1, round(max(out.shape[:2]) / 400))
    for box, score, label in zip(det["boxes"], det["scores"], det["labels"]):
        x0, y0, x1, y1 = (int(round(v)) for v in box)
        cv2.rectangle(out, (x0, y0), (x1, y1), (0, 255, 0), thick)
        cv2.putText(
            out,
            f"{names[int(label)]} {score:.2f}",
            (x0, max(y0 - 4, 10)),
            cv2.FONT_HERSHEY_SIMPLEX,
            0.4 * thick,
            (0, 255, 0),
            thick,
        )
    return cv2.cvtColor(out, cv2.COLOR_BGR2RGB)


def predict_folder(
    weights: str | Path, images: str | Path, out: str | Path, score: float = 0.3, skipped: dict | None = None
) -> list[dict]:
    """Detections of every image of the folder (drawn into ``out``, listed in ``out/detections.json``). An image
    that cannot be read is a logged skip, recorded in ``skipped`` ({file name: reason}) when given; none readable:
    ValueError."""
    skipped = {} if skipped is None else skipped
    model, names, _ = load_checkpoint(weights)
    cfg = dataclasses.replace(model.cfg.inference, score_threshold=score)
    paths = sorted(p for p in Path(images).iterdir() if p.suffix.lower() in IMAGE_SUFFIXES)
    if not paths:
        raise ValueError(f"no images ({', '.join(IMAGE_SUFFIXES)}) in {images}")
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    results, unread = [], []
    for p in paths:
        try:
            image = read_image_rgb(p)
        except (OSError, ValueError, cv2.error) as e:
            skipped[p.name] = " ".join(str(e).split())
            unread.append(p.name)
            log.warning("skipping unreadable image %s: %s", p, skipped[p.name])
            continue
        det = predict_images(model, [image], model.cfg.train.img_size, cfg)[0]
        drawn = draw_detections(image, det, names)
        cv2.imwrite(str(out / f"{p.stem}.jpg"), cv2.cvtColor(drawn, cv2.COLOR_RGB2BGR))
        for box, s, label in zip(det["boxes"], det["scores"], det["labels"]):
            results.append(
                {
                    "file_name": p.name,
                    "category": names[int(label)],
                    "score": float(s),
                    "bbox_xywh": [float(box[0]), float(box[1]), float(box[2] - box[0]), float(box[3] - box[1])],
                }
            )
    if len(unread) == len(paths):
        raise ValueError(f"none of the {len(paths)} images in {images} could be read (e.g. {unread[0]})")
    (out / "detections.json").write_text(json.dumps(results, indent=1))
    return results


def add_predict_args(p: argparse.ArgumentParser) -> None:
    """The arguments of ``detection-eval predict`` (read by :func:`cmd_predict`)."""
    p.add_argument("--weights", required=True)
    p.add_argument("--images", required=True, help="folder of images")
    p.add_argument("--out", required=True, help="folder for drawn images and detections.json")
    p.add_argument("--score", type=float, default=0.3, help="minimum score to keep a box")


def cmd_predict(args: argparse.Namespace) -> None:
    torch.set_num_threads(1)
    skipped: dict[str, str] = {}
    res = predict_folder(args.weights, args.images, args.out, args.score, skipped)
    note = f"; {len(skipped)} unreadable images skipped" if skipped else ""
    print(f"{len(res)} detections written to {args.out}{note}")


def main(argv: list[str] | None = None) -> None:
    p = OneLineArgumentParser(
        prog="detection-eval predict", description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    add_predict_args(p)
    add_logging_args(p)
    args = p.parse_args(argv)
    configure_logging(args)
    cmd_predict(args)


if __name__ == "__main__":
    main()

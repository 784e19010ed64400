"""``aias-augment``: offline augmentation of a COCO or YOLO dataset."""
from __future__ import annotations

import argparse
import logging
from dataclasses import replace

from .offline import items_from_coco, items_from_yolo, run
from .pipeline import PRESETS, load_preset


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="aias-augment", description=__doc__)
    src = ap.add_mutually_exclusive_group(required=True)
    src.add_argument("--input", help="COCO json of the dataset (with --images)")
    src.add_argument("--yolo", help="folder of images with YOLO txt labels (labels/ beside images/)")
    ap.add_argument("--images", help="image folder for --input")
    ap.add_argument("--class-names", nargs="*", default=None, help="YOLO class names by index")
    ap.add_argument("--categories", nargs="+", default=["traffic_cone"])
    ap.add_argument("--per-image", type=int, default=2, help="maximum objects inserted per image")
    ap.add_argument("--preset", choices=PRESETS, default="balanced")
    ap.add_argument("--out", required=True)
    ap.add_argument("--workers", type=int, default=1)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--limit", type=int, default=None, help="process only the first N images")
    a = ap.parse_args(argv)
    logging.basicConfig(level=logging.INFO, format="%(levelname)s %(name)s: %(message)s")
    if a.input and not a.images:
        ap.error("--input needs --images")
    items = items_from_coco(a.input, a.images) if a.input else items_from_yolo(a.yolo)
    items = items[: a.limit] if a.limit else items
    cfg = replace(load_preset(a.preset), categories=tuple(a.categories), max_objects=a.per_image,
                  min_objects=min(1, a.per_image))
    summary = run(items, cfg, a.seed, a.out, workers=a.workers, class_names=a.class_names)
    print(summary)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

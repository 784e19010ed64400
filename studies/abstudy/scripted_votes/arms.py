"""Render the arms of a small human A/B study: the same empty-road images through several pipeline settings.

Each arm is an ordinary ``aias-augment`` output folder (``images/``, ``records/``, ``annotations.json``), written by
the same ``aias_augment.cli.offline.run`` that the CLI calls, on the same input list, so ``aias-abstudy build`` can pair
the arms image by image. The arms are the detection study's (``detection_eval.study.arms.ARM_FLAGS``, one table):

    inserted     the whole pipeline (placement, lighting, shadow, harmonization)
    naive_paste  a plain render pasted at a random position and scale (3D Copy-Paste's "random insertion")
    no_shadow    the whole pipeline without the cast shadow

    python -m studies.abstudy.scripted_votes.arms --images $AIAS_DATA/tracon/images/train --n 6 --out out/abstudy_arms
"""

from __future__ import annotations

import argparse
import logging
from dataclasses import replace
from pathlib import Path

from aias_augment.cli.offline import IMAGE_SUFFIXES, Item, run
from aias_augment.pipeline.image import PRESETS, load_preset
from detection_eval.study.arms import ARM_FLAGS

ARMS = {arm: ARM_FLAGS[arm] for arm in ("inserted", "naive_paste", "no_shadow", "no_harmonize", "no_lighting")}


def empty_road_images(images_dir: Path, labels_dir: Path, n: int) -> list[Path]:
    """The first ``n`` images (sorted by name) whose YOLO label file exists and is empty: roads without cones."""
    out = []
    for p in sorted(images_dir.iterdir()):
        lab = labels_dir / (p.stem + ".txt")
        if p.suffix.lower() in IMAGE_SUFFIXES and lab.exists() and not lab.read_text().strip():
            out.append(p)
            if len(out) == n:
                break
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--images", required=True, help="YOLO image folder (labels/ beside images/)")
    ap.add_argument("--labels", default=None, help="label folder (default: images -> labels)")
    ap.add_argument("--n", type=int, default=6, help="number of empty-road images")
    ap.add_argument("--arms", nargs="+", default=["inserted", "naive_paste", "no_shadow"], choices=list(ARMS))
    ap.add_argument("--preset", choices=PRESETS, default="balanced")
    ap.add_argument("--categories", nargs="+", default=["traffic_cone"])
    ap.add_argument("--per-image", type=int, default=2)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--out", required=True)
    a = ap.parse_args(argv)
    logging.basicConfig(level=logging.INFO, format="%(levelname)s %(name)s: %(message)s")
    images = Path(a.images)
    labels = Path(a.labels) if a.labels else Path(str(images).replace("images", "labels"))
    paths = empty_road_images(images, labels, a.n)
    if not paths:
        ap.error(f"no image with an empty label file in {images}")
    items = [Item(str(p.resolve())) for p in paths]
    for arm in a.arms:
        cfg = replace(
            load_preset(a.preset, **ARMS[arm]),
            categories=tuple(a.categories),
            max_objects=a.per_image,
            min_objects=min(1, a.per_image),
        )
        summary = run(items, cfg, a.seed, str(Path(a.out) / arm))
        print(arm, summary)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

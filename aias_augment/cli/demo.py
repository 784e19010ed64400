"""``make demo``: insert traffic cones into real KITTI frames (known K, depth from the stereo pair) and TraCon
empty-road images (unknown camera: priors); writes images, a validated COCO json, per-image records and a contact
sheet under ``out/demo/``; then one cone through 16 posed KITTI frames (``out/demo/clip/``: side-by-side video,
COCO track, contact sheet), a car driving through a static camera's clip without poses (``out/demo/moving/``) and
two cones knocked over in it (``out/demo/topple/``)."""

from __future__ import annotations

import argparse
from dataclasses import replace
from pathlib import Path

import numpy as np

from aias_augment.cli.offline import Item, run
from aias_augment.core.config import data_root
from aias_augment.core.logs import add_logging_args, configure_logging
from aias_augment.pipeline.image import load_preset

KITTI_K = [[707.0912, 0, 601.8873], [0, 707.0912, 183.1104], [0, 0, 1]]
KITTI_BASELINE_M = 379.8145 / 707.0912


def demo_items(n_tracon: int = 6) -> list[Item]:
    root = data_root()
    snip = root / "kitti06_color_snippet"
    seq = root / "kitti06_seq"
    items = [
        Item(
            str(snip / "kitti06-12-color.png"),
            K=KITTI_K,
            stereo_right=str(snip / "kitti06-12-R-color.png"),
            baseline_m=KITTI_BASELINE_M,
            meta={"dataset": "kitti06 colour"},
        )
    ]
    for f in (5, 25, 45):  # grey stereo frames of the same street (real, rectified)
        items.append(
            Item(
                str(seq / "image_l" / f"{f:06d}.png"),
                K=KITTI_K,
                stereo_right=str(seq / "image_r" / f"{f:06d}.png"),
                baseline_m=KITTI_BASELINE_M,
                meta={"dataset": "kitti06 grey"},
            )
        )
    tr_img = root / "tracon" / "images" / "train"
    tr_lab = root / "tracon" / "labels" / "train"
    empty = sorted(
        p
        for p in tr_img.iterdir()
        if (tr_lab / (p.stem + ".txt")).exists() and not (tr_lab / (p.stem + ".txt")).read_text().strip()
    )
    rng = np.random.default_rng(0)
    for p in rng.choice(empty, size=min(n_tracon, len(empty)), replace=False):
        items.append(Item(str(p), meta={"dataset": "tracon empty road"}))
    return items


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="aias-demo", description=__doc__)
    ap.add_argument("--out", default="out/demo")
    ap.add_argument("--preset", default="balanced")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--tracon", type=int, default=6, help="number of TraCon empty-road images")
    ap.add_argument("--clip-frames", type=int, default=16, help="frames of the KITTI clip demo (0: skip it)")
    add_logging_args(ap)
    a = ap.parse_args(argv)
    configure_logging(a)
    out = Path(a.out)
    if (out / "records").exists():  # the demo always starts fresh (the CLI resumes; the demo shows)
        import shutil

        shutil.rmtree(out)
    cfg = replace(load_preset(a.preset), categories=("traffic_cone",), max_objects=3)
    summary = run(demo_items(a.tracon), cfg, a.seed, str(out))
    print(f"demo: {summary}")
    print(f"demo: wrote {out}/images, {out}/annotations.json, {out}/contact_sheet.png, {out}/records/")
    seq = data_root() / "kitti06_seq"
    if a.clip_frames > 0 and seq.exists():
        from aias_augment.cli.clip import ClipJob, augment_clip

        rec = augment_clip(
            ClipJob(
                str(seq / "image_l"),
                str(seq / "calib.txt"),
                str(seq / "poses.txt"),
                str(out / "clip"),
                ("traffic_cone",),
                a.seed,
                max_frames=a.clip_frames,  # published poses alone: on this footage flow refinement drifts
            )
        )
        print(
            f"demo: clip of {rec['frames']} frames, object in {rec['visible_frames']}, {rec['wall_s']} s: "
            f"{out}/clip/side_by_side.mp4, {out}/clip/contact_sheet.jpg, {out}/clip/annotations.json"
        )
    tripod = data_root() / "video" / "vtest.avi"
    if a.clip_frames > 0 and tripod.exists():  # a static camera without poses, a car driving through
        from aias_augment.cli.clip import ClipJob, augment_clip

        rec = augment_clip(
            ClipJob(
                str(tripod),
                None,
                None,
                str(out / "moving"),
                ("car",),
                a.seed,
                max_frames=a.clip_frames,
                stride=3,
                camera_height_m=8.0,  # a camera on a first floor
                fps=8.0,
                object_speed_mps=2.0,
            )
        )
        print(
            f"demo: a car driving through a static camera's clip, {rec['frames']} frames, in view in "
            f"{rec['visible_frames']}, {rec['wall_s']} s: {out}/moving/side_by_side.mp4, {out}/moving/contact_sheet.jpg"
        )
        rec = augment_clip(  # two cones; each is knocked over at a moment drawn in the plan
            ClipJob(
                str(tripod),
                None,
                None,
                str(out / "topple"),
                ("traffic_cone",),
                a.seed,
                max_frames=a.clip_frames,
                stride=2,
                camera_height_m=8.0,
                fps=12.0,
                topple_s=0.6,
                objects=2,
            )
        )
        print(
            f"demo: two cones knocked over in a static camera's clip, {rec['frames']} frames: "
            f"{out}/topple/side_by_side.mp4, {out}/topple/contact_sheet.jpg"
        )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

"""``aias-augment``: offline augmentation of a COCO or YOLO dataset, or of one posed clip.

  aias-augment --input train.json --images train/ --categories traffic_cone --per-image 2 --out train_aug/
  aias-augment --input clip.mp4 --camera calib.txt --poses poses.txt --categories traffic_cone --out clip_aug/
"""
from __future__ import annotations

import argparse
import logging
import sys
from dataclasses import replace

from .geometry import CAMERA_HEIGHT_PRIOR_M
from .offline import IMAGE_SUFFIXES, coco_categories, items_from_coco, items_from_yolo, run
from .pipeline import PRESETS, load_preset


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="aias-augment", description=__doc__)
    src = ap.add_mutually_exclusive_group(required=True)
    src.add_argument("--input", help="COCO json of the dataset (with --images), or a clip: a video file or a folder "
                                     "of frames (with --camera and --poses)")
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
    ap.add_argument("--backend", choices=("local", "ray"), default="local",
                    help="local: this process or a pool of --workers; ray: Ray tasks (pip install 'aias-augment[ray]')"
                         ", same outputs")
    ap.add_argument("--address", default=None, help="--backend ray: an existing cluster (default: a local instance)")
    ap.add_argument("--overwrite", action="store_true",
                    help="replace the run in --out when its manifest differs (default: refuse; the same run resumes)")
    ap.add_argument("--boxes", choices=("clip", "drop"), default="clip",
                    help="input boxes crossing the image border: clipped to it or dropped (counted in report.json)")
    ap.add_argument("--max-megapixels", type=float, default=4.0,
                    help="larger images are augmented at this size (INTER_AREA; recorded per image); 0: no bound")
    ap.add_argument("--scene-cache", default=None,
                    help="folder of scene analyses (camera, ground, region, lighting) reused across runs and workers")
    clip = ap.add_argument_group("clip (--input is a video file or a frame folder)")
    clip.add_argument("--camera", help="KITTI calib.txt, pyslam KITTI*.yaml, or a yaml with fx, fy, cx, cy")
    clip.add_argument("--poses", help="one pose per frame: KITTI (12 numbers) or TUM (tx ty tz qx qy qz qw) lines")
    clip.add_argument("--colour", action="store_true", help="KITTI calib.txt: the colour camera (P2)")
    clip.add_argument("--start", type=int, default=0, help="first frame")
    clip.add_argument("--stride", type=int, default=1)
    clip.add_argument("--max-frames", type=int, default=None)
    clip.add_argument("--camera-height", type=float, default=CAMERA_HEIGHT_PRIOR_M, help="metres above the ground")
    clip.add_argument("--lighting", choices=("clip", "ambient"), default="clip")
    clip.add_argument("--harmonize", default="fast", choices=("none", "reinhard", "camera", "fast", "network"),
                      help="clip harmonization ('fast': one colour transform for the whole clip)")
    clip.add_argument("--flow-refine", action="store_true",
                      help="track the ground under the object (KLT) and correct drifting poses per frame")
    a = ap.parse_args(argv)
    logging.basicConfig(level=logging.INFO, format="%(levelname)s %(name)s: %(message)s")
    if a.input and (a.camera or a.poses):
        if not (a.camera and a.poses):
            ap.error("a clip needs both --camera and --poses")
        from .offline_video import ClipJob, augment_clip

        record = augment_clip(ClipJob(a.input, a.camera, a.poses, a.out, tuple(a.categories), a.seed, a.start,
                                      a.max_frames, a.stride, a.colour,
                                      a.camera_height, lighting=a.lighting,
                                      flow_refine=a.flow_refine, harmonize=a.harmonize))
        print({k: record[k] for k in ("category", "asset", "frames", "visible_frames", "wall_s")})
        return 0
    if a.input and not a.images:
        ap.error("--input needs --images")
    from .manifest import ManifestMismatch
    from .validate import InputError, check_categories
    if a.per_image < 0 or a.workers < 1 or (a.limit is not None and a.limit < 1) or a.max_megapixels < 0:
        ap.error("--per-image >= 0, --workers >= 1, --limit >= 1 and --max-megapixels >= 0 please")
    try:
        check_categories(a.categories)
        items = (items_from_coco(a.input, a.images, box_policy=a.boxes) if a.input else
                 items_from_yolo(a.yolo, class_names=a.class_names, box_policy=a.boxes))
        items = items[: a.limit] if a.limit else items
        if not items:
            raise InputError(f"no images ({', '.join(sorted(IMAGE_SUFFIXES))}) in {a.images or a.yolo}")
        cfg = replace(load_preset(a.preset), categories=tuple(a.categories), max_objects=a.per_image,
                      min_objects=min(1, a.per_image))
        summary = run(items, cfg, a.seed, a.out, workers=a.workers, class_names=a.class_names,
                      scene_cache=a.scene_cache, preset=a.preset, overwrite=a.overwrite,
                      max_pixels=int(a.max_megapixels * 1e6) or None, options={"boxes": a.boxes},
                      backend=a.backend, ray_address=a.address,
                      categories=coco_categories(a.input) if a.input else None)
    except (InputError, ManifestMismatch) as e:
        print(f"aias-augment: error: {e}", file=sys.stderr)
        return 2
    except OSError as e:   # an unwritable or full --out, a path through a file: one line that says what to do
        where = f" ({e.filename})" if e.filename else ""
        print(f"aias-augment: error: {e.strerror or e}{where}: check that --out is a writable folder with free "
              "space; a rerun of the same command resumes", file=sys.stderr)
        return 2
    print(summary)
    if not summary["written"]:   # an empty dataset is a failure, whatever the reasons
        print(f"aias-augment: error: no image written: all {summary['images']} images were skipped; see "
              f"{a.out}/report.json", file=sys.stderr)
        return 1
    if summary["skipped"]:
        print(f"aias-augment: {summary['skipped']} of {summary['images']} images skipped; see "
              f"{a.out}/report.json", file=sys.stderr)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

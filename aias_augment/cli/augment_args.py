"""The arguments of ``aias-augment``: one parser for an image dataset and for a clip (the input says which runs,
:func:`aias_augment.cli.augment.main`)."""

from __future__ import annotations

import argparse

from aias_augment.cli.dataset_out import add_output_arguments
from aias_augment.core.arg_parser import OneLineArgumentParser
from aias_augment.core.geometry import CAMERA_HEIGHT_PRIOR_M
from aias_augment.core.logs import add_logging_args
from aias_augment.pipeline.config import PRESETS


def build_parser(description: str | None = None) -> OneLineArgumentParser:
    """The one parser of ``aias-augment``: the dataset options, then the clip's group (the input says which runs)."""
    ap = OneLineArgumentParser(
        prog="aias-augment", description=description, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    _add_input_arguments(ap)
    _add_run_arguments(ap)
    _add_clip_arguments(ap)
    add_logging_args(ap)
    add_output_arguments(ap)
    return ap


def _add_input_arguments(ap) -> None:
    src = ap.add_mutually_exclusive_group()
    src.add_argument(
        "--input",
        help="COCO json of the dataset (with --images), or a clip: a video file or a folder "
        "of frames (with --camera and --poses; a static camera's clip needs neither)",
    )
    src.add_argument(
        "--yolo",
        help="a YOLO dataset: its data.yaml, a folder with images/<split>/ and labels/<split>/, or a folder of "
        "images with YOLO txt labels (labels/ beside images/)",
    )
    ap.add_argument(
        "--images",
        metavar="DIR",
        help="image folder for --input; alone: a folder of unlabelled background images "
        "(the output holds only the inserted objects)",
    )
    ap.add_argument(
        "--class-names", nargs="*", default=None, help="YOLO class names by index (default: the data.yaml's names)"
    )
    ap.add_argument(
        "--categories",
        nargs="+",
        default=None,
        help="categories to insert (default: those of --config, else of --assets/--assets-bank, else traffic_cone)",
    )
    ap.add_argument(
        "--per-image",
        type=int,
        default=None,
        help="maximum objects inserted per image (default: --config's max_objects, else 2)",
    )
    ap.add_argument("--preset", choices=PRESETS, default="balanced")
    ap.add_argument(
        "--config",
        metavar="FILE",
        default=None,
        help="YAML of InsertionConfig fields (nested placement_cfg etc.) applied over --preset; "
        "--categories and --per-image apply over it",
    )
    ap.add_argument(
        "--box-convention",
        metavar="FILE",
        default=None,
        help="the JSON `aias-assets box-convention` wrote: inserted boxes sit around their objects as your labels "
        "do (margins per side; applied over --config)",
    )
    ap.add_argument(
        "--assets",
        nargs="+",
        metavar="CATEGORY=PATH",
        default=None,
        help="your own meshes: PATH a mesh file (.glb .gltf .obj .dae .ply .stl .off), a folder of them "
        "or a gazebo model folder; a category may repeat; it need not be a built-in one",
    )
    ap.add_argument(
        "--assets-bank",
        metavar="DIR",
        default=None,
        help="a folder written by `aias-assets from-labels` (its bank.json): its assets per category",
    )
    ap.add_argument(
        "--sun-from",
        metavar="LAT,LON,UTC,HEADING",
        default=None,
        help="the sun from position and time for every image: degrees, ISO UTC time, camera heading "
        "in degrees clockwise from north (e.g. 48.1,11.6,2024-06-01T12:00:00Z,90)",
    )
    ap.add_argument(
        "--envmap",
        metavar="FILE",
        default=None,
        help="an equirectangular HDR/EXR of the scene's light for every image (the camera looks level at "
        "its centre column): its brightest compact light is the sun, the rest the ambient",
    )


def _add_run_arguments(ap) -> None:
    ap.add_argument("--out", required=True)
    ap.add_argument("--workers", type=int, default=1)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--limit", type=int, default=None, help="process only the first N images")
    ap.add_argument(
        "--backend",
        choices=("local", "ray"),
        default="local",
        help="local: this process or a pool of --workers; ray: Ray tasks (pip install 'aias-augment[ray]')"
        ", same outputs",
    )
    ap.add_argument("--address", default=None, help="--backend ray: an existing cluster (default: a local instance)")
    ap.add_argument(
        "--overwrite",
        action="store_true",
        help="replace the run in --out when its manifest differs (default: refuse; the same run resumes)",
    )
    ap.add_argument(
        "--boxes",
        choices=("clip", "drop"),
        default="clip",
        help="input boxes crossing the image border: clipped to it or dropped (counted in report.json)",
    )
    ap.add_argument(
        "--max-megapixels",
        type=float,
        default=4.0,
        help="larger images are augmented at this size (INTER_AREA; recorded per image); 0: no bound",
    )
    ap.add_argument(
        "--scene-cache",
        default=None,
        help="folder of scene analyses (camera, ground, region, lighting) reused across runs and workers",
    )


def _add_clip_arguments(ap) -> None:
    clip = ap.add_argument_group("clip (--input is a video file or a frame folder)")
    clip.add_argument(
        "--camera",
        help="KITTI calib.txt, pyslam KITTI*.yaml, or a yaml with fx, fy, cx, cy (default for a static camera: "
        "estimated from the first frame)",
    )
    clip.add_argument("--poses", help="one pose per frame: KITTI (12 numbers) or TUM (tx ty tz qx qy qz qw) lines")
    clip.add_argument(
        "--stereo-right",
        metavar="FRAMES",
        help="the rectified right camera's frames (a folder or video, frame for frame): poses by stereo odometry "
        "instead of --poses; --camera must give both cameras (KITTI calib.txt P0/P1, or a yaml with Camera.bf)",
    )
    clip.add_argument("--colour", action="store_true", help="KITTI calib.txt: the colour camera (P2)")
    clip.add_argument("--start", type=int, default=0, help="first frame")
    clip.add_argument("--stride", type=int, default=1)
    clip.add_argument("--max-frames", type=int, default=None)
    clip.add_argument("--camera-height", type=float, default=CAMERA_HEIGHT_PRIOR_M, help="metres above the ground")
    clip.add_argument("--fps", type=float, default=10.0, help="frame rate of the clip as read (after --stride)")
    clip.add_argument(
        "--object-speed",
        type=float,
        default=0.0,
        metavar="M_PER_S",
        help="the object moves along its heading at this speed (a car driving, a cart crossing); 0: it stands",
    )
    clip.add_argument(
        "--object-start",
        type=float,
        default=0.0,
        metavar="SECONDS",
        help="with --object-speed: the object stands this long first (a parked car pulling out)",
    )
    clip.add_argument(
        "--object-accel",
        type=float,
        default=0.0,
        metavar="SECONDS",
        help="with --object-speed: it reaches its speed from rest over this long (0: at once)",
    )
    clip.add_argument(
        "--topple",
        type=float,
        default=0.0,
        metavar="SECONDS",
        help="the object is knocked over during the clip, falling onto its side over this long; 0: it stays upright",
    )
    clip.add_argument(
        "--objects",
        type=int,
        default=1,
        metavar="N",
        help="objects inserted into the clip, each with its own track (alternating sides of the path, nearer each)",
    )
    clip.add_argument(
        "--labels",
        metavar="FILE",
        help="the clip's own track labels (MOTChallenge gt.txt or COCO-video json): carried into the output with "
        "their track ids, occluding inserted objects behind them",
    )
    clip.add_argument(
        "--labels-format", choices=("coco-video", "mot"), default=None, help="of --labels (default: detected)"
    )
    clip.add_argument(
        "--labels-category", default="object", metavar="NAME", help="the class of --labels' MOT rows (MOT names none)"
    )
    clip.add_argument("--lighting", choices=("clip", "ambient"), default="clip")
    clip.add_argument(
        "--harmonize",
        default="fast",
        choices=("none", "reinhard", "camera", "fast", "network"),
        help="clip harmonization ('fast': one colour transform for the whole clip)",
    )
    clip.add_argument(
        "--flow-refine",
        action="store_true",
        help="track the ground under the object (KLT) and correct drifting poses per frame",
    )

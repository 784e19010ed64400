"""``aias-study``: generate the pools, train the runs, summarize (``python -m detection_eval.study``)."""

from __future__ import annotations

import argparse
import logging
from pathlib import Path

from aias_augment.core.arg_parser import OneLineArgumentParser
from aias_augment.core.config import ConfigError
from aias_augment.core.logs import add_logging_args, configure_logging
from detection_eval.config import load_detector_config
from detection_eval.data import load_yolo_dir
from detection_eval.study.arms import PER_SEED_ARMS, available_arms, uses_pool
from detection_eval.study.config import dataset_root, load_study_config
from detection_eval.study.pools import generate_arm_set
from detection_eval.study.report import write_summary
from detection_eval.study.runs import run_one
from detection_eval.study.splits import split_dev, thin_cone_images

log = logging.getLogger("detection_eval.study")


def main(argv: list[str] | None = None, command: str | None = None) -> None:
    """``command``: how the run is named in the table and ``run.json`` (default ``aias-study <argv>``); a study's
    ``run.py`` passes its own ``python -m studies.detection.<study> ...``."""
    import torch

    p = OneLineArgumentParser(
        prog="aias-study", description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    p.add_argument("--config", default="studies/detection/core/config.yaml")
    p.add_argument("--stage", choices=("all", "generate", "train", "summarize"), default="all")
    p.add_argument("--arms", nargs="*", help="subset of the config's arms")
    p.add_argument("--seeds", nargs="*", type=int, help="subset of the config's seeds")
    p.add_argument("--amounts", nargs="*", type=int, help="subset of the config's amounts")
    p.add_argument("--force", action="store_true", help="re-run runs whose results exist")
    add_logging_args(p, default="INFO")  # a study runs for hours: its INFO lines are the progress log
    args = p.parse_args(argv)
    configure_logging(args, fmt="%(asctime)s %(levelname)s %(name)s: %(message)s")
    torch.set_num_threads(1)
    try:
        _run(args, argv, command)
    except (ValueError, OSError, ConfigError) as e:  # a bad config or dataset: one line (DEBUG: the traceback)
        log.debug("aias-study failed", exc_info=True)
        p.exit(2, f"aias-study: error: {' '.join(str(e).split())}\n")


def _run(args, argv, command: str | None = None) -> None:
    import shlex
    import sys

    cfg = load_study_config(args.config)
    arms = available_arms(args.arms or cfg.arms)
    seeds = args.seeds if args.seeds is not None else list(cfg.seeds)
    amounts = args.amounts if args.amounts is not None else list(cfg.amounts)
    if command is None:
        command = "aias-study " + " ".join(shlex.quote(a) for a in (sys.argv[1:] if argv is None else argv))
    root = dataset_root(cfg)
    train = load_yolo_dir(root, cfg.train_split, cfg.class_names)
    val = load_yolo_dir(root, cfg.val_split, cfg.class_names)
    train, dev = split_dev(train, cfg.dev_cone_images, cfg.dev_empty_images, cfg.dev_seed)
    log.info(
        "train: %d images, %d boxes; dev: %d images, %d boxes", len(train), train.num_boxes, len(dev), dev.num_boxes
    )
    if args.stage == "generate":
        _, empty = thin_cone_images(train, cfg.keep_fraction, seeds[0])
        for arm in arms:
            if uses_pool(arm) and arm not in PER_SEED_ARMS:
                generate_arm_set(cfg, arm, train, empty)
            elif uses_pool(arm):
                for seed in seeds:
                    base, empty = thin_cone_images(train, cfg.keep_fraction, seed)
                    generate_arm_set(cfg, arm, train, empty, seed, base)
        return
    if args.stage in ("all", "train"):
        from detection_eval.loader import cache_dataset

        det_cfg = load_detector_config(cfg.detector)
        val_cache = cache_dataset(val, det_cfg.train.img_size)
        dev_cache = cache_dataset(dev, det_cfg.train.img_size) if len(dev) else None
        for seed in seeds:
            for arm in arms:
                for amount in amounts if uses_pool(arm) else [None]:
                    run_one(
                        cfg, arm, seed, train, val, val_cache, amount, force=args.force, dev=dev, dev_cache=dev_cache
                    )
    print(write_summary(cfg, str(args.config), command, train, val))


def run_study_folder(folder: Path, argv: list[str] | None = None) -> int:
    """``python -m studies.detection.<study>``: ``aias-study`` with the folder's ``config.yaml`` (another file of
    the folder by ``--config``), named in the table and ``run.json`` by that module command."""
    import shlex
    import sys

    from aias_augment.core.config import REPO_ROOT

    argv = sys.argv[1:] if argv is None else list(argv)
    config = [] if any(a == "--config" or a.startswith("--config=") for a in argv) else ["--config", "config.yaml"]
    argv = [*config, *argv]
    for i, a in enumerate(argv[:-1]):  # a folder's file by its name, shown relative to the repository
        if a == "--config" and not Path(argv[i + 1]).is_absolute() and (folder / argv[i + 1]).is_file():
            argv[i + 1] = str((folder / argv[i + 1]).resolve().relative_to(REPO_ROOT))
    module = ".".join(folder.resolve().relative_to(REPO_ROOT).parts)
    main(argv, command=" ".join(["python", "-m", module, *(shlex.quote(a) for a in argv)]))
    return 0

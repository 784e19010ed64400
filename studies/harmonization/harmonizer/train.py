#!/usr/bin/env python
"""Train the harmonization network and/or the fast harmonizer on pairs made from real images.

  nice -n 10 .venv/bin/python -m studies.harmonization.harmonizer.train --config configs/harmonize_small.yaml \
      --which both --out-network checkpoints/harmonizer_small.pt --out-fast checkpoints/harmonizer_fast.pt
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import logging
import shlex
import sys
import time

from aias_augment.apply.harmonize.train import (
    TrainConfig,
    cached_pool,
    train_fast,
    train_network,
    tune_camera_strengths,
)
from aias_augment.core.config import load_config


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--config", default="configs/harmonize_small.yaml")
    ap.add_argument(
        "--which",
        choices=["network", "fast", "both", "camera"],
        default="both",
        help="camera: grid-search the camera matching's gain strengths on training pairs (no checkpoint)",
    )
    ap.add_argument("--out-network", default="checkpoints/harmonizer_small.pt")
    ap.add_argument("--out-fast", default="checkpoints/harmonizer_fast.pt")
    ap.add_argument("--init-network", default=None, help="continue training from this network checkpoint")
    ap.add_argument("--init-fast", default=None, help="continue training the fast model from this checkpoint")
    ap.add_argument(
        "--init-global",
        default=None,
        help="fast-harmonizer checkpoint that starts the network's global stage (network.global_stage)",
    )
    ap.add_argument("--time-limit-s", type=float, default=None, help="override the config's network time limit")
    args = ap.parse_args(argv)
    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(message)s")
    cfg = load_config(TrainConfig, args.config)
    if args.time_limit_s is not None:
        cfg = dataclasses.replace(cfg, time_limit_s=args.time_limit_s)
    meta = {"command": " ".join(shlex.quote(a) for a in [sys.executable.split("/")[-1], *sys.argv])}
    t0 = time.perf_counter()
    pool = cached_pool(cfg.data, cfg.network.resolution_px, cfg.seed)
    meta["pool_time_s"] = round(time.perf_counter() - t0, 1)
    results = {}
    if args.which == "camera":
        r = tune_camera_strengths(cfg, pool)
        print(json.dumps({k: v for k, v in r.items() if k != "table"}))
        return 0
    if args.which in ("fast", "both"):
        results["fast"] = train_fast(cfg, args.out_fast, pool, meta, init_from=args.init_fast)
    if args.which in ("network", "both"):
        # "both": the network's global stage starts from the fast model just trained (same architecture)
        init_global = args.init_global or (
            args.out_fast if args.which == "both" and cfg.network.global_stage and args.init_network is None else None
        )
        results["network"] = train_network(
            cfg, args.out_network, pool, meta, init_from=args.init_network, init_global_from=init_global
        )
    for k, r in results.items():
        print(
            json.dumps(
                {
                    "which": k,
                    "steps": r["steps"],
                    "train_time_s": r["train_time_s"],
                    "holdout_raw_fmse": round(r["holdout_raw_fmse"], 2),
                    "holdout_fmse": round(r["holdout_fmse"], 2),
                }
            )
        )
    print(f"total wall time {time.perf_counter() - t0:.1f} s")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

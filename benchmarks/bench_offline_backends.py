"""Throughput of ``aias-augment`` on one input: the local pool with 1 and 2 workers and Ray with 2 workers, the
outputs compared byte for byte; and the cost of the manifest and the checks (a resumed run, where every record is
reused, costs exactly the manifest hashes, the output checks and the COCO assembly).

  python -m benchmarks.bench_offline_backends --n 12 --out results/bench/offline_backends.json

Wall time per configuration (a fresh output folder each; the pool's includes starting its spawn workers) and the CPU
time of this process and its pool children (Ray's workers are not children: not counted). Ray: the local instance
is started apart (``ray_init_s``), then the jobs run cold (new worker processes: imports, EGL context) and again warm
into another folder. On a machine where the workers share cores the 2-worker figures measure overhead, not scaling:
the result says which.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import resource
import shutil
import sys
import tempfile
import time
from dataclasses import replace
from pathlib import Path

from aias_augment.cli.offline import items_from_yolo, run
from aias_augment.core.config import data_root
from aias_augment.pipeline.image import load_preset


def _cpu() -> float:
    s, c = resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(resource.RUSAGE_CHILDREN)
    return s.ru_utime + s.ru_stime + c.ru_utime + c.ru_stime


def _tree_bytes(out: Path) -> dict:
    names = ["annotations.json", "report.json", "manifest.json"] + sorted(
        f"images/{p.name}" for p in (out / "images").iterdir()
    )
    return {n: (out / n).read_bytes() for n in names}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--images", default=str(data_root() / "tracon" / "images" / "train"))
    ap.add_argument("--n", type=int, default=12)
    ap.add_argument("--preset", default="fast")
    ap.add_argument("--configs", nargs="+", default=["local:1", "local:2", "ray:2"])
    ap.add_argument("--out", default="results/bench/offline_backends.json")
    ap.add_argument("--note", default="", help="machine load, pinning (written into the result)")
    a = ap.parse_args(argv)
    all_items = items_from_yolo(a.images, class_names=["cone"])
    items, warm_items = all_items[: a.n], all_items[a.n : 2 * a.n]
    cfg = replace(load_preset(a.preset), categories=("traffic_cone",), max_objects=1, min_objects=1)
    tmp = Path(tempfile.mkdtemp(prefix="bench_offline_"))
    rows, trees = [], {}
    try:
        for spec in a.configs:
            backend, workers = spec.split(":")
            extra = {}
            if backend == "ray":  # the instance is started here, timed apart, and kept for a second (warm) run
                import ray

                t0 = time.perf_counter()
                try:
                    ray.init(
                        num_cpus=int(workers),
                        include_dashboard=False,
                        log_to_driver=False,
                        runtime_env={
                            "env_vars": {
                                k: os.environ[k]
                                for k in ("PYOPENGL_PLATFORM", "AIAS_DATA", "NO_ALBUMENTATIONS_UPDATE")
                                if k in os.environ
                            }
                        },
                    )
                except Exception as e:  # the raylet may not register within Ray's 30 s on a starved machine
                    ray.shutdown()
                    rows.append({"config": spec, "error": f"{type(e).__name__}: {str(e)[:300]}"})
                    continue
                extra["ray_init_s"] = time.perf_counter() - t0
            out = tmp / spec.replace(":", "_")
            c0, t0 = _cpu(), time.perf_counter()
            summary = run(items, cfg, 0, str(out), workers=int(workers), backend=backend, preset=a.preset)
            wall, cpu = time.perf_counter() - t0, _cpu() - c0
            if backend == "ray" and warm_items:
                # The NEXT n images (the workers' in-memory scene caches hold the first n: the same images again
                # would time the cache, not Ray) on the warm workers: imports done, renderers created.
                t2 = time.perf_counter()
                run(warm_items, cfg, 0, str(tmp / "ray_warm"), workers=int(workers), backend=backend, preset=a.preset)
                extra["warm_wall_s_next_n_images"] = time.perf_counter() - t2
                extra["warm_images_per_s"] = len(warm_items) / extra["warm_wall_s_next_n_images"]
                shutil.rmtree(tmp / "ray_warm", ignore_errors=True)
                ray.shutdown()
            # Resumed run on the complete folder: manifest (content hashes), output checks, COCO, report.
            c1, t1 = _cpu(), time.perf_counter()
            run(items, cfg, 0, str(out), workers=1, backend="local", preset=a.preset)
            resume_wall, resume_cpu = time.perf_counter() - t1, _cpu() - c1
            trees[spec] = _tree_bytes(out)
            rows.append(
                {
                    "config": spec,
                    "images": len(items),
                    "written": summary["written"],
                    "wall_s": wall,
                    "images_per_s": len(items) / wall,
                    "cpu_s": cpu,
                    "median_seconds_per_image": summary["median_seconds_per_image"],
                    "resume_wall_s": resume_wall,
                    "resume_cpu_s": resume_cpu,
                    "resume_ms_per_image": 1e3 * resume_wall / len(items),
                    **extra,
                }
            )
            print(json.dumps(rows[-1]), flush=True)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    ref = next(iter(trees.values()), None)
    identical = {spec: t == ref for spec, t in trees.items()}
    res = {
        "command": "python -m benchmarks.bench_offline_backends " + " ".join(sys.argv[1:] if argv is None else argv),
        "input": f"{a.images} (first {len(items)} images), preset {a.preset}, 1 object per image, seed 0",
        "rows": rows,
        "outputs_byte_identical_to_first": identical,
        "machine": f"{os.cpu_count()} CPUs visible, affinity {sorted(os.sched_getaffinity(0))}, "
        f"{platform.processor() or platform.machine()}",
        "note": a.note,
    }
    Path(a.out).parent.mkdir(parents=True, exist_ok=True)
    Path(a.out).write_text(json.dumps(res, indent=1))
    print(json.dumps({"outputs_byte_identical_to_first": identical}))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

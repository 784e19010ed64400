"""The offline CLI per image at the photos' own size, on one core: issue 56's bound (fast <= 0.3 s, balanced
<= 1.0 s per image).

    taskset -c 0 python -m benchmarks.bench_offline_sizes --out results/bench/offline_sizes

Two sets of 12 photos from the shared data, copied into a temporary folder (the CLI reads a folder):

* ``tracon``: the first 12 TraCon training photos by name (339-1024 px on their long side);
* ``road_2mp``: the 9 DGP camera frames (1936x1216, 2.4 MP) and KITTI 06 colour frames 12-14 (1242x375).

Each (set, preset) runs ``aias-augment --images DIR --preset P --per-image 2 --seed 0`` in a fresh process pinned to
``--cpu`` with one thread per library, ``--rounds`` times, alternating presets; reported: the run's own median seconds
per image (``summary.json``: the per-image work, imports and start-up excluded) and the process's wall seconds per
image (everything), medians over the rounds. Writes ``<out>.json`` and ``<out>.md`` with the command.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from statistics import median

from aias_augment.core.config import data_root
from benchmarks.bench_regression_guard import REPO, SINGLE_THREAD, tracon_files

BOUND_S = {"fast": 0.3, "balanced": 1.0}


def photo_sets() -> dict[str, list[Path]]:
    root = data_root()
    tracon = tracon_files(12)
    dgp = sorted((root / "dgp_scene").rglob("rgb/*/*.jpg"))
    kitti = [root / "kitti06_color_snippet" / f"kitti06-{i}-color.png" for i in (12, 13, 14)]
    sets = {"tracon": tracon, "road_2mp": dgp + kitti}
    for name, files in sets.items():
        missing = [str(f) for f in files if not f.exists()]
        if len(files) != 12 or missing:
            raise SystemExit(
                f"bench_offline_sizes: set {name} needs 12 photos under {root}, got {len(files)} {missing}"
            )
    return sets


def run_cli(images: Path, preset: str, cpu: int, tmp: Path) -> dict:
    out = tmp / f"out_{preset}"
    shutil.rmtree(out, ignore_errors=True)
    cmd = ["taskset", "-c", str(cpu), sys.executable, "-m", "aias_augment.cli.augment", "--images", str(images)]
    cmd += ["--preset", preset, "--per-image", "2", "--seed", "0", "--out", str(out)]
    t0 = time.perf_counter()
    r = subprocess.run(cmd, cwd=REPO, env={**os.environ, **SINGLE_THREAD}, capture_output=True, text=True)
    wall = time.perf_counter() - t0
    if r.returncode != 0 or not (out / "summary.json").exists():
        raise SystemExit(f"bench_offline_sizes: {preset} on {images} failed (exit {r.returncode}): {r.stderr[-500:]}")
    summary = json.loads((out / "summary.json").read_text())
    if summary["images"] != len(list(images.iterdir())):
        raise SystemExit(f"bench_offline_sizes: {preset} read {summary['images']} of the photos in {images}")
    return {"median_s_per_image": summary["median_seconds_per_image"], "wall_s": wall, "images": summary["images"]}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rounds", type=int, default=2)
    ap.add_argument("--cpu", type=int, default=0, help="the core every run is pinned to (taskset -c)")
    ap.add_argument("--out", type=Path, default=REPO / "results" / "bench" / "offline_sizes")
    a = ap.parse_args(argv)
    sets = photo_sets()
    samples: dict = {s: {p: [] for p in BOUND_S} for s in sets}
    with tempfile.TemporaryDirectory(prefix="bench_offline_sizes_") as tmp_dir:
        tmp = Path(tmp_dir)
        for name, files in sets.items():
            folder = tmp / name
            folder.mkdir()
            for i, f in enumerate(files):  # numbered: DGP's cameras share file names
                shutil.copy(f, folder / f"{i:02d}_{f.name}")
            for r in range(a.rounds):
                for preset in BOUND_S if r % 2 == 0 else reversed(list(BOUND_S)):
                    samples[name][preset].append(run_cli(folder, preset, a.cpu, tmp))
                    print(f"{name} {preset} round {r + 1}: {samples[name][preset][-1]}", flush=True)

    rows = []
    for name in sets:
        for preset, bound in BOUND_S.items():
            s = samples[name][preset]
            per = median([x["median_s_per_image"] for x in s])
            wall = median([x["wall_s"] / x["images"] for x in s])
            rows.append(
                {
                    "set": name,
                    "preset": preset,
                    "median_s_per_image": per,
                    "wall_s_per_image": wall,
                    "bound_s": bound,
                    "met": per <= bound,
                }
            )
    command = "taskset -c {0} python -m benchmarks.bench_offline_sizes --rounds {1} --cpu {0} --out {2}".format(
        a.cpu, a.rounds, os.path.relpath(a.out, REPO)
    )
    a.out.parent.mkdir(parents=True, exist_ok=True)
    a.out.with_suffix(".json").write_text(json.dumps({"command": command, "rows": rows, "samples": samples}, indent=1))
    lines = [
        "# The offline CLI per image at the photos' own size (one core)",
        "",
        f"    {command}",
        "",
        "| set | preset | run's median s per image | wall s per image (process) | bound | met |",
        "|---|---|---:|---:|---:|---|",
    ]
    lines += [
        f"| {r['set']} | {r['preset']} | {r['median_s_per_image']:.2f} | {r['wall_s_per_image']:.2f} | "
        f"{r['bound_s']:.1f} | {'yes' if r['met'] else 'no'} |"
        for r in rows
    ]
    a.out.with_suffix(".md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

"""First sight of an image with the fast preset: a reference checkout against the working tree, alternately.

    git worktree add /tmp/wt-ref <ref commit>
    taskset -c 1 nice python -m benchmarks.bench_first_sight --ref-root /tmp/wt-ref [--tree-root /tmp/wt-new] --rounds 3

``InsertObjects(preset="fast", p=1)`` in a ``Compose`` (the regression guard's transform) on 640x480 TraCon training
roads: ``--warmup`` calls over six roads in rotation, then one call on each of ``--first-sight`` roads the process
has not seen (the scene analysis and the asset views run); then, in the same process, ``analyse_scene`` alone
(the transform's analysis config, no cache) on each of those roads. Each round runs one process per side
(``PYTHONPATH`` the side's root, one thread per library, on the core this command is pinned to), the side that goes
first alternating. Prints the median CPU ms (``time.process_time``, all threads) of each side's first-sight calls
and analyses, and the first-sight wall ms. ``--sun decided``: the first-sight roads are the next photos on which the
evidence model decides a direct sun (they pay the sun search that the others skip).
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import time

from benchmarks.bench_regression_guard import REPO, ROTATION, SINGLE_THREAD, tracon_files


def road_640(path):
    """A TraCon photo as the bench sees it: RGB, area-resized to 640x480."""
    import cv2

    return cv2.resize(cv2.cvtColor(cv2.imread(str(path)), cv2.COLOR_BGR2RGB), (640, 480), interpolation=cv2.INTER_AREA)


def sun_decided_roads(n: int) -> list[str]:
    """The first ``n`` TraCon training photos after the rotation's six (sorted by name) on which the evidence model
    decides a direct sun at 640x480: first sights that pay the sun search."""
    from aias_augment.analyse.lighting.sun_evidence import decide_direct_sun, direct_sun_probability

    out: list[str] = []
    for f in sorted(tracon_files(1)[0].parent.glob("*.jpg"))[ROTATION:]:  # tracon_files' order, all of them
        if decide_direct_sun(direct_sun_probability(road_640(f))):
            out.append(str(f))
            if len(out) == n:
                return out
    raise SystemExit(f"bench_first_sight: only {len(out)} TraCon photos with a decided sun, {n} asked")


def worker(warmup: int, first_sight: int, photos: list[str] | None = None) -> dict:
    import albumentations as A
    import numpy as np

    from aias_augment import InsertObjects

    rotation = tracon_files(ROTATION + (0 if photos else first_sight))
    images = [road_640(f) for f in (rotation[:ROTATION] + photos if photos else rotation)]
    tf = A.Compose(
        [InsertObjects(preset="fast", p=1.0)], bbox_params=A.BboxParams(format="coco", label_fields=["labels"]), seed=7
    )
    no_boxes = np.zeros((0, 4))
    for i in range(warmup):
        tf(image=images[i % ROTATION], bboxes=no_boxes, labels=[])
    cpu, wall = [], []
    for img in images[ROTATION:]:
        t0, c0 = time.perf_counter(), time.process_time()
        tf(image=img, bboxes=no_boxes, labels=[])
        wall.append(1e3 * (time.perf_counter() - t0))
        cpu.append(1e3 * (time.process_time() - c0))
    from aias_augment.analyse.analysis import analyse_scene
    from aias_augment.core.frame import Frame

    cfg = tf.transforms[0].config
    analyse = []
    for img in images[ROTATION:]:
        c0 = time.process_time()
        analyse_scene(Frame(img), cfg)
        analyse.append(1e3 * (time.process_time() - c0))
    return {"cpu_ms": cpu, "wall_ms": wall, "analyse_cpu_ms": analyse}


def run_side(root: str, a) -> dict:
    env = {**os.environ, **SINGLE_THREAD, "PYTHONPATH": root, "NO_ALBUMENTATIONS_UPDATE": "1"}
    env.setdefault("PYOPENGL_PLATFORM", "egl")
    # -P: the script's own folder is not put on sys.path, the side's root (PYTHONPATH) is what it imports
    cmd = [sys.executable, "-P", os.path.abspath(__file__), "--worker", str(a.warmup), str(a.first_sight)]
    if a.photos:
        cmd += ["--photos", *a.photos]
    out = subprocess.run(cmd, cwd=root, env=env, capture_output=True, text=True, check=True).stdout
    return json.loads(out.strip().splitlines()[-1])


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--ref-root", help="a checkout of the reference commit (git worktree add)")
    ap.add_argument("--tree-root", default=str(REPO), help="the checkout measured against it (default: this tree)")
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--warmup", type=int, default=12, help="calls over the six rotation roads before timing")
    ap.add_argument("--first-sight", type=int, default=12, help="first-sight roads per process")
    ap.add_argument(
        "--sun",
        choices=("any", "decided"),
        default="any",
        help="first-sight roads: the next photos by name (any), or the next on which the evidence decides a sun",
    )
    ap.add_argument("--worker", nargs=2, type=int, help=argparse.SUPPRESS)
    ap.add_argument("--photos", nargs="+", help=argparse.SUPPRESS)
    a = ap.parse_args(argv)
    if a.worker:
        print(json.dumps(worker(*a.worker, a.photos)))
        return 0
    if a.sun == "decided":
        a.photos = sun_decided_roads(a.first_sight)
        print(f"first-sight roads with a decided sun: {[os.path.basename(p) for p in a.photos]}", file=sys.stderr)
    for name, root in (("--ref-root", a.ref_root), ("--tree-root", a.tree_root)):
        if not root or not os.path.isdir(os.path.join(root, "aias_augment")):
            print(
                f"bench_first_sight: {name} {root} holds no aias_augment checkout (git worktree add)", file=sys.stderr
            )
            return 2
    sides = {"ref": a.ref_root, "tree": a.tree_root}
    got: dict = {k: {"cpu_ms": [], "wall_ms": [], "analyse_cpu_ms": []} for k in sides}
    for r in range(a.rounds):
        for name in list(sides) if r % 2 == 0 else list(sides)[::-1]:
            res = run_side(sides[name], a)
            for k in got[name]:
                got[name][k] += res[k]
            print(f"round {r + 1} {name}: cpu median {statistics.median(res['cpu_ms']):.1f} ms", file=sys.stderr)
    print("| side | first-sight CPU ms | first-sight wall ms | analyse_scene CPU ms | calls |")
    print("|---|---:|---:|---:|---:|")
    med = {name: {k: statistics.median(x) for k, x in v.items()} for name, v in got.items()}
    for name, m in med.items():
        n = len(got[name]["cpu_ms"])
        print(f"| {name} | {m['cpu_ms']:.1f} | {m['wall_ms']:.1f} | {m['analyse_cpu_ms']:.1f} | {n} |")
    print(
        f"| tree / ref | {med['tree']['cpu_ms'] / med['ref']['cpu_ms']:.3f} | | "
        f"{med['tree']['analyse_cpu_ms'] / med['ref']['analyse_cpu_ms']:.3f} | |"
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())

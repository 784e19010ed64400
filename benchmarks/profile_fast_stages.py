"""Where the fast preset's time goes, by stage: a fresh call on a seen image, and the first sight of an image.

    taskset -c 0 nice python -m benchmarks.profile_fast_stages --out results/bench/profile_fast.md
    taskset -c 0 nice python -m benchmarks.profile_fast_stages --sun decided --out results/bench/profile_fast_sun.md

``InsertObjects(preset="fast", p=1)`` in a ``Compose`` on 640x480 TraCon training roads (the regression guard's
transform, ``benchmarks/bench_regression_guard.py``): ``--warmup`` calls over six roads in rotation, then ``--calls``
fresh calls over the same six (an image seen before: scene-cache hit, a new insertion), then ``--first-sight`` calls
each on a road the process has not seen (the scene analysis and the asset views run); ``--sun decided``: every road
one on which the evidence model decides a direct sun (the objects cast sun shadows). The process runs under py-spy
(a sampling profiler: ``--rate`` stacks per second, native calls counted in the Python frame that made them, waits
included so that a frame waiting on the GL rasteriser's threads carries the render's cost); each sample goes to the
phase whose function is on its stack and to the pipeline step and stage of its innermost ``aias_augment`` frame (the
module: a stage is a file in this code base). Shares are of the phase's samples; ms per call are the share times the
phase's median CPU ms per call measured in the process (``time.process_time``, all its threads), so that a loaded
machine's waiting for a core does not count.
"""

from __future__ import annotations

import argparse
import json
import os
import re
import shlex
import shutil
import subprocess
import sys
import tempfile
import time
from collections import Counter
from pathlib import Path

from benchmarks.bench_first_sight import sun_decided_roads
from benchmarks.bench_regression_guard import REPO, ROTATION, SINGLE_THREAD, tracon_files

PHASES = {"_phase_fresh": "fresh call (seen image)", "_phase_first_sight": "first sight of an image"}
FRAME = re.compile(r"^(?P<func>.*) \((?P<file>.*):(?P<line>\d+)\)$")
OUTSIDE = "(outside aias_augment: albumentations' Compose, this script)"


def _phase_warmup(tf, images, n, no_boxes):
    for i in range(n):
        tf(image=images[i % ROTATION], bboxes=no_boxes, labels=[])


def _timed_calls(tf, images, no_boxes) -> list[tuple[float, float]]:
    out = []
    for img in images:
        t0, c0 = time.perf_counter(), time.process_time()
        tf(image=img, bboxes=no_boxes, labels=[])
        out.append((1e3 * (time.perf_counter() - t0), 1e3 * (time.process_time() - c0)))
    return out


def _phase_fresh(tf, images, n, no_boxes):
    return _timed_calls(tf, [images[i % ROTATION] for i in range(n)], no_boxes)


def _phase_first_sight(tf, images, no_boxes):
    return _timed_calls(tf, images, no_boxes)


def worker(a) -> dict:
    os.environ.setdefault("NO_ALBUMENTATIONS_UPDATE", "1")
    import albumentations as A
    import cv2
    import numpy as np

    from aias_augment import InsertObjects

    images = [
        cv2.resize(cv2.cvtColor(cv2.imread(str(f)), cv2.COLOR_BGR2RGB), (640, 480), interpolation=cv2.INTER_AREA)
        for f in (
            sun_decided_roads(ROTATION + a.first_sight)
            if a.sun == "decided"
            else tracon_files(ROTATION + a.first_sight)
        )
    ]
    tf = A.Compose(
        [InsertObjects(preset="fast", p=1.0)], bbox_params=A.BboxParams(format="coco", label_fields=["labels"]), seed=7
    )
    no_boxes = np.zeros((0, 4))
    _phase_warmup(tf, images, a.warmup, no_boxes)
    fresh = _phase_fresh(tf, images, a.calls, no_boxes)
    first = _phase_first_sight(tf, images[ROTATION:], no_boxes)
    return {
        "_phase_fresh": {"wall_ms": [w for w, _ in fresh], "cpu_ms": [c for _, c in fresh]},
        "_phase_first_sight": {"wall_ms": [w for w, _ in first], "cpu_ms": [c for _, c in first]},
    }


def parse_raw(text: str) -> list[tuple[list[tuple[str, str]], int]]:
    """py-spy's raw format: one line per distinct stack, ``frame;frame;... count``, outermost frame first."""
    stacks = []
    for line in text.splitlines():
        stack, _, count = line.rpartition(" ")
        if not stack or not count.isdigit():
            continue
        frames = []
        for f in stack.split(";"):
            m = FRAME.match(f.strip())
            frames.append((m["func"], m["file"]) if m else (f.strip(), ""))
        stacks.append((frames, int(count)))
    return stacks


def _project_path(file: str) -> str | None:
    i = file.replace("\\", "/").rfind("aias_augment/")
    return file[i:] if i >= 0 else None


def attribute(stacks) -> dict[str, dict[str, Counter]]:
    """Per phase: samples by pipeline step (``aias_augment/<step>/``), by stage (the module of the innermost
    aias_augment frame) and by function."""
    out = {p: {"step": Counter(), "stage": Counter(), "function": Counter()} for p in PHASES}
    for frames, n in stacks:
        phase = next((f for f, _ in frames if f in PHASES), None)
        if phase is None:
            continue
        inner = next(((f, _project_path(p)) for f, p in reversed(frames) if _project_path(p)), None)
        out[phase]["step"][inner[1].split("/")[1] if inner else OUTSIDE] += n
        out[phase]["stage"][inner[1] if inner else OUTSIDE] += n
        out[phase]["function"][f"{inner[1]}:{inner[0]}" if inner else OUTSIDE] += n
    return out


def _median(xs):
    xs = sorted(xs)
    m = len(xs) // 2
    return xs[m] if len(xs) % 2 else 0.5 * (xs[m - 1] + xs[m])


def markdown(command: str, a, counts: dict, timings: dict, load: tuple, code: str) -> str:
    lines = [
        "# The fast preset by stage",
        "",
        f"    {command}",
        "",
        f"Code: {code}.",
        "",
        f"py-spy {a.rate} samples/s; {a.warmup} warm-up calls, {a.calls} fresh calls over {ROTATION} roads, "
        f"{a.first_sight} first-sight roads"
        + (
            " (all of them photos on which the evidence decides a sun: the objects cast sun shadows)"
            if a.sun == "decided"
            else ""
        )
        + f' (640x480 TraCon, `InsertObjects(preset="fast", p=1)`). One core '
        f"(taskset), a shared machine (load average {load[0]:.1f} before, {load[1]:.1f} after): ms are CPU ms "
        "(the phase's median CPU per call times the stage's share of samples, waits on the GL threads included), "
        "the shares are what to read.",
        "",
    ]
    for phase, title in PHASES.items():
        stage = counts[phase]["stage"]
        total = sum(stage.values())
        cpu, wall = _median(timings[phase]["cpu_ms"]), _median(timings[phase]["wall_ms"])
        lines += [
            f"## {title}: {cpu:.1f} ms CPU per call (median; wall {wall:.1f} ms), {total} samples",
            "",
        ]
        for key, head in (("step", "step"), ("stage", "stage (module)")):
            lines += [f"| {head} | ms | share |", "|---|---:|---:|"]
            for name, n in counts[phase][key].most_common():
                lines.append(f"| `{name}` | {cpu * n / total:.1f} | {100 * n / total:.1f} % |")
            lines.append("")
        lines += ["Top functions (innermost `aias_augment` frame):", "", "| function | ms | share |"]
        lines.append("|---|---:|---:|")
        for name, n in counts[phase]["function"].most_common(a.top):
            lines.append(f"| `{name}` | {cpu * n / total:.1f} | {100 * n / total:.1f} % |")
        lines.append("")
    return "\n".join(lines)


def _code_version() -> str:
    def git(*args):
        return subprocess.run(["git", *args], capture_output=True, text=True, cwd=Path(__file__).parent).stdout.strip()

    dirty = git("status", "--porcelain", "--untracked-files=no")
    return f"HEAD {git('rev-parse', '--short=10', 'HEAD')}" + (" with uncommitted changes" if dirty else "")


def main(argv: list[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--warmup", type=int, default=240)
    ap.add_argument("--calls", type=int, default=200)
    ap.add_argument("--first-sight", type=int, default=12)
    ap.add_argument("--rate", type=int, default=250, help="py-spy samples per second")
    ap.add_argument("--top", type=int, default=15, help="functions listed per phase")
    ap.add_argument(
        "--sun",
        choices=("any", "decided"),
        default="any",
        help="the roads: the first TraCon photos by name (any), or the first on which the evidence decides a sun",
    )
    ap.add_argument("--out", default="results/bench/profile_fast.md")
    ap.add_argument("--worker", default=None, help=argparse.SUPPRESS)
    a = ap.parse_args(argv)
    if a.worker:
        Path(a.worker).write_text(json.dumps(worker(a)))
        return 0
    py_spy = shutil.which("py-spy") or str(Path(sys.executable).with_name("py-spy"))
    if not Path(py_spy).exists():
        print("profile_fast_stages: error: py-spy not found: pip install 'aias-augment[dev]'", file=sys.stderr)
        return 2
    with tempfile.TemporaryDirectory(prefix="aias_profile_") as tmp:
        raw, res = Path(tmp) / "stacks.txt", Path(tmp) / "timings.json"
        # --idle: a frame waiting on the GL rasteriser's threads is sampled too (the wait is the render's cost).
        cmd = [py_spy, "record", "--idle", "--format", "raw", "-r", str(a.rate), "-o", str(raw), "--"]
        cmd += [sys.executable, "-m", "benchmarks.profile_fast_stages", *argv, "--worker", str(res)]
        load_before = os.getloadavg()
        r = subprocess.run(cmd, env={**os.environ, **SINGLE_THREAD}, capture_output=True, text=True, cwd=REPO)
        if r.returncode or not res.exists():
            tail = (r.stderr.strip().splitlines() or ["(no stderr)"])[-1]
            print(f"profile_fast_stages: error: the profiled run failed: {tail}", file=sys.stderr)
            return 2
        counts = attribute(parse_raw(raw.read_text()))
        timings = json.loads(res.read_text())
    cpus = ",".join(str(c) for c in sorted(os.sched_getaffinity(0)))
    command = f"taskset -c {cpus} nice python -m benchmarks.profile_fast_stages " + " ".join(
        shlex.quote(x) for x in argv
    )
    text = markdown(command, a, counts, timings, (load_before[0], os.getloadavg()[0]), _code_version())
    Path(a.out).parent.mkdir(parents=True, exist_ok=True)
    Path(a.out).write_text(text)
    print(text)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

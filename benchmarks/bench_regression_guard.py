"""Performance regression guard: a reference commit against the working tree, run alternately in one sitting.

    taskset -c 0 nice python -m benchmarks.bench_regression_guard --ref <commit>           # 3 rounds, ~8 min
    taskset -c 0 nice python -m benchmarks.bench_regression_guard --ref <commit> --quick   # 2 rounds, ~3 min

(Minutes on the project's 2-core machine shared with other jobs, load average 7-10: 4 rounds took 704 s.)

The reference is checked out with ``git worktree add`` into a temporary folder under /tmp (removed at the end) and
imported through ``PYTHONPATH`` in a subprocess; the working tree (or ``--tree <commit>``, checked out the same way)
likewise. Every subprocess is pinned to one core (``taskset -c --cpu``) with one thread per library. Each round runs
each measurement on both sides back to back, the side that goes first alternating between rounds, so that both see
the same machine. Measurements:

* ``transform``: ``InsertObjects(preset="fast", p=1)`` in a ``Compose`` on 640x480 TraCon training roads. After
  ``--warmup`` calls over six roads in rotation, ``--calls`` timed calls over the same six (a fresh insertion on an
  image seen before: a training loop's steady state, ``fresh``), then ``--first-sight`` calls each on a road never
  seen by the process (``first_sight``: the scene analysis and the asset views run).
* ``transform_sun``: the same fresh calls with six TraCon roads on which the evidence model decides a direct sun
  (``bench_first_sight.sun_decided_roads``, chosen once by the tree's code) as the rotation: the objects cast
  projected sun shadows, which the six default roads (no decided sun) never pay for.
* ``transform_labelled``: the same fresh calls on six TraCon roads with two or more labelled cones, their boxes
  passed as a training loop passes its labels (``labelled_roads``): the inserted cones are drawn like the labelled
  ones and continue their row (``arrangement: row``), which the unlabelled roads never exercise.
* ``cli_fast`` / ``cli_balanced``: ``aias-augment --images DIR --preset P`` on the first ``--images`` TraCon training
  photos at their own resolution (2 objects each, seed 0), a new output folder per run: the process's wall seconds,
  its CPU seconds and the run's own median seconds per image (``summary.json``).

Writes ``--out`` (default results/bench/regression_guard.json: medians per side, the ratios tree/ref, every sample,
the command) and prints a table. Wall times on a shared machine move with its load; the ratios, taken within one
sitting, are what the guard reports (a ratio above 1.10 is a slowdown that needs a reason).
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import resource
import shlex
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
TRACON_TRAIN = ("tracon", "images", "train")
SINGLE_THREAD = {k: "1" for k in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMEXPR_NUM_THREADS")}
#: Rotating roads of the transform's steady state (the issue's benchmark: six different TraCon roads).
ROTATION = 6


class GuardError(Exception):
    """A side could not be measured (checkout, import or a failed run): reported in one line, exit 2."""


def _data_root() -> Path:
    return Path(os.environ.get("AIAS_DATA", REPO.parent / "shared" / "data"))


def _label_file(image: Path) -> Path:
    """A TraCon photo's YOLO label file (``labels/<split>/<stem>.txt`` beside ``images/<split>/``)."""
    return image.parent.parent.parent / "labels" / image.parent.name / f"{image.stem}.txt"


def labelled_roads(n: int) -> list[Path]:
    """The first ``n`` TraCon training photos (name order) with two or more labelled cones."""
    out = []
    for f in sorted((_data_root().joinpath(*TRACON_TRAIN)).glob("*.jpg")):
        txt = _label_file(f)
        if txt.exists() and len([ln for ln in txt.read_text().splitlines() if ln.strip()]) >= 2:
            out.append(f)
        if len(out) == n:
            return out
    raise GuardError(f"need {n} TraCon training photos with two or more labelled cones, found {len(out)}")


def _coco_boxes_640x480(image: Path):
    """The photo's YOLO labels as COCO boxes (x, y, w, h) on its 640x480 copy, clipped to the frame."""
    import numpy as np

    lines = _label_file(image).read_text().splitlines()
    rows = np.array([[float(x) for x in ln.split()[1:5]] for ln in lines if ln.strip()])
    x0 = np.clip((rows[:, 0] - rows[:, 2] / 2) * 640, 0, 640)
    y0 = np.clip((rows[:, 1] - rows[:, 3] / 2) * 480, 0, 480)
    x1 = np.clip((rows[:, 0] + rows[:, 2] / 2) * 640, 0, 640)
    y1 = np.clip((rows[:, 1] + rows[:, 3] / 2) * 480, 0, 480)
    keep = (x1 - x0 >= 1) & (y1 - y0 >= 1)
    return np.c_[x0, y0, x1 - x0, y1 - y0][keep]


def tracon_files(n: int) -> list[Path]:
    files = sorted((_data_root().joinpath(*TRACON_TRAIN)).glob("*.jpg"))
    if len(files) < n:
        raise GuardError(f"need {n} TraCon images under {_data_root().joinpath(*TRACON_TRAIN)}, found {len(files)}")
    return files[:n]


# ---------------------------------------------------------------- worker: runs inside the side's PYTHONPATH


def transform_worker(
    warmup: int, calls: int, first_sight: int, root: str, photos: list[str] | None = None, labelled: bool = False
) -> dict:
    """Per-call wall and CPU ms of the fast transform (see the module docstring); run in a subprocess. ``photos``:
    the rotation's roads instead of the first six TraCon ones (then no first sight); ``labelled``: each call passes
    its road's labelled cones."""
    os.environ.setdefault("NO_ALBUMENTATIONS_UPDATE", "1")
    import albumentations as A
    import cv2
    import numpy as np

    import aias_augment
    from aias_augment import InsertObjects

    if not Path(aias_augment.__file__).resolve().is_relative_to(Path(root).resolve()):
        raise GuardError(f"imported aias_augment from {aias_augment.__file__}, not from {root}")
    files = [Path(f) for f in photos] if photos else tracon_files(ROTATION + first_sight)
    images = [
        cv2.resize(cv2.cvtColor(cv2.imread(str(f)), cv2.COLOR_BGR2RGB), (640, 480), interpolation=cv2.INTER_AREA)
        for f in files
    ]
    tf = A.Compose(
        [InsertObjects(preset="fast", p=1.0)], bbox_params=A.BboxParams(format="coco", label_fields=["labels"]), seed=7
    )
    boxes = [_coco_boxes_640x480(f) if labelled else np.zeros((0, 4)) for f in files]

    def call(i: int) -> None:
        tf(image=images[i], bboxes=boxes[i], labels=["cone"] * len(boxes[i]))

    def timed(i: int) -> tuple[float, float]:
        t0, c0 = time.perf_counter(), time.process_time()
        call(i)
        return 1e3 * (time.perf_counter() - t0), 1e3 * (time.process_time() - c0)

    for i in range(warmup):
        call(i % ROTATION)
    fresh = [timed(i % ROTATION) for i in range(calls)]
    first = [timed(ROTATION + i) for i in range(0 if photos else first_sight)]
    return {
        "fresh_ms": [w for w, _ in fresh],
        "fresh_cpu_ms": [c for _, c in fresh],
        "first_sight_ms": [w for w, _ in first],
        "first_sight_cpu_ms": [c for _, c in first],
    }


# ---------------------------------------------------------------- the guard


def _git(*args: str, cwd: Path = REPO) -> str:
    r = subprocess.run(["git", *args], cwd=cwd, capture_output=True, text=True)
    if r.returncode:
        raise GuardError(f"git {' '.join(args)}: {r.stderr.strip().splitlines()[-1] if r.stderr.strip() else r}")
    return r.stdout.strip()


def default_ref() -> str:
    """The merge-base of HEAD with ``main`` (HEAD itself on main: then the guard measures the uncommitted changes)."""
    return _git("merge-base", "HEAD", "main")


class Side:
    """One code version: a folder whose ``aias_augment`` the subprocesses import."""

    def __init__(self, name: str, root: Path, label: str, worktree: bool):
        self.name, self.root, self.label, self.worktree = name, root, label, worktree

    def env(self) -> dict:
        env = {**os.environ, **SINGLE_THREAD, "PYTHONPATH": str(self.root), "NO_ALBUMENTATIONS_UPDATE": "1"}
        env.setdefault("PYOPENGL_PLATFORM", "egl")
        env["AIAS_DATA"] = str(_data_root())
        return env


def checkout(commit: str, name: str, tmp: Path) -> Side:
    sha = _git("rev-parse", "--verify", f"{commit}^{{commit}}")
    path = tmp / f"{name}_{sha[:10]}"
    _git("worktree", "add", "--detach", str(path), sha)
    return Side(name, path, f"{commit} ({sha[:10]})", True)


def working_tree() -> Side:
    head = _git("rev-parse", "--short=10", "HEAD")
    dirty = bool(_git("status", "--porcelain", "--untracked-files=no"))
    return Side("tree", REPO, f"working tree (HEAD {head}{', uncommitted changes' if dirty else ''})", False)


def _run_child(
    side: Side, cmd: list[str], cpu: int, timeout: float
) -> tuple[subprocess.CompletedProcess, float, float]:
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    try:
        r = subprocess.run(
            ["taskset", "-c", str(cpu), *cmd],
            cwd=side.root,
            env=side.env(),
            capture_output=True,
            text=True,
            timeout=timeout,
        )
    except subprocess.TimeoutExpired:
        raise GuardError(f"{side.name}: {' '.join(cmd[:4])} ... ran past {timeout:.0f} s") from None
    wall = time.perf_counter() - t0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu_s = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    if r.returncode:
        tail = (r.stderr.strip().splitlines() or ["(no stderr)"])[-1]
        raise GuardError(f"{side.name} ({side.label}): {' '.join(cmd[1:4])} ... exited {r.returncode}: {tail}")
    return r, wall, cpu_s


def measure_transform(side: Side, a, cpu: int, photos: list[str] | None = None, labelled: bool = False) -> dict:
    cmd = [sys.executable, str(Path(__file__).resolve()), "--worker", "--root", str(side.root)]
    cmd += ["--warmup", str(a.warmup), "--calls", str(a.calls), "--first-sight", str(a.first_sight)]
    if photos:
        cmd += ["--photos", *photos]
    if labelled:
        cmd += ["--labelled"]
    r, _, _ = _run_child(side, cmd, cpu, timeout=900)
    return json.loads(r.stdout.strip().splitlines()[-1])


def measure_cli(side: Side, preset: str, images: Path, tmp: Path, cpu: int) -> dict:
    out = Path(tempfile.mkdtemp(prefix=f"cli_{side.name}_{preset}_", dir=tmp))
    shutil.rmtree(out)  # a new output folder per run: nothing is resumed
    cmd = [sys.executable, "-m", "aias_augment.cli.augment", "--images", str(images), "--preset", preset]
    cmd += ["--per-image", "2", "--seed", "0", "--out", str(out)]
    _, wall, cpu_s = _run_child(side, cmd, cpu, timeout=900)
    summary = json.loads((out / "summary.json").read_text()) if (out / "summary.json").exists() else {}
    shutil.rmtree(out, ignore_errors=True)
    return {"wall_s": wall, "cpu_s": cpu_s, "median_s_per_image": summary.get("median_seconds_per_image")}


def _median(xs: list[float]) -> float | None:
    xs = sorted(x for x in xs if x is not None)
    if not xs:
        return None
    m = len(xs) // 2
    return xs[m] if len(xs) % 2 else 0.5 * (xs[m - 1] + xs[m])


#: (metric, unit, where its samples come from): transform samples pool every call of every round, CLI samples are
#: one per run.
METRICS = (
    ("transform fresh call", "ms", "transform", "fresh_ms"),
    ("transform fresh call (CPU)", "ms", "transform", "fresh_cpu_ms"),
    ("transform first sight", "ms", "transform", "first_sight_ms"),
    ("transform first sight (CPU)", "ms", "transform", "first_sight_cpu_ms"),
    ("transform fresh call, decided sun", "ms", "transform_sun", "fresh_ms"),
    ("transform fresh call, decided sun (CPU)", "ms", "transform_sun", "fresh_cpu_ms"),
    ("transform fresh call, labelled cones", "ms", "transform_labelled", "fresh_ms"),
    ("transform fresh call, labelled cones (CPU)", "ms", "transform_labelled", "fresh_cpu_ms"),
    ("cli fast: run", "s", "cli_fast", "wall_s"),
    ("cli fast: run (CPU)", "s", "cli_fast", "cpu_s"),
    ("cli fast: per image", "s", "cli_fast", "median_s_per_image"),
    ("cli balanced: run", "s", "cli_balanced", "wall_s"),
    ("cli balanced: run (CPU)", "s", "cli_balanced", "cpu_s"),
    ("cli balanced: per image", "s", "cli_balanced", "median_s_per_image"),
)


def _values(run: dict, key: str) -> list:
    return run[key] if isinstance(run[key], list) else [run[key]]


def summarize(samples: dict) -> dict:
    """Per metric: each side's median over every sample, their ratio tree/ref, and the ratio within each round (the
    two sides measured back to back: its spread shows how far the machine's load moved the pooled ratio)."""
    out = {}
    for name, unit, kind, key in METRICS:
        row = {"unit": unit}
        for side in ("ref", "tree"):
            vals = [v for run in samples[side][kind] for v in _values(run, key)]
            row[side] = _median(vals)
            row[f"{side}_n"] = len([v for v in vals if v is not None])
        row["ratio"] = row["tree"] / row["ref"] if row["ref"] and row["tree"] is not None else None
        rounds = zip(samples["ref"][kind], samples["tree"][kind])
        per_round = [(_median(_values(t, key)), _median(_values(r, key))) for r, t in rounds]
        row["round_ratios"] = [t / r if r and t is not None else None for t, r in per_round]
        out[name] = row
    return out


def table(metrics: dict) -> str:
    lines = ["| measurement | ref | tree | tree/ref | per round (min-max) |", "|---|---:|---:|---:|---:|"]
    for name, r in metrics.items():
        digits = 1 if r["unit"] == "ms" else 2
        fmt = lambda v: "-" if v is None else f"{v:.{digits}f} {r['unit']}"
        ratio = "-" if r["ratio"] is None else f"{r['ratio']:.3f}"
        rr = [x for x in r["round_ratios"] if x is not None]
        spread = f"{min(rr):.2f}-{max(rr):.2f}" if rr else "-"
        lines.append(f"| {name} | {fmt(r['ref'])} | {fmt(r['tree'])} | {ratio} | {spread} |")
    return "\n".join(lines)


def run_guard(a) -> dict:
    tmp = Path(tempfile.mkdtemp(prefix="aias_guard_", dir="/tmp"))
    sides: dict[str, Side] = {}
    try:
        sides["ref"] = checkout(a.ref or default_ref(), "ref", tmp)
        sides["tree"] = checkout(a.tree, "tree", tmp) if a.tree else working_tree()
        images = tmp / "images"
        images.mkdir()
        for f in tracon_files(a.images):
            shutil.copy(f, images / f.name)
        from benchmarks.bench_first_sight import sun_decided_roads

        sunny = sun_decided_roads(ROTATION)
        labelled = [str(f) for f in labelled_roads(ROTATION)]
        kinds = ("transform", "transform_sun", "transform_labelled", "cli_fast", "cli_balanced")
        samples = {s: {k: [] for k in kinds} for s in sides}
        load_before = os.getloadavg()
        t_start = time.perf_counter()
        for r in range(a.rounds):
            order = ("ref", "tree") if r % 2 == 0 else ("tree", "ref")
            for kind in kinds:
                for s in order:
                    if kind.startswith("transform"):
                        photos = {"transform_sun": sunny, "transform_labelled": labelled}.get(kind)
                        res = measure_transform(sides[s], a, a.cpu, photos, labelled=kind == "transform_labelled")
                    else:
                        res = measure_cli(sides[s], kind.split("_")[1], images, tmp, a.cpu)
                    samples[s][kind].append(res)
            print(f"round {r + 1}/{a.rounds} done ({time.perf_counter() - t_start:.0f} s)", flush=True)
        return {
            "command": f"taskset -c {a.cpu} nice python -m benchmarks.bench_regression_guard "
            + " ".join(shlex.quote(x) for x in a.argv),
            "ref": sides["ref"].label,
            "tree": sides["tree"].label,
            "machine": {
                "cpu_pinned": a.cpu,
                "cpus_online": os.cpu_count(),
                "processor": platform.processor() or platform.machine(),
                "loadavg_before": load_before,
                "loadavg_after": os.getloadavg(),
                "seconds": round(time.perf_counter() - t_start, 1),
            },
            "settings": {k: getattr(a, k) for k in ("rounds", "warmup", "calls", "first_sight", "images", "quick")},
            "metrics": summarize(samples),
            "samples": samples,
        }
    finally:
        for side in sides.values():
            if side.worktree:
                subprocess.run(["git", "worktree", "remove", "--force", str(side.root)], cwd=REPO, capture_output=True)
        shutil.rmtree(tmp, ignore_errors=True)


def parse_args(argv: list[str]) -> argparse.Namespace:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--ref", default=None, help="reference commit (default: git merge-base HEAD main)")
    ap.add_argument("--tree", default=None, help="a commit to measure instead of the working tree")
    ap.add_argument("--quick", action="store_true", help="2 rounds, fewer calls, 2 CLI images (~2-3 min)")
    ap.add_argument("--rounds", type=int, default=None, help="default 3 (--quick: 2)")
    ap.add_argument("--warmup", type=int, default=None, help="transform calls before timing (default 120; quick 40)")
    ap.add_argument("--calls", type=int, default=None, help="timed fresh calls per run (default 60; quick 24)")
    ap.add_argument("--first-sight", type=int, default=None, help="first-sight calls per run (default 6; quick 3)")
    ap.add_argument("--images", type=int, default=None, help="TraCon photos for the CLI runs (default 4; quick 2)")
    ap.add_argument("--cpu", type=int, default=0, help="the core every run is pinned to (taskset -c)")
    ap.add_argument("--out", default=str(REPO / "results" / "bench" / "regression_guard.json"))
    ap.add_argument("--worker", action="store_true", help=argparse.SUPPRESS)
    ap.add_argument("--root", default=None, help=argparse.SUPPRESS)
    ap.add_argument("--photos", nargs="+", default=None, help=argparse.SUPPRESS)
    ap.add_argument("--labelled", action="store_true", help=argparse.SUPPRESS)
    a = ap.parse_args(argv)
    defaults = {"rounds": (3, 2), "warmup": (120, 40), "calls": (60, 24), "first_sight": (6, 3), "images": (4, 2)}
    for k, (full, quick) in defaults.items():
        if getattr(a, k) is None:
            setattr(a, k, quick if a.quick else full)
        if getattr(a, k) < (0 if k == "warmup" else 1):
            ap.error(f"--{k.replace('_', '-')} {getattr(a, k)}: must be at least {0 if k == 'warmup' else 1}")
    a.argv = argv
    return a


def main(argv: list[str] | None = None) -> int:
    a = parse_args(list(sys.argv[1:] if argv is None else argv))
    try:
        if a.worker:
            print(json.dumps(transform_worker(a.warmup, a.calls, a.first_sight, a.root, a.photos, a.labelled)))
            return 0
        if shutil.which("taskset") is None:
            raise GuardError("taskset not found (util-linux): the guard pins every run to one core")
        result = run_guard(a)
    except GuardError as e:
        print(f"bench_regression_guard: error: {e}", file=sys.stderr)
        return 2
    Path(a.out).parent.mkdir(parents=True, exist_ok=True)
    Path(a.out).write_text(json.dumps(result, indent=1))
    print(f"ref:  {result['ref']}\ntree: {result['tree']}")
    print(table(result["metrics"]))
    print(f"-> {a.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

"""Issue 14's loader bound, measured with paired epochs: a torch DataLoader with ``InsertObjects(p=0.5,
preset="fast")`` against the same loader without insertion.

All arms' loaders exist at once (2 spawn workers each, persistent, OpenCV threads 0 in the workers as
albumentations advises); after a warm-up epoch each, every round runs one epoch of each arm, in an order that
rotates from round to round. A round's ratios (arm img/s over the baseline's img/s in the same round) are paired:
the VM's speed, which moves by tens of per cent over minutes, moves both. Reported: the median of the per-round
ratios with a bootstrap 95 % interval (percentile, 10,000 resamples, seeded), and the CPU seconds per image of
the parent and its workers (from ``/proc``) per arm.

Arms (the dataset: TraCon JPEGs decoded and resized to 320x320 per item, batch 8, shuffled):
- ``without``: no Compose (the dataset returns the decoded image).
- ``compose_only``: the same Compose as the insertion arm (coco boxes with a label field) with ``NoOp(p=0.5)``
  instead of InsertObjects: the user's loader without the insertion.
- ``boxes_only``: the same Compose with a transform that only appends two fixed boxes at p=0.5 (no pixel changed):
  the Compose's own cost of returned boxes, the ceiling of any insertion transform inside it.
- ``variants_warmed``: ``InsertObjects(p=0.5, preset="fast", variants_per_image=K, scene_cache=DIR)`` after
  ``warm(images, variants=True)`` (its seconds are reported: paid once, before training).
- ``fresh_warmed``: a new insertion per call (no variants) after ``warm(images)`` (analyses on disk).
- ``compose_labels`` / ``variants_labels``: as ``compose_only`` / ``variants_warmed``, each item carrying its
  TraCon cone boxes (YOLO labels at 320x320, COCO xywh; the variants warmed with them), as a detection loader does.

    python -m benchmarks.bench_loader --images 192 --rounds 40 --out results/bench/loader

Writes ``<out>/loader.json``, ``<out>/loader.md`` (with the command) and ``<out>/loader_ratios.jpg`` (per-round
ratios). Run it with nothing else on the machine, pinned to one core (``taskset -c 0``): the parent and all
workers then share that core, as the CPU budget the bound is about.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile
import time
from pathlib import Path

os.environ.setdefault("NO_ALBUMENTATIONS_UPDATE", "1")

import albumentations as A
import numpy as np

from aias_augment import InsertObjects
from aias_augment.core.config import data_root
from benchmarks.transform_fixtures import AppendBoxes, Images, compose_for, decoded, set_cv2_threads

ARMS = ("without", "compose_only", "boxes_only", "variants_warmed", "fresh_warmed", "compose_labels", "variants_labels")
BOUND = 0.9


def _cpu_seconds_tree(pid: int) -> float:
    """CPU seconds (all threads) of ``pid`` and its children (the DataLoader workers): live ones from the scheduler's
    nanosecond counters in /proc (``task/*/schedstat``; the clock-tick counters of ``stat`` are too coarse for
    sub-second epochs), ended ones (non-persistent workers) from ``getrusage(RUSAGE_CHILDREN)``."""
    import resource

    ended = resource.getrusage(resource.RUSAGE_CHILDREN)
    total_ns = int(1e9 * (ended.ru_utime + ended.ru_stime))
    for p in [d for d in os.listdir("/proc") if d.isdigit()]:
        try:
            if p != str(pid):
                with open(f"/proc/{p}/stat") as f:
                    if int(f.read().rsplit(")", 1)[1].split()[1]) != pid:  # its ppid
                        continue
            for t in os.listdir(f"/proc/{p}/task"):
                with open(f"/proc/{p}/task/{t}/schedstat") as f:
                    total_ns += int(f.read().split()[0])
        except (OSError, ValueError, IndexError):
            continue
    return total_ns / 1e9


def tracon_boxes(image_path: Path, size: int = 320) -> np.ndarray:
    """The image's cone boxes from its YOLO label file, as COCO xywh on the ``size`` x ``size`` resized image
    (clipped to it; boxes under 1 px dropped)."""
    f = image_path.parent.parent.parent / "labels" / image_path.parent.name / (image_path.stem + ".txt")
    rows = np.loadtxt(f, ndmin=2) if f.exists() and f.stat().st_size else np.zeros((0, 5))
    x0, y0 = (rows[:, 1] - rows[:, 3] / 2) * size, (rows[:, 2] - rows[:, 4] / 2) * size
    x1, y1 = (rows[:, 1] + rows[:, 3] / 2) * size, (rows[:, 2] + rows[:, 4] / 2) * size
    x0, y0, x1, y1 = (np.clip(v, 0, size) for v in (x0, y0, x1, y1))
    keep = (x1 - x0 >= 1) & (y1 - y0 >= 1)
    return np.stack([x0, y0, x1 - x0, y1 - y0], axis=1)[keep].astype(np.float64)


class _LabelledImages(Images):
    """:class:`Images` with each item's TraCon boxes passed to the transform (labels "traffic_cone")."""

    def __init__(self, paths, transform):
        super().__init__(paths, transform)
        self.boxes = [tracon_boxes(Path(p)) for p in self.paths]

    def __getitem__(self, i):
        import cv2
        import torch

        img = cv2.resize(
            cv2.cvtColor(cv2.imread(self.paths[i]), cv2.COLOR_BGR2RGB), (320, 320), interpolation=cv2.INTER_AREA
        )
        b = self.boxes[i]
        img = self.transform(image=img, bboxes=b, labels=["traffic_cone"] * len(b))["image"]
        return torch.from_numpy(np.ascontiguousarray(img)).permute(2, 0, 1)


def make_loader(arm: str, paths, variants: int, cache_dir: str, warm_info: dict, persistent: bool = True):
    import functools

    import torch

    tf = None
    labelled = arm.endswith("_labels")
    if arm in ("compose_only", "compose_labels"):
        tf = compose_for(A.NoOp(p=0.5))
    elif arm == "boxes_only":
        tf = compose_for(AppendBoxes(p=0.5))
    elif arm in ("variants_warmed", "fresh_warmed", "variants_labels"):
        t = InsertObjects(
            categories=["traffic_cone"],
            preset="fast",
            p=0.5,
            scene_cache=cache_dir,
            variants_per_image=None if arm == "fresh_warmed" else variants,
        )
        tf = compose_for(t)
        t0, c0 = time.perf_counter(), time.process_time()
        info = t.warm(
            decoded(paths),
            variants=arm != "fresh_warmed",
            bboxes=[tracon_boxes(Path(p)) for p in paths] if labelled else None,
        )
        warm_info[arm] = {
            **{k: v for k, v in info.items() if isinstance(v, (int, float, str))},
            "wall_s": time.perf_counter() - t0,
            "cpu_s": time.process_time() - c0,
        }
    elif arm != "without":
        raise ValueError(arm)
    return torch.utils.data.DataLoader(
        (_LabelledImages if labelled else Images)(paths, tf),
        batch_size=8,
        shuffle=True,
        num_workers=2,
        multiprocessing_context="spawn",
        persistent_workers=persistent,
        generator=torch.Generator().manual_seed(0),
        worker_init_fn=functools.partial(set_cv2_threads, 0),
    )


def epoch(dl) -> tuple[float, float, int]:
    """(wall s, CPU s of this process and its workers, images) of one epoch."""
    c0, t0 = _cpu_seconds_tree(os.getpid()), time.perf_counter()
    n = sum(len(b) for b in dl)
    return time.perf_counter() - t0, _cpu_seconds_tree(os.getpid()) - c0, n


def median_ci(x, rng: np.random.Generator, n_boot: int = 10_000) -> tuple[float, float, float]:
    x = np.asarray(x, float)
    boots = np.median(x[rng.integers(0, len(x), (n_boot, len(x)))], axis=1)
    return float(np.median(x)), float(np.quantile(boots, 0.025)), float(np.quantile(boots, 0.975))


def pooled_ci(rounds: list[dict], arm: str, base: str, rng: np.random.Generator, n_boot: int = 10_000) -> list[float]:
    """Bootstrap 95 % interval (rounds resampled) of the pooled throughput ratio: all the arm's images over all
    its seconds, against the baseline's."""
    ai, aw = (np.array([x[arm][k] for x in rounds], float) for k in ("images", "wall_s"))
    bi, bw = (np.array([x[base][k] for x in rounds], float) for k in ("images", "wall_s"))
    idx = rng.integers(0, len(rounds), (n_boot, len(rounds)))
    boot = (ai[idx].sum(1) / aw[idx].sum(1)) / (bi[idx].sum(1) / bw[idx].sum(1))
    return [float(np.quantile(boot, 0.025)), float(np.quantile(boot, 0.975))]


def summarise(rounds: list[dict], arms: list[str], baselines: list[str], seed: int = 0) -> dict:
    rng = np.random.default_rng(seed)
    out = {}
    for base in baselines:
        for arm in arms:
            if (
                arm == base
                or arm == "without"
                or (base != "without" and arm.endswith("_labels") != base.endswith("_labels"))
            ):
                continue  # each Compose baseline against the arms with its own inputs
            r = [x[arm]["img_s"] / x[base]["img_s"] for x in rounds]
            c = [x[base]["cpu_per_img"] / x[arm]["cpu_per_img"] for x in rounds]
            pooled = (sum(x[arm]["images"] for x in rounds) / sum(x[arm]["wall_s"] for x in rounds)) / (
                sum(x[base]["images"] for x in rounds) / sum(x[base]["wall_s"] for x in rounds)
            )
            m, lo, hi = median_ci(r, rng)
            cm, clo, chi = median_ci(c, rng)
            out[f"{arm} / {base}"] = {
                "median": m,
                "ci95": [lo, hi],
                "pooled_throughput_ratio": pooled,
                "pooled_ci95": pooled_ci(rounds, arm, base, rng),
                "cpu_ratio_median": cm,
                "cpu_ratio_ci95": [clo, chi],
                "per_round": r,
                "bound_shown_met": lo >= BOUND,
            }
    return out


def plot(summary: dict, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    keys = list(summary)
    fig, ax = plt.subplots(figsize=(1.8 + 1.6 * len(keys), 4))
    rng = np.random.default_rng(0)
    for i, k in enumerate(keys):
        r = np.asarray(summary[k]["per_round"])
        ax.scatter(i + rng.uniform(-0.15, 0.15, len(r)), r, s=9, alpha=0.5)
        lo, hi = summary[k]["ci95"]
        ax.errorbar(
            i,
            summary[k]["median"],
            yerr=[[summary[k]["median"] - lo], [hi - summary[k]["median"]]],
            fmt="o",
            color="k",
            capsize=6,
        )
    ax.axhline(BOUND, color="r", ls="--", lw=1, label=f"bound {BOUND}x")
    ax.axhline(1.0, color="grey", lw=0.8)
    ax.set_xticks(range(len(keys)), [k.replace(" / ", "\n/ ") for k in keys], fontsize=8)
    ax.set_ylabel("images/s ratio, paired per round")
    ax.set_title("DataLoader: median of per-round ratios, 95 % bootstrap interval", fontsize=9)
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110, pil_kwargs={"quality": 85})  # committed pictures are JPEG
    plt.close(fig)


def report(res: dict, out: Path) -> None:
    """Summaries (per-round medians, pooled ratios, bootstrap intervals) of a run's rounds, written to
    ``out/loader.{json,md}`` and ``out/loader_ratios.jpg``."""
    rounds, arms = res["rounds"], res.get("arms") or list(res["rounds"][0])
    baselines = [b for b in ("without", "compose_only", "compose_labels") if b in arms]
    res["summary"] = summarise(rounds, arms, baselines)
    out.mkdir(parents=True, exist_ok=True)
    (out / "loader.json").write_text(json.dumps(res, separators=(",", ":")) + "\n")  # per-round samples: compact
    plot(res["summary"], out / "loader_ratios.jpg")
    med = {arm: float(np.median([x[arm]["img_s"] for x in rounds])) for arm in arms}
    cpu = {arm: 1000 * float(np.median([x[arm]["cpu_per_img"] for x in rounds])) for arm in arms}
    lines = ["# DataLoader with and without InsertObjects: paired epochs", "", f"Command: `{res['command'].strip()}`"]
    if res.get("resummarised"):
        lines += ["", f"Summary recomputed from the run's rounds: `{res['resummarised']}`"]
    lines += [
        "",
        f"{res['images']} TraCon images at 320x320, batch 8, 2 spawn workers per loader "
        f"({'persistent' if res.get('persistent_workers', True) else 'started every epoch: persistent_workers=False'}), "
        f"{res.get('warmup_epochs', 1)} warm-up epoch(s) per arm, then {len(rounds)} rounds of one epoch per arm "
        f"(rotating order). Load average {res['loadavg_before'][0]:.2f} before, {res['loadavg_after'][0]:.2f} "
        "after.",
        "",
        "| arm | median img/s | median CPU ms per image (parent + workers) |",
        "|---|---:|---:|",
    ]
    lines += [f"| {arm} | {med[arm]:.1f} | {cpu[arm]:.2f} |" for arm in arms]
    lines += [
        "",
        "| ratio | median of per-round ratios [95 % CI] | pooled throughput ratio [95 % CI] | CPU-time ratio "
        "[95 % CI] | bound 0.9 shown met (median's interval) |",
        "|---|---:|---:|---:|---|",
    ]
    for k, s in res["summary"].items():
        lines.append(
            f"| {k} | {s['median']:.3f} [{s['ci95'][0]:.3f}, {s['ci95'][1]:.3f}] | "
            f"{s['pooled_throughput_ratio']:.3f} [{s['pooled_ci95'][0]:.3f}, {s['pooled_ci95'][1]:.3f}] | "
            f"{s['cpu_ratio_median']:.3f} [{s['cpu_ratio_ci95'][0]:.3f}, {s['cpu_ratio_ci95'][1]:.3f}] | "
            f"{'yes' if s['bound_shown_met'] else 'no'} |"
        )
    for k, w in res["warm"].items():
        lines.append(
            f"\nWarm-up of {k} (once, before training): "
            + ", ".join(f"{n} {v:.1f}" if isinstance(v, float) else f"{n} {v}" for n, v in w.items())
        )
    (out / "loader.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--images", type=int, default=192, help="TraCon train images per epoch")
    ap.add_argument("--rounds", type=int, default=40, help="timed rounds (one epoch of every arm each)")
    ap.add_argument("--warmup-epochs", type=int, default=1, help="untimed epochs of every arm first")
    ap.add_argument("--variants", type=int, default=4, help="variants_per_image of the variants arm")
    ap.add_argument("--arms", nargs="+", default=list(ARMS[:4]), choices=ARMS)
    ap.add_argument(
        "--non-persistent",
        action="store_true",
        help="DataLoader's default persistent_workers=False: every epoch starts its workers (imports, "
        "the transform unpickled, empty in-memory caches)",
    )
    ap.add_argument(
        "--from-json",
        default=None,
        help="no run: recompute the summaries of a loader.json's rounds and rewrite its folder's files",
    )
    ap.add_argument("--out", default="results/bench/loader")
    a = ap.parse_args(argv)
    if a.from_json:
        res = json.loads(Path(a.from_json).read_text())
        res["resummarised"] = "python -m benchmarks.bench_loader --from-json " + a.from_json
        report(res, Path(a.from_json).parent)
        return 0
    if "without" not in a.arms:
        raise SystemExit("the arms must include 'without'")
    cmd = "python -m benchmarks.bench_loader " + " ".join(argv if argv is not None else sys.argv[1:])
    import torch

    torch.set_num_threads(1)
    paths = sorted((data_root() / "tracon" / "images" / "train").glob("*.jpg"))[: a.images]
    load_before = os.getloadavg()
    warm_info: dict = {}
    with tempfile.TemporaryDirectory() as d:
        loaders = {
            arm: make_loader(arm, paths, a.variants, f"{d}/{arm}", warm_info, not a.non_persistent) for arm in a.arms
        }
        for _ in range(a.warmup_epochs):
            for arm, dl in loaders.items():
                w, _, n = epoch(dl)
                print(f"warm-up {arm}: {n / w:.1f} img/s", flush=True)
        rounds = []
        t_start = time.perf_counter()
        for r in range(a.rounds):
            order = a.arms[r % len(a.arms) :] + a.arms[: r % len(a.arms)]
            row = {}
            for arm in order:
                w, c, n = epoch(loaders[arm])
                row[arm] = {"img_s": n / w, "wall_s": w, "cpu_s": c, "images": n, "cpu_per_img": c / n}
            rounds.append(row)
            print(
                f"round {r + 1}/{a.rounds} ({time.perf_counter() - t_start:.0f} s): "
                + ", ".join(f"{k} {v['img_s']:.0f} img/s" for k, v in row.items()),
                flush=True,
            )
        del loaders
    res = {
        "command": cmd,
        "persistent_workers": not a.non_persistent,
        "loadavg_before": load_before,
        "loadavg_after": os.getloadavg(),
        "images": len(paths),
        "variants_per_image": a.variants,
        "arms": a.arms,
        "warmup_epochs": a.warmup_epochs,
        "warm": warm_info,
        "rounds": rounds,
    }
    report(res, Path(a.out))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

"""Speed and variety of a finite procedural cone family (``InsertionConfig.family_members``) against the
continuous family (a new cone per object, ray-cast: the fast preset's ``render_method: raycast``; and the same
through the view cache, ``render_method: view_cache``), the shared mesh (``asset_source: default``) and
albumentations' ``OverlayElements``.

    taskset -c 0 nice python -m benchmarks.bench_family_speed --out results/bench/family_speed

Speed (issue 56's protocol): every arm is an ``InsertObjects(preset="fast", p=1)`` in a ``Compose`` (one object per
image: ``min_objects = max_objects = 1``) on six 640x480 TraCon training roads in rotation; each arm has its own
in-memory view cache (as a training process running that one arm would), ``--warmup`` calls per arm over the six
roads first (scene analyses and views), then ``--rounds`` rounds, each one fresh call per arm (a seen image, a new
insertion), interleaved so that every arm meets the same machine load. Medians of wall and process CPU ms
(``time.process_time``: all threads, the GL rasteriser's included). One core: run it under ``taskset -c 0``.

Variety: the member index drawn 1000 times (distinct members seen), and the parameters a draw gives (body hue,
sleeve count, height) against the continuous family's (a two-sample Kolmogorov-Smirnov statistic per parameter,
beside the statistic of two independent continuous samples of the same size: the noise floor).

Writes ``<out>.json`` and ``<out>.md`` with the command.
"""

from __future__ import annotations

import argparse
import colorsys
import json
import os
import platform
import shlex
import sys
import time
from pathlib import Path

os.environ.setdefault("NO_ALBUMENTATIONS_UPDATE", "1")

import numpy as np

from benchmarks.bench_regression_guard import ROTATION, tracon_files

#: The family's seed in every arm (a config value, recorded here and in every record the arm makes).
FAMILY_SEED = 56


def arm_overrides(sizes: list[int]) -> dict[str, dict]:
    arms = {"continuous": {}, "continuous_view_cache": {"render_method": "view_cache"}}
    for n in sizes:
        arms[f"family_{n}"] = {"family_members": n, "family_seed": FAMILY_SEED}
    arms["asset_default"] = {"asset_source": "default"}
    return arms


def draw_params(seed: int) -> dict:
    """The parameters the procedural cone of ``seed`` is made with (``generate``'s draws, without the mesh)."""
    from aias_augment.assets.bank.procedural import CATEGORY_SPECS, cone_params

    rng = np.random.default_rng(int(seed))
    lo, hi = CATEGORY_SPECS["traffic_cone"].height_range_m
    h = float(rng.uniform(lo, hi))
    p = cone_params(rng, h)
    r, g, b = (np.asarray(p["colour_rgb"]) / 255.0).tolist()
    return {"body_hue_deg": 360.0 * colorsys.rgb_to_hsv(r, g, b)[0], "sleeves": len(p["bands_z_m"]), "height_m": h}


def variety(sizes: list[int], draws: int, seed: int) -> dict:
    """Distinct members in ``draws`` draws and the KS statistic per parameter against the continuous draw."""
    from scipy.stats import ks_2samp

    from aias_augment.assets.bank.family_cache import member_seed

    def continuous(rng):
        return [draw_params(int(rng.integers(2**63 - 1))) for _ in range(draws)]

    def column(rows, k):
        return np.array([r[k] for r in rows], float)

    keys = ("body_hue_deg", "sleeves", "height_m")
    ref = continuous(np.random.default_rng(seed))
    other = continuous(np.random.default_rng(seed + 1))
    out = {"draws": draws, "noise_floor_ks": {k: float(ks_2samp(column(ref, k), column(other, k))[0]) for k in keys}}
    for n in sizes:
        idx = np.random.default_rng(seed + 2).integers(n, size=draws)
        members = {i: draw_params(member_seed(FAMILY_SEED, i)) for i in set(idx.tolist())}
        rows = [members[i] for i in idx.tolist()]
        out[f"family_{n}"] = {
            "distinct_members": len(members),
            "ks": {k: float(ks_2samp(column(ref, k), column(rows, k))[0]) for k in keys},
            "ks_pvalue": {k: float(ks_2samp(column(ref, k), column(rows, k))[1]) for k in keys},
        }
    return out


def speed(sizes: list[int], warmup: int, rounds: int) -> dict:
    import albumentations as A
    import cv2

    from aias_augment import InsertObjects
    from aias_augment.apply.view_cache import ViewCache
    from benchmarks.transform_fixtures import cone_sprite

    images = [
        cv2.resize(cv2.cvtColor(cv2.imread(str(f)), cv2.COLOR_BGR2RGB), (640, 480), interpolation=cv2.INTER_AREA)
        for f in tracon_files(ROTATION)
    ]
    h, w = images[0].shape[:2]
    no_boxes = np.zeros((0, 4))
    sprite, smask = cone_sprite()
    overlay = A.Compose([A.OverlayElements(p=1.0)], seed=7)
    orng = np.random.default_rng(0)

    def overlay_call(img):
        sh, sw = sprite.shape[:2]
        x0, y0 = orng.integers(0, w - sw), orng.integers(h // 2, h - sh)
        meta = [{"image": sprite, "mask": smask, "bbox": [x0 / w, y0 / h, (x0 + sw) / w, (y0 + sh) / h]}]
        return overlay(image=img, overlay_metadata=meta)

    arms, caches = {"overlay": overlay_call}, {}
    for name, over in arm_overrides(sizes).items():
        t = InsertObjects(min_objects=1, max_objects=1, preset="fast", p=1.0, config_overrides=over)
        t._view_cache = caches[name] = ViewCache()  # the arm's own cache, as its own training process would have
        tf = A.Compose([t], bbox_params=A.BboxParams(format="coco", label_fields=["labels"]), seed=7)
        arms[name] = (lambda tf: lambda img: tf(image=img, bboxes=no_boxes, labels=[]))(tf)
    for i in range(warmup):  # interleaved too: the arms' warm-ups meet the same load
        for fn in arms.values():
            fn(images[i % ROTATION])
    before = {k: (c.hits, c.misses) for k, c in caches.items()}
    wall, cpu = {k: [] for k in arms}, {k: [] for k in arms}
    for r in range(rounds):
        for name, fn in arms.items():
            t0, c0 = time.perf_counter(), time.process_time()
            fn(images[r % ROTATION])
            wall[name].append(1e3 * (time.perf_counter() - t0))
            cpu[name].append(1e3 * (time.process_time() - c0))
        if (r + 1) % 20 == 0:
            print(
                f"round {r + 1}/{rounds}: " + ", ".join(f"{k} {np.median(v):.1f}" for k, v in cpu.items()), flush=True
            )
    out = {}
    for k in arms:
        out[k] = {"median_ms": float(np.median(wall[k])), "median_cpu_ms": float(np.median(cpu[k])), "n": rounds}
        if k in caches:
            c = caches[k]
            out[k]["view_cache"] = {
                "timed_hits": c.hits - before[k][0],
                "timed_misses": c.misses - before[k][1],
                "entries": len(c),
                "MB": round(c.nbytes / 2**20, 1),
            }
    return out


def markdown(res: dict, command: str) -> str:
    sp, va = res["speed"], res["variety"]
    ov = sp["overlay"]["median_cpu_ms"]
    lines = [
        "# A finite procedural cone family at view-cache speed",
        "",
        f"    {command}",
        "",
        f"Code: {res['commit']}. {res['machine']}; load average {res['load_before']} before, {res['load_after']} after.",
        "",
        f"## Fresh fast call (seen image, new insertion), {res['args']['rounds']} interleaved rounds after "
        f"{res['args']['warmup']} warm-up calls per arm, six 640x480 TraCon roads",
        "",
        "| arm | CPU ms (median) | x OverlayElements (CPU) | wall ms (median) | view hits / misses (timed) |",
        "|---|---:|---:|---:|---:|",
    ]
    for k, v in sp.items():
        vc = v.get("view_cache")
        hm = f"{vc['timed_hits']} / {vc['timed_misses']}" if vc else ""
        lines.append(
            f"| {k} | {v['median_cpu_ms']:.1f} | {v['median_cpu_ms'] / ov:.1f}x | {v['median_ms']:.1f} | {hm} |"
        )
    keys = list(va["noise_floor_ks"])
    lines += [
        "",
        f"## Variety: {va['draws']} draws of the member index; KS statistic per parameter against "
        f"{va['draws']} continuous draws",
        "",
        "| family | distinct members | " + " | ".join(f"KS {k}" for k in keys) + " |",
        "|---|---:|" + "---:|" * len(keys),
        "| continuous (a second sample: noise floor) | all | "
        + " | ".join(f"{va['noise_floor_ks'][k]:.3f}" for k in keys)
        + " |",
    ]
    for k, v in va.items():
        if k.startswith("family_"):
            lines.append(
                f"| {k} | {v['distinct_members']} | "
                + " | ".join(f"{v['ks'][c]:.3f} (p {v['ks_pvalue'][c]:.2f})" for c in keys)
                + " |"
            )
    return "\n".join(lines) + "\n"


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--sizes", type=int, nargs="+", default=[64, 256], help="family sizes (members)")
    ap.add_argument("--warmup", type=int, default=240, help="warm-up calls per arm")
    ap.add_argument("--rounds", type=int, default=120, help="timed rounds (one fresh call per arm each)")
    ap.add_argument("--draws", type=int, default=1000, help="draws of the variety measure")
    ap.add_argument("--out", type=Path, required=True, help="output stem: writes <out>.json and <out>.md")
    a = ap.parse_args(argv)
    if a.warmup < 0 or a.rounds < 1 or a.draws < 2 or any(n < 1 for n in a.sizes):
        ap.error("need --warmup >= 0, --rounds >= 1, --draws >= 2 and --sizes >= 1")
    import subprocess

    commit = subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True).stdout.strip()
    dirty = subprocess.run(["git", "status", "--porcelain", "-uno"], capture_output=True, text=True).stdout.strip()
    load_before = round(os.getloadavg()[0], 1)
    res = {
        "args": {k: (str(v) if isinstance(v, Path) else v) for k, v in vars(a).items()},
        "commit": f"{commit}{' with uncommitted changes' if dirty else ''}",
        "machine": f"{platform.processor() or platform.machine()}, affinity {sorted(os.sched_getaffinity(0))}",
        "family_seed": FAMILY_SEED,
        "variety": variety(a.sizes, a.draws, seed=0),
        "speed": speed(a.sizes, a.warmup, a.rounds),
        "load_before": load_before,
        "load_after": round(os.getloadavg()[0], 1),
    }
    cpus = ",".join(str(c) for c in sorted(os.sched_getaffinity(0)))
    command = f"taskset -c {cpus} nice python -m benchmarks.bench_family_speed " + shlex.join(sys.argv[1:] or [])
    a.out.parent.mkdir(parents=True, exist_ok=True)
    a.out.with_suffix(".json").write_text(json.dumps(res, indent=1))
    a.out.with_suffix(".md").write_text(markdown(res, command))
    print(markdown(res, command))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

"""Cost of the issue-16 checks of ``aias-augment`` on a real dataset (TraCon train, YOLO): parsing and validating
the labels, the manifest's content hashes, and the checked image decode (full PIL decode + OpenCV) against a plain
``cv2.imread``. No rendering. Also lists what the validation finds in the real labels.

  python -m benchmarks.bench_offline_checks --out results/bench/offline_checks.json
"""

from __future__ import annotations

import argparse
import json
import os
import time
from collections import Counter
from pathlib import Path

import cv2

from aias_augment.adapters.boundary import read_image_checked
from aias_augment.cli.manifest import item_hash
from aias_augment.cli.offline import items_from_yolo
from aias_augment.core.config import data_root


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--images", default=str(data_root() / "tracon" / "images" / "train"))
    ap.add_argument("--limit", type=int, default=200, help="images for the decode timing")
    ap.add_argument("--out", default="results/bench/offline_checks.json")
    a = ap.parse_args(argv)
    t0 = time.process_time()
    items = items_from_yolo(a.images, class_names=["cone"])
    t_parse = time.process_time() - t0
    t0 = time.process_time()
    for it in items:
        item_hash(it)
    t_hash = time.process_time() - t0
    sub = items[: a.limit]
    t0 = time.process_time()
    for it in sub:
        cv2.imread(it.path, cv2.IMREAD_COLOR)
    t_plain = time.process_time() - t0
    t0 = time.process_time()
    skips = Counter()
    for it in sub:
        try:
            read_image_checked(it.path)
        except ValueError as e:
            skips[str(e).split(":", 1)[0]] += 1
    t_checked = time.process_time() - t0
    notes = Counter(p["kind"] for it in items for p in it.problems)
    invalid = Counter(it.invalid.split(":", 1)[0] for it in items if it.invalid)
    res = {
        "images": len(items),
        "decode_timed_images": len(sub),
        "labels_parse_and_validate_cpu_ms_per_image": 1e3 * t_parse / len(items),
        "manifest_hash_cpu_ms_per_image": 1e3 * t_hash / len(items),
        "cv2_imread_cpu_ms_per_image": 1e3 * t_plain / len(sub),
        "checked_decode_cpu_ms_per_image": 1e3 * t_checked / len(sub),
        "found_in_labels": {"box_notes": dict(notes), "image_skips": dict(invalid)},
        "found_in_images": dict(skips),
        "timing": "CPU time of this process (time.process_time): wall time is meaningless on this machine",
        "machine": f"{os.cpu_count()} CPUs, loaded (shared with detector trainings); run under nice -n 19",
    }
    Path(a.out).parent.mkdir(parents=True, exist_ok=True)
    Path(a.out).write_text(json.dumps(res, indent=1) + "\n")
    print(json.dumps(res, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

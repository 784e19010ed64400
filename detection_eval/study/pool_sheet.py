"""A contact sheet of study pools side by side: the same copies (same background, same draws) from each arm's pool,
one row per arm, the inserted boxes drawn.

    python -m detection_eval.study.pool_sheet --pools out/study_probe/cache/inserted_gazebo_cone/pool \
        out/study_probe/cache/inserted_procedural/pool --labels "shared mesh" "procedural family" \
        --copies 0 3 7 12 --out studies/detection/probe/result/pools_sheet.jpg
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import cv2
import numpy as np

from aias_augment.core.image_io import read_image


def tile(pool: Path, copy: int, size: tuple[int, int]) -> np.ndarray:
    entry = next(e for e in json.loads((pool / "manifest.json").read_text()) if e["copy"] == copy and "image" in e)
    img = np.ascontiguousarray(read_image(pool / "images" / entry["image"])[..., ::-1])  # BGR for cv2 drawing
    h, w = img.shape[:2]
    label = pool / "labels" / (Path(entry["image"]).stem + ".txt")
    for line in label.read_text().split("\n") if label.exists() else []:
        if line.strip():
            _, cx, cy, bw, bh = map(float, line.split())
            x0, y0 = int((cx - bw / 2) * w), int((cy - bh / 2) * h)
            cv2.rectangle(img, (x0, y0), (int(x0 + bw * w), int(y0 + bh * h)), (0, 255, 0), 2)
    return cv2.resize(img, size, interpolation=cv2.INTER_AREA)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--pools", type=Path, nargs="+", required=True)
    ap.add_argument("--labels", nargs="+", required=True)
    ap.add_argument("--copies", type=int, nargs="+", default=[0, 1, 2, 3])
    ap.add_argument("--size", type=int, nargs=2, default=[320, 240])
    ap.add_argument("--out", type=Path, required=True)
    a = ap.parse_args(argv)
    if len(a.labels) != len(a.pools):
        ap.error("one label per pool")
    rows = []
    for pool, label in zip(a.pools, a.labels):
        row = np.concatenate([tile(pool, c, tuple(a.size)) for c in a.copies], axis=1)
        cv2.putText(row, label, (8, 22), cv2.FONT_HERSHEY_SIMPLEX, 0.7, (255, 255, 255), 2, cv2.LINE_AA)
        rows.append(row)
    a.out.parent.mkdir(parents=True, exist_ok=True)
    cv2.imwrite(str(a.out), np.concatenate(rows, axis=0), [cv2.IMWRITE_JPEG_QUALITY, 85])
    print(a.out)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

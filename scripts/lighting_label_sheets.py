"""The photos of the lighting benchmark and the sheets they are labelled from: TraCon train photos (seeded draw),
KITTI 06 colour frames and the DGP scene's camera frames, numbered on contact sheets of 4 x 4 for labelling by eye
(hard cast shadows visible: 1, not: 0), one row per photo in ``results/lighting/benchmark/labels.csv``.

    python scripts/lighting_label_sheets.py --tracon 84 --out out/lighting_labels     # then label from the sheets
"""

import argparse
import csv
import sys
from pathlib import Path

import cv2
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from aias_augment.core.config import data_root  # noqa: E402


def benchmark_photos(n_tracon: int, seed: int = 0) -> list[Path]:
    d = data_root()
    tracon = sorted((d / "tracon" / "images" / "train").iterdir())
    pick = np.random.default_rng(seed).choice(len(tracon), size=min(n_tracon, len(tracon)), replace=False)
    photos = [tracon[i] for i in sorted(pick)]
    photos += sorted((d / "kitti06_color_snippet").glob("kitti06-1[2-7]-color.png"))
    photos += sorted((d / "dgp_scene").glob("scene_*/rgb/CAMERA_*/*.jpg"))
    return photos


def tile(path: Path, k: int, size: int = 300) -> np.ndarray:
    img = cv2.imread(str(path))
    s = size / max(img.shape[:2])
    img = cv2.resize(
        img, (max(1, round(img.shape[1] * s)), max(1, round(img.shape[0] * s))), interpolation=cv2.INTER_AREA
    )
    out = np.full((size, size, 3), 255, np.uint8)
    out[: img.shape[0], : img.shape[1]] = img
    cv2.putText(out, str(k), (6, 30), cv2.FONT_HERSHEY_SIMPLEX, 1.0, (0, 0, 0), 4)
    cv2.putText(out, str(k), (6, 30), cv2.FONT_HERSHEY_SIMPLEX, 1.0, (0, 255, 255), 2)
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--tracon", type=int, default=84)
    ap.add_argument("--out", type=Path, default=Path("out/lighting_labels"))
    a = ap.parse_args(argv)
    photos = benchmark_photos(a.tracon)
    a.out.mkdir(parents=True, exist_ok=True)
    root = data_root()
    with open(a.out / "photos.csv", "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["index", "photo"])
        for k, p in enumerate(photos):
            w.writerow([k, str(p.relative_to(root))])
    for s in range(0, len(photos), 16):
        tiles = [tile(p, s + i) for i, p in enumerate(photos[s : s + 16])]
        tiles += [np.full_like(tiles[0], 255)] * (16 - len(tiles))
        sheet = np.vstack([np.hstack(tiles[r * 4 : r * 4 + 4]) for r in range(4)])
        cv2.imwrite(str(a.out / f"sheet_{s // 16:02d}.png"), sheet)
    print(len(photos), "photos,", (len(photos) + 15) // 16, "sheets in", a.out)
    return 0


if __name__ == "__main__":
    sys.exit(main())

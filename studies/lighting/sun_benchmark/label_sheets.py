"""The photos of the lighting benchmark and the sheets they are labelled from: TraCon train photos (seeded draw),
KITTI 06 colour frames and the DGP scene's camera frames, numbered on contact sheets of 4 x 4 for labelling by eye
(hard cast shadows visible: 1, not: 0), one row per photo in ``studies/lighting/sun_benchmark/labels/labels.csv``.

    python -m studies.lighting.sun_benchmark.label_sheets --tracon 84 --out out/lighting_labels     # then label from the sheets

With ``--shadow-grids`` it writes each photo labelled ``direct_sun`` at 760 px wide under a 0.05 grid, from which
the cast-shadow lines of ``studies/lighting/sun_benchmark/labels/shadow_directions.csv`` were read (base of an occluder, the
far end of its shadow, as fractions of the width and height).
"""

import argparse
import csv
import sys
from pathlib import Path

import cv2
import numpy as np

from aias_augment.core.config import data_root


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


def shadow_grid(path: Path, index: str, width: int = 760) -> np.ndarray:
    """The photo at ``width`` px under a grid every 0.05 of its width and height (labelled every 0.1)."""
    img = cv2.imread(str(path))
    img = cv2.resize(img, None, fx=width / img.shape[1], fy=width / img.shape[1], interpolation=cv2.INTER_AREA)
    h, w = img.shape[:2]
    for k in range(1, 20):
        f = k / 20
        colour = (0, 255, 255) if k % 2 == 0 else (255, 255, 0)
        x, y = round(f * w), round(f * h)
        cv2.line(img, (x, 0), (x, h), colour, 1)
        cv2.line(img, (0, y), (w, y), colour, 1)
        if k % 2 == 0:
            for org in ((x + 2, 12), (2, y - 2)):
                cv2.putText(img, f"{f:.1f}", org, cv2.FONT_HERSHEY_SIMPLEX, 0.4, (0, 0, 0), 3)
                cv2.putText(img, f"{f:.1f}", org, cv2.FONT_HERSHEY_SIMPLEX, 0.4, (0, 255, 255), 1)
    cv2.putText(img, index, (w - 60, h - 10), cv2.FONT_HERSHEY_SIMPLEX, 0.9, (0, 0, 255), 2)
    return img


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--tracon", type=int, default=84)
    ap.add_argument("--out", type=Path, default=Path("out/lighting_labels"))
    ap.add_argument("--shadow-grids", action="store_true", help="grids of the direct-sun photos for shadow lines")
    ap.add_argument("--labels", type=Path, default=Path("studies/lighting/sun_benchmark/labels/labels.csv"))
    ap.add_argument(
        "--extra",
        type=int,
        default=0,
        help="sheets of N more TraCon train photos outside the benchmark (seeded draw), labelled into "
        "labels_extra.csv: training data for the sun-evidence model only, never scored",
    )
    ap.add_argument(
        "--more",
        type=int,
        default=0,
        help="sheets of N more TraCon train photos outside the benchmark and labels_extra.csv (seeded draw), "
        "labelled into labels_more.csv: the asymmetric sun decision's dev and held-out parts",
    )
    a = ap.parse_args(argv)
    if a.more:
        extra = a.labels.with_name("labels_extra.csv")
        taken = {p.name for p in benchmark_photos(a.tracon)} | {
            Path(r["photo"]).name for r in csv.DictReader(open(extra))
        }
        rest = [p for p in sorted((data_root() / "tracon" / "images" / "train").iterdir()) if p.name not in taken]
        pick = np.random.default_rng(2).choice(len(rest), size=min(a.more, len(rest)), replace=False)
        photos = [rest[i] for i in sorted(pick)]
        write_sheets(photos, a.out, "more_")
        print(len(photos), "more photos in", a.out)
        return 0
    if a.extra:
        root = data_root()
        taken = {p.name for p in benchmark_photos(a.tracon)}
        rest = [p for p in sorted((root / "tracon" / "images" / "train").iterdir()) if p.name not in taken]
        pick = np.random.default_rng(1).choice(len(rest), size=min(a.extra, len(rest)), replace=False)
        photos = [rest[i] for i in sorted(pick)]
        write_sheets(photos, a.out, "extra_")
        print(len(photos), "extra photos in", a.out)
        return 0
    if a.shadow_grids:
        (a.out / "grids").mkdir(parents=True, exist_ok=True)
        sunny = [r for r in csv.DictReader(open(a.labels)) if r["direct_sun"] == "1"]
        for r in sunny:
            cv2.imwrite(
                str(a.out / "grids" / f"{int(r['index']):03d}.png"), shadow_grid(data_root() / r["photo"], r["index"])
            )
        print(len(sunny), "grids in", a.out / "grids")
        return 0
    photos = benchmark_photos(a.tracon)
    write_sheets(photos, a.out, "")
    print(len(photos), "photos,", (len(photos) + 15) // 16, "sheets in", a.out)
    return 0


def write_sheets(photos: list[Path], out: Path, prefix: str) -> None:
    """``{prefix}photos.csv`` (index, path under the data root) and numbered 4 x 4 sheets ``{prefix}sheet_NN.png``."""
    out.mkdir(parents=True, exist_ok=True)
    root = data_root()
    with open(out / f"{prefix}photos.csv", "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["index", "photo"])
        for k, p in enumerate(photos):
            w.writerow([k, str(p.relative_to(root))])
    for s in range(0, len(photos), 16):
        tiles = [tile(p, s + i) for i, p in enumerate(photos[s : s + 16])]
        tiles += [np.full_like(tiles[0], 255)] * (16 - len(tiles))
        sheet = np.vstack([np.hstack(tiles[r * 4 : r * 4 + 4]) for r in range(4)])
        cv2.imwrite(str(out / f"{prefix}sheet_{s // 16:02d}.png"), sheet)


if __name__ == "__main__":
    sys.exit(main())

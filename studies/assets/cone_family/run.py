"""Contact sheet: real TraCon cones vs the procedural cone family (``asset_source="procedural"``).

    python -m studies.assets.cone_family --out studies/assets/cone_family/result/cone_family_sheet.jpg

Rows, top to bottom:
1. real cones: crops of TraCon val label boxes (boxes at least ``--min-real-px`` tall, every k-th image);
2. procedural cones inserted by the full pipeline (``--preset``, ``asset_source="procedural"``) into TraCon train
   images whose label file is empty (road scenes without cones), cropped at the inserted boxes;
3. the current default mesh (gazebo construction_cone, ``asset_source="default"``) inserted the same way;
4. procedural cones alone: ``render_object`` albedo x a fixed Lambert sun + ambient (no pipeline), one seed each.
Everything is seeded (``--seed``); the same command gives the same sheet.
"""

from __future__ import annotations

import argparse
import os
import time
from dataclasses import replace
from pathlib import Path

import numpy as np
from PIL import Image, ImageDraw

os.environ.setdefault("PYOPENGL_PLATFORM", "egl")

from aias_augment.apply.render import linear_to_srgb, render_object
from aias_augment.assets.bank.procedural import procedural_asset
from aias_augment.core.config import data_root
from aias_augment.core.geometry import Intrinsics, make_rigid
from aias_augment.pipeline.config import load_preset
from aias_augment.pipeline.image import insert_into_image
from aias_augment.plan.placement import PlacementConfig

TILE = (96, 136)  # (w, h) of one crop tile
COLS = 10
BG = (128, 128, 128)


def _image_of(label: Path, split: str, root: Path) -> Path:
    return next(p for p in sorted((root / "images" / split).glob(label.stem + ".*")))


def _tile(img: Image.Image, box_xyxy, margin: float = 0.12) -> Image.Image:
    """The box with a margin, fitted (aspect kept) into a grey tile."""
    x0, y0, x1, y1 = box_xyxy
    mw, mh = (x1 - x0) * margin, (y1 - y0) * margin
    crop = img.crop(
        (
            max(0, int(x0 - mw)),
            max(0, int(y0 - mh)),
            min(img.width, int(np.ceil(x1 + mw))),
            min(img.height, int(np.ceil(y1 + mh))),
        )
    )
    s = min(TILE[0] / crop.width, TILE[1] / crop.height)
    crop = crop.resize((max(1, round(crop.width * s)), max(1, round(crop.height * s))), Image.LANCZOS)
    t = Image.new("RGB", TILE, BG)
    t.paste(crop, ((TILE[0] - crop.width) // 2, (TILE[1] - crop.height) // 2))
    return t


def real_tiles(root: Path, n: int, min_px: int) -> list[Image.Image]:
    cands = []
    for lab in sorted((root / "labels" / "val").glob("*.txt")):
        rows = [r.split() for r in lab.read_text().splitlines() if r.strip()]
        if rows:
            cands.append((lab, rows))
    step = max(1, len(cands) // n)
    out = []
    for lab, rows in cands[::step]:
        img = Image.open(_image_of(lab, "val", root)).convert("RGB")
        W, H = img.size
        boxes = [tuple(map(float, r[1:5])) for r in rows]
        x, y, w, h = max(boxes, key=lambda b: b[3])  # the tallest cone of the image
        if h * H < min_px:
            continue
        out.append(_tile(img, ((x - w / 2) * W, (y - h / 2) * H, (x + w / 2) * W, (y + h / 2) * H), 0.04))
        if len(out) == n:
            break
    return out


def inserted_tiles(
    root: Path, n: int, asset_source: str, preset: str, seed: int, min_px: int
) -> tuple[list[Image.Image], float]:
    empty = [lab for lab in sorted((root / "labels" / "train").glob("*.txt")) if not lab.read_text().strip()]
    rng_pick = np.random.default_rng(seed)
    order = rng_pick.permutation(len(empty))
    # big enough to see the texture: box heights 20-45 % of the image height
    cfg = replace(
        load_preset(preset),
        asset_source=asset_source,
        min_objects=2,
        max_objects=2,
        placement_cfg=replace(PlacementConfig(), box_height_frac_range=(0.2, 0.45)),
    )
    out, t0, k = [], time.perf_counter(), 0
    for i in order:
        img = np.asarray(Image.open(_image_of(empty[i], "train", root)).convert("RGB"))
        res = insert_into_image(img, rng=np.random.default_rng(seed * 1000 + int(i)), cfg=cfg)
        k += 1
        pil = Image.fromarray(res.image)
        for x, y, w, h in res.inserted_bboxes:
            if h >= min_px:
                out.append(_tile(pil, (x, y, x + w, y + h)))
        if len(out) >= n:
            break
    return out[:n], (time.perf_counter() - t0) / max(k, 1)


def studio_tiles(n: int, seed: int) -> list[Image.Image]:
    """Each cone alone, seen from 1.6 m eye height at ~4 m, albedo x Lambert (sun from upper left) + ambient."""
    out = []
    intr = Intrinsics(600.0, 600.0, TILE[0] - 0.5, TILE[1] - 0.5, TILE[0] * 2, TILE[1] * 2)
    R_up = np.array([[1, 0, 0], [0, 0, -1], [0, 1, 0]], float)  # object z (up) -> camera -y
    el = np.deg2rad(15.0)
    Rx = np.array([[1, 0, 0], [0, np.cos(el), -np.sin(el)], [0, np.sin(el), np.cos(el)]])
    sun = np.array([-0.55, -0.65, -0.5])
    sun /= np.linalg.norm(sun)
    for s in range(n):
        a = procedural_asset("traffic_cone", np.random.default_rng([seed, s]))
        z = 600.0 * a.height_m / (TILE[1] * 1.6)
        R = Rx @ R_up
        t = np.array([0.0, 0.0, z]) - R @ np.array([0.0, 0.0, a.height_m / 2])
        L = render_object(a, make_rigid(R, t), intr, ssaa=2)
        shade = np.clip((L.normals_in_cam * sun).sum(-1), 0, 1) * 0.85 + 0.3
        lin = np.clip(L.albedo_linear * shade[..., None], 0, 1)
        al = L.alpha[..., None]
        rgb = linear_to_srgb(lin) * al + (np.array(BG) / 255.0) * (1 - al)
        out.append(Image.fromarray((rgb * 255 + 0.5).astype(np.uint8)).resize(TILE, Image.LANCZOS))
    return out


def body_colour_stats(tiles: list[Image.Image]) -> tuple[float, float, float]:
    """Median saturation, value (0-1) and hue (deg) of the cone-body pixels of ``tiles``: hue within 30 deg of red/
    orange/yellow and saturation > 0.45 (backgrounds are mostly grey/green/blue); bands and bases are left out."""
    hsv = np.concatenate([np.asarray(t.convert("HSV"), float).reshape(-1, 3) for t in tiles]) / 255.0
    hue = hsv[:, 0] * 360
    m = ((hue < 65) | (hue > 340)) & (hsv[:, 1] > 0.45) & (hsv[:, 2] > 0.15)
    hue = np.where(hue > 180, hue - 360, hue)
    return float(np.median(hsv[m, 1])), float(np.median(hsv[m, 2])), float(np.median(hue[m]))


def sheet(sections: list[tuple[str, list[Image.Image]]]) -> Image.Image:
    head = 18
    rows = [(title, [tiles[i : i + COLS] for i in range(0, len(tiles), COLS)]) for title, tiles in sections]
    H = sum(head + len(r) * TILE[1] for _, r in rows)
    out = Image.new("RGB", (COLS * TILE[0], H), (30, 30, 30))
    d = ImageDraw.Draw(out)
    y = 0
    for title, rr in rows:
        d.text((4, y + 3), title, fill=(235, 235, 235))
        y += head
        for row in rr:
            for j, t in enumerate(row):
                out.paste(t, (j * TILE[0], y))
            y += TILE[1]
    return out


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--tracon", type=Path, default=None, help="TraCon root (default $AIAS_DATA/tracon)")
    ap.add_argument("--out", type=Path, default=Path("studies/assets/cone_family/result/cone_family_sheet.jpg"))
    ap.add_argument("--preset", default="balanced")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--min-real-px", type=int, default=60)
    ap.add_argument("--min-inserted-px", type=int, default=40)
    args = ap.parse_args(argv)
    root = args.tracon or data_root() / "tracon"
    t0 = time.perf_counter()
    real = real_tiles(root, 2 * COLS, args.min_real_px)
    proc, s_proc = inserted_tiles(root, 2 * COLS, "procedural", args.preset, args.seed, args.min_inserted_px)
    default, s_def = inserted_tiles(root, COLS, "default", args.preset, args.seed, args.min_inserted_px)
    studio = studio_tiles(COLS, args.seed)
    img = sheet(
        [
            ("real: TraCon val label boxes", real),
            (f"procedural family, inserted by the pipeline ({args.preset}) into empty TraCon train images", proc),
            ("current default mesh (gazebo construction_cone), inserted the same way", default),
            ("procedural family alone: render_object albedo x Lambert sun + ambient, seeds 0-9", studio),
        ]
    )
    for name, tiles in (
        ("real", real),
        ("procedural inserted", proc),
        ("default inserted", default),
        ("procedural studio", studio),
    ):
        sat, val, hue = body_colour_stats(tiles)
        print(f"{name:20s} cone-body pixels: median saturation {sat:.2f}, value {val:.2f}, hue {hue:.0f} deg")
    args.out.parent.mkdir(parents=True, exist_ok=True)
    img.save(args.out)
    print(
        f"wrote {args.out} ({img.width}x{img.height}); pipeline {s_proc:.1f} s/image (procedural), "
        f"{s_def:.1f} s/image (default); total {time.perf_counter() - t0:.0f} s"
    )


if __name__ == "__main__":
    main()

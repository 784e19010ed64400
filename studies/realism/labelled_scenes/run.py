"""Inserted cones beside a photo's own labelled cones: the same size on the same row, the same look.

Per photo (TraCon photos with >= 2 labelled cones whole in the frame, bottom rows >= 30 px apart; the first N in
name order of a split), the image door inserts 3 cones (``--preset``, seed ``[53, i]``) with the labelled cones as
existing boxes, as a user with a labelled dataset runs it. Measured on the output, the same way for real and inserted
cones (none of it reads the code's records except the inserted boxes):

- **same-row size ratio**: an inserted box's height over the height the photo's own cones have on its bottom row,
  from the line ``h = c v_bottom + c0`` fitted to the labelled whole boxes (equal objects on a planar ground); the
  real cones' own ratio, each against the line of the others (leave one out), is the measure's floor;
- **nearest-row neighbour ratio** (no line): an inserted box's height over the labelled whole box whose bottom row
  is nearest, counted when the rows are within 5 % of the image height; the real cones' own ratio against their
  nearest other real cone is its floor;
- **base brightness**: the median HSV value of a box's base band (rows 88-98 % of its height, the central 60 % of its
  width), an inserted cone's over the median of the photo's real cones'; each real cone's over the median of the
  others (leave one out) is its floor;
- **body brightness**: :func:`aias_augment.analyse.instances.fit_cone_look`'s body value of an inserted cone over
  the median of the photo's real cones' (leave one out among the real cones: the floor);
- **look agreement**: :func:`aias_augment.analyse.instances.fit_cone_look` on each inserted box against the photo's
  labelled cones: the base class and the sleeve count of at least one of them, body hue within 15 deg of it.

Commands (``before``: rendered from a checkout of the previous code, its own ``render``; the development split is
TraCon train, val is reported once; every box is mask-tight, as labels are: an inserted cone's is its annotation's
``amodal_box_xywh``, the box of its whole rendered mask)::

  python -m studies.realism.labelled_scenes render --split train --tag after --tmp T
  (cd OLD && python -m studies.realism.labelled_scenes render --split train --tag before --tmp T)
  python -m studies.realism.labelled_scenes measure --tmp T --tags before after --name train
"""

from __future__ import annotations

import argparse
import json
from dataclasses import replace
from pathlib import Path

import cv2
import numpy as np

from aias_augment.pipeline.config import load_preset
from aias_augment.pipeline.image import insert_into_image
from studies._shared.labelled_cones import base_v, photos, whole_boxes
from studies._shared.pictures import write_jpeg

NEIGHBOUR_ROWS = 0.05  # a labelled cone is an inserted one's neighbour when their bottom rows are this close


def render(a) -> None:
    cfg = load_preset(a.preset)
    if a.variety:
        cfg = replace(cfg, cone_look="variety")
    if a.no_pitch:
        cfg = replace(cfg, placement_cfg=replace(cfg.placement_cfg, pitch_from_references=False))
    if a.no_rows:
        cfg = replace(cfg, placement_cfg=replace(cfg.placement_cfg, sizes_from_rows=False))
    if a.arrangement:
        cfg = replace(cfg, arrangement=a.arrangement)
    a.tmp.mkdir(parents=True, exist_ok=True)
    rows = []
    for i, (stem, img, boxes) in enumerate(photos(a.split, a.n)):
        xywh = np.c_[boxes[:, :2], boxes[:, 2:] - boxes[:, :2]]
        res = insert_into_image(
            img, xywh, ["cone"] * len(boxes), cfg=cfg, rng=np.random.default_rng([53, i]), n_objects=3
        )
        inserted = [  # mask-tight, occluded parts included: the box a labeller draws round the whole cone
            [x, y, x + w, y + h]
            for p, ann in zip(res.record.placements, res.record.annotations)
            if not p.decoy
            for x, y, w, h in [map(float, ann.amodal_box_xywh)]
        ]
        cv2.imwrite(str(a.tmp / f"{a.tag}_{i}.png"), cv2.cvtColor(res.image, cv2.COLOR_RGB2BGR))
        arranged = res.record.modules.get("arrangement")  # which objects stood with the others (the record's note)
        rows.append({"photo": stem, "real": boxes.tolist(), "inserted": inserted, "arrangement": arranged})
        print(f"{a.tag} {i} {stem}: {len(inserted)} inserted", flush=True)
    (a.tmp / f"{a.tag}.json").write_text(json.dumps(rows))


def _hue(rgb) -> float:
    hsv = cv2.cvtColor(np.uint8([[np.clip(rgb, 0, 255)]]), cv2.COLOR_RGB2HSV_FULL)[0, 0]
    return float(hsv[0]) * 360.0 / 256.0


def _agrees(look, real_looks) -> bool:
    for r in real_looks:
        gap = abs(_hue(look.colour_rgb) - _hue(r.colour_rgb)) % 360
        if look.base_colour == r.base_colour and look.bands == r.bands and min(gap, 360 - gap) <= 15:
            return True
    return False


def measure_tag(rows: list, images: list) -> dict:
    from aias_augment.analyse.instances import fit_cone_look  # here: ``render`` also runs on older checkouts

    ratios, base, floor, base_floor, body, body_floor, agree, looked = [], [], [], [], [], [], 0, 0
    near, near_floor = [], []
    for row, img in zip(rows, images):
        whole = whole_boxes(np.array(row["real"]), img.shape[0])
        gap = NEIGHBOUR_ROWS * img.shape[0]
        for box in row["inserted"]:
            d = np.abs(whole[:, 3] - box[3])
            if d.min() <= gap:
                near.append((box[3] - box[1]) / (whole[d.argmin(), 3] - whole[d.argmin(), 1]))
        for j in range(len(whole)):
            d = np.abs(whole[:, 3] - whole[j, 3])
            d[j] = np.inf
            if d.min() <= gap:
                near_floor.append((whole[j, 3] - whole[j, 1]) / (whole[d.argmin(), 3] - whole[d.argmin(), 1]))
        c, c0 = np.polyfit(whole[:, 3], whole[:, 3] - whole[:, 1], 1)
        vs = np.array([base_v(img, b) for b in whole])
        real_v = np.median(vs)
        base_floor += [vs[j] / max(np.median(np.delete(vs, j)), 1.0) for j in range(len(vs))]
        real_looks = [x for x in (fit_cone_look(img, b) for b in whole) if x is not None]
        real_body = [x.body_value for x in real_looks]
        for box in row["inserted"]:
            ratios.append((box[3] - box[1]) / (c * box[3] + c0))
            base.append(base_v(img, box) / max(real_v, 1.0))
            look = fit_cone_look(img, box)
            if look is not None and real_body:
                body.append(look.body_value / np.median(real_body))
            if look is not None and real_looks:
                looked += 1
                agree += _agrees(look, real_looks)
        body_floor += [v / np.median(np.delete(real_body, j)) for j, v in enumerate(real_body) if len(real_body) >= 2]
        for j in range(len(whole)) if len(whole) >= 3 else ():
            o = np.delete(whole, j, 0)
            cj, c0j = np.polyfit(o[:, 3], o[:, 3] - o[:, 1], 1)
            floor.append((whole[j, 3] - whole[j, 1]) / (cj * whole[j, 3] + c0j))
    r, b, f, nr, nf = np.array(ratios), np.array(base), np.array(floor), np.array(near), np.array(near_floor)
    within = lambda x, lo, hi: float(np.mean((x >= lo) & (x <= hi))) if len(x) else None  # noqa: E731
    return {
        "photos": len(rows),
        "inserted": len(r),
        "size_ratio_median": float(np.median(r)) if len(r) else None,
        "size_ratio_within_0.8_1.25": within(r, 0.8, 1.25),
        "size_ratio_within_count": int(((r >= 0.8) & (r <= 1.25)).sum()),
        "real_leave_one_out_within_0.8_1.25": within(f, 0.8, 1.25),
        "neighbour_ratio_counted": len(nr),
        "neighbour_ratio_median": float(np.median(nr)) if len(nr) else None,
        "neighbour_ratio_within_0.8_1.25": within(nr, 0.8, 1.25),
        "real_neighbour_ratio_within_0.8_1.25": within(nf, 0.8, 1.25),
        "base_v_ratio_median": float(np.median(b)) if len(b) else None,
        "base_v_within_10pct": within(b, 0.9, 1.1),
        "base_v_within_25pct": within(b, 0.75, 1.25),
        "body_v_ratio_median": float(np.median(body)) if body else None,
        "body_v_within_10pct": within(np.array(body), 0.9, 1.1),
        "real_body_v_within_10pct": within(np.array(body_floor), 0.9, 1.1),
        "real_base_v_within_10pct": within(np.array(base_floor), 0.9, 1.1),
        "real_base_v_within_25pct": within(np.array(base_floor), 0.75, 1.25),
        "look_agrees": agree,
        "look_measured": looked,
        **_arrangement_counts(rows),
    }


def _arrangement_counts(rows: list) -> dict:
    """How many inserted objects joined an arrangement and how many stood on their own for want of ground at their
    place in it (the records' notes; none for a render without them)."""
    notes = [row.get("arrangement") for row in rows if row.get("arrangement")]
    if not notes:
        return {}
    joined = [n.split("[", 1)[1].split("]", 1)[0] for n in notes]
    return {
        "arranged_photos": len(notes),
        "arrangement_joined": sum(0 if j == "none" else len(j.split(", ")) for j in joined),
        "arrangement_alone": sum(int(n.split(" placed on their own")[0].rsplit(" ", 1)[1]) for n in notes),
    }


CROP_PX = 72  # crop height on the sheet


def _crops(img: np.ndarray, boxes, colour, n: int) -> list[np.ndarray]:
    """Up to ``n`` boxes of ``img`` (RGB) cut out with 15 % context, CROP_PX high, framed in ``colour`` (BGR)."""
    out = []
    for x0, y0, x1, y1 in list(boxes)[:n]:
        m = 0.15 * (y1 - y0)
        cut = img[max(0, int(y0 - m)) : int(np.ceil(y1 + m)), max(0, int(x0 - m)) : int(np.ceil(x1 + m))]
        if not cut.size:
            continue
        w = max(8, int(round(CROP_PX * cut.shape[1] / cut.shape[0])))
        tile = cv2.resize(cv2.cvtColor(cut, cv2.COLOR_RGB2BGR), (w, CROP_PX), interpolation=cv2.INTER_AREA)
        out.append(cv2.copyMakeBorder(tile, 2, 2, 2, 2, cv2.BORDER_CONSTANT, value=colour))
    return out


def crop_sheet(tags: list[str], rows: dict, imgs: dict, n_photos: int) -> np.ndarray:
    """Per photo one row: its labelled cones (green), then each tag's inserted cones (red), the tags apart by a
    grey bar; a header names the groups. The plans of two tags differ, so their cones are other draws."""
    lines = []
    for i in range(min(n_photos, *(len(rows[t]) for t in tags))):
        img = imgs[tags[0]][i]
        groups = [_crops(img, whole_boxes(np.array(rows[tags[0]][i]["real"]), img.shape[0]), (0, 200, 0), 3)]
        groups += [_crops(imgs[t][i], rows[t][i]["inserted"], (0, 0, 230), 3) for t in tags]
        if not any(groups[1:]):
            continue
        gap = np.full((CROP_PX + 4, 10, 3), 128, np.uint8)
        parts = []
        for g in groups:
            parts += (g or [np.full((CROP_PX + 4, 40, 3), 255, np.uint8)]) + [gap]
        lines.append(np.hstack(parts[:-1]))
    if not lines:
        return np.zeros((1, 1, 3), np.uint8)
    width = max(x.shape[1] for x in lines)
    header = np.full((26, width, 3), 255, np.uint8)
    cv2.putText(header, "labelled | " + " | ".join(tags), (4, 19), cv2.FONT_HERSHEY_SIMPLEX, 0.6, (0, 0, 0), 1)
    return np.vstack(
        [header] + [np.pad(x, ((0, 2), (0, width - x.shape[1]), (0, 0)), constant_values=255) for x in lines]
    )


def frame_sheet(tags: list[str], rows: dict, imgs: dict, n_photos: int, width: int = 240) -> np.ndarray:
    """Per photo the whole output of each tag side by side (``width`` px wide), two photos a line, its labelled
    cones framed green and its inserted cones red, so that where the new cones stand beside the photo's own can be
    seen."""
    lines = []
    for i in range(min(len(rows[t]) for t in tags)):
        if len(lines) == n_photos:
            break
        if not any(len(rows[t][i]["inserted"]) for t in tags):
            continue
        tiles = []
        for t in tags:
            img = cv2.cvtColor(imgs[t][i], cv2.COLOR_RGB2BGR)
            k = width / img.shape[1]
            tile = cv2.resize(img, (width, int(round(img.shape[0] * k))), interpolation=cv2.INTER_AREA)
            for boxes, colour in ((rows[t][i]["real"], (0, 200, 0)), (rows[t][i]["inserted"], (0, 0, 230))):
                for x0, y0, x1, y1 in np.asarray(boxes, float).reshape(-1, 4) * k:
                    cv2.rectangle(tile, (int(x0), int(y0)), (int(x1), int(y1)), colour, 2)
            cv2.putText(tile, t, (6, 22), cv2.FONT_HERSHEY_SIMPLEX, 0.7, (255, 255, 255), 2)
            tiles.append(tile)
        height = max(x.shape[0] for x in tiles)
        lines.append(np.hstack([np.pad(x, ((0, height - x.shape[0] + 4), (0, 4), (0, 0))) for x in tiles]))
    if not lines:
        return np.zeros((1, 1, 3), np.uint8)
    lines += [np.zeros_like(lines[0][:1])] * (len(lines) % 2)  # two photos a line: the sheet stays legible
    pairs = []
    for left, right in zip(lines[::2], lines[1::2]):
        h = max(left.shape[0], right.shape[0])
        pad = [np.pad(x, ((0, h - x.shape[0]), (0, 0), (0, 0)), constant_values=255) for x in (left, right)]
        pairs.append(np.hstack([pad[0], np.full((h, 16, 3), 255, np.uint8), pad[1]]))
    width = max(x.shape[1] for x in pairs)
    return np.vstack([np.pad(x, ((0, 0), (0, width - x.shape[1]), (0, 0)), constant_values=255) for x in pairs])


def measure(a) -> None:
    out, rows, imgs = {}, {}, {}
    for tag in a.tags:
        rows[tag] = json.loads((a.tmp / f"{tag}.json").read_text())
        imgs[tag] = [
            cv2.cvtColor(cv2.imread(str(a.tmp / f"{tag}_{i}.png")), cv2.COLOR_BGR2RGB) for i in range(len(rows[tag]))
        ]
        out[tag] = measure_tag(rows[tag], imgs[tag])
    a.out.mkdir(parents=True, exist_ok=True)
    (a.out / f"{a.name}.json").write_text(json.dumps(out, indent=1) + "\n")
    write_jpeg(a.out / f"{a.name}_sheet.jpg", crop_sheet(a.tags, rows, imgs, a.sheet))
    if a.frames:
        write_jpeg(a.out / f"{a.name}_frames.jpg", frame_sheet(a.tags, rows, imgs, a.frames))
    print(json.dumps(out, indent=1))


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = ap.add_subparsers(dest="step", required=True)
    r = sub.add_parser("render")
    r.add_argument("--split", choices=("train", "val"), default="train")
    r.add_argument("--n", type=int, default=30)
    r.add_argument("--preset", default="balanced")
    r.add_argument("--tag", required=True)
    r.add_argument("--tmp", type=Path, required=True)
    r.add_argument("--variety", action="store_true", help="cone_look: variety")
    r.add_argument("--no-pitch", action="store_true", help="placement_cfg.pitch_from_references: false")
    r.add_argument("--no-rows", action="store_true", help="placement_cfg.sizes_from_rows: false")
    r.add_argument("--arrangement", default=None, help="InsertionConfig.arrangement instead of the preset's")
    m = sub.add_parser("measure")
    m.add_argument("--tmp", type=Path, required=True)
    m.add_argument("--tags", nargs="+", required=True)
    m.add_argument("--name", default="train")
    m.add_argument("--sheet", type=int, default=14, help="photos on the crop sheet")
    m.add_argument("--frames", type=int, default=0, help="photos on a whole-frame sheet (0: none; it is large)")
    m.add_argument("--out", type=Path, default=Path(__file__).parent / "result")
    a = ap.parse_args()
    render(a) if a.step == "render" else measure(a)
    return 0

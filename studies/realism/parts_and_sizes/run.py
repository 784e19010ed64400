"""Before/after sheet of issue 53 items 3 and 5 (materials per part, per-object sizes) on TraCon val photos.

Run once per code version, then compose (``before``: a checkout of the commit before the change on PYTHONPATH):

  PYTHONPATH=OLD_CHECKOUT python -m studies.realism.parts_and_sizes render --tag before --tmp T
  python -m studies.realism.parts_and_sizes render --tag after --tmp T
  python -m studies.realism.parts_and_sizes compose --tmp T

Per photo: the balanced preset, 3 cones inserted (seeded), the labelled cones as existing boxes ("traffic_cone").
Measured on the output, the same way for real and inserted cones: base V = median HSV value of the box's base band
(rows 88-98 % of the box height, the central 60 % of its width), inserted cones with a black base only; size ratio =
inserted box height over the height a real cone has on that row, from the line h = c (v_bottom - v0) fitted to the
photo's own labelled cones (a planar ground: equal objects' box heights are linear in their bottom rows).
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import cv2
import numpy as np

from aias_augment.analyse.analysis import analyse_scene
from aias_augment.apply.stages import apply_plan
from aias_augment.core.frame import Frame
from aias_augment.pipeline.config import load_preset
from aias_augment.plan.insertion import plan_insertion
from studies._shared.labelled_cones import base_v, photos

HERE = Path(__file__).parent / "result"


def render(tag: str, tmp: Path) -> None:
    cfg = load_preset("balanced")
    rows = []
    for i, (stem, img, boxes) in enumerate(photos("val", 4)):
        an = analyse_scene(Frame(img, None), cfg)
        plan = plan_insertion(
            an,
            cfg,
            np.random.default_rng([53, i]),
            n_objects=3,
            existing_boxes_xyxy=boxes,
            existing_labels=["traffic_cone"] * len(boxes),
        )
        out = apply_plan(Frame(img, None), an, plan, cfg)
        ins = [
            (list(p.amodal_box_xyxy), p.asset_meta.get("base_colour"))
            for p in out.placements
            if p.category == "traffic_cone"
        ]
        cv2.imwrite(str(tmp / f"{tag}_{i}.png"), cv2.cvtColor(out.image, cv2.COLOR_RGB2BGR))
        rows.append({"photo": stem, "real": boxes.tolist(), "inserted": ins})
    (tmp / f"{tag}.json").write_text(json.dumps(rows))


def measure(rows: list, images: list) -> dict:
    ratios, ins_v, real_v = [], [], []
    for row, img in zip(rows, images):
        real = np.array(row["real"])
        H = img.shape[0]
        whole = real[(real[:, 1] > 1) & (real[:, 3] < H - 2)]
        c, c0 = np.polyfit(whole[:, 3], whole[:, 3] - whole[:, 1], 1)  # h = c v + c0
        real_v += [base_v(img, b) for b in whole]
        for box, base in row["inserted"]:
            ratios.append((box[3] - box[1]) / (c * box[3] + c0))
            if base == "black":
                ins_v.append(base_v(img, box))
    r = np.array(ratios)
    return {
        "size_ratio": np.round(np.sort(r), 2).tolist(),
        "size_ratio_within_0.8_1.25": float(np.mean((r >= 0.8) & (r <= 1.25))) if len(r) else None,
        "base_v_inserted_black": np.round(ins_v, 0).tolist(),
        "base_v_real": np.round(real_v, 0).tolist(),
    }


def compose(tmp: Path) -> None:
    out, tiles = {}, []
    for tag in ("before", "after"):
        rows = json.loads((tmp / f"{tag}.json").read_text())
        imgs = [cv2.imread(str(tmp / f"{tag}_{i}.png")) for i in range(len(rows))]
        out[tag] = measure(rows, [cv2.cvtColor(m, cv2.COLOR_BGR2RGB) for m in imgs])
        for row, img in zip(rows, imgs):
            for b in row["real"]:
                cv2.rectangle(img, tuple(map(int, b[:2])), tuple(map(int, b[2:])), (0, 255, 0), 1)
            for b, _ in row["inserted"]:
                cv2.rectangle(img, tuple(map(int, b[:2])), tuple(map(int, b[2:])), (0, 0, 255), 1)
            cv2.putText(img, tag, (8, 24), cv2.FONT_HERSHEY_SIMPLEX, 0.8, (255, 255, 255), 2)
        tiles.append([cv2.resize(m, (400, int(400 * m.shape[0] / m.shape[1]))) for m in imgs])
    rows_img = []
    for b, a in zip(*tiles):
        h = max(b.shape[0], a.shape[0])
        rows_img.append(np.hstack([np.pad(m, ((0, h - m.shape[0]), (0, 0), (0, 0))) for m in (b, a)]))
    sheet = np.vstack(rows_img)
    s = min(1.0, 1600 / max(sheet.shape[:2]))
    sheet = cv2.resize(sheet, None, fx=s, fy=s, interpolation=cv2.INTER_AREA) if s < 1 else sheet
    cv2.imwrite(str(HERE / "sheet.jpg"), sheet, [cv2.IMWRITE_JPEG_QUALITY, 88])
    (HERE / "numbers.json").write_text(json.dumps(out, indent=1))
    print(json.dumps(out, indent=1))


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("step", choices=("render", "compose"))
    ap.add_argument("--tag", default="after")
    ap.add_argument("--tmp", type=Path, required=True)
    a = ap.parse_args()
    a.tmp.mkdir(parents=True, exist_ok=True)
    render(a.tag, a.tmp) if a.step == "render" else compose(a.tmp)


if __name__ == "__main__":
    main()

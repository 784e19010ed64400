"""Real vs lifted vs rendered cones, side by side at the same height, and the lifted assets inserted into roads.

For TraCon train cone instances: the photo's crop | the lifted surface of revolution rendered from its source view
(albedo under a fixed grey light) | the same turned 90 deg | the shared cone mesh | a member of the procedural cone
family (the presets' cones), all at the same pixel height; the silhouette IoU of each source-view render with its
cutout; then six empty TraCon roads with lifted cones inserted by the pipeline (fast preset) beside the same roads
with the shared mesh.

    python -m studies.assets.lift --images 40 --out studies/assets/lift/result
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import cv2
import numpy as np

from aias_augment.apply.render import linear_to_srgb, render_object
from aias_augment.assets.asset import default_asset
from aias_augment.assets.bank.lift import LiftConfig, LiftedAssets, cut_out, lift_instances, profile_iou
from aias_augment.assets.bank.lift_view import source_view
from aias_augment.assets.bank.procedural import procedural_asset_from_seed
from aias_augment.core.config import data_root
from detection_eval.data import load_yolo_dir, read_image_rgb
from studies._shared.pictures import write_jpeg

CELL = 160


def _shade(layers) -> np.ndarray:
    """Albedo x (0.35 + 0.65 max(0, n.l)) for a light from the upper left-front, as sRGB on grey."""
    n = layers.normals_in_cam
    light = np.array([-0.4, -0.5, -0.77])
    light /= np.linalg.norm(light)
    lin = layers.albedo_linear * (0.35 + 0.65 * np.clip(n @ light, 0, None))[..., None]
    rgb = linear_to_srgb(lin)
    a = layers.alpha[..., None]
    return np.clip((a * rgb + (1 - a) * 0.5) * 255, 0, 255).astype(np.uint8)


def _cell(img: np.ndarray) -> np.ndarray:
    h, w = img.shape[:2]
    s = CELL / max(h, w)
    r = cv2.resize(img, (max(1, round(w * s)), max(1, round(h * s))), interpolation=cv2.INTER_AREA)
    out = np.full((CELL, CELL, 3), 128, np.uint8)
    y0, x0 = (CELL - r.shape[0]) // 2, (CELL - r.shape[1]) // 2
    out[y0 : y0 + r.shape[0], x0 : x0 + r.shape[1]] = r
    return out


def _turned(T: np.ndarray, deg: float) -> np.ndarray:
    c, s = np.cos(np.radians(deg)), np.sin(np.radians(deg))
    Rz = np.eye(4)
    Rz[:2, :2] = [[c, -s], [s, c]]
    return T @ Rz


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--images", type=int, default=40, help="cone images of TraCon train to lift from")
    p.add_argument("--rows", type=int, default=10, help="instances shown in the contact sheet")
    p.add_argument("--out", default="studies/assets/lift/result")
    args = p.parse_args()
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    train = load_yolo_dir(data_root() / "tracon", "train", ("cone",))
    recs = [r for r in train.records if len(r.labels)][: args.images]
    cfg = LiftConfig()
    t0 = time.perf_counter()
    items = [(r.image_path, read_image_rgb(r.image_path), r.boxes_xyxy) for r in recs]
    assets, report = lift_instances(items, "traffic_cone", out / "bank", cfg)
    lift_s = time.perf_counter() - t0
    by_src = {(a.meta["source_image"], tuple(a.meta["source_box_xyxy"])): a for a in assets}
    mesh_cone = default_asset("traffic_cone")
    rows, ious = [], []
    for path, image, boxes in items:
        for k, box in enumerate(boxes):
            a = by_src.get((str(path), tuple(map(float, box))))
            if a is None:
                continue
            cut, _ = cut_out(image, box, [b for j, b in enumerate(boxes) if j != k], cfg)
            T, intr = source_view(cut, a)
            lay = render_object(a, T, intr, ssaa=1)
            m = lay.alpha > 0.5
            iou = float((m & cut.mask).sum() / max((m | cut.mask).sum(), 1))
            ious.append(
                {
                    "image": Path(path).name,
                    "box": k,
                    "render_iou": iou,
                    "profile_iou": profile_iou(cut.mask),
                    "height_px": int(cut.mask.any(1).sum()),
                }
            )
            if len(rows) < args.rows:
                crop = cut.rgb.copy()
                cnt, _ = cv2.findContours(cut.mask.astype(np.uint8), cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_NONE)
                cv2.drawContours(crop, cnt, -1, (0, 255, 0), 1)
                lay_hi = render_object(a, T, intr, ssaa=2)
                turned = render_object(a, _turned(T, 90), intr, ssaa=2)
                scale = a.height_m / mesh_cone.height_m
                mesh = render_object(mesh_cone.scaled(scale), T, intr, ssaa=2)
                fam = procedural_asset_from_seed("traffic_cone", len(rows))  # the presets' family, one per row
                fam = render_object(fam.scaled(a.height_m / fam.height_m), T, intr, ssaa=2)
                rows.append(
                    np.hstack(
                        [
                            _cell(crop),
                            _cell(_shade(lay_hi)),
                            _cell(_shade(turned)),
                            _cell(_shade(mesh)),
                            _cell(_shade(fam)),
                        ]
                    )
                )
    head = np.full((28, 5 * CELL, 3), 255, np.uint8)
    titles = ("real (mask outline)", "lifted, source view", "lifted, turned 90 deg", "shared mesh", "procedural family")
    for i, t in enumerate(titles):
        cv2.putText(head, t, (i * CELL + 4, 19), cv2.FONT_HERSHEY_SIMPLEX, 0.42, (0, 0, 0), 1, cv2.LINE_AA)
    write_jpeg(out / "contact_sheet.jpg", np.vstack([head] + rows)[..., ::-1])

    # The lifted bank (read back from its GLB files) inserted by the pipeline, beside the shared mesh.
    from aias_augment.pipeline.image import insert_into_image, load_preset

    cfg_ins = load_preset("fast", harmonize_method="camera")
    bank = LiftedAssets.from_dir(out / "bank")
    empties = [r for r in train.records if not len(r.labels)][:6]
    tiles = []
    for j, r in enumerate(empties):
        img = read_image_rgb(r.image_path)
        s = min(1.0, 640 / max(img.shape[:2]))
        img = cv2.resize(img, (round(img.shape[1] * s), round(img.shape[0] * s)), interpolation=cv2.INTER_AREA)
        pair = []
        for b in (bank, None):
            res = insert_into_image(img, np.zeros((0, 4)), [], np.random.default_rng([0, j]), cfg_ins, bank=b)
            pair.append(cv2.resize(res.image, (400, 300), interpolation=cv2.INTER_AREA))
        tiles.append(np.hstack(pair))
    write_jpeg(out / "inserted_lifted_vs_mesh.jpg", np.ascontiguousarray(np.vstack(tiles)[..., ::-1]))
    r_iou = [e["render_iou"] for e in ious]
    summary = {
        "command": "python -m studies.assets.lift " + " ".join(f"--{k} {v}" for k, v in vars(args).items()),
        "images": len(items),
        "lift": report.to_dict()["rejected"],
        "lifted": report.lifted,
        "lift_seconds_per_instance": lift_s / max(report.lifted, 1),
        "render_iou_median": float(np.median(r_iou)) if r_iou else None,
        "render_iou_min": float(np.min(r_iou)) if r_iou else None,
        "render_iou_below_0.9": int(sum(i < 0.9 for i in r_iou)),
        "label_margins_frac_median": dict(
            zip(
                ("left", "top", "right", "bottom"),
                np.median([a.meta["label_margins_frac"] for a in assets], axis=0).round(4).tolist(),
            )
        )
        if assets
        else None,
        "instances": ious,
    }
    (out / "report.json").write_text(json.dumps(summary, indent=1))
    print(json.dumps({k: v for k, v in summary.items() if k != "instances"}, indent=1))


if __name__ == "__main__":
    main()

"""Shadow depth check on a sunny KITTI street: inserted objects' shadows against the real cast shadows of the frame.

Real shadows: the road box in front of the car (flat ground 1.65 m below the camera, KITTI's mounting height;
lateral -1.5..2.0 m, 6..20 m ahead: the asphalt lane, no curb or grass) is split into lit and shadowed asphalt by
``ratio.measure_lit_shadow`` (2-component Gaussian mixture on log-luminance, same-material chroma gate, confident
posteriors only); real shadow/lit = median shadowed / median lit linear luminance.

Inserted shadows: ``pipeline.insert_into_image`` inserts one object (harmonization off, so only the shadow changes
the road) with the KITTI intrinsics; per road pixel q = output / input linear luminance. The inserted shadow is where
q < 0.97 outside the object's own mask (dilated by 2 px) and away from its base (ground within half the footprint
diagonal + 0.75 x height of the object's origin is excluded: there the pipeline's contact occlusion, not the sun
shadow, darkens the road); its umbra is that set eroded by 2 px (away from the soft
edge); inserted shadow/lit = median q over the umbra of pixels that were lit in the input. Two variants:
"road_placement" stands the object just left of the road box (drawn per seed, like this street's poles) and runs the pipeline's own shading, shadow-catcher
(``pipeline._object_shadow``) and compositing functions with ``estimate_lighting`` measured on the road box (the public
``insert_into_image`` cannot be told to place on the road); "pipeline" is ``insert_into_image`` end to end (camera
given, no depth), counted only when its shadow falls on the road box.

Usage: python scripts/eval_lighting_kitti.py --out results/lighting
"""
from __future__ import annotations

import argparse
import json
import os
import sys
import time
from dataclasses import replace
from pathlib import Path

os.environ.setdefault("PYOPENGL_PLATFORM", "egl")

import numpy as np  # noqa: E402
from scipy import ndimage  # noqa: E402

from aias_augment.config import data_root  # noqa: E402
from aias_augment.geometry import Intrinsics  # noqa: E402
from aias_augment.lighting import hdr, ratio  # noqa: E402

KITTI_K = (707.0912, 707.0912, 601.8873, 183.1104)
KITTI_CAMERA_HEIGHT_M = 1.65
ROAD_LATERAL_M = (-1.5, 2.0)
ROAD_FORWARD_M = (6.0, 20.0)


def load_frame(folder: Path, idx: int) -> np.ndarray:
    from PIL import Image

    p = folder / f"kitti06-{idx}-color.png"
    if not p.is_file():
        raise FileNotFoundError(p)
    return np.array(Image.open(p).convert("RGB"))


def road_mask(K: Intrinsics) -> np.ndarray:
    return ratio.ground_region_mask(K, np.array([0.0, -1.0, 0.0]), KITTI_CAMERA_HEIGHT_M, ROAD_LATERAL_M, ROAD_FORWARD_M)


def real_shadow(img: np.ndarray, road: np.ndarray) -> ratio.LitShadowMeasurement:
    m = ratio.measure_lit_shadow(hdr.srgb_to_linear(img), road)
    if m is None:
        raise RuntimeError("too few road pixels")
    return m


def near_object(K: Intrinsics, cam_from_object: np.ndarray, asset, radius_factor: float = 0.75) -> np.ndarray:
    """Ground pixels within (half the footprint diagonal + ``radius_factor`` x height) of the object's origin: where
    the pipeline's contact occlusion (e-folding 0.25 x height) still darkens the ground by > 5 %."""
    g, ok = ratio.ground_coordinates(K, np.array([0.0, -1.0, 0.0]), KITTI_CAMERA_HEIGHT_M)
    origin = cam_from_object[:3, 3]
    ext = np.asarray(asset.extents_m, dtype=np.float64)
    r = 0.5 * float(np.hypot(ext[0], ext[1])) + radius_factor * float(ext[2])
    return ok & (np.hypot(g[..., 0] - origin[0], g[..., 1] - origin[2]) < r)


def inserted_shadow(img_in: np.ndarray, img_out: np.ndarray, road: np.ndarray, lit_in: np.ndarray,
                    object_mask: np.ndarray, exclude: np.ndarray | None = None) -> dict:
    y_in = hdr.luminance(hdr.srgb_to_linear(img_in)).astype(np.float64)
    y_out = hdr.luminance(hdr.srgb_to_linear(img_out)).astype(np.float64)
    q = y_out / np.maximum(y_in, 1e-4)  # eps: black input pixels are excluded below anyway
    obj = ndimage.binary_dilation(object_mask, iterations=2)
    valid = road & ~obj & (y_in > 1e-3) & (img_in.max(axis=2) < 250)
    if exclude is not None:
        valid &= ~exclude
    shadow = valid & (q < 0.97)
    umbra = ndimage.binary_erosion(shadow, iterations=2) & lit_in
    out = {"shadow_pixels": int(shadow.sum()), "umbra_pixels": int(umbra.sum())}
    if umbra.sum() >= 100:  # fewer umbra pixels: a sliver of penumbra or contact shade, not a measurable shadow
        out["inserted_shadow_to_lit"] = float(np.median(q[umbra]))
    return out, umbra


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--data", default=str(data_root() / "kitti06_color_snippet"))
    ap.add_argument("--frames", type=int, nargs="+", default=[12, 13, 14, 17])
    ap.add_argument("--categories", nargs="+", default=["barrier", "barrel", "car"])
    ap.add_argument("--seeds", type=int, nargs="+", default=[0, 1])
    ap.add_argument("--out", default="out/lighting")
    ap.add_argument("--skip-insertion", action="store_true", help="only measure the real shadows")
    args = ap.parse_args(argv)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    folder = Path(args.data)
    fx, fy, cx, cy = KITTI_K
    report = {"command": "python " + " ".join([Path(sys.argv[0]).as_posix()] + (argv if argv is not None else sys.argv[1:])),
              "frames": {}, "insertions": []}
    vis_rows = []
    for idx in args.frames:
        img = load_frame(folder, idx)
        K = Intrinsics(fx, fy, cx, cy, img.shape[1], img.shape[0])
        road = road_mask(K)
        m = real_shadow(img, road)
        report["frames"][idx] = {"real_shadow_to_lit": m.shadow_to_lit, "sun_sky_ratio": m.sun_sky_ratio,
                                 "separation": m.separation, "shadow_fraction": m.shadow_fraction,
                                 "dominant_sun": m.dominant_sun, "road_pixels": m.n_pixels}
        print(f"frame {idx}: real shadow/lit {m.shadow_to_lit:.3f} (sun/sky {m.sun_sky_ratio:.2f}, D {m.separation:.2f},"
              f" shadow {100 * m.shadow_fraction:.1f} %)")
        vis = img.copy()
        vis[road] = (0.6 * vis[road] + [0, 60, 0]).astype(np.uint8)
        vis[m.shadow_mask] = [255, 0, 0]
        vis[m.lit_mask] = (0.5 * vis[m.lit_mask] + [0, 0, 110]).astype(np.uint8)
        if args.skip_insertion:
            vis_rows.append(vis)
            continue
        from pycocotools import mask as mask_utils

        from aias_augment import composite as comp
        from aias_augment import pipeline
        from aias_augment.assets import CATEGORY_HEIGHT_RANGE_M, default_asset
        from aias_augment.lighting.estimate import estimate_lighting
        from aias_augment.lighting.shading import shade_object
        from aias_augment.render import render_object

        lighting_road = estimate_lighting(img, K, meta={"ground_mask": road})
        report["frames"][idx]["estimate"] = lighting_road.to_dict()
        for cat in args.categories:
            for seed in args.seeds:
                rng = np.random.default_rng(seed)
                # (a) "road_placement": the object stands on the road box (lateral, forward drawn per seed) and goes
                # through the pipeline's own shading, shadow-catcher and compositing functions with the lighting
                # estimated on the road box. (b) "pipeline": insert_into_image end to end, wherever it places.
                # Like the real occluders of this street (poles on the left verge), the object stands just left of the
                # road box so that its shadow can cross the lit asphalt instead of hiding behind the object itself.
                yaw = rng.uniform(-np.pi, np.pi)
                base = default_asset(cat)
                lo_h, hi_h = CATEGORY_HEIGHT_RANGE_M.get(cat, (base.height_m, base.height_m))
                asset = base.scaled(rng.uniform(lo_h, hi_h) / base.height_m)
                half_diag = 0.5 * float(np.hypot(*np.asarray(asset.extents_m)[:2]))
                lateral = ROAD_LATERAL_M[0] - half_diag - rng.uniform(0.2, 1.0)
                forward = rng.uniform(8.0, 14.0)
                c, s_ = np.cos(yaw), np.sin(yaw)
                R_up = np.array([[1.0, 0, 0], [0, 0, -1.0], [0, 1.0, 0]])  # object z-up -> camera -y
                cam_from_object = np.eye(4)
                cam_from_object[:3, :3] = R_up @ np.array([[c, -s_, 0], [s_, c, 0], [0, 0, 1.0]])
                cam_from_object[:3, 3] = [lateral, KITTI_CAMERA_HEIGHT_M, forward]
                t = time.perf_counter()
                rl = render_object(asset, cam_from_object, K, ssaa=2)
                shadow_ratio = pipeline._object_shadow(asset, cam_from_object, K, lighting_road, None)
                bg = comp.apply_shadow(comp.to_linear(img), shadow_ratio)
                shaded = shade_object(rl.albedo_linear, rl.normals_in_cam, rl.alpha > 0, lighting_road)
                out_a = comp.to_uint8(comp.alpha_over(bg, shaded, rl.alpha))
                runs = [("road_placement", out_a, rl.alpha > 0, lighting_road, time.perf_counter() - t,
                         near_object(K, cam_from_object, asset))]
                cfg = replace(pipeline.InsertionConfig(categories=(cat,)), harmonize=False, min_objects=1, max_objects=1)
                t = time.perf_counter()
                res = pipeline.insert_into_image(img, rng=np.random.default_rng(seed), cfg=cfg, intrinsics=K, n_objects=1)
                dt = time.perf_counter() - t
                if res.record.annotations:
                    obj = np.zeros(img.shape[:2], bool)
                    for a in res.record.annotations:
                        rle = dict(a.rle)
                        rle["counts"] = rle["counts"].encode("ascii")
                        obj |= mask_utils.decode(rle).astype(bool)
                    near = np.zeros(img.shape[:2], bool)
                    for p in res.record.placements:
                        T = np.asarray(p.cam_from_object, dtype=np.float64)
                        ext_asset = default_asset(cat).scaled(float(p.scale))  # pipeline default asset
                        near |= near_object(K, T, ext_asset)
                    runs.append(("pipeline", res.image, obj, res.record.lighting, dt, near))
                for variant, out_img, obj, light, dt, near in runs:
                    meas, umbra = inserted_shadow(img, out_img, road, m.lit_mask, obj, near)
                    row = {"frame": idx, "category": cat, "seed": seed, "variant": variant, "seconds": dt,
                           "estimated_sun_sky_ratio": light.sun_sky_ratio if light is not None else None,
                           "dominant_sun": bool(light.dominant_sun) if light is not None else None,
                           "real_shadow_to_lit": m.shadow_to_lit, **meas}
                    if "inserted_shadow_to_lit" in meas:
                        row["rel_error"] = abs(meas["inserted_shadow_to_lit"] - m.shadow_to_lit) / m.shadow_to_lit
                        if variant == "road_placement" and seed == args.seeds[0]:
                            v2 = out_img.copy()
                            v2[umbra] = (0.5 * v2[umbra] + [120, 0, 120]).astype(np.uint8)
                            vis = np.concatenate([vis, v2], axis=0)
                    report["insertions"].append(row)
                    print(f"  {cat:8s} seed {seed} {variant:15s}: inserted "
                          f"{meas.get('inserted_shadow_to_lit', float('nan')):.3f} vs real {m.shadow_to_lit:.3f}  "
                          f"rel err {row.get('rel_error', float('nan')):.3f}  (umbra {meas['umbra_pixels']} px, {dt:.1f} s)")
        vis_rows.append(vis)
    summary = {}
    for variant in ("road_placement", "pipeline"):
        errs = [r["rel_error"] for r in report["insertions"] if r["variant"] == variant and "rel_error" in r]
        if errs:
            summary[variant] = {"n": len(errs), "median_rel_error": float(np.median(errs)),
                                "max_rel_error": float(np.max(errs)), "frac_within_15pct": float(np.mean(np.array(errs) < 0.15))}
    report["summary"] = summary
    reals = [f["real_shadow_to_lit"] for f in report["frames"].values()]
    report["real_shadow_to_lit_median"] = float(np.median(reals))
    (out / "kitti_shadow_report.json").write_text(json.dumps(report, indent=1))
    from PIL import Image

    width = max(v.shape[1] for v in vis_rows)
    Image.fromarray(np.concatenate([np.pad(v, ((0, 0), (0, width - v.shape[1]), (0, 0))) for v in vis_rows], 0)[::2, ::2]
                    ).save(out / "kitti_shadows.jpg", quality=80)
    lines = ["# KITTI 06: inserted vs real shadow depth on the road", "", f"Command: `{report['command']}`", "",
             "Real shadow/lit per frame (road box, lit vs shadowed asphalt):", "",
             "| frame | real shadow/lit | sun/sky ratio | Ashman D | shadow fraction | dominant sun |", "|---|---|---|---|---|---|"]
    for idx, f in report["frames"].items():
        lines.append(f"| {idx} | {f['real_shadow_to_lit']:.3f} | {f['sun_sky_ratio']:.2f} | {f['separation']:.2f} "
                     f"| {100 * f['shadow_fraction']:.1f} % | {f['dominant_sun']} |")
    if report["insertions"]:
        lines += ["", "| frame | object | seed | variant | inserted shadow/lit | real | rel. error | umbra px |",
                  "|---|---|---|---|---|---|---|---|"]
        for r in report["insertions"]:
            lines.append(f"| {r['frame']} | {r['category']} | {r['seed']} | {r['variant']} "
                         f"| {r.get('inserted_shadow_to_lit', float('nan')):.3f} | {r['real_shadow_to_lit']:.3f} "
                         f"| {100 * r.get('rel_error', float('nan')):.1f} % | {r['umbra_pixels']} |")
        lines += ["", "Summary (target: within 15 %):", ""]
        for k, s in summary.items():
            lines.append(f"- {k}: n={s['n']}, median rel. error {100 * s['median_rel_error']:.1f} %, max "
                         f"{100 * s['max_rel_error']:.1f} %, {100 * s['frac_within_15pct']:.0f} % within 15 %")
    lines += ["", "![overlay](kitti_shadows.jpg)", "",
              "Overlay: green = road box, red = real shadow pixels, blue = real lit pixels; below each frame, one "
              "insertion with the umbra of its shadow in magenta.", ""]
    (out / "kitti_shadow_report.md").write_text("\n".join(lines))
    print(json.dumps(summary, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())

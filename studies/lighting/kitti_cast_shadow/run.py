"""Does every insertion into a sunny, hard-shadowed street get a cast shadow, and does it point the right way?

Frames: the KITTI 06 colour frames 12, 13, 14, 17 (``kitti06_color_snippet``) and every ``--grey-step``-th frame of the
grey KITTI 06 sequence (``kitti06_seq/image_l``, 8-bit 1-channel PNGs passed as (H, W) arrays, as a user would: the
transform replicates grey to RGB and writes the luminance back). All of them are sunny with hard cast shadows (poles,
trees, cars), so the expected answer is a cast shadow in every insertion.

Production path: ``InsertObjects`` (the albumentations transform, ``p=1``, one object of ``--categories``) with the
presets ``--presets`` (fast: the cheap 160 px analysis, projected shadows, view cache; balanced: full analysis), the
camera given (``camera_k``, KITTI P0/P2) and, with ``--unknown-camera``, also without it; ``--seeds`` seeds each.

Per insertion, from the record and the pixels:
- the sun decision (``lighting.dominant_sun``), its confidence, sun/sky ratio, the estimated sun azimuth (camera frame,
  from forward, right positive) and elevation, and the record's shadow module line;
- cast-shadow pixels: ground pixels outside the object (its RLE mask dilated by 3 px) darkened by the insertion more
  than the contact occlusion alone would (output / input luminance q < c(rho) - ``DARK_MARGIN``, c(rho) = 1 - 0.6
  exp(-rho / (0.25 h)) the documented contact shade at the distance rho from the footprint rectangle, h the object's
  height; and q < ``DARK_Q`` = 0.85; a margin of 0.15: without a sun, the object's anti-aliased edge (1-2 px
  beyond its mask) and the contact shade darkened 5-41 pixels by 10-25 % at 0.05). The ground is the plane
  through the object's base with the object's up axis (the plane the pipeline projects the shadow onto). "Cast shadow" = at least max(``MIN_SHADOW_PX``, 3 % of the object's
  own pixels) such pixels (a distant cone's shadow is a sliver of a few pixels);
- the cast shadow's direction on the ground: from the footprint centre to the darkness-weighted centroid of those
  pixels, as an azimuth in the camera's ground frame.

Truth for the direction (independent of the pipeline): the real shadows of the colour frames. On each colour frame the
road box of ``eval_lighting_kitti`` is split into lit / shadowed asphalt (``ratio.measure_lit_shadow``) and the axis
of the shadow bands (``ratio.shadow_axis_on_ground``) gives the sun's azimuth up to 180 deg; the end is fixed by the
reference read off the frames by eye (sunlit right-hand facades, pole shadows across the road to the right: sun on
the LEFT, see ``eval_lighting_kitti_sun``). The four per-frame azimuths are moved into the world frame with the KITTI
poses and their circular mean is the street's sun; each frame (colour or grey) gets it rotated into its camera. The
real shadows point away from it: expected shadow azimuth = sun azimuth + 180 deg.

Usage: PYOPENGL_PLATFORM=egl python -m studies.lighting.kitti_cast_shadow --out studies/lighting/kitti_cast_shadow/result
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

os.environ.setdefault("PYOPENGL_PLATFORM", "egl")
os.environ.setdefault("NO_ALBUMENTATIONS_UPDATE", "1")

import numpy as np
from scipy import ndimage

from aias_augment.analyse.lighting import ratio
from aias_augment.core import hdr
from aias_augment.core.config import data_root
from aias_augment.core.geometry import Intrinsics
from studies.lighting.kitti_shadow_depth import run as ek

DARK_Q = 0.85
DARK_MARGIN = 0.15
MIN_SHADOW_PX = 5
MIN_SHADOW_FRAC = 0.03
COLOUR_FRAMES = (12, 13, 14, 17)


def load_poses(path: Path) -> np.ndarray:
    """(N, 3, 3) rotations world <- camera of each frame (KITTI pose file, 12 numbers a line)."""
    rows = [np.array(line.split(), float) for line in path.read_text().splitlines() if line.strip()]
    return np.stack([r[-12:].reshape(3, 4)[:, :3] for r in rows])


def yaw_of(R_world_from_cam: np.ndarray) -> float:
    """Heading of the camera's forward axis in the world's ground plane (KITTI world: x right, z forward of frame 0)."""
    f = R_world_from_cam @ np.array([0.0, 0.0, 1.0])
    return float(np.arctan2(f[0], f[2]))


def real_sun_azimuth(img: np.ndarray, K: Intrinsics) -> dict:
    """The sun's azimuth (camera frame, from forward, right positive) from the real shadow bands on the road box,
    with the end chosen on the left (the by-eye reference)."""
    road = ek.road_mask(K)
    m = ek.real_shadow(img, road)
    g, _ = ratio.ground_coordinates(K, np.array([0.0, -1.0, 0.0]), ek.KITTI_CAMERA_HEIGHT_M)
    axis, strength = ratio.shadow_axis_on_ground(m.shadow_mask, road, g)
    lat, fwd = np.cos(axis), np.sin(axis)  # axis = atan2(forward, lateral)
    if lat > 0:
        lat, fwd = -lat, -fwd  # the end on the left
    return {
        "azimuth_deg": float(np.degrees(np.arctan2(lat, fwd))),
        "axis_strength": strength,
        "shadow_pixels": int(m.shadow_mask.sum()),
    }


def circ_mean_deg(a) -> float:
    r = np.deg2rad(np.asarray(a, float))
    return float(np.degrees(np.arctan2(np.sin(r).mean(), np.cos(r).mean())))


def wrap_deg(a: float) -> float:
    return float((a + 180.0) % 360.0 - 180.0)


def asset_of(placement):
    from aias_augment.assets.asset import DEFAULT_ASSETS, default_asset

    for i in range(len(DEFAULT_ASSETS.get(placement.category, ()))):
        a = default_asset(placement.category, i)
        if a.name == placement.asset_name:
            return a.scaled(float(placement.scale))
    return None


def cast_shadow(img_in: np.ndarray, img_out: np.ndarray, record, K: Intrinsics) -> dict:
    """Cast-shadow pixels of the (one) inserted object and their direction on the ground (see the module doc)."""
    from pycocotools import mask as mask_utils

    img_in, img_out = np.squeeze(img_in), np.squeeze(img_out)
    grey = img_in.ndim == 2
    lin_in = hdr.srgb_to_linear(np.repeat(img_in[..., None], 3, 2) if grey else img_in)
    lin_out = hdr.srgb_to_linear(np.repeat(img_out[..., None], 3, 2) if grey else img_out)
    y_in, y_out = hdr.luminance(lin_in).astype(np.float64), hdr.luminance(lin_out).astype(np.float64)
    q = y_out / np.maximum(y_in, 1e-4)
    obj = np.zeros(y_in.shape, bool)
    for a in record.annotations:
        rle = dict(a.rle)
        rle["counts"] = rle["counts"].encode("ascii")
        obj |= mask_utils.decode(rle).astype(bool)
    n_obj = int(obj.sum())
    obj = ndimage.binary_dilation(obj, iterations=3)
    p = record.placements[0]
    T = np.asarray(p.cam_from_object, float)
    R, t = T[:3, :3], T[:3, 3]
    n = R[:, 2]  # object up in the camera
    vv, uu = np.mgrid[0 : K.height, 0 : K.width]
    rays = np.stack([(uu - K.cx) / K.fx, (vv - K.cy) / K.fy, np.ones_like(uu, float)], -1)
    denom = rays @ n
    s = (t @ n) / np.where(np.abs(denom) > 1e-9, denom, np.nan)
    pts = rays * s[..., None]
    on_ground = np.isfinite(s) & (s > 0)
    local = (pts - t) @ R  # object frame
    asset = asset_of(p)
    if asset is not None:
        lo, hi = np.asarray(asset.bounds_m, float)
    else:  # unknown asset: a square footprint of the object's height
        lo, hi = -0.25 * np.array([p.height_m] * 3), 0.25 * np.array([p.height_m] * 3)
    dx = np.maximum(np.maximum(lo[0] - local[..., 0], local[..., 0] - hi[0]), 0.0)
    dy = np.maximum(np.maximum(lo[1] - local[..., 1], local[..., 1] - hi[1]), 0.0)
    contact = 1.0 - 0.6 * np.exp(-np.hypot(dx, dy) / (0.25 * float(p.height_m)))
    dark = on_ground & ~obj & (q < np.minimum(DARK_Q, contact - DARK_MARGIN)) & (y_in > 1e-3)
    out = {
        "cast_shadow_pixels": int(dark.sum()),
        "darkened_pixels_any": int((~obj & (q < DARK_Q)).sum()),
        "object_pixels": n_obj,
        "min_q": float(q[~obj].min()) if (~obj).any() else 1.0,
        "cast_shadow": bool(dark.sum() >= max(MIN_SHADOW_PX, MIN_SHADOW_FRAC * n_obj)),
    }
    L = record.lighting
    if L is not None and L.dominant_sun and L.sun_direction_in_cam is not None:
        # Where the shadow of the object's top should land (its own sun): outside the image, or inside the object's
        # own box (a sun behind the camera hides the shadow behind the object), no cast shadow can be seen.
        sd = np.asarray(L.sun_direction_in_cam, float)
        h_m = float(p.height_m)
        tip = t + h_m * n - h_m / max(float(sd @ n), 1e-3) * sd
        if tip[2] > 1e-3:
            u, v = K.fx * tip[0] / tip[2] + K.cx, K.fy * tip[1] / tip[2] + K.cy
            x0, y0, x1, y1 = p.amodal_box_xyxy
            out["shadow_tip_px"] = [float(u), float(v)]
            out["shadow_tip_in_image"] = bool(0 <= u < K.width and 0 <= v < K.height)
            out["shadow_tip_behind_object"] = bool(x0 <= u <= x1 and y0 <= v <= y1)
        else:
            out["shadow_tip_in_image"] = False
    if dark.sum() >= MIN_SHADOW_PX:
        w = 1.0 - q[dark]
        c = (local[dark][:, :2] * w[:, None]).sum(0) / w.sum() - 0.5 * (lo[:2] + hi[:2])
        d_cam = R[:, :2] @ c  # ground vector in the camera frame
        fwd = np.array([0.0, 0.0, 1.0]) - n[2] * n
        fwd /= np.linalg.norm(fwd)
        right = np.cross(fwd, n)
        out["shadow_azimuth_deg"] = float(np.degrees(np.arctan2(d_cam @ right, d_cam @ fwd)))
        out["shadow_length_m"] = float(np.linalg.norm(c))
        out["median_q"] = float(np.median(q[dark]))
    return out


def frames(root: Path, grey_step: int):
    from PIL import Image

    col = root / "kitti06_color_snippet"
    for i in COLOUR_FRAMES:
        yield "colour", i, np.array(Image.open(col / f"kitti06-{i}-color.png").convert("RGB"))
    seq = root / "kitti06_seq" / "image_l"
    for i in range(0, 51, grey_step):
        g = np.array(Image.open(seq / f"{i:06d}.png"))
        if g.ndim != 2:
            raise RuntimeError(f"expected a 1-channel grey PNG, got {g.shape}")
        yield "grey", i, g


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--data", default=str(data_root()))
    ap.add_argument("--presets", nargs="+", default=["fast", "balanced"])
    ap.add_argument("--categories", nargs="+", default=["barrel", "traffic_cone"])
    ap.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    ap.add_argument("--grey-step", type=int, default=5)
    ap.add_argument("--unknown-camera", action="store_true", help="also run every insertion without camera_k")
    ap.add_argument("--out", default="out/lighting")
    ap.add_argument("--name", default="kitti_cast_shadow")
    args = ap.parse_args(argv)
    import albumentations as A

    from aias_augment import InsertObjects

    root = Path(args.data)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    fx, fy, cx, cy = ek.KITTI_K
    poses = load_poses(root / "kitti06_seq" / "poses.txt")
    # Truth: the sun of the street from the colour frames' real shadows, in the world frame.
    truth = {}
    for i in COLOUR_FRAMES:
        img = ek.load_frame(root / "kitti06_color_snippet", i)
        K = Intrinsics(fx, fy, cx, cy, img.shape[1], img.shape[0])
        truth[i] = real_sun_azimuth(img, K)
        truth[i]["world_azimuth_deg"] = wrap_deg(truth[i]["azimuth_deg"] + np.degrees(yaw_of(poses[i])))
    sun_world = circ_mean_deg([truth[i]["world_azimuth_deg"] for i in COLOUR_FRAMES])
    print(
        "truth (real shadow axis, sun on the left):",
        {i: round(v["azimuth_deg"], 1) for i, v in truth.items()},
        f"world {sun_world:.1f} deg",
    )
    report = {
        "command": "python -m studies.lighting.kitti_cast_shadow "
        + " ".join(argv if argv is not None else sys.argv[1:]),
        "truth": {"per_colour_frame": truth, "sun_world_azimuth_deg": sun_world},
        "insertions": [],
    }
    cams = [True] + ([False] if args.unknown_camera else [])
    for preset in args.presets:
        transforms = {}
        for kind, idx, img in frames(root, args.grey_step):
            h, w = img.shape[:2]
            K = Intrinsics(fx, fy, cx, cy, w, h)
            sun_az_truth = wrap_deg(sun_world - np.degrees(yaw_of(poses[idx])))
            for known in cams:
                for seed in args.seeds:
                    # A fresh transform per call (its generator seeded by the Compose: the same draw for the same
                    # seed, whatever ran before), sharing one scene cache per preset and camera mode.
                    t = InsertObjects(categories=args.categories, max_objects=1, min_objects=1, preset=preset, p=1.0)
                    t._scene_cache = transforms.setdefault(known, t._scene_cache)
                    comp = A.Compose([t], seed=seed)
                    t0 = time.perf_counter()
                    res = comp(image=img, **({"camera_k": K.K} if known else {}))
                    dt = time.perf_counter() - t0
                    rec = t.last_record
                    row = {
                        "preset": preset,
                        "kind": kind,
                        "frame": idx,
                        "camera_known": known,
                        "seed": seed,
                        "seconds": dt,
                        "truth_sun_azimuth_deg": sun_az_truth,
                    }
                    if rec is None or not rec.placements:
                        row["inserted"] = False
                        row["why"] = None if rec is None else rec.modules.get("placement")
                        report["insertions"].append(row)
                        print(f"{preset:8s} {kind:6s} {idx:2d} K={known!s:5s} seed {seed}: nothing inserted")
                        continue
                    L = rec.lighting
                    row.update(
                        {
                            "inserted": True,
                            "category": rec.placements[0].category,
                            "dominant_sun": bool(L.dominant_sun),
                            "confidence": float(L.confidence),
                            "sun_sky_ratio": float(L.sun_sky_ratio),
                            "source": L.source,
                            "shadow_module": rec.modules.get("shadow"),
                            "lighting_module": rec.modules.get("lighting"),
                        }
                    )
                    if L.sun_direction_in_cam is not None:
                        d = np.asarray(L.sun_direction_in_cam)
                        up = np.asarray(L.up_in_cam)
                        fwd = np.array([0.0, 0.0, 1.0]) - up[2] * up
                        fwd /= np.linalg.norm(fwd)
                        right = np.cross(fwd, up)
                        row["sun_azimuth_deg"] = float(np.degrees(np.arctan2(d @ right, d @ fwd)))
                        row["sun_elevation_deg"] = float(np.degrees(np.arcsin(np.clip(d @ up, -1, 1))))
                        row["sun_azimuth_error_deg"] = abs(wrap_deg(row["sun_azimuth_deg"] - sun_az_truth))
                    # The camera the pipeline used (its estimate when camera_k is not given): the analysis the
                    # call just used is the most recent entry of the transform's scene cache.
                    used_K = list(t._scene_cache._lru.values())[-1].intrinsics
                    if (used_K.width, used_K.height) != (w, h):
                        raise RuntimeError("scene cache: unexpected analysis")
                    row["used_focal_px"] = float(used_K.fx)
                    row.update(cast_shadow(img, res["image"], rec, used_K))
                    if "shadow_azimuth_deg" in row:
                        row["shadow_vs_truth_deg"] = abs(wrap_deg(row["shadow_azimuth_deg"] - (sun_az_truth + 180.0)))
                        if "sun_azimuth_deg" in row:
                            row["shadow_vs_own_sun_deg"] = abs(
                                wrap_deg(row["shadow_azimuth_deg"] - (row["sun_azimuth_deg"] + 180.0))
                            )
                    report["insertions"].append(row)
                    print(
                        f"{preset:8s} {kind:6s} {idx:2d} K={known!s:5s} seed {seed}: {row['category']:12s} "
                        f"sun {row['dominant_sun']!s:5s} conf {row['confidence']:.2f} r {row['sun_sky_ratio']:.2f} "
                        f"az {row.get('sun_azimuth_deg', float('nan')):7.1f} (truth {sun_az_truth:6.1f}) "
                        f"cast {row['cast_shadow_pixels']:5d} px dir err "
                        f"{row.get('shadow_vs_truth_deg', float('nan')):5.1f} / own "
                        f"{row.get('shadow_vs_own_sun_deg', float('nan')):5.1f} ({dt:.1f} s)",
                        flush=True,
                    )
    # Summary per preset x kind x camera
    summary = {}
    for r in report["insertions"]:
        key = f"{r['preset']} / {r['kind']} / {'K given' if r['camera_known'] else 'K unknown'}"
        s = summary.setdefault(
            key,
            {
                "calls": 0,
                "inserted": 0,
                "dominant_sun": 0,
                "cast_shadow": 0,
                "frames_without_sun": [],
                "dir_err": [],
                "sun_err": [],
                "own_err": [],
            },
        )
        s["calls"] += 1
        if not r["inserted"]:
            continue
        s["inserted"] += 1
        s["dominant_sun"] += int(r["dominant_sun"])
        s["cast_shadow"] += int(r["cast_shadow"])
        if r["dominant_sun"] and not r["cast_shadow"]:
            why = (
                "shadow off the image"
                if not r.get("shadow_tip_in_image", True)
                else "shadow behind the object"
                if r.get("shadow_tip_behind_object")
                else "other"
            )
            s.setdefault("sun_but_no_visible_shadow", {}).setdefault(why, 0)
            s["sun_but_no_visible_shadow"][why] += 1
        if not r["dominant_sun"] and r["frame"] not in s["frames_without_sun"]:
            s["frames_without_sun"].append(r["frame"])
        for k, col in (
            ("dir_err", "shadow_vs_truth_deg"),
            ("sun_err", "sun_azimuth_error_deg"),
            ("own_err", "shadow_vs_own_sun_deg"),
        ):
            if col in r:
                s[k].append(r[col])
    for s in summary.values():
        for k in ("dir_err", "sun_err", "own_err"):
            v = s.pop(k)
            s[k + "_median_deg"] = float(np.median(v)) if v else None
            s[k + "_max_deg"] = float(np.max(v)) if v else None
            if k == "dir_err":
                s["dir_within_45_deg"] = int(np.sum(np.array(v) <= 45.0))
                s["dir_measured"] = len(v)
    report["summary"] = summary
    (out / f"{args.name}.json").write_text(json.dumps(report, indent=1))
    lines = [
        "# KITTI 06 (sunny, hard shadows): does every insertion get a cast shadow?",
        "",
        f"Command: `PYOPENGL_PLATFORM=egl {report['command']}`",
        "",
        "Truth for the direction: the real shadow bands on the road box of the colour frames (axis) with the sun "
        "on the left (by eye), moved to the world frame with the KITTI poses: "
        + ", ".join(
            f"frame {i}: {v['azimuth_deg']:.0f} deg (axis strength {v['axis_strength']:.2f})" for i, v in truth.items()
        )
        + f"; street sun at world azimuth {sun_world:.1f} deg. Azimuths: camera frame, from forward, right "
        "positive. Cast shadow: at least max(5, 3 % of the object's pixels) ground pixels outside the object darkened "
        "by more than the contact shade alone (q < min(0.85, 1 - 0.6 exp(-rho / 0.25 h) - 0.15)).",
        "",
        "| preset / frames / camera | insertions | dominant sun | cast shadow | sun but no visible shadow: why "
        "(the own sun's shadow tip) | frames without sun | shadow dir vs real: median / max deg (within 45) | sun "
        "azimuth err median / max | shadow vs own sun median / max |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for k, s in summary.items():
        f = lambda x: "-" if x is None else f"{x:.0f}"  # noqa: E731
        whys = ", ".join(f"{w}: {c}" for w, c in s.get("sun_but_no_visible_shadow", {}).items()) or "-"
        lines.append(
            f"| {k} | {s['inserted']} / {s['calls']} | {s['dominant_sun']} | {s['cast_shadow']} | {whys} "
            f"| {', '.join(map(str, s['frames_without_sun'])) or '-'} "
            f"| {f(s['dir_err_median_deg'])} / {f(s['dir_err_max_deg'])} ({s['dir_within_45_deg']} of "
            f"{s['dir_measured']}) | {f(s['sun_err_median_deg'])} / {f(s['sun_err_max_deg'])} "
            f"| {f(s['own_err_median_deg'])} / {f(s['own_err_max_deg'])} |"
        )
    lines += ["", "Per insertion: `" + f"{args.name}.json" + "` (`insertions`).", ""]
    (out / f"{args.name}.md").write_text("\n".join(lines))
    print(json.dumps(summary, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())

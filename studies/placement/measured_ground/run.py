"""Is the inserted object's contact point on the MEASURED ground, and free of scene points?

Takes any KITTI-odometry-layout sequence (stereo -> SGBM depth) or DGP-style scene (LiDAR) by path:

    python -m studies.placement.measured_ground $AIAS_DATA/kitti06_seq --out studies/placement/measured_ground/result --seeds 0 1 2
    python -m studies.placement.measured_ground $AIAS_DATA/dgp_scene  --out studies/placement/measured_ground/result --seeds 0 1 2

Per frame: measured points (stereo or LiDAR, camera frame) -> coarse ground (RANSAC) -> placeable region
(depth evidence) -> the production ``placement.sample_placement`` with those points: it chooses a contact pixel,
refits the ground LOCALLY around it (radius ``--local-radius``, points within ``--ground-band`` of the coarse
plane), re-intersects the pixel's ray with the local plane, orients the object by the local normal and runs the
collision checks (scene points in the box, existing 3D boxes incl. earlier insertions, depth occlusion). A
rejected candidate keeps its reason and the next is drawn.

Measurement (independent of any fitted plane): the measured points within ``--measure-radius`` metres of the
contact point horizontally (perpendicular to the rig's up: KITTI camera -y, DGP vehicle z) whose height is within
0.3 m of the contact; error = contact height - median height of those points. Intersections: DBSCAN clusters
(sklearn) of measured points more than 0.2 m above the locally measured ground; a placement intersects when any
clustered point lies inside its box.
"""

from __future__ import annotations

import argparse
import json
import logging
import sys
import time
from collections import Counter
from pathlib import Path

import cv2
import numpy as np
from sklearn.cluster import DBSCAN

from aias_augment.analyse.ground import GroundFitError, depth_to_points, fit_ground_plane
from aias_augment.analyse.region import RegionConfig, placeable_region
from aias_augment.assets.asset import default_asset
from aias_augment.core.geometry import project_points
from aias_augment.core.oriented_box import OrientedBox
from aias_augment.plan.collision import points_inside_box
from aias_augment.plan.placement import PlacementConfig, sample_placement

log = logging.getLogger("eval_placement")


def load_frames(path: Path, step: int):
    """Yield (name, frame, measured points in cam, up_in_cam, existing boxes, depth_source)."""
    if list(path.glob("scene_*.json")) or list(path.glob("*/scene_*.json")):
        from aias_augment.scenes.dgp import open_dgp_scene

        scene = open_dgp_scene(path)
        for s in range(0, len(scene), step):
            for cam in scene.camera_names:
                f = scene.frame(s, cam)
                uv, z = project_points(f.meta["lidar_points_in_cam"], f.intrinsics.K)
                yield (
                    f"sample{s}/{cam}",
                    f,
                    f.meta["lidar_points_in_cam"],
                    f.meta["up_in_cam"],
                    f.meta["boxes_in_cam"],
                    "lidar",
                )
    else:
        from aias_augment.scenes.kitti import open_kitti_sequence

        seq = open_kitti_sequence(path)
        for i in range(0, len(seq), step):
            f = seq.frame(i, with_depth=True)
            points, _ = depth_to_points(f.depth, f.intrinsics, max_depth_m=40.0)
            yield (f"frame{seq.frame_ids[i]:06d}", f, points, np.array([0.0, -1.0, 0.0]), [], "stereo")


def measured_contact_error(contact, points, up, radius_m, band_m=0.3, min_points=3):
    rel = points - contact
    height = rel @ up
    horiz = np.linalg.norm(rel - height[:, None] * up, axis=1)
    near = (horiz < radius_m) & (np.abs(height) < band_m)
    if near.sum() < min_points:
        return None, int(near.sum())
    return float(-np.median(height[near])), int(near.sum())  # contact height above the measured ground


def above_ground_clusters(points, up, contact, radius_m, ground_height_offset):
    """Points within radius_m of the contact, > 0.2 m above the measured ground there, in DBSCAN clusters."""
    rel = points - contact
    height = rel @ up + ground_height_offset  # height above the measured ground at the contact
    horiz = np.linalg.norm(rel - (rel @ up)[:, None] * up, axis=1)
    cand = points[(horiz < radius_m) & (height > 0.2) & (height < 4.0)]
    if len(cand) < 3:
        return np.zeros((0, 3))
    labels = DBSCAN(eps=0.4, min_samples=3).fit_predict(cand)
    return cand[labels >= 0]


def place_one(frame, points, up, existing, asset, rng, args, reasons: Counter):
    """One placement through the production path: coarse ground, placeable region, then ``sample_placement`` with
    the measured points (local refit + 3D collision checks happen inside it)."""
    intr = frame.intrinsics
    try:
        coarse = fit_ground_plane(
            points[points[:, 2] < 30], rng, up_hint=up, max_tilt_deg=15, threshold_m=0.08, source="coarse"
        )
    except GroundFitError as e:
        reasons[f"no coarse ground: {e}"] += 1
        return None
    region = placeable_region(intr, coarse, depth=frame.depth, cfg=RegionConfig())
    pcfg = PlacementConfig(
        max_tries=args.max_tries,
        max_distance_m=args.max_distance,
        min_distance_m=3.0,
        local_radius_m=args.local_radius,
        local_ground_band_m=args.ground_band,
        local_fallback=args.local_fallback,
    )
    placement, report = sample_placement(
        asset,
        coarse,
        intr,
        rng,
        depth=frame.depth,
        region_mask=region.mask,
        cfg=pcfg,
        points_in_cam=points,
        existing_objects=existing,
    )
    for k, v in report.rejected.items():
        reasons[k] += v
    reasons["local refit failed (candidates)"] += report.local_refit_failed
    if placement is None:
        reasons["no candidate passed"] += 1
        return None
    contact = np.array(placement.contact_point_in_cam)
    box = OrientedBox.standing_on_ground(
        placement.cam_from_object_matrix, tuple(asset.extents_m * placement.scale), asset.category
    )
    coarse_contact = coarse.intersect_pixels(np.array(placement.contact_pixel), intr)
    return {
        "contact": contact,
        "box": box,
        "coarse": coarse,
        "coarse_contact": coarse_contact,
        "placement": placement,
        "region": region.to_dict(),
    }


def draw(frame, placed, points, path):
    img = frame.image.copy()
    intr = frame.intrinsics
    for p in placed:
        corners = p["box"].corners()
        uv, _ = project_points(corners, intr.K)
        for a, b in [(0, 1), (0, 2), (1, 3), (2, 3), (4, 5), (4, 6), (5, 7), (6, 7), (0, 4), (1, 5), (2, 6), (3, 7)]:
            cv2.line(img, tuple(np.round(uv[a]).astype(int)), tuple(np.round(uv[b]).astype(int)), (255, 40, 40), 2)
        cuv, _ = project_points(p["contact"], intr.K)
        cv2.circle(img, tuple(np.round(cuv).astype(int)), 5, (40, 255, 40), -1)
        near = p["near_points"]
        if len(near):
            nuv, _ = project_points(near, intr.K)
            for q in nuv[np.isfinite(nuv).all(1)]:
                cv2.circle(img, tuple(np.round(q).astype(int)), 2, (255, 255, 0), -1)
    if img.shape[1] > 1280:  # keep committed pictures small: at most 1280 px wide, JPEG quality 85
        f = 1280 / img.shape[1]
        img = cv2.resize(img, (1280, round(img.shape[0] * f)), interpolation=cv2.INTER_AREA)
    cv2.imwrite(str(path), img[..., ::-1], [cv2.IMWRITE_JPEG_QUALITY, 85])


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("scene", type=Path, help="KITTI-layout sequence folder or DGP scene folder")
    ap.add_argument("--out", type=Path, default=Path("out/placement"))
    ap.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    ap.add_argument("--step", type=int, default=5, help="every step-th frame / sample")
    ap.add_argument("--per-frame", type=int, default=3, help="objects placed per frame and seed")
    ap.add_argument("--categories", nargs="+", default=["traffic_cone", "barrel"])
    ap.add_argument("--local-radius", type=float, default=3.0, help="m, ground refit around the contact point")
    ap.add_argument("--measure-radius", type=float, default=0.5, help="m, measured points around the contact")
    ap.add_argument("--max-distance", type=float, default=25.0, help="m, farthest contact point")
    ap.add_argument(
        "--ground-band",
        type=float,
        default=0.4,
        help="m, local refit uses points within this distance of the coarse ground",
    )
    ap.add_argument("--max-tries", type=int, default=300, help="candidates per object (PlacementConfig.max_tries)")
    ap.add_argument(
        "--local-fallback",
        choices=("global", "reject"),
        default="global",
        help="when the local refit fails: use the coarse plane (production default) or reject",
    )
    ap.add_argument("--pictures", type=int, default=3)
    args = ap.parse_args(argv)
    logging.basicConfig(level=logging.INFO, format="%(message)s")
    assets = [default_asset(c) for c in args.categories]
    args.out.mkdir(parents=True, exist_ok=True)
    tag = args.scene.resolve().name
    frames = list(load_frames(args.scene, args.step))
    per_seed = []
    rows = []
    reasons = Counter()
    t0 = time.perf_counter()
    pictures = 0
    for seed in args.seeds:
        rng = np.random.default_rng(seed)
        errs = []
        for name, frame, points, up, existing, depth_source in frames:
            placed = []
            for k in range(args.per_frame):
                asset = assets[k % len(assets)]
                existing_now = list(existing) + [p["box"] for p in placed]
                p = place_one(frame, points, up, existing_now, asset, rng, args, reasons)
                if p is None:
                    continue
                err, n_near = measured_contact_error(p["contact"], points, up, args.measure_radius)
                if err is None:  # sparse LiDAR far away: widen once, and say so
                    err, n_near = measured_contact_error(p["contact"], points, up, 2 * args.measure_radius)
                    radius = 2 * args.measure_radius
                else:
                    radius = args.measure_radius
                clusters = above_ground_clusters(points, up, p["contact"], 6.0, err or 0.0)
                hits = int(points_inside_box(clusters, p["box"]).sum()) if len(clusters) else 0
                rel = points - p["contact"]
                hgt = rel @ up
                p["near_points"] = points[
                    (np.linalg.norm(rel - hgt[:, None] * up, axis=1) < radius) & (np.abs(hgt) < 0.3)
                ]
                placed.append(p)
                row = {
                    "seed": seed,
                    "frame": name,
                    "category": asset.category,
                    "depth_source": depth_source,
                    "contact_in_cam": p["contact"].round(4).tolist(),
                    "distance_m": float(np.linalg.norm(p["contact"])),
                    "contact_err_m": err,
                    "measured_points_near": n_near,
                    "measure_radius_m": radius,
                    "coarse_plane_contact_err_m": measured_contact_error(p["coarse_contact"], points, up, radius)[0],
                    "coarse_vs_local_contact_m": float(np.linalg.norm(p["coarse_contact"] - p["contact"])),
                    "ground_used": p["placement"].ground_used,
                    "ground": {
                        "normal": p["placement"].ground_normal_in_cam,
                        "d": p["placement"].ground_d,
                        "num_inliers": p["placement"].ground_num_inliers,
                        "rms_m": p["placement"].ground_rms_m,
                    },
                    "clustered_points_inside_box": hits,
                    "region": p["region"],
                }
                rows.append(row)
                if err is not None:
                    errs.append(abs(err))
            if pictures < args.pictures and seed == args.seeds[0] and placed:
                draw(frame, placed, points, args.out / f"placement_{tag}_{pictures}.jpg")
                pictures += 1
        per_seed.append(
            {
                "seed": seed,
                "placements": sum(r["seed"] == seed for r in rows),
                "median_abs_contact_err_m": float(np.median(errs)) if errs else None,
            }
        )
    elapsed = time.perf_counter() - t0
    measured = [abs(r["contact_err_m"]) for r in rows if r["contact_err_m"] is not None]
    summary = {
        "scene": str(args.scene.resolve()),
        "depth_source": rows[0]["depth_source"] if rows else None,
        "frames": len(frames),
        "seeds": args.seeds,
        "placements": len(rows),
        "placements_measured": len(measured),
        "placements_unmeasured_no_ground_points_nearby": len(rows) - len(measured),
        "median_abs_contact_err_m": float(np.median(measured)) if measured else None,
        "p90_abs_contact_err_m": float(np.percentile(measured, 90)) if measured else None,
        "median_of_seed_medians_m": float(
            np.median([s["median_abs_contact_err_m"] for s in per_seed if s["median_abs_contact_err_m"] is not None])
        ),
        "per_seed": per_seed,
        "placements_intersecting_point_clusters": int(sum(r["clustered_points_inside_box"] > 0 for r in rows)),
        "median_distance_m": float(np.median([r["distance_m"] for r in rows])) if rows else None,
        "median_abs_contact_err_if_coarse_plane_m": float(
            np.median(
                [abs(r["coarse_plane_contact_err_m"]) for r in rows if r["coarse_plane_contact_err_m"] is not None]
            )
        ),
        "placements_on_local_plane": int(sum(r["ground_used"] == "local" for r in rows)),
        "median_abs_contact_err_local_plane_m": float(
            np.median(
                [
                    abs(r["contact_err_m"])
                    for r in rows
                    if r["contact_err_m"] is not None and r["ground_used"] == "local"
                ]
                or [np.nan]
            )
        ),
        "median_coarse_vs_local_contact_shift_m": float(np.median([r["coarse_vs_local_contact_m"] for r in rows])),
        "rejected_candidates": dict(reasons.most_common()),
        "seconds": elapsed,
        "command": "python -m studies.placement.measured_ground "
        + " ".join(argv if argv is not None else sys.argv[1:]),
    }
    (args.out / f"placement_{tag}.json").write_text(json.dumps({"summary": summary, "placements": rows}, indent=1))
    print(json.dumps(summary, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

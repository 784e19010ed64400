"""Placement on a single image (no depth, no LiDAR): is the image-only placeable region on the MEASURED ground?

    python -m studies.placement.image_only $AIAS_DATA/kitti06_seq $AIAS_DATA/dgp_scene --out studies/placement/image_only/result

Per frame (the loaders of ``studies/placement/measured_ground/run.py``: KITTI stereo -> SGBM depth <= 40 m, DGP -> LiDAR):

(a) measured ground mask. Every pixel with a measured 3D point is labelled ground / not ground; pixels without a
    measurement are "unknown" and left out of every ratio. Ground = the point lies within ``--tol`` (10 cm) of the
    LOCALLY measured ground: the coarse RANSAC plane (as eval_placement) gives the band of candidate ground points
    (within 0.4 m; the RANSAC runs on the points near the commonest height of the lower half, see
    ``coarse_ground``); the production ``placement.refit_local_ground`` (3 m window, kerb/ramp support check, 1.5 and
    0.75 m retries) is run at the centre of each ``--cell`` x ``--cell`` m cell of the ground plane, and a point is
    ground when it is within ``--tol`` of the local plane of its cell or of one of the 8 neighbouring cells (so a
    kerb between two cells, road and sidewalk, are both ground). Points more than 0.4 m off the coarse plane are
    not ground.
(b) the image-only region exactly as production computes it: ``analyse_scene(Frame(image, K))`` (no depth, no
    LiDAR; K given, or ``--unknown-k``). "before" is the region production used before issue 15 (every pixel
    below the estimated horizon: ``placeable_region`` without the image), "after" the current analysis' region.
    precision = |region & ground| / |region & known|, recall = |region & ground| / |ground|.
(c) image-only placements: the production planner ``plan_insertion`` on that analysis (several seeds; DGP's
    existing objects given as 2D boxes, the projections of its 3D boxes), each contact pixel checked against the
    measured labels: the known pixels within ``--contact-radius`` px (KITTI; DGP LiDAR: ``--contact-radius-sparse``)
    vote; the placement lands on measured ground when most of them are ground.
Also the horizon/camera estimate against the measured coarse ground: horizon row error at cx, pitch/roll, height.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import logging
import sys
import time
from pathlib import Path

import cv2
import numpy as np

from aias_augment.analyse.analysis import analyse_scene
from aias_augment.analyse.ground import GroundFitError, GroundPlane, depth_to_points, fit_ground_plane
from aias_augment.analyse.region import placeable_region
from aias_augment.analyse.single_image import horizon_row_error_px
from aias_augment.core.frame import Frame
from aias_augment.core.geometry import project_points
from aias_augment.pipeline.config import InsertionConfig
from aias_augment.plan.insertion import plan_insertion
from aias_augment.plan.placement import PlacementConfig, ground_band_points, refit_local_ground
from studies.placement.measured_ground.run import load_frames

log = logging.getLogger("eval_placement_image_only")

UNKNOWN, OFF_GROUND, GROUND = -1, 0, 1


def coarse_ground(points, up, rng, max_depth_m: float = 30.0, band_m: float = 0.35):
    """RANSAC ground (as eval_placement) on the points in front of the camera near the commonest height of their
    lower half: a LiDAR sweep holds car bodies, walls and kerbs whose planes can outvote the road otherwise (seen on
    DGP CAMERA_06: a plane 1.0-1.15 m below the camera, the road at 1.6 m)."""
    front = points[(points[:, 2] > 0) & (points[:, 2] < max_depth_m)]
    hgt = front @ up
    lower = hgt[hgt <= np.median(hgt)]
    hist, edges = np.histogram(lower, bins=np.arange(lower.min(), lower.max() + 0.2, 0.1))
    mode = edges[np.argmax(hist)] + 0.05
    return fit_ground_plane(
        front[np.abs(hgt - mode) < band_m], rng, up_hint=up, max_tilt_deg=15, threshold_m=0.08, source="coarse"
    )


def measured_ground_labels(frame, points, up, rng, *, tol_m: float, cell_m: float, max_depth_m: float = 40.0):
    """(H, W) int8 labels (GROUND / OFF_GROUND / UNKNOWN), the coarse plane, and the count of local planes."""
    intr = frame.intrinsics
    labels = np.full((intr.height, intr.width), UNKNOWN, np.int8)
    pix_pts, rc = depth_to_points(frame.depth, intr, max_depth_m=max_depth_m)
    coarse = coarse_ground(points, up, rng)
    pcfg = PlacementConfig(local_max_points=60_000)
    band = ground_band_points(coarse, intr, rng, points_in_cam=points, cfg=pcfg)
    n = coarse.normal
    e1 = np.cross(n, [0.0, 0.0, 1.0])
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(n, e1)
    in_band = np.abs(coarse.signed_distance(pix_pts)) < pcfg.local_ground_band_m
    cells = np.floor(np.c_[pix_pts @ e1, pix_pts @ e2] / cell_m).astype(np.int64)
    planes = {}
    for key in {tuple(c) for c in cells[in_band]}:
        centre = coarse.project_to_plane(((np.array(key) + 0.5) * cell_m) @ np.stack([e1, e2]))
        try:
            planes[key], _ = refit_local_ground(band, coarse, centre, rng, pcfg)
        except GroundFitError:  # too few points or uneven: the neighbours' planes (or the coarse one) decide
            pass
    dist = np.full(len(pix_pts), np.inf)
    idx = np.flatnonzero(in_band)
    by_cell = {}
    for i in idx:
        by_cell.setdefault((cells[i, 0], cells[i, 1]), []).append(i)
    for key, members in by_cell.items():
        members = np.array(members)
        near = [
            planes[(key[0] + a, key[1] + b)]
            for a in (-1, 0, 1)
            for b in (-1, 0, 1)
            if (key[0] + a, key[1] + b) in planes
        ] or [coarse]
        dist[members] = np.min([np.abs(p.signed_distance(pix_pts[members])) for p in near], axis=0)
    labels[rc[:, 0], rc[:, 1]] = np.where(dist < tol_m, GROUND, OFF_GROUND)
    return labels, coarse, len(planes)


def cached_labels(frame, points, up, args, key):
    """measured_ground_labels, kept in ``--cache`` (a folder outside the repository) when given."""
    path = None if args.cache is None else args.cache / f"{key}_tol{args.tol}_cell{args.cell}.npz"
    if path is not None and path.exists():
        with np.load(path) as z:
            return z["labels"], GroundPlane(z["normal"], float(z["d"]), "coarse"), int(z["planes"])
    labels, coarse, n = measured_ground_labels(
        frame, points, up, np.random.default_rng(0), tol_m=args.tol, cell_m=args.cell
    )
    if path is not None:
        path.parent.mkdir(parents=True, exist_ok=True)
        np.savez_compressed(path, labels=labels, normal=coarse.normal, d=coarse.d, planes=n)
    return labels, coarse, n


def contact_label(labels, uv, radius_px: int) -> tuple[int, int]:
    """(GROUND / OFF_GROUND / UNKNOWN, number of known pixels) by majority of the known pixels within radius."""
    h, w = labels.shape
    u, v = int(round(uv[0])), int(round(uv[1]))
    if not (-radius_px <= u < w + radius_px and -radius_px <= v < h + radius_px):
        return UNKNOWN, 0  # the contact is outside the image (a random 2D box reaching below the frame)
    win = labels[max(0, v - radius_px) : min(h, v + radius_px + 1), max(0, u - radius_px) : min(w, u + radius_px + 1)]
    yy, xx = np.mgrid[
        max(0, v - radius_px) : min(h, v + radius_px + 1), max(0, u - radius_px) : min(w, u + radius_px + 1)
    ]
    known = (win != UNKNOWN) & ((yy - v) ** 2 + (xx - u) ** 2 <= radius_px**2)
    if not known.any():
        return UNKNOWN, 0
    return (GROUND if (win[known] == GROUND).mean() >= 0.5 else OFF_GROUND), int(known.sum())


def boxes_2d(frame) -> np.ndarray:
    """Existing objects as xyxy image boxes: the projections of the frame's 3D boxes (DGP), clipped."""
    out = []
    intr = frame.intrinsics
    for b in frame.meta.get("boxes_in_cam") or []:
        c = b.corners()
        if np.all(c[:, 2] <= 0.1):
            continue
        uv, _ = project_points(c[c[:, 2] > 0.1], intr.K)
        x0, y0 = np.clip(uv.min(0), 0, [intr.width - 1, intr.height - 1])
        x1, y1 = np.clip(uv.max(0), 0, [intr.width - 1, intr.height - 1])
        if x1 > x0 and y1 > y0:
            out.append([x0, y0, x1, y1])
    return np.array(out, float).reshape(-1, 4)


def region_scores(mask, labels) -> dict:
    known = labels != UNKNOWN
    ground = labels == GROUND
    rk = int((mask & known).sum())
    rg = int((mask & ground).sum())
    return {
        "region_known_px": rk,
        "region_on_ground_px": rg,
        "ground_px": int(ground.sum()),
        "precision": rg / rk if rk else None,
        "recall": rg / int(ground.sum()) if ground.any() else None,
        "region_fraction": float(mask.mean()),
    }


def draw(image, mask, labels, contacts, path):
    img = image.astype(np.float32).copy()
    good = mask & (labels == GROUND)
    bad = mask & (labels == OFF_GROUND)
    unk = mask & (labels == UNKNOWN)
    if labels[labels != UNKNOWN].size < 0.2 * labels.size:  # sparse LiDAR: make the labelled pixels visible
        k = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (7, 7))
        good = mask & cv2.dilate(good.astype(np.uint8), k).astype(bool)
        bad = mask & cv2.dilate(bad.astype(np.uint8), k).astype(bool)
    img[unk] = 0.75 * img[unk] + 0.25 * np.array([60, 120, 255])
    img[good] = 0.45 * img[good] + 0.55 * np.array([0, 255, 0])
    img[bad] = 0.3 * img[bad] + 0.7 * np.array([255, 0, 0])
    img = img.clip(0, 255).astype(np.uint8)
    r = max(4, image.shape[1] // 250)
    for (u, v), lab in contacts:
        colour = {GROUND: (255, 255, 255), OFF_GROUND: (255, 0, 255), UNKNOWN: (255, 255, 0)}[lab]
        cv2.circle(img, (int(round(u)), int(round(v))), r, colour, -1)
        cv2.circle(img, (int(round(u)), int(round(v))), r, (0, 0, 0), 1)
    if img.shape[1] > 1280:  # committed pictures: at most 1280 px wide, JPEG quality 85
        f = 1280 / img.shape[1]
        img = cv2.resize(img, (1280, round(img.shape[0] * f)), interpolation=cv2.INTER_AREA)
    cv2.imwrite(str(path), img[..., ::-1], [cv2.IMWRITE_JPEG_QUALITY, 85])


def summarise(rows: list[dict], placements: list[dict], variant: str) -> dict:
    rk = sum(r[variant]["region_known_px"] for r in rows)
    rg = sum(r[variant]["region_on_ground_px"] for r in rows)
    gp = sum(r[variant]["ground_px"] for r in rows)
    pl = [p for p in placements if p["variant"] == variant]
    known = [p for p in pl if p["label"] != UNKNOWN]
    on = sum(p["label"] == GROUND for p in known)
    prec = [r[variant]["precision"] for r in rows if r[variant]["precision"] is not None]
    return {
        "precision": rg / rk if rk else None,
        "recall": rg / gp if gp else None,
        "median_frame_precision": float(np.median(prec)) if prec else None,
        "min_frame_precision": float(np.min(prec)) if prec else None,
        "frames_with_precision_below_0.95": int(sum(p < 0.95 for p in prec)),
        "region_fraction_mean": float(np.mean([r[variant]["region_fraction"] for r in rows])),
        "placements": len(pl),
        "placements_measured": len(known),
        "placements_on_ground": on,
        "placements_on_ground_frac": on / len(known) if known else None,
        "frames_without_placement": int(sum(not any(p["frame"] == r["frame"] for p in pl) for r in rows)),
    }


def evaluate_scene(path: Path, args, out: Path) -> dict:
    tag = path.resolve().name
    rows, placements = [], []
    pictures = 0
    t0 = time.perf_counter()
    cfg = InsertionConfig(
        lighting=False, categories=tuple(args.categories), min_objects=args.per_frame, max_objects=args.per_frame
    )
    step = args.step if "kitti" in tag else args.dgp_step
    for name, frame, points, up, _existing3d, source in load_frames(path, step):
        labels, coarse, n_planes = cached_labels(frame, points, up, args, f"{tag}_{name.replace('/', '_')}")
        single = Frame(frame.image, None if args.unknown_k else frame.intrinsics)
        analysis = analyse_scene(single, cfg)
        intr = analysis.intrinsics
        before = placeable_region(intr, analysis.ground)  # the region from the ground prior alone
        variants = {"before": dataclasses.replace(analysis, region=before), "after": analysis}
        cols = np.array([intr.cx])
        row = {
            "frame": name,
            "depth_source": source,
            "local_planes": n_planes,
            "known_px": int((labels != UNKNOWN).sum()),
            "ground_px": int((labels == GROUND).sum()),
            "region_evidence": analysis.region.evidence,
            "modules": {k: analysis.modules.get(k) for k in ("camera", "ground", "region")},
            "horizon_row_err_at_cx_px": float(
                horizon_row_error_px(analysis.ground.horizon_line(intr), coarse.horizon_line(frame.intrinsics), cols)[0]
            ),
            "pitch_roll_deg_estimated": [float(np.degrees(x)) for x in analysis.ground.pitch_roll_rad()],
            "pitch_roll_deg_measured": [float(np.degrees(x)) for x in coarse.pitch_roll_rad()],
            "camera_height_m_measured": float(coarse.camera_height_m),
            "camera_height_m_used": float(analysis.ground.camera_height_m),
        }
        existing = boxes_2d(frame)
        contacts_after = []
        # "random_2d": where the realism/study arms without placement (no_placement, naive_paste) put an object: a
        # random pixel and size, no geometry; its contact is the bottom centre of its box. The other arms (no shadow,
        # no lighting, no harmonization) place exactly as "after" (same analysis, same planner).
        variants["random_2d"] = analysis
        for vname, an in variants.items():
            row[vname] = region_scores(an.region.mask, labels)
            vcfg = dataclasses.replace(cfg, placement=False) if vname == "random_2d" else cfg
            for seed in args.seeds:
                plan = plan_insertion(an, vcfg, np.random.default_rng([seed, len(rows)]), existing_boxes_xyxy=existing)
                for o in plan.objects:
                    uv = o.placement.contact_pixel
                    if vname == "random_2d":
                        x0, _, x1, y1 = o.placement.amodal_box_xyxy
                        uv = (0.5 * (x0 + x1), y1)
                    radius = args.contact_radius if source == "stereo" else args.contact_radius_sparse
                    lab, n_known = contact_label(labels, uv, radius)
                    placements.append(
                        {
                            "variant": vname,
                            "frame": name,
                            "seed": seed,
                            "category": o.placement.category,
                            "contact_pixel": [round(uv[0], 1), round(uv[1], 1)],
                            "distance_m_image_only": float(np.linalg.norm(o.placement.contact_point_in_cam)),
                            "label": lab,
                            "known_px_near": n_known,
                        }
                    )
                    if vname == "after":
                        contacts_after.append((uv, lab))
        rows.append(row)
        log.info(
            "%s %s: precision before %.3f after %s, recall after %s, horizon err %.1f px",
            tag,
            name,
            row["before"]["precision"] or float("nan"),
            row["after"]["precision"],
            row["after"]["recall"],
            row["horizon_row_err_at_cx_px"],
        )
        if pictures < args.pictures and (len(rows) - 1) % max(1, args.picture_every) == 0:
            draw(frame.image, analysis.region.mask, labels, contacts_after, out / f"image_only_{tag}_{pictures}.jpg")
            if pictures == 0:
                draw(frame.image, before.mask, labels, [], out / f"image_only_{tag}_{pictures}_before.jpg")
            pictures += 1
    herr = np.abs([r["horizon_row_err_at_cx_px"] for r in rows])
    return {
        "scene": str(path.resolve()),
        "depth_source": rows[0]["depth_source"],
        "frames": len(rows),
        "step": step,
        "seeds": args.seeds,
        "before": summarise(rows, placements, "before"),
        "after": summarise(rows, placements, "after"),
        "random_2d": summarise(rows, placements, "random_2d"),
        "horizon_row_err_at_cx_px": {
            "median": float(np.median(herr)),
            "p90": float(np.percentile(herr, 90)),
            "max": float(herr.max()),
        },
        "seconds": time.perf_counter() - t0,
        "per_frame": rows,
        "placements": placements,
    }


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("scenes", type=Path, nargs="+", help="KITTI-layout sequence folders and/or DGP scene folders")
    ap.add_argument("--out", type=Path, default=Path("out/placement"))
    ap.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    ap.add_argument("--step", type=int, default=5, help="every step-th KITTI frame")
    ap.add_argument("--dgp-step", type=int, default=1, help="every step-th DGP sample (all its cameras)")
    ap.add_argument("--per-frame", type=int, default=3, help="objects planned per frame and seed")
    ap.add_argument("--categories", nargs="+", default=["traffic_cone", "barrel"])
    ap.add_argument("--tol", type=float, default=0.10, help="m, a measured point this close to local ground is ground")
    ap.add_argument("--cell", type=float, default=2.0, help="m, cells of the local ground refits")
    ap.add_argument("--contact-radius", type=int, default=3, help="px, measured pixels voting at a contact (dense)")
    ap.add_argument("--contact-radius-sparse", type=int, default=30, help="px, the same for LiDAR")
    ap.add_argument("--unknown-k", action="store_true", help="analyse without K (focal from vanishing points/prior)")
    ap.add_argument("--pictures", type=int, default=2)
    ap.add_argument("--picture-every", type=int, default=5)
    ap.add_argument("--cache", type=Path, default=None, help="folder for the measured labels (reruns skip SGBM)")
    ap.add_argument("--name", default="image_only", help="results file stem")
    args = ap.parse_args(argv)
    logging.basicConfig(level=logging.INFO, format="%(message)s")
    args.out.mkdir(parents=True, exist_ok=True)
    results = {
        "command": "python -m studies.placement.image_only " + " ".join(argv if argv is not None else sys.argv[1:]),
        "scenes": {},
    }
    for path in args.scenes:
        res = evaluate_scene(path, args, args.out)
        results["scenes"][path.resolve().name] = res
        print(
            json.dumps(
                {
                    k: res[k]
                    for k in ("scene", "frames", "before", "after", "random_2d", "horizon_row_err_at_cx_px", "seconds")
                },
                indent=1,
            )
        )
    # per-frame records: compact JSON (the table is image_only.md)
    (args.out / f"{args.name}.json").write_text(json.dumps(results, separators=(",", ":")) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

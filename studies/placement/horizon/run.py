"""Accuracy of the single-image horizon / pitch / roll / focal estimate on a KITTI-layout sequence.

True horizon of frame i: the vanishing line of the ground, l_i = K^-T n_i with n_i = R_{cam_i <- world} up_world.
up_world comes from K and the poses plus a measured up: the stereo ground normal of a few frames, each moved
into the world frame with its GT pose and averaged (``--up stereo``, default), or the nominal KITTI mounting
assumption that cam0 of frame 0 is level (``--up level``: up_world = (0, -1, 0)).

    python -m studies.placement.horizon $AIAS_DATA/kitti06_seq --out studies/placement/horizon/result
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

from aias_augment.analyse.ground import GroundFitError, ground_plane_from_depth
from aias_augment.analyse.single_image import estimate_camera_from_image, horizon_row_error_px
from aias_augment.scenes.kitti import open_kitti_sequence


def world_up_from_stereo(seq, indices, rng) -> tuple[np.ndarray, list[float]]:
    ups = []
    heights = []
    for i in indices:
        depth = seq.stereo_depth(i)
        lower = np.zeros(depth.shape, bool)
        lower[int(seq.intrinsics.cy) + 10 :] = True
        try:
            g = ground_plane_from_depth(depth, seq.intrinsics, rng, mask=lower, max_depth_m=20)
        except GroundFitError as e:
            print(f"frame {seq.frame_ids[i]}: no stereo ground ({e})", file=sys.stderr)
            continue
        ups.append(seq.world_from_cams[i][:3, :3] @ g.normal)
        heights.append(g.d)
    up = np.mean(ups, axis=0)
    return up / np.linalg.norm(up), heights


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("sequence", help="KITTI-odometry-layout folder (calib, poses, left[/right] images)")
    ap.add_argument("--out", default="out/horizon")
    ap.add_argument("--up", choices=["stereo", "level"], default="stereo")
    ap.add_argument("--step", type=int, default=1, help="evaluate every step-th frame")
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args(argv)
    seq = open_kitti_sequence(args.sequence)
    if seq.world_from_cams is None:
        raise SystemExit(f"{args.sequence}: no poses, the true horizon cannot be derived")
    rng = np.random.default_rng(args.seed)
    indices = list(range(0, len(seq), args.step))
    if args.up == "stereo":
        up_world, heights = world_up_from_stereo(seq, indices[:: max(1, len(indices) // 10)], rng)
    else:
        up_world, heights = np.array([0.0, -1.0, 0.0]), []
    K = seq.intrinsics.K
    cols = np.array([0.0, seq.intrinsics.cx, seq.intrinsics.width - 1.0])
    rows = []
    t0 = time.perf_counter()
    for i in indices:
        frame = seq.frame(i)
        n_true = seq.world_from_cams[i][:3, :3].T @ up_world
        line_true = -np.linalg.inv(K).T @ n_true
        line_true /= np.hypot(line_true[0], line_true[1])
        true_pitch = float(np.arcsin(np.clip(-n_true[2], -1, 1)))
        true_roll = float(np.arctan2(n_true[0], -n_true[1]))
        known = estimate_camera_from_image(frame.image, np.random.default_rng(args.seed), intrinsics=seq.intrinsics)
        unknown = estimate_camera_from_image(frame.image, np.random.default_rng(args.seed))
        err_known = horizon_row_error_px(known.horizon_line, line_true, cols)
        err_unknown = horizon_row_error_px(unknown.horizon_line, line_true, cols)
        rows.append(
            {
                "frame_id": seq.frame_ids[i],
                "true_horizon_row_at_cx": float(-(line_true[0] * seq.intrinsics.cx + line_true[2]) / line_true[1]),
                "est_horizon_row_at_cx": known.horizon_row_at(seq.intrinsics.cx),
                "horizon_err_px_center": float(err_known[1]),
                "horizon_err_px_max_edges": float(err_known.max()),
                "pitch_err_deg_known_K": float(np.degrees(known.pitch_rad - true_pitch)),
                "roll_err_deg": float(np.degrees(known.roll_rad - true_roll)),
                "horizon_source": known.horizon_source,
                "unknown_K_horizon_err_px_center": float(err_unknown[1]),
                "unknown_K_focal_source": unknown.focal_source,
                "unknown_K_focal_rel_err": float(unknown.intrinsics.fx / seq.intrinsics.fx - 1),
                "unknown_K_pitch_err_deg": float(np.degrees(unknown.pitch_rad - true_pitch)),
            }
        )
    elapsed = time.perf_counter() - t0

    def stats(key, absolute=True):
        v = np.array([r[key] for r in rows], float)
        v = np.abs(v) if absolute else v
        return {"median": float(np.median(v)), "p90": float(np.percentile(v, 90)), "max": float(v.max())}

    fv = [r for r in rows if r["unknown_K_focal_source"] == "vanishing_points"]
    summary = {
        "sequence": str(Path(args.sequence).resolve()),
        "frames": len(rows),
        "up_source": args.up,
        "up_world": up_world.tolist(),
        "stereo_camera_heights_m": heights,
        "known_K": {
            "horizon_err_px_center": stats("horizon_err_px_center"),
            "horizon_err_px_max_edges": stats("horizon_err_px_max_edges"),
            "pitch_err_deg": stats("pitch_err_deg_known_K"),
            "roll_err_deg": stats("roll_err_deg"),
            "horizon_sources": {
                s: sum(r["horizon_source"] == s for r in rows) for s in sorted({r["horizon_source"] for r in rows})
            },
        },
        "unknown_K": {
            "horizon_err_px_center": stats("unknown_K_horizon_err_px_center"),
            "pitch_err_deg": stats("unknown_K_pitch_err_deg"),
            "focal_from_vanishing_points_frames": len(fv),
            "focal_rel_err_when_from_vps": (
                stats("unknown_K_focal_rel_err")
                if False
                else (float(np.median(np.abs([r["unknown_K_focal_rel_err"] for r in fv]))) if fv else None)
            ),
            "focal_rel_err_all": stats("unknown_K_focal_rel_err"),
        },
        "seconds_per_frame": elapsed / len(rows),
        "command": "python -m studies.placement.horizon " + " ".join(argv if argv is not None else sys.argv[1:]),
    }
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    (out / "horizon.json").write_text(json.dumps({"summary": summary, "frames": rows}, indent=1))
    print(json.dumps(summary, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

"""Poses estimated from the frames of a moving camera against the published ones, and what they do to a
world-fixed object: KITTI 06 (51 frames, 59.9 m, ``$AIAS_DATA/kitti06_seq``) with its poses withheld.

Estimators: stereo odometry (``scenes.video.estimate_stereo_motion``: metric, from the rectified pair; with and
without its two-frame bundle adjustment) and
monocular odometry (``estimate_video_motion``: essential matrices, each step scaled by a speed prior of 1.2 m per
frame, the clip's average speed as its SOURCE.txt gives it; or by the ground, the camera 1.65 m above the road,
KITTI's mounting height, which is what a user knows). Reported: the camera-centre error against the published
trajectory (world = frame 0 for both), the step-length ratio, the rotation error at the last frame, and for an
object placed as the clip CLI places it (beside where the camera is at frame L, 2.5 m to its right, on the 1.65 m
level prior) the distance in pixels between its contact's projection with the estimated poses and with the
published ones, over the frames where both see it ("placed": the object placed and seen with the estimated poses;
"same point": the ground point the published poses chose, seen with the estimated poses).

    python -m studies.video.unposed --out studies/video/unposed/result
"""

import argparse
import json
import time
from pathlib import Path

import numpy as np

from aias_augment.analyse.ground import prior_ground_plane, project_world_point_track
from aias_augment.core.config import data_root
from aias_augment.core.geometry import invert_rigid
from aias_augment.pipeline.clip import VideoInsertionConfig, choose_world_contact
from aias_augment.plan.stabilize import track_contact_with_flow
from aias_augment.scenes.kitti import open_kitti_sequence, read_image_rgb
from aias_augment.scenes.video import (
    StereoOdometryConfig,
    VideoMotionConfig,
    estimate_stereo_motion,
    estimate_video_motion,
)
from studies._shared.pictures import save_figure_jpeg

LOOKAHEADS = (10, 20, 30, 50)


def rotation_deg(A: np.ndarray, B: np.ndarray) -> float:
    R = A[:3, :3] @ B[:3, :3].T
    return float(np.degrees(np.arccos(np.clip((np.trace(R) - 1) / 2, -1, 1))))


def contact_errors(est: np.ndarray, truth: np.ndarray, intrinsics, lookahead: int, frames=None):
    """Per frame where both see it, pixel distances to the contact as the published poses place and project it:
    (placed and projected with the estimated poses, the published contact projected with the estimated poses, the
    change of the first offset from one such frame to the next). With ``frames``, the estimated contact pixels are
    carried through the clip by the clip pipeline's KLT ground tracking (``plan.stabilize``, what ``flow_refine``
    does), anchored at frame 0; frames where the tracking is refused keep the pose's prediction."""
    g = prior_ground_plane(1.65)
    cfg = VideoInsertionConfig(lookahead_frames=lookahead, lateral_offset_m=2.5)
    rng = np.random.default_rng(0)  # not drawn from: the lookahead contact is deterministic
    c_true, _ = choose_world_contact(truth, g, intrinsics, rng, cfg)
    c_est, ground_w = choose_world_contact(est, g, intrinsics, rng, cfg)
    uv_t, v_t = project_world_point_track(c_true, intrinsics, truth)
    uv_e, v_e = project_world_point_track(c_est, intrinsics, est)
    uv_s, v_s = project_world_point_track(c_true, intrinsics, est)  # the same ground point, seen with the estimate
    if frames is not None:
        grounds = [ground_w.transformed(T) for T in est]
        for uv, vis in ((uv_e, v_e), (uv_s, v_s)):
            pred = np.where(vis[:, None], uv, np.nan)
            track = track_contact_with_flow(frames, pred, grounds, intrinsics, np.random.default_rng(0), est)
            uv[:] = track.uv
    both, same = v_t & v_e, v_t & v_s
    return (
        np.linalg.norm(uv_t[both] - uv_e[both], axis=1),
        np.linalg.norm(uv_t[same] - uv_s[same], axis=1),
        np.linalg.norm(np.diff(uv_e[both] - uv_t[both], axis=0), axis=1),  # how the offset changes frame to frame
    )


def report(name: str, est: np.ndarray, truth: np.ndarray, intrinsics, seconds: float, frames=None) -> dict:
    c_t = np.array([invert_rigid(T)[:3, 3] for T in truth])
    c_e = np.array([invert_rigid(T)[:3, 3] for T in est])
    err = np.linalg.norm(c_e - c_t, axis=1)
    steps_t = np.linalg.norm(np.diff(c_t, axis=0), axis=1)
    steps_e = np.linalg.norm(np.diff(c_e, axis=0), axis=1)
    path = float(steps_t.sum())
    out = {
        "estimator": name,
        "seconds": round(seconds, 1),
        "final_error_m": round(float(err[-1]), 3),
        "final_error_pct_of_path": round(100 * float(err[-1]) / path, 2),
        "rmse_m": round(float(np.sqrt(np.mean(err**2))), 3),
        "step_ratio_median": round(float(np.median(steps_e / steps_t)), 4),
        "final_rotation_error_deg": round(rotation_deg(est[-1], truth[-1]), 2),
        "final_error_xyz_m": [round(float(v), 3) for v in (c_e[-1] - c_t[-1])],
        "contact": {},
    }
    for L in LOOKAHEADS:
        e, same, change = contact_errors(est, truth, intrinsics, L, frames)
        out["contact"][str(L)] = {
            "frames": int(e.size),
            "median_px": round(float(np.median(e)), 2),
            "p95_px": round(float(np.percentile(e, 95)), 2),
            "max_px": round(float(e.max()), 2),
            "same_point_median_px": round(float(np.median(same)), 2),
            "same_point_p95_px": round(float(np.percentile(same, 95)), 2),
            "offset_change_median_px": round(float(np.median(change)), 2),
            "offset_change_p95_px": round(float(np.percentile(change, 95)), 2),
        }
    return out


def error_plots(trajs: dict, truth: np.ndarray, intrinsics, path: Path) -> None:
    """Per frame: each estimator's camera-centre error (left) and the contact's pixel error of the L = 50 object
    (right)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    c_t = np.array([invert_rigid(T)[:3, 3] for T in truth])
    fig, (ax0, ax1) = plt.subplots(1, 2, figsize=(11, 3.6))
    for name, est in trajs.items():
        c_e = np.array([invert_rigid(T)[:3, 3] for T in est])
        ax0.plot(np.linalg.norm(c_e - c_t, axis=1), label=name)
        g = prior_ground_plane(1.65)
        cfg = VideoInsertionConfig(lookahead_frames=50, lateral_offset_m=2.5)
        rng = np.random.default_rng(0)
        ct, _ = choose_world_contact(truth, g, intrinsics, rng, cfg)
        ce, _ = choose_world_contact(est, g, intrinsics, rng, cfg)
        uv_t, v_t = project_world_point_track(ct, intrinsics, truth)
        uv_e, v_e = project_world_point_track(ce, intrinsics, est)
        e = np.where(v_t & v_e, np.linalg.norm(uv_t - uv_e, axis=1), np.nan)
        ax1.plot(e, label=name)
    ax0.set(xlabel="frame", ylabel="camera centre error (m)", title="against the published poses")
    ax1.axhline(2.0, color="grey", ls="--", lw=1)
    ax1.set(xlabel="frame", ylabel="contact error (px)", title="object beside camera 50, 2.5 m right (target 2 px)")
    ax0.legend(fontsize=8)
    fig.tight_layout()
    save_figure_jpeg(fig, path, dpi=100)
    plt.close(fig)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--out", type=Path, default=Path("studies/video/unposed/result"))
    ap.add_argument("--seed", type=int, default=0)
    a = ap.parse_args(argv)
    a.out.mkdir(parents=True, exist_ok=True)
    seq = open_kitti_sequence(data_root() / "kitti06_seq")
    n = len(seq.left_paths)
    lefts = [read_image_rgb(p) for p in seq.left_paths]
    rights = [read_image_rgb(p) for p in seq.right_paths]
    truth = np.stack([seq.cam_from_world(i) for i in range(n)])
    rows, trajs = [], {}
    for name, cfg in (
        ("stereo odometry (PnP)", StereoOdometryConfig()),
        ("stereo odometry + two-frame bundle adjustment", StereoOdometryConfig(bundle_adjust=True)),
    ):
        t0 = time.perf_counter()
        stereo = estimate_stereo_motion(
            lefts, rights, seq.intrinsics, seq.baseline_m, np.random.default_rng(a.seed), cfg
        )
        rows.append(report(name, stereo.cams_from_world, truth, seq.intrinsics, time.perf_counter() - t0))
        trajs[name] = stereo.cams_from_world
    t0 = time.perf_counter()
    mono = estimate_video_motion(
        lefts, np.random.default_rng(a.seed), intrinsics=seq.intrinsics, cfg=VideoMotionConfig(step_scale_m=1.2)
    )
    rows.append(
        report("monocular, 1.2 m/frame prior", mono.cams_from_world, truth, seq.intrinsics, time.perf_counter() - t0)
    )
    trajs["monocular, speed prior"] = mono.cams_from_world
    t0 = time.perf_counter()
    ground = estimate_video_motion(
        lefts, np.random.default_rng(a.seed), intrinsics=seq.intrinsics, cfg=VideoMotionConfig(ground_height_m=1.65)
    )
    rows.append(
        report(
            "monocular, steps from the ground 1.65 m below",
            ground.cams_from_world,
            truth,
            seq.intrinsics,
            time.perf_counter() - t0,
        )
    )
    trajs["monocular, ground scale"] = ground.cams_from_world
    # The same trajectories with the contact carried by KLT ground tracking (the clip CLI's --flow-refine).
    for name, key, row_name in (
        ("stereo odometry (PnP) + KLT ground tracking", "stereo odometry (PnP)", "stereo odometry (PnP)"),
        (
            "monocular, steps from the ground + KLT ground tracking",
            "monocular, ground scale",
            "monocular, steps from the ground 1.65 m below",
        ),
    ):
        base = next(r for r in rows if r["estimator"] == row_name)
        t0 = time.perf_counter()
        row = report(name, trajs[key], truth, seq.intrinsics, base["seconds"], frames=lefts)
        row["seconds"] = round(base["seconds"] + (time.perf_counter() - t0) / len(LOOKAHEADS) / 2, 1)  # per track
        rows.append(row)
    result = {
        "clip": "kitti06_seq, 51 frames, 59.9 m",
        "stereo_config": StereoOdometryConfig().__dict__,  # the first row's; the second adds bundle_adjust
        "command": "python -m studies.video.unposed --out " + str(a.out),
        "rows": rows,
    }
    (a.out / "report.json").write_text(json.dumps(result, indent=1))
    error_plots(trajs, truth, seq.intrinsics, a.out / "errors.jpg")
    lines = [
        "| estimator | final error | RMSE | step ratio | rotation at the end | "
        + " | ".join(f"L = {L}: placed / same point, median (p95) px" for L in LOOKAHEADS)
        + " | s |",
        "|---" * (6 + len(LOOKAHEADS)) + "|",
    ]
    for r in rows:
        lines.append(
            f"| {r['estimator']} | {r['final_error_m']} m ({r['final_error_pct_of_path']} %) | {r['rmse_m']} m | "
            f"{r['step_ratio_median']} | {r['final_rotation_error_deg']} deg | "
            + " | ".join(
                "{median_px} ({p95_px}) / {same_point_median_px} ({same_point_p95_px})".format(**r["contact"][str(L)])
                for L in LOOKAHEADS
            )
            + f" | {r['seconds']} |"
        )
    (a.out / "table.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

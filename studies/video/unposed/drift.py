"""Where the stereo odometry's contact error on KITTI 06 comes from (``studies/video/unposed/result``: 4-8 px against the
2 px target): its rotations or its camera centres, chained or measured directly over long gaps.

1. Hybrids: the estimated rotations with the published centres, and the published rotations with the estimated
   centres, through the same contact metric as ``eval_unposed_odometry.py``.
2. Direct long-gap geometry: essential matrices between frames i and i+k (KLT chained through the frames between,
   forward-backward checked; RANSAC at 0.5 px), their rotation and direction of travel against the published poses,
   beside the chained odometry's over the same gaps.
3. Rotation averaging: the odometry's rotations refit to the direct relative rotations of 1-16-frame gaps
   (robust least squares on the rotation vectors, 1- and 2-frame edges down-weighted 20x), centres kept.

    python -m studies.video.unposed.drift --out studies/video/unposed/result
"""

import argparse
import json
import time
from pathlib import Path

import cv2
import numpy as np
from scipy.optimize import least_squares
from scipy.spatial.transform import Rotation

from aias_augment.core.config import data_root
from aias_augment.core.geometry import invert_rigid, make_rigid
from aias_augment.scenes.kitti import open_kitti_sequence, read_image_rgb
from aias_augment.scenes.video import estimate_stereo_motion, track_points
from studies.video.unposed.run import report

GAPS = (1, 2, 4, 8, 16)


def relative(P: np.ndarray, i: int, j: int) -> np.ndarray:
    return P[j] @ invert_rigid(P[i])


def with_centres(rot_src: np.ndarray, centre_src: np.ndarray) -> np.ndarray:
    out = []
    for A, B in zip(rot_src, centre_src):
        R, c = A[:3, :3], invert_rigid(B)[:3, 3]
        out.append(make_rigid(R, -R @ c))
    return np.stack(out)


def travel_angles(T: np.ndarray) -> np.ndarray:
    """Direction of camera j's centre in camera i's frame (T = j from i): horizontal and vertical angle, deg."""
    c = -T[:3, :3].T @ T[:3, 3]
    return np.degrees([np.arctan2(c[0], c[2]), np.arctan2(c[1], c[2])])


def median3(values: list) -> list:
    return [round(float(x), 3) for x in np.median(np.asarray(values), axis=0)]


def direct_edges(greys: list, K: np.ndarray, gaps=GAPS) -> list:
    """(i, j, R j-from-i, inliers, t direction) from essential matrices between frames i and j = i + gap."""
    cv2.setRNGSeed(0)
    edges = []
    n = len(greys)
    for i in range(n - 1):
        p = cv2.goodFeaturesToTrack(greys[i], 3000, 0.005, 7).reshape(-1, 2).astype(np.float64)
        cur, ok = p.copy(), np.ones(len(p), bool)
        for j in range(i, min(n - 1, i + max(gaps))):
            cur, o = track_points(greys[j], greys[j + 1], cur, 0.5)
            ok &= o
            if j + 1 - i not in gaps or ok.sum() < 40:
                continue
            E, inl = cv2.findEssentialMat(p[ok], cur[ok], K, cv2.RANSAC, 0.999, 0.5)
            if E is None or E.shape != (3, 3):
                continue
            nin, R, t, _ = cv2.recoverPose(E, p[ok], cur[ok], K, mask=inl)
            if nin >= 30:
                edges.append((i, j + 1, R, int(nin), make_rigid(R, t.ravel())))
    return edges


def average_rotations(est: np.ndarray, edges: list, short_weight: float = 0.05) -> np.ndarray:
    n = len(est)

    def rots(x):
        return [np.eye(3)] + list(Rotation.from_rotvec(x.reshape(n - 1, 3)).as_matrix())

    def residuals(x):
        Rs = rots(x)
        return np.concatenate(
            [
                np.sqrt(w * (short_weight if j - i < 4 else 1.0))
                * Rotation.from_matrix(Rs[j] @ Rs[i].T @ Rij.T).as_rotvec()
                for i, j, Rij, w, _ in edges
            ]
        )

    x0 = Rotation.from_matrix(est[1:, :3, :3]).as_rotvec().ravel()
    fit = least_squares(residuals, x0, loss="soft_l1", f_scale=10 * np.radians(0.05))
    Rs = rots(fit.x)
    return np.stack([make_rigid(R, -R @ invert_rigid(T)[:3, 3]) for R, T in zip(Rs, est)])


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--out", type=Path, default=Path("studies/video/unposed/result"))
    a = ap.parse_args(argv)
    a.out.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    seq = open_kitti_sequence(data_root() / "kitti06_seq")
    n, K = len(seq.left_paths), seq.intrinsics
    lefts = [read_image_rgb(p) for p in seq.left_paths]
    rights = [read_image_rgb(p) for p in seq.right_paths]
    truth = np.stack([seq.cam_from_world(i) for i in range(n)])
    est = estimate_stereo_motion(lefts, rights, K, seq.baseline_m, np.random.default_rng(0)).cams_from_world
    edges = direct_edges([cv2.cvtColor(f, cv2.COLOR_RGB2GRAY) for f in lefts], K.K)
    averaged = average_rotations(est, edges)

    def contact(P):
        r = report("", P, truth, K, 0.0)
        return {L: (c["median_px"], c["same_point_median_px"]) for L, c in r["contact"].items()}, r

    rows = []
    for name, P in (
        ("stereo odometry", est),
        ("its rotations, the published centres", with_centres(est, truth)),
        ("the published rotations, its centres", with_centres(truth, est)),
        ("rotations averaged over 1-16-frame direct edges, its centres", averaged),
    ):
        c, r = contact(P)
        rows.append(
            {"trajectory": name, "contact_placed_same_px": c, "final_rotation_error_deg": r["final_rotation_error_deg"]}
        )
    gaps = []
    for gap in (1, 4, 8, 16):
        sel = [e for e in edges if e[1] - e[0] == gap]
        d_rot = [
            np.degrees(Rotation.from_matrix(R @ relative(truth, i, j)[:3, :3].T).as_rotvec()) for i, j, R, _, _ in sel
        ]
        c_rot = [
            np.degrees(Rotation.from_matrix(relative(est, i, j)[:3, :3] @ relative(truth, i, j)[:3, :3].T).as_rotvec())
            for i, j, _, _, _ in sel
        ]
        d_dir = [travel_angles(T) - travel_angles(relative(truth, i, j)) for i, j, _, _, T in sel]
        c_dir = [travel_angles(relative(est, i, j)) - travel_angles(relative(truth, i, j)) for i, j, _, _, _ in sel]
        gaps.append(
            {
                "gap": gap,
                "pairs": len(sel),
                "direct_rotation_err_deg_xyz": median3(d_rot),
                "chained_rotation_err_deg_xyz": median3(c_rot),
                "direct_travel_dir_err_deg_h_v": median3(d_dir),
                "chained_travel_dir_err_deg_h_v": median3(c_dir),
            }
        )
    out = {
        "command": "python -m studies.video.unposed.drift --out " + str(a.out),
        "seconds": round(time.perf_counter() - t0, 1),
        "contact": rows,
        "gaps": gaps,
    }
    (a.out / "drift.json").write_text(json.dumps(out, indent=1))
    lines = [
        "| trajectory | L = 10 | L = 20 | L = 30 | L = 50 | rotation at the end |",
        "|---|---|---|---|---|---|",
        *(
            f"| {r['trajectory']} | "
            + " | ".join(f"{p} / {s}" for p, s in r["contact_placed_same_px"].values())
            + f" | {r['final_rotation_error_deg']} deg |"
            for r in rows
        ),
        "",
        "| gap (frames) | pairs | rotation error, direct E (x, y, z deg) | chained odometry | direction of travel error, direct E (horizontal, vertical deg) | chained odometry |",
        "|---|---|---|---|---|---|",
        *(
            f"| {g['gap']} | {g['pairs']} | {g['direct_rotation_err_deg_xyz']} | {g['chained_rotation_err_deg_xyz']} | "
            f"{g['direct_travel_dir_err_deg_h_v']} | {g['chained_travel_dir_err_deg_h_v']} |"
            for g in gaps
        ),
    ]
    (a.out / "drift.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

"""Camera motion of a video without poses, from tracked features.

Per consecutive pair: Shi-Tomasi corners tracked with pyramidal Lucas-Kanade (forward-backward check), the
essential matrix by RANSAC (OpenCV, seeded through ``cv2.setRNGSeed`` from the caller's generator) and
``recoverPose``. Monocular translation has no scale: each step gets ``step_scale_m`` (a speed prior, or 1), so
poses are metric only up to that prior; ``metric_scale_from_ground`` can rescale with a camera-height prior.
Pairs with a median flow below ``static_flow_px`` are treated as a static camera (identity motion), which is also
what a tripod video (e.g. ``$AIAS_DATA/video/vtest.avi``) gives.
K is given, or estimated from the first frame by :func:`aias_augment.scenes.single_image.estimate_camera_from_image`.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import cv2
import numpy as np

from aias_augment.core.geometry import Intrinsics, invert_rigid, make_rigid

__all__ = [
    "VideoMotionConfig",
    "VideoMotion",
    "StaticCameraCheck",
    "track_pair",
    "relative_pose",
    "estimate_video_motion",
    "static_camera_check",
    "read_video",
]


@dataclass(frozen=True)
class VideoMotionConfig:
    max_corners: int = 1500
    quality_level: float = 0.01
    min_distance_px: int = 7
    fb_max_err_px: float = 1.0  # forward-backward tracking error allowed
    ransac_threshold_px: float = 1.0
    static_flow_px: float = 0.5
    min_inliers: int = 30
    step_scale_m: float = 1.0  # translation length per frame (unknown in monocular video)


@dataclass(frozen=True, eq=False)
class VideoMotion:
    intrinsics: Intrinsics
    cams_from_world: np.ndarray  # (N, 4, 4), world = camera of frame 0
    num_inliers: tuple[int, ...]  # per pair (0 for static / failed)
    status: tuple[str, ...]  # per pair: "moving" | "static" | "failed: ..."
    focal_source: str = "given"
    meta: dict = field(default_factory=dict)


def read_video(path: str, max_frames: int | None = None, stride: int = 1) -> list[np.ndarray]:
    """RGB uint8 frames of a video file (every ``stride``-th, at most ``max_frames``)."""
    cap = cv2.VideoCapture(str(path))
    if not cap.isOpened():
        raise FileNotFoundError(f"cannot open video {path}")
    frames, i = [], 0
    try:
        while max_frames is None or len(frames) < max_frames:
            ok, bgr = cap.read()
            if not ok:
                break
            if i % stride == 0:
                frames.append(cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB))
            i += 1
    finally:
        cap.release()
    if not frames:
        raise ValueError(f"{path}: no frames decoded")
    return frames


def _grey(img: np.ndarray) -> np.ndarray:
    img = np.asarray(img)
    if img.dtype != np.uint8:
        raise ValueError(f"expected uint8 frames, got {img.dtype}")
    return cv2.cvtColor(img, cv2.COLOR_RGB2GRAY) if img.ndim == 3 else img


def track_pair(
    img0: np.ndarray, img1: np.ndarray, cfg: VideoMotionConfig = VideoMotionConfig()
) -> tuple[np.ndarray, np.ndarray]:
    """Matched pixels (M, 2), (M, 2) of corners tracked from img0 to img1 that pass a forward-backward check."""
    g0, g1 = _grey(img0), _grey(img1)
    p0 = cv2.goodFeaturesToTrack(g0, cfg.max_corners, cfg.quality_level, cfg.min_distance_px)
    if p0 is None:
        return np.zeros((0, 2)), np.zeros((0, 2))
    p1, st1, _ = cv2.calcOpticalFlowPyrLK(g0, g1, p0, None, winSize=(21, 21), maxLevel=3)
    pb, st2, _ = cv2.calcOpticalFlowPyrLK(g1, g0, p1, None, winSize=(21, 21), maxLevel=3)
    fb = np.linalg.norm((p0 - pb).reshape(-1, 2), axis=1)
    ok = (st1.ravel() == 1) & (st2.ravel() == 1) & (fb < cfg.fb_max_err_px)
    return p0.reshape(-1, 2)[ok].astype(np.float64), p1.reshape(-1, 2)[ok].astype(np.float64)


def relative_pose(
    pts0: np.ndarray,
    pts1: np.ndarray,
    intrinsics: Intrinsics,
    rng: np.random.Generator,
    cfg: VideoMotionConfig = VideoMotionConfig(),
) -> tuple[np.ndarray, int, str]:
    """cam1_from_cam0 with unit (or zero, when static) translation, number of inliers, status."""
    if len(pts0) < cfg.min_inliers:
        return np.eye(4), 0, f"failed: {len(pts0)} tracks < {cfg.min_inliers}"
    if np.median(np.linalg.norm(pts1 - pts0, axis=1)) < cfg.static_flow_px:
        return np.eye(4), 0, "static"
    cv2.setRNGSeed(int(rng.integers(0, 2**31 - 1)))
    E, mask = cv2.findEssentialMat(
        pts0, pts1, intrinsics.K, method=cv2.RANSAC, prob=0.999, threshold=cfg.ransac_threshold_px
    )
    if E is None or E.shape != (3, 3):
        return np.eye(4), 0, "failed: no essential matrix"
    n, R, t, mask_pose = cv2.recoverPose(E, pts0, pts1, intrinsics.K, mask=mask)
    if n < cfg.min_inliers:
        return np.eye(4), int(n), f"failed: {n} inliers < {cfg.min_inliers}"
    return make_rigid(R, t.ravel() / max(np.linalg.norm(t), 1e-12)), int(n), "moving"


def estimate_video_motion(
    frames: list[np.ndarray],
    rng: np.random.Generator,
    *,
    intrinsics: Intrinsics | None = None,
    cfg: VideoMotionConfig = VideoMotionConfig(),
) -> VideoMotion:
    """Chain pairwise motions into ``cams_from_world`` (world = first camera). A failed pair keeps the previous
    pose (recorded in ``status``) rather than inventing motion."""
    if len(frames) < 2:
        raise ValueError("need at least 2 frames")
    focal_source = "given"
    if intrinsics is None:
        from aias_augment.scenes.single_image import estimate_camera_from_image

        est = estimate_camera_from_image(frames[0], rng)
        intrinsics, focal_source = est.intrinsics, est.focal_source
    h, w = np.asarray(frames[0]).shape[:2]
    if (intrinsics.width, intrinsics.height) != (w, h):
        raise ValueError("intrinsics do not match the frame size")
    poses = [np.eye(4)]
    inliers, status = [], []
    for a, b in zip(frames[:-1], frames[1:]):
        p0, p1 = track_pair(a, b, cfg)
        T, n, st = relative_pose(p0, p1, intrinsics, rng, cfg)
        if st == "moving":
            T = make_rigid(T[:3, :3], T[:3, 3] * cfg.step_scale_m)
        poses.append(T @ poses[-1])
        inliers.append(n)
        status.append(st)
    return VideoMotion(intrinsics, np.stack(poses), tuple(inliers), tuple(status), focal_source)


@dataclass(frozen=True)
class StaticCameraCheck:
    """Whether a clip's camera stands still: the median motion of the first frame's corners, tracked to frames spread
    over the clip (``frames``, their indices), against ``threshold_px``."""

    static: bool
    frames: tuple[int, ...]
    median_flow_px: tuple[float, ...]
    threshold_px: float

    def reason(self) -> str:
        worst = max(self.median_flow_px) if self.median_flow_px else float("nan")
        verdict = "static camera" if self.static else "moving camera"
        return (
            f"{verdict}: the first frame's corners move {worst:.2f} px (median, worst of {len(self.frames)} frames "
            f"spread over the clip) against {self.threshold_px} px"
        )


def static_camera_check(
    frames: list[np.ndarray], cfg: VideoMotionConfig = VideoMotionConfig(), samples: int = 8
) -> StaticCameraCheck:
    """A camera is static when, from the first frame to every sampled later one, the median displacement of the
    tracked corners stays under ``cfg.static_flow_px``: people and cars moving through the view are a minority of
    the corners, the background holds the median. Frames with fewer than 20 tracked corners count as moving (no
    evidence of standing still)."""
    if len(frames) < 2:
        raise ValueError("need at least 2 frames")
    picks = np.unique(np.linspace(1, len(frames) - 1, min(samples, len(frames) - 1)).round().astype(int))
    flows = []
    for i in picks:
        p0, p1 = track_pair(frames[0], frames[int(i)], cfg)
        flows.append(float(np.median(np.linalg.norm(p1 - p0, axis=1))) if len(p0) >= 20 else float("inf"))
    static = all(f <= cfg.static_flow_px for f in flows)
    return StaticCameraCheck(static, tuple(int(i) for i in picks), tuple(flows), cfg.static_flow_px)


def trajectory_errors(est_cams_from_world: np.ndarray, gt_cams_from_world: np.ndarray) -> dict:
    """Per-step rotation error (deg) and translation-direction error (deg) between two pose chains."""
    rot, direction = [], []
    for i in range(len(est_cams_from_world) - 1):
        e = est_cams_from_world[i + 1] @ invert_rigid(est_cams_from_world[i])
        g = gt_cams_from_world[i + 1] @ invert_rigid(gt_cams_from_world[i])
        dR = e[:3, :3] @ g[:3, :3].T
        rot.append(np.degrees(np.arccos(np.clip((np.trace(dR) - 1) / 2, -1, 1))))
        te, tg = e[:3, 3], g[:3, 3]
        if np.linalg.norm(te) > 1e-9 and np.linalg.norm(tg) > 1e-9:
            c = te @ tg / (np.linalg.norm(te) * np.linalg.norm(tg))
            direction.append(np.degrees(np.arccos(np.clip(c, -1, 1))))
    return {
        "rotation_err_deg_median": float(np.median(rot)),
        "translation_dir_err_deg_median": float(np.median(direction)) if direction else None,
    }

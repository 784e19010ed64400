"""Camera motion of a video without poses, from tracked features.

Per consecutive pair: Shi-Tomasi corners tracked with pyramidal Lucas-Kanade (forward-backward check), the
essential matrix by RANSAC (OpenCV, seeded through ``cv2.setRNGSeed`` from the caller's generator) and
``recoverPose``. Monocular translation has no scale: each step gets ``step_scale_m`` (a speed prior, or 1), so
poses are metric only up to that prior; or, with ``ground_height_m`` (the camera's height above the road, e.g. the
1.65 m of a car's roof camera), each step's length comes from the ground: the pair's tracked points on the lane
ahead (pixels whose ray meets a level ground at that height within ``ground_lane_half_width_m`` of the camera's
path, ``ground_lane_depth_m`` away) are triangulated with the unit step, a plane
is fitted to them by RANSAC (its normal within ``ground_max_tilt_deg`` of the camera's up), and the step is
``ground_height_m`` over the plane's distance from the camera; the median over the ``ground_scale_window`` pairs
centred on each pair smooths the per-pair estimates (a pair without a ground fit takes its neighbours').
Pairs with a median flow below ``static_flow_px`` are treated as a static camera (identity motion), which is also
what a tripod video (e.g. ``$AIAS_DATA/video/vtest.avi``) gives.
K is given (a camera estimated from one frame: :func:`aias_augment.analyse.single_image.estimate_camera_from_image`).

A rectified stereo clip (:func:`estimate_stereo_motion`) has metric poses without any prior: in each frame the left
corners are matched along their rows in the right image (Lucas-Kanade, forward-backward checked), their disparity
gives their depth, and tracked into the next left frame they give its pose by PnP RANSAC (OpenCV, seeded the same
way). Depth from a disparity is biased long (E[1/d] > 1/E[d]: far points most), which biases the step's length, so
the pose is refined by a two-frame stereo bundle adjustment: the step and every inlier's 3D point fitted to its
four observations (left and right image of both frames; scipy's sparse robust least squares), no depth assumed.
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
    "StereoOdometryConfig",
    "estimate_stereo_motion",
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
    ground_height_m: float | None = None  # the camera's height above the ground: steps scaled from it (module doc)
    ground_scale_window: int = 5
    ground_max_tilt_deg: float = 20.0
    ground_min_points: int = 20
    ground_ransac_iterations: int = 200
    ground_lane_half_width_m: float = 1.5
    ground_lane_depth_m: tuple[float, float] = (4.0, 25.0)

    def __post_init__(self):
        if self.ground_height_m is not None and not (np.isfinite(self.ground_height_m) and self.ground_height_m > 0):
            raise ValueError(f"ground_height_m must be positive, got {self.ground_height_m}")
        if self.ground_scale_window < 1:
            raise ValueError(f"ground_scale_window must be >= 1, got {self.ground_scale_window}")


@dataclass(frozen=True, eq=False)
class VideoMotion:
    intrinsics: Intrinsics
    cams_from_world: np.ndarray  # (N, 4, 4), world = camera of frame 0
    num_inliers: tuple[int, ...]  # per pair (0 for static / failed)
    status: tuple[str, ...]  # per pair: "moving" | "static" | "failed: ..."
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
    intrinsics: Intrinsics,
    cfg: VideoMotionConfig = VideoMotionConfig(),
) -> VideoMotion:
    """Chain pairwise motions into ``cams_from_world`` (world = first camera). A failed pair keeps the previous
    pose (recorded in ``status``) rather than inventing motion."""
    if len(frames) < 2:
        raise ValueError("need at least 2 frames")
    h, w = np.asarray(frames[0]).shape[:2]
    if (intrinsics.width, intrinsics.height) != (w, h):
        raise ValueError("intrinsics do not match the frame size")
    steps, inliers, status, measured = [], [], [], []
    for a, b in zip(frames[:-1], frames[1:]):
        p0, p1 = track_pair(a, b, cfg)
        T, n, st = relative_pose(p0, p1, intrinsics, rng, cfg)
        g = None
        if st == "moving" and cfg.ground_height_m is not None:
            unit_height = ground_distance_unit_step(a, b, T, intrinsics, rng, cfg)
            g = None if unit_height is None else cfg.ground_height_m / unit_height
        steps.append(T)
        measured.append(g)
        inliers.append(n)
        status.append(st)
    meta = {}
    if cfg.ground_height_m is not None:
        lengths = ground_step_lengths(measured, cfg.ground_scale_window)
        if lengths is None:
            status = [s if s != "moving" else "failed: no ground plane measured in the clip" for s in status]
        meta = {"ground_steps_m": [round(x, 4) for x in measured if x is not None]}
    poses = [np.eye(4)]
    for k, (T, st) in enumerate(zip(steps, status)):
        if st == "moving":
            length = cfg.step_scale_m if cfg.ground_height_m is None else lengths[k]
            T = make_rigid(T[:3, :3], T[:3, 3] * length)
        else:
            T = np.eye(4)
        poses.append(T @ poses[-1])
    return VideoMotion(intrinsics, np.stack(poses), tuple(inliers), tuple(status), meta)


def ground_step_lengths(measured: list, window: int) -> list[float] | None:
    """Per pair, the median of the ground-measured step lengths of the ``window`` pairs centred on it (the whole
    clip is known; a pair measures its own step only roughly), widened until it holds one; None if none was
    measured."""
    got = np.array([np.nan if m is None else m for m in measured], float)
    if not np.isfinite(got).any():
        return None
    out = []
    for k in range(len(got)):
        half = window // 2
        while True:
            part = got[max(0, k - half) : k + half + 1]
            if np.isfinite(part).any():
                out.append(float(np.nanmedian(part)))
                break
            half += 1
    return out


def ground_distance_unit_step(
    img0: np.ndarray,
    img1: np.ndarray,
    cam1_from_cam0: np.ndarray,
    intrinsics: Intrinsics,
    rng: np.random.Generator,
    cfg: VideoMotionConfig = VideoMotionConfig(),
) -> float | None:
    """Distance from camera 0 to the ground plane in units of the step ``cam1_from_cam0`` (unit translation):
    corners of the lane ahead in ``img0`` (found there with a low quality threshold: a road's texture is faint)
    tracked into ``img1`` and triangulated, a plane fitted by RANSAC with its normal within
    ``cfg.ground_max_tilt_deg`` of the camera's up (-y), refitted to its inliers. None without enough points."""
    K = intrinsics.K
    # the lane ahead: pixels whose ray meets a level ground ``ground_height_m`` below within the lane's half width
    # and the distance range (kerbs, pavements and parked cars beside the lane stay out)
    vv, uu = np.mgrid[0 : intrinsics.height, 0 : intrinsics.width].astype(np.float64)
    dv = vv - intrinsics.cy
    with np.errstate(divide="ignore", invalid="ignore"):
        z = np.where(dv > 1.0, intrinsics.fy * float(cfg.ground_height_m or 1.0) / dv, np.inf)
    x = (uu - intrinsics.cx) * z / intrinsics.fx
    near, far = cfg.ground_lane_depth_m
    lane = ((z >= near) & (z <= far) & (np.abs(x) <= cfg.ground_lane_half_width_m)).astype(np.uint8)
    g0, g1 = _grey(img0), _grey(img1)
    c = cv2.goodFeaturesToTrack(g0, 400, 0.001, 5, mask=lane)
    if c is None or len(c) < cfg.ground_min_points:
        return None
    pts0 = c.reshape(-1, 2).astype(np.float32)
    pts1, ok = track_points(g0, g1, pts0, cfg.fb_max_err_px)
    pts0, pts1 = pts0[ok].astype(np.float64), pts1[ok].astype(np.float64)
    if len(pts0) < cfg.ground_min_points:
        return None
    region = np.ones(len(pts0), bool)
    P0 = K @ np.eye(3, 4)
    P1 = K @ cam1_from_cam0[:3]
    X = cv2.triangulatePoints(P0, P1, pts0[region].T, pts1[region].T)
    X = (X[:3] / X[3]).T
    X1 = X @ cam1_from_cam0[:3, :3].T + cam1_from_cam0[:3, 3]
    ok = (X[:, 2] > 0) & (X1[:, 2] > 0) & (X[:, 1] > 0)  # in front of both cameras, below the camera centre
    for P, q in ((P0, pts0[region]), (P1, pts1[region])):
        xh = np.c_[X, np.ones(len(X))] @ P.T
        with np.errstate(divide="ignore", invalid="ignore"):
            ok &= np.linalg.norm(xh[:, :2] / xh[:, 2:3] - q, axis=1) < 1.0
    X = X[ok]
    if len(X) < cfg.ground_min_points:
        return None
    up = np.array([0.0, -1.0, 0.0])
    cos_tilt = np.cos(np.radians(cfg.ground_max_tilt_deg))
    tol = 0.02 * float(np.median(np.linalg.norm(X, axis=1)))  # 2 % of the points' distance, in unit steps
    best = None
    for _ in range(cfg.ground_ransac_iterations):
        s = X[rng.choice(len(X), 3, replace=False)]
        n = np.cross(s[1] - s[0], s[2] - s[0])
        if np.linalg.norm(n) < 1e-12:
            continue
        n = n / np.linalg.norm(n)
        n = n if n @ up > 0 else -n
        if n @ up < cos_tilt:
            continue
        d = -float(n @ s[0])
        inl = np.abs(X @ n + d) < tol
        if best is None or inl.sum() > best.sum():
            best = inl
    if best is None or best.sum() < cfg.ground_min_points:
        return None
    Q = X[best]
    c = Q.mean(axis=0)
    n = np.linalg.svd(Q - c)[2][-1]
    n = n if n @ up > 0 else -n
    if n @ up < cos_tilt:
        return None
    return float(abs(n @ c))


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


@dataclass(frozen=True)
class StereoOdometryConfig:
    max_corners: int = 2000
    quality_level: float = 0.005
    min_distance_px: int = 7
    fb_max_err_px: float = 0.5  # forward-backward tracking error allowed (left-right and frame to frame)
    max_row_error_px: float = 1.0  # a rectified match stays on its row
    min_disparity_px: float = 2.0
    max_depth_m: float = 40.0  # depth error grows as depth^2 / (f b): far points only add noise
    ransac_threshold_px: float = 1.0
    ransac_iterations: int = 500
    min_inliers: int = 30
    bundle_adjust: bool = (
        False  # the two-frame stereo bundle adjustment after PnP (7x slower, see studies/video/unposed/result)
    )
    # frames measured from one keyframe's points (tracked on) before its successor: fewer steps chained, less drift
    keyframe_every: int = 1


def track_points(g0: np.ndarray, g1: np.ndarray, p0: np.ndarray, fb_max: float) -> tuple[np.ndarray, np.ndarray]:
    """Lucas-Kanade from g0 to g1 with a forward-backward check: (p1, ok)."""
    q0 = p0.reshape(-1, 1, 2).astype(np.float32)
    q1, st1, _ = cv2.calcOpticalFlowPyrLK(g0, g1, q0, None, winSize=(21, 21), maxLevel=3)
    qb, st2, _ = cv2.calcOpticalFlowPyrLK(g1, g0, q1, None, winSize=(21, 21), maxLevel=3)
    fb = np.linalg.norm((q0 - qb).reshape(-1, 2), axis=1)
    ok = (st1.ravel() == 1) & (st2.ravel() == 1) & (fb < fb_max)
    return q1.reshape(-1, 2).astype(np.float64), ok


def stereo_points(
    left: np.ndarray,
    right: np.ndarray,
    intrinsics: Intrinsics,
    baseline_m: float,
    cfg: StereoOdometryConfig = StereoOdometryConfig(),
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(left pixels (M, 2), their right matches (M, 2), points (M, 3) in the left camera) of corners matched along
    their row in the right image: depth f b / disparity."""
    p = cv2.goodFeaturesToTrack(_grey(left), cfg.max_corners, cfg.quality_level, cfg.min_distance_px)
    if p is None:
        return np.zeros((0, 2)), np.zeros((0, 2)), np.zeros((0, 3))
    p = p.reshape(-1, 2).astype(np.float64)
    q, ok = _row_matches(left, right, p, cfg)
    p, q = p[ok], q[ok]
    disparity = p[:, 0] - q[:, 0]
    z = intrinsics.fx * baseline_m / disparity
    keep = z < cfg.max_depth_m
    p, q, z = p[keep], q[keep], z[keep]
    xyz = np.c_[(p[:, 0] - intrinsics.cx) / intrinsics.fx * z, (p[:, 1] - intrinsics.cy) / intrinsics.fy * z, z]
    return p, q, xyz


def estimate_stereo_motion(
    lefts: list[np.ndarray],
    rights: list[np.ndarray],
    intrinsics: Intrinsics,
    baseline_m: float,
    rng: np.random.Generator,
    cfg: StereoOdometryConfig = StereoOdometryConfig(),
) -> VideoMotion:
    """Metric ``cams_from_world`` (world = left camera of frame 0) of a rectified stereo clip (module doc). A pair
    whose PnP fails keeps the previous pose, and ``status`` says why."""
    if len(lefts) != len(rights) or len(lefts) < 2:
        raise ValueError(f"need as many right as left frames, at least 2: {len(lefts)} left, {len(rights)} right")
    if not (np.isfinite(baseline_m) and baseline_m > 0):
        raise ValueError(f"baseline_m must be positive, got {baseline_m}")
    for f in (*lefts, *rights):
        if np.asarray(f).shape[:2] != (intrinsics.height, intrinsics.width):
            raise ValueError("frames do not match the intrinsics' size")
    poses, inliers, status = [np.eye(4)], [], []
    key = None  # the keyframe: its index, left and right pixels, 3D points, and where they are tracked now
    for i in range(len(lefts) - 1):
        if key is None or i - key[0] >= cfg.keyframe_every or key[5].sum() < cfg.min_inliers:
            px, qx, xyz = stereo_points(lefts[i], rights[i], intrinsics, baseline_m, cfg)
            key = [i, px, qx, xyz, px.copy(), np.ones(len(px), bool)]
        k, px, qx, xyz, cur, alive = key
        nxt, ok = (
            track_points(_grey(lefts[i]), _grey(lefts[i + 1]), cur, cfg.fb_max_err_px) if len(cur) else (cur, alive)
        )
        ok &= alive
        key[4], key[5] = nxt, ok
        if ok.sum() < cfg.min_inliers:
            poses.append(poses[-1]), inliers.append(0), status.append(f"failed: {int(ok.sum())} tracked points")
            key = None
            continue
        cv2.setRNGSeed(int(rng.integers(0, 2**31 - 1)))
        found, rvec, tvec, inl = cv2.solvePnPRansac(
            xyz[ok],
            nxt[ok],
            intrinsics.K,
            None,
            iterationsCount=cfg.ransac_iterations,
            reprojectionError=cfg.ransac_threshold_px,
            confidence=0.999,
            flags=cv2.SOLVEPNP_EPNP,
        )
        n = 0 if inl is None else len(inl)
        if not found or n < cfg.min_inliers:
            poses.append(poses[-1]), inliers.append(n), status.append(f"failed: {n} PnP inliers")
            key = None
            continue
        idx = inl.ravel()
        rvec, tvec = cv2.solvePnPRefineLM(xyz[ok][idx], nxt[ok][idx], intrinsics.K, None, rvec, tvec)
        if cfg.bundle_adjust:
            right_next, on_row = _row_matches(lefts[i + 1], rights[i + 1], nxt[ok][idx], cfg)
            obs = (px[ok][idx], qx[ok][idx], nxt[ok][idx], right_next, on_row)
            rvec, tvec = _stereo_bundle_adjust(xyz[ok][idx], obs, intrinsics, baseline_m, rvec, tvec)
        step = make_rigid(cv2.Rodrigues(rvec)[0], tvec.ravel())  # cam_{i+1} from the keyframe's camera
        poses.append(step @ poses[k]), inliers.append(n), status.append("moving")
    return VideoMotion(intrinsics, np.stack(poses), tuple(inliers), tuple(status), {"baseline_m": float(baseline_m)})


def _row_matches(left: np.ndarray, right: np.ndarray, p: np.ndarray, cfg: StereoOdometryConfig):
    """Right-image matches (M, 2) of left pixels ``p`` along their rows, and which passed the checks."""
    q, ok = track_points(_grey(left), _grey(right), p, cfg.fb_max_err_px)
    ok &= (np.abs(p[:, 1] - q[:, 1]) < cfg.max_row_error_px) & (p[:, 0] - q[:, 0] > cfg.min_disparity_px)
    return q, ok


def _stereo_bundle_adjust(xyz, obs, intrinsics: Intrinsics, baseline_m: float, rvec, tvec):
    """The step (rvec, tvec: cam1 from cam0) and the points (M, 3, in cam0) that best reproject into the left and
    right images of both frames: ``obs`` = (left0, right0, left1, right1, has_right1) pixels (right1 only where
    matched). Huber residuals at 1 px; the points are nuisance parameters."""
    from scipy.optimize import least_squares
    from scipy.sparse import lil_matrix

    left0, right0, left1, right1, has_right1 = obs
    m = len(xyz)
    fx, fy, cx, cy = intrinsics.fx, intrinsics.fy, intrinsics.cx, intrinsics.cy
    w1 = has_right1.astype(float)[:, None]
    right1 = np.where(has_right1[:, None], right1, 0.0)

    def proj(X, shift):
        return np.c_[fx * (X[:, 0] - shift) / X[:, 2] + cx, fy * X[:, 1] / X[:, 2] + cy]

    def residuals(x):
        R = cv2.Rodrigues(x[:3])[0]
        X0 = x[6:].reshape(m, 3)
        X1 = X0 @ R.T + x[3:6]
        return np.concatenate(
            [
                (proj(X0, 0.0) - left0).ravel(),
                (proj(X0, baseline_m) - right0).ravel(),
                (proj(X1, 0.0) - left1).ravel(),
                ((proj(X1, baseline_m) - right1) * w1).ravel(),
            ]
        )

    sparsity = lil_matrix((8 * m, 6 + 3 * m), dtype=int)
    for block in range(4):
        for j in range(m):
            rows = slice(block * 2 * m + 2 * j, block * 2 * m + 2 * j + 2)
            sparsity[rows, 6 + 3 * j : 9 + 3 * j] = 1
            if block >= 2:
                sparsity[rows, :6] = 1
    x0 = np.r_[np.ravel(rvec), np.ravel(tvec), np.asarray(xyz, float).ravel()]
    fit = least_squares(residuals, x0, jac_sparsity=sparsity, loss="huber", f_scale=1.0, x_scale="jac", max_nfev=50)
    return fit.x[:3].reshape(3, 1), fit.x[3:6].reshape(3, 1)

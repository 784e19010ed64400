"""Placement stabilisation across video frames: optical-flow tracking of the ground under the object.

Poses that drift (visual odometry, a noisy rig) make a world-fixed object slide over the road. The paper corrects
this by tracking the image around the object's contact point and refining each frame's pose. Here the ground patch
around the contact is tracked frame to frame with pyramidal Lucas-Kanade (forward-backward checked); a RANSAC
homography between consecutive frames (the ground is a plane, so the homography is exact for its points and
rejects off-plane corners) carries the contact pixel along. Where tracking is healthy the tracked pixel replaces
the pose-predicted one; :func:`refined_cam_from_object` then slides the object on the frame's ground so its
contact lands on that pixel (a per-frame pose refinement, translation only, so the object keeps its world
orientation).

Pure functions; randomness (RANSAC) is seeded from the ``numpy.random.Generator`` passed in.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from aias_augment.analyse.ground import GroundPlane
from aias_augment.core.geometry import Intrinsics, invert_rigid, make_rigid

__all__ = ["FlowRefineConfig", "FlowTrack", "track_contact_with_flow", "refined_cam_from_object"]


@dataclass(frozen=True)
class FlowRefineConfig:
    patch_half_m: tuple[float, float] = (3.0, 5.0)  # tracked ground patch around the contact: sideways, depth
    max_corners: int = 300
    quality_level: float = 0.005
    min_distance_px: int = 5
    lk_window_px: int = 21
    lk_levels: int = 3
    fb_max_err_px: float = 0.5  # forward-backward consistency
    min_inliers: int = 12  # homography inliers needed to trust a step
    ransac_threshold_px: float = 1.0
    # A tracked contact whose correction (tracked - predicted) jumps by more than this from the previous frame's is
    # refused: drift grows smoothly, a lost track jumps.
    max_correction_jump_px: float = 30.0
    max_anchor_scale: float = 1.6  # re-anchor when the patch has zoomed this much since its anchor frame (LK on
    #                                     a view warped back from a closer one loses corners fast: 82 % survive at 1.1x, 12 % at 1.37x)

    def __post_init__(self):
        if min(self.patch_half_m) <= 0 or self.min_inliers < 4 or self.max_correction_jump_px <= 0:
            raise ValueError("FlowRefineConfig: need patch_half_m > 0, min_inliers >= 4, max_correction_jump_px > 0")


@dataclass(frozen=True, eq=False)
class FlowTrack:
    uv: np.ndarray  # (N, 2) contact pixel per frame: tracked where ``status`` is "flow", else predicted
    status: tuple[str, ...]  # per frame: "anchor" | "flow" | "pose: <why>"
    inliers: tuple[int, ...]  # homography inliers of the step into each frame (0 for the anchor / refused)


def _grey(img) -> np.ndarray:
    img = np.asarray(img)
    if img.dtype != np.uint8:
        raise ValueError(f"expected uint8 frames, got {img.dtype}")
    return cv2.cvtColor(img, cv2.COLOR_RGB2GRAY) if img.ndim == 3 else img


def ground_patch_mask(
    uv: np.ndarray, ground: GroundPlane, intr: Intrinsics, half_m: tuple[float, float]
) -> np.ndarray | None:
    """uint8 mask of the ground rectangle (+-half_m[0] sideways, +-half_m[1] in depth) around the ground point seen
    at ``uv``; None when that pixel does not see the ground. Only corners in front of the camera are drawn."""
    c = ground.intersect_pixels(np.asarray(uv, np.float64)[None], intr)[0]
    if not np.all(np.isfinite(c)):
        return None
    n = ground.normal
    side = np.array([1.0, 0.0, 0.0]) - n[0] * n  # the camera's x axis laid on the plane
    side /= max(np.linalg.norm(side), 1e-9)  # eps: a plane perpendicular to x (not a ground seen by a camera)
    depth = np.cross(n, side)
    depth = depth if depth[2] > 0 else -depth
    # Near corners are clipped to 0.5 m in front of the camera so the polygon stays projectable.
    near = min(half_m[1], max(0.0, float(c[2]) - 0.5) / max(depth[2], 1e-6))
    corners = [c + a * half_m[0] * side + b * depth for a in (-1, 1) for b in (-near, half_m[1])]
    pts = np.array([corners[0], corners[1], corners[3], corners[2]])
    if np.any(pts[:, 2] <= 0.1):
        return None
    uvs = np.stack([intr.fx * pts[:, 0] / pts[:, 2] + intr.cx, intr.fy * pts[:, 1] / pts[:, 2] + intr.cy], 1)
    mask = np.zeros((intr.height, intr.width), np.uint8)
    cv2.fillConvexPoly(mask, np.round(uvs).astype(np.int32), 255)
    return mask


def _detect(
    g: np.ndarray, uv: np.ndarray, ground: GroundPlane, intr: Intrinsics, cfg: FlowRefineConfig
) -> tuple[np.ndarray | None, str]:
    """Corners of the ground patch around ``uv`` (float32 (M, 2)), or None and why."""
    roi = ground_patch_mask(uv, ground, intr, cfg.patch_half_m)
    if roi is None or roi.sum() < 64 * 255:
        return None, "no ground patch around the contact in view"
    p = cv2.goodFeaturesToTrack(g, cfg.max_corners, cfg.quality_level, cfg.min_distance_px, mask=roi)
    if p is None or len(p) < cfg.min_inliers:
        return None, f"{0 if p is None else len(p)} corners < {cfg.min_inliers}"
    return p.reshape(-1, 2).astype(np.float32), ""


def _lk(g0: np.ndarray, g1: np.ndarray, p0: np.ndarray, cfg: FlowRefineConfig) -> tuple[np.ndarray, np.ndarray]:
    """Forward-backward checked LK: (p1 (M, 2), ok (M,) bool)."""
    lk = dict(winSize=(cfg.lk_window_px, cfg.lk_window_px), maxLevel=cfg.lk_levels)
    p1, st1, _ = cv2.calcOpticalFlowPyrLK(g0, g1, p0.reshape(-1, 1, 2), None, **lk)
    pb, st2, _ = cv2.calcOpticalFlowPyrLK(g1, g0, p1, None, **lk)
    fb = np.linalg.norm(pb.reshape(-1, 2) - p0, axis=1)
    return p1.reshape(-1, 2), (st1.ravel() == 1) & (st2.ravel() == 1) & (fb < cfg.fb_max_err_px)


def ground_homography(cam1_from_cam0: np.ndarray, ground_in_cam0: GroundPlane, intr: Intrinsics) -> np.ndarray:
    """Pixel homography of the ground plane from camera 0 to camera 1: K (R - t n^T / d) K^-1 (n . X + d = 0)."""
    R, t = cam1_from_cam0[:3, :3], cam1_from_cam0[:3, 3]
    d = ground_in_cam0.d if abs(ground_in_cam0.d) > 1e-9 else 1e-9  # eps: a camera on the plane sees it edge-on
    H = intr.K @ (R - np.outer(t, ground_in_cam0.normal) / d) @ np.linalg.inv(intr.K)
    return H / H[2, 2] if abs(H[2, 2]) > 1e-12 else H


def _apply(H: np.ndarray, uv: np.ndarray) -> np.ndarray:
    q = H @ np.array([uv[0], uv[1], 1.0])
    return q[:2] / q[2] if abs(q[2]) > 1e-12 else np.full(2, np.nan)  # eps: point sent to infinity


def _local_scale(H: np.ndarray, uv: np.ndarray) -> float:
    """Area scale of the homography around ``uv`` (sqrt of the Jacobian determinant)."""
    e = 1.0
    a, b, c = _apply(H, uv), _apply(H, uv + [e, 0]), _apply(H, uv + [0, e])
    (ux, uy), (vx, vy) = b - a, c - a
    return float(np.sqrt(abs(ux * vy - uy * vx))) / e


def track_contact_with_flow(
    frames,
    predicted_uv: np.ndarray,
    grounds_in_cam: list[GroundPlane],
    intrinsics: Intrinsics,
    rng: np.random.Generator,
    cams_from_world: np.ndarray,
    start: int = 0,
    cfg: FlowRefineConfig = FlowRefineConfig(),
) -> FlowTrack:
    """Carry the contact pixel of frame ``start`` through the clip by tracking its ground patch (both directions).

    KLT against an anchor: corners of the ground patch around the contact are detected in an anchor frame. For each
    next frame, the ground homography anchor -> frame is predicted (the last estimate composed with the poses'
    ground homography for one step), the anchor is warped into the frame's view with it, and LK between that warped
    anchor and the frame measures only the small residual (no scale change, no chaining of per-step errors); a
    RANSAC homography of the residual corrects the prediction and maps the anchor's contact pixel.
    The anchor moves on when the view has zoomed by ``max_anchor_scale`` or too few corners remain.

    predicted_uv: (N, 2) pose-predicted contact pixels (NaN where behind the camera); the first anchor is
    ``predicted_uv[start]``. grounds_in_cam: each frame's ground in its camera. cams_from_world: (N, 4, 4) the
    (possibly drifting) poses, for the per-step prediction only. A frame whose tracking fails, or whose tracked
    pixel's correction jumps by more than ``max_correction_jump_px``, keeps the prediction; tracking restarts there.
    """
    pred = np.asarray(predicted_uv, np.float64)
    poses = np.asarray(cams_from_world, np.float64)
    n = len(frames)
    if pred.shape != (n, 2) or len(grounds_in_cam) != n or poses.shape != (n, 4, 4):
        raise ValueError(f"need one predicted pixel, one ground and one pose per frame ({n} frames)")
    if not np.all(np.isfinite(pred[start])):
        raise ValueError(f"the contact is not in front of the camera in the anchor frame {start}")
    greys = [_grey(f) for f in frames]
    size = (greys[0].shape[1], greys[0].shape[0])
    uv = pred.copy()
    status = ["pose: not reached"] * n
    inliers = [0] * n
    status[start] = "anchor"
    for order in (range(start + 1, n), range(start - 1, -1, -1)):
        prev, anchor = start, None  # anchor: (frame index, contact pixel there, its corners, H anchor -> prev)
        for i in order:
            if not np.all(np.isfinite(pred[i])):
                status[i], prev, anchor = "pose: contact behind the camera", i, None
                continue
            if anchor is None:
                pts, why = _detect(greys[prev], uv[prev], grounds_in_cam[prev], intrinsics, cfg)
                if pts is None:
                    status[i], prev = f"pose: {why}", i
                    continue
                anchor = (prev, uv[prev].copy(), pts, np.eye(3))
            a_idx, a_uv, a_pts, H_prev = anchor
            step = ground_homography(poses[i] @ invert_rigid(poses[prev]), grounds_in_cam[prev], intrinsics)
            H_pred = step @ H_prev
            # The anchor warped into this frame's view (a magnification: no aliasing), its corners moved with it.
            warped = cv2.warpPerspective(greys[a_idx], H_pred, size, flags=cv2.INTER_LINEAR)
            moved = cv2.perspectiveTransform(a_pts.reshape(-1, 1, 2), H_pred).reshape(-1, 2).astype(np.float32)
            nxt, ok = _lk(warped, greys[i], moved, cfg)
            q, k = None, int(ok.sum())
            if k >= cfg.min_inliers:
                cv2.setRNGSeed(int(rng.integers(0, 2**31 - 1)))
                H_res, inl = cv2.findHomography(
                    moved[ok], nxt[ok], cv2.RANSAC, cfg.ransac_threshold_px, maxIters=2000, confidence=0.999
                )
                k = 0 if inl is None else int(inl.sum())
                if H_res is not None and k >= cfg.min_inliers:
                    H = H_res @ H_pred
                    q = _apply(H, a_uv)
            inliers[i] = k
            if q is None or not np.all(np.isfinite(q)):
                status[i], anchor = f"pose: {k} tracked corners / inliers < {cfg.min_inliers}", None
            elif np.linalg.norm((q - pred[i]) - (uv[prev] - pred[prev])) > cfg.max_correction_jump_px:
                jump = np.linalg.norm((q - pred[i]) - (uv[prev] - pred[prev]))
                status[i], anchor = f"pose: the correction jumped {jump:.0f} px", None
            else:
                uv[i], status[i] = q, "flow"
                anchor = (a_idx, a_uv, a_pts, H)
                if k < 2 * cfg.min_inliers or _local_scale(H, a_uv) > cfg.max_anchor_scale:
                    anchor = None  # re-anchor on this frame next time
            prev = i
    return FlowTrack(uv, tuple(status), tuple(inliers))


def refined_cam_from_object(
    cam_from_object: np.ndarray,
    contact_in_cam: np.ndarray,
    target_uv: np.ndarray,
    ground_in_cam: GroundPlane,
    intrinsics: Intrinsics,
) -> np.ndarray:
    """Slide the object on the ground so its contact (``contact_in_cam``) projects to ``target_uv``.

    The new contact is the ground point seen at ``target_uv``; the object is translated by the difference (its
    orientation is kept). Returns ``cam_from_object`` unchanged when that pixel does not see the ground.
    """
    p = ground_in_cam.intersect_pixels(np.asarray(target_uv, np.float64)[None], intrinsics)[0]
    if not np.all(np.isfinite(p)):
        return cam_from_object
    return make_rigid(np.eye(3), p - np.asarray(contact_in_cam, np.float64)) @ cam_from_object

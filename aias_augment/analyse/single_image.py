"""Camera of a single image with unknown calibration: horizon, pitch, roll and focal from vanishing lines.

Method (man-made / street scenes):
1. Line segments (OpenCV LSD) longer than ``min_segment_frac`` of the image diagonal.
2. A vertical vanishing point from near-vertical segments (poles, facades) and a dominant horizontal one from
   the rest (road edges, lane marks, facades along the road), each by length-weighted RANSAC over segment pairs
   with an angular consistency test, refined by least squares on the inliers (homogeneous, so points at infinity
   are fine).
3. Horizon = the line through the horizontal VP perpendicular to the direction principal point -> vertical VP
   (the vanishing line of the ground is l = K^-T n and n ~ K^-1 v_vertical; with square pixels its normal is
   parallel to v_vertical - c, which needs no focal length). Without a vertical VP: roll 0, the horizontal line
   through the horizontal VP. Without any VP: the prior (level camera, horizon through the principal point).
4. Focal: given K wins; else from two orthogonal VPs f^2 = -(v1 - c).(v3 - c) when that is positive and gives a
   plausible field of view; else a field-of-view prior.
5. Ground: the plane whose normal is the horizon's (n ~ -K^T l), at ``camera_height_m`` (a prior: 1.65 m is
   KITTI's; pass your rig's).
"""

from __future__ import annotations

import hashlib
import threading
from collections import OrderedDict
from dataclasses import dataclass

import cv2
import numpy as np

from aias_augment.analyse.ground import GroundPlane
from aias_augment.core.geometry import CAMERA_HEIGHT_PRIOR_M, Intrinsics

__all__ = [
    "SingleImageCamera",
    "SingleImageConfig",
    "consistency_deg",
    "detect_line_segments",
    "lsd_segments",
    "fit_vanishing_point",
    "homogeneous_lines",
    "refine_vanishing_point",
    "unit_hypotheses",
    "vps_within",
    "estimate_camera_from_image",
    "horizon_row_error_px",
]


@dataclass(frozen=True)
class SingleImageConfig:
    min_segment_frac: float = 0.02  # of the image diagonal
    vertical_tolerance_deg: float = 15.0  # segments within this of the image vertical are vertical candidates
    inlier_angle_deg: float = 1.5  # segment direction vs direction to the VP
    ransac_iterations: int = 400
    min_vp_inliers: int = 6
    horizontal_vp_radius_frac: float = 1.0  # the street VP lies within this fraction of the diagonal of the centre
    hfov_prior_deg: float = 70.0
    plausible_hfov_deg: tuple[float, float] = (30.0, 120.0)
    camera_height_m: float = CAMERA_HEIGHT_PRIOR_M


@dataclass(frozen=True)
class SingleImageCamera:
    intrinsics: Intrinsics
    horizon_line: tuple[float, float, float]  # a u + b v + c = 0, (a, b) unit, ground side positive
    pitch_rad: float
    roll_rad: float
    ground: GroundPlane
    focal_source: str  # "given" | "vanishing_points" | "prior"
    horizon_source: str  # "vertical+horizontal_vp" | "horizontal_vp" | "prior"
    vp_horizontal: tuple[float, float, float] | None
    vp_vertical: tuple[float, float, float] | None
    num_segments: int

    def horizon_row_at(self, u: float) -> float:
        a, b, c = self.horizon_line
        return float(-(a * u + c) / b) if abs(b) > 1e-12 else float("nan")


#: The last few images' LSD segments, by content: the camera estimate and the sun's side read the same grey copy of
#: a photo (~15 ms of LSD each at 640 px); read-only arrays, so a caller cannot change another's.
_LSD_CACHE: OrderedDict = OrderedDict()
_LSD_CACHE_SIZE = 4
_LSD_LOCK = threading.Lock()


def lsd_segments(grey: np.ndarray) -> np.ndarray:
    """(N, 4) float64 every segment x1, y1, x2, y2 that OpenCV's LSD (standard refinement) finds in the (H, W) uint8
    ``grey``, read-only; the same image again (by content) gives the same array without a second detection."""
    grey = np.ascontiguousarray(grey)
    if grey.ndim != 2 or grey.dtype != np.uint8:
        raise ValueError(f"expected a (H, W) uint8 grey image, got {grey.shape} {grey.dtype}")
    key = (grey.shape, hashlib.blake2b(grey.data, digest_size=16).digest())
    with _LSD_LOCK:
        seg = _LSD_CACHE.get(key)
        if seg is not None:
            _LSD_CACHE.move_to_end(key)
            return seg
    lines = cv2.createLineSegmentDetector(cv2.LSD_REFINE_STD).detect(grey)[0]
    seg = np.zeros((0, 4)) if lines is None else lines.reshape(-1, 4).astype(np.float64)
    seg.setflags(write=False)
    with _LSD_LOCK:
        _LSD_CACHE[key] = seg
        while len(_LSD_CACHE) > _LSD_CACHE_SIZE:
            _LSD_CACHE.popitem(last=False)
    return seg


def detect_line_segments(grey: np.ndarray, min_length_px: float) -> np.ndarray:
    """(N, 4) segments x1, y1, x2, y2 (pixels) longer than ``min_length_px``."""
    if grey.ndim != 2 or grey.dtype != np.uint8:
        raise ValueError(f"expected a (H, W) uint8 grey image, got {grey.shape} {grey.dtype}")
    seg = lsd_segments(grey)
    length = np.hypot(seg[:, 2] - seg[:, 0], seg[:, 3] - seg[:, 1])
    return seg[length >= min_length_px]


def homogeneous_lines(seg: np.ndarray) -> np.ndarray:
    """(N, 3) lines through the segments' end points (N, 4), scaled so that (a, b) is a unit normal."""
    p1 = np.column_stack([seg[:, :2], np.ones(len(seg))])
    p2 = np.column_stack([seg[:, 2:], np.ones(len(seg))])
    lines = np.cross(p1, p2)
    return lines / np.linalg.norm(lines[:, :2], axis=1, keepdims=True)


def consistency_deg(seg: np.ndarray, vps: np.ndarray) -> np.ndarray:
    """Angle (deg) between each segment and the line from its midpoint to each VP: (N, 4), (K, 3) -> (K, N)."""
    mid = (seg[:, :2] + seg[:, 2:]) / 2
    direction = seg[:, 2:] - seg[:, :2]
    direction /= np.linalg.norm(direction, axis=1, keepdims=True)
    # direction midpoint -> vp in homogeneous form: vp_xy - w * mid (valid for w = 0: points at infinity); its x and
    # y as (K, N) planes: the norm and the dot product as element-wise sums (numpy's order for a 2-long axis: x + y),
    # not reductions over a 2-long last axis
    tx = vps[:, 0, None] - vps[:, 2, None] * mid[None, :, 0]
    ty = vps[:, 1, None] - vps[:, 2, None] * mid[None, :, 1]
    norm = np.sqrt(tx * tx + ty * ty)
    unit = np.maximum(norm, 1e-12)
    cos = np.abs((tx / unit) * direction[None, :, 0] + (ty / unit) * direction[None, :, 1])
    ang = np.degrees(np.arccos(np.clip(cos, 0.0, 1.0)))
    return np.where(norm > 1e-9, ang, 90.0)


def weighted_pairs(rng: np.random.Generator, prob: np.ndarray, n: int) -> np.ndarray:
    """``np.stack([rng.choice(len(prob), 2, replace=False, p=prob) for _ in range(n)])``, the same pairs and the same
    generator state afterwards (tested), without n calls: numpy draws two uniforms per pair through the cdf and, when
    both hit the same index, one more through the cdf without it; that walk runs here over one block of uniforms,
    then the generator is set to where the n calls would have left it."""
    prob = np.asarray(prob, dtype=np.float64)
    if n <= 0 or np.count_nonzero(prob > 0) < 2:
        return np.stack([rng.choice(len(prob), 2, replace=False, p=prob) for _ in range(n)]).reshape(-1, 2)
    state = rng.bit_generator.state
    cdf = np.cumsum(prob)
    cdf /= cdf[-1]
    x = rng.random(3 * n)  # enough for every pair drawing its third uniform
    first = cdf.searchsorted(x, side="right")
    out = np.empty((n, 2), np.int64)
    pos = 0
    for i in range(n):
        a, b = first[pos], first[pos + 1]
        pos += 2
        while a == b:  # numpy: the found index gets p = 0, the cdf is rebuilt, one more draw
            if pos >= len(x):
                x = np.concatenate([x, rng.random(n)])
                first = cdf.searchsorted(x, side="right")
            q = prob.copy()
            q[a] = 0.0
            c2 = np.cumsum(q)
            c2 /= c2[-1]
            b = c2.searchsorted(x[pos], side="right")
            pos += 1
        out[i] = a, b
    rng.bit_generator.state = state
    rng.random(pos)  # consume exactly what the n calls consumed
    return out


def fit_vanishing_point(
    seg: np.ndarray,
    rng: np.random.Generator,
    *,
    iterations: int = 400,
    inlier_angle_deg: float = 1.5,
    min_inliers: int = 6,
    finite_within: tuple[np.ndarray, float] | None = None,
) -> tuple[np.ndarray, np.ndarray] | None:
    """Length-weighted RANSAC VP of segments: (homogeneous unit VP (3,), inlier mask) or None.

    ``finite_within=(centre_xy, radius_px)`` only accepts finite VPs within ``radius_px`` of ``centre_xy``.
    """
    if len(seg) < max(2, min_inliers):
        return None
    lines = homogeneous_lines(seg)
    length = np.hypot(seg[:, 2] - seg[:, 0], seg[:, 3] - seg[:, 1])
    prob = length / length.sum()
    pairs = weighted_pairs(rng, prob, iterations)
    vps = unit_hypotheses(np.cross(lines[pairs[:, 0]], lines[pairs[:, 1]]), finite_within)
    if len(vps) == 0:
        return None
    inl = consistency_deg(seg, vps) < inlier_angle_deg
    score = inl @ length
    best = int(np.argmax(score))
    mask = inl[best]
    if mask.sum() < min_inliers:
        return None
    return refine_vanishing_point(seg, lines, length, mask, inlier_angle_deg, min_inliers, finite_within)


def unit_hypotheses(vps: np.ndarray, finite_within: tuple[np.ndarray, float] | None = None) -> np.ndarray:
    """Hypothesis VPs (K, 3) scaled to unit length, those of parallel pairs (zero) dropped and, with
    ``finite_within=(centre_xy, radius_px)``, only the finite ones within the radius kept; possibly empty."""
    norm = np.linalg.norm(vps, axis=1)
    ok = norm > 1e-12
    vps = vps[ok] / norm[ok, None]
    return vps if finite_within is None else vps[vps_within(vps, *finite_within)]


def refine_vanishing_point(
    seg: np.ndarray,
    lines: np.ndarray,
    length: np.ndarray,
    mask: np.ndarray,
    inlier_angle_deg: float,
    min_inliers: int,
    finite_within: tuple[np.ndarray, float] | None = None,
) -> tuple[np.ndarray, np.ndarray] | None:
    """Two rounds of least squares from the inliers ``mask`` of segments ``seg`` (their ``homogeneous_lines`` and
    lengths given): the smallest eigenvector of sum w l l^T, then its inliers again. None when too few remain or
    the VP leaves ``finite_within``."""
    for _ in range(2):
        w = length[mask]
        M = (lines[mask] * w[:, None]).T @ lines[mask]
        vp = np.linalg.eigh(M)[1][:, 0]
        mask = consistency_deg(seg, vp[None])[0] < inlier_angle_deg
        if mask.sum() < min_inliers or (finite_within is not None and not vps_within(vp[None], *finite_within)[0]):
            return None
    return vp, mask


def vps_within(vps: np.ndarray, centre_xy: np.ndarray, radius_px: float) -> np.ndarray:
    """(K,) bool: homogeneous VPs (K, 3) that are finite and within ``radius_px`` of ``centre_xy``."""
    w = vps[:, 2]
    finite = np.abs(w) > 1e-12
    xy = vps[:, :2] / np.where(finite, w, 1.0)[:, None]
    return finite & (np.linalg.norm(xy - np.asarray(centre_xy), axis=1) < radius_px)


def _finite_point(vp: np.ndarray, far: float) -> np.ndarray | None:
    return vp[:2] / vp[2] if abs(vp[2]) > 1e-12 and np.all(np.abs(vp[:2] / vp[2]) < far) else None


def estimate_camera_from_image(
    image: np.ndarray,
    rng: np.random.Generator,
    *,
    intrinsics: Intrinsics | None = None,
    cfg: SingleImageConfig = SingleImageConfig(),
) -> SingleImageCamera:
    """Horizon, pitch, roll, focal and a ground-plane prior for one (H, W[, 3]) uint8 image."""
    img = np.asarray(image)
    if img.dtype != np.uint8 or img.ndim not in (2, 3):
        raise ValueError(f"expected a uint8 grey or RGB image, got {img.shape} {img.dtype}")
    grey = img if img.ndim == 2 else cv2.cvtColor(img, cv2.COLOR_RGB2GRAY)
    h, w = grey.shape
    if intrinsics is not None and (intrinsics.width, intrinsics.height) != (w, h):
        raise ValueError("intrinsics do not match the image size")
    c = np.array([intrinsics.cx, intrinsics.cy]) if intrinsics else np.array([(w - 1) / 2, (h - 1) / 2])
    diag = float(np.hypot(w, h))
    seg = detect_line_segments(grey, cfg.min_segment_frac * diag)
    angle_from_vertical = np.degrees(np.arctan2(np.abs(seg[:, 2] - seg[:, 0]), np.abs(seg[:, 3] - seg[:, 1])))
    vertical = angle_from_vertical < cfg.vertical_tolerance_deg
    kw = dict(iterations=cfg.ransac_iterations, inlier_angle_deg=cfg.inlier_angle_deg, min_inliers=cfg.min_vp_inliers)
    vert = fit_vanishing_point(seg[vertical], rng, **kw)
    # street VP: a finite point near the image (facade lines nearly parallel to the image plane fix no horizon)
    horiz = fit_vanishing_point(seg[~vertical], rng, **kw, finite_within=(c, cfg.horizontal_vp_radius_frac * diag))

    vp_v = vert[0] if vert is not None else None
    vp_h = horiz[0] if horiz is not None else None
    vh_pt = _finite_point(vp_h, 1e9) if vp_h is not None else None
    if vp_v is not None:
        down = vp_v[:2] - vp_v[2] * c  # direction c -> vertical VP (homogeneous: works at infinity)
        if np.linalg.norm(down) < 1e-12:
            vp_v, down = None, None
        else:
            down = down / np.linalg.norm(down) * (1 if down[1] >= 0 else -1)  # ground is below: point down
    if vh_pt is not None and vp_v is not None:
        a, b = down
        horizon = np.array([a, b, -(a * vh_pt[0] + b * vh_pt[1])])
        horizon_source = "vertical+horizontal_vp"
    elif vh_pt is not None:
        horizon = np.array([0.0, 1.0, -vh_pt[1]])
        horizon_source = "horizontal_vp"
    else:
        horizon = np.array([0.0, 1.0, -c[1]])
        horizon_source = "prior"

    focal_source = "given"
    if intrinsics is None:
        f = None
        v_pt = _finite_point(vp_v, 50 * diag) if vp_v is not None else None
        if vh_pt is not None and v_pt is not None:
            f2 = -float((vh_pt - c) @ (v_pt - c))
            if f2 > 0:
                hfov = np.degrees(2 * np.arctan(w / 2 / np.sqrt(f2)))
                if cfg.plausible_hfov_deg[0] <= hfov <= cfg.plausible_hfov_deg[1]:
                    f = float(np.sqrt(f2))
        focal_source = "vanishing_points" if f is not None else "prior"
        if f is None:
            f = 0.5 * w / np.tan(np.deg2rad(cfg.hfov_prior_deg) / 2)
        intrinsics = Intrinsics(f, f, c[0], c[1], w, h)
    # up normal from the horizon: the ground side has l . x > 0 and n . K^-1 x < 0  =>  n ~ -K^T l
    n = -intrinsics.K.T @ horizon
    n /= np.linalg.norm(n)  # unit first: GroundPlane treats (n, d) as plane coefficients and rescales d with n
    ground = GroundPlane(n, cfg.camera_height_m, f"single_image:{horizon_source}", assumed_scale=True)
    pitch, roll = ground.pitch_roll_rad()
    return SingleImageCamera(
        intrinsics=intrinsics,
        horizon_line=tuple(map(float, horizon)),
        pitch_rad=pitch,
        roll_rad=roll,
        ground=ground,
        focal_source=focal_source,
        horizon_source=horizon_source,
        vp_horizontal=None if vp_h is None else tuple(map(float, vp_h)),
        vp_vertical=None if vp_v is None else tuple(map(float, vp_v)),
        num_segments=len(seg),
    )


def horizon_row_error_px(line_a, line_b, columns: np.ndarray) -> np.ndarray:
    """|v_a(u) - v_b(u)| at the given columns for two horizon lines (a, b, c) with b != 0."""
    la, lb = np.asarray(line_a, float), np.asarray(line_b, float)
    if abs(la[1]) < 1e-12 or abs(lb[1]) < 1e-12:
        raise ValueError("vertical horizon line: row error undefined")
    u = np.asarray(columns, dtype=np.float64)
    return np.abs(-(la[0] * u + la[2]) / la[1] + (lb[0] * u + lb[2]) / lb[1])

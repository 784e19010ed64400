"""Which side the sun is on: the vertical-surface cue and the shadow-end cue (known camera, flat ground).

The sky gradient and the cast-shadow axis (``ratio.shadow_axis_on_ground``) fix the sun's azimuth only up to 180 deg
when the sun is out of view. Two physical cues pick the end:

- **Vertical surfaces** (Lalonde, Efros, Narasimhan, "Estimating natural illumination from a single outdoor image",
  ICCV 2009): a Lambertian vertical surface with horizontal normal n receives ``E_sky(n) + E_sun max(0, n . s)``; so
  among facades of comparable albedo, those facing the sun are brighter. With a known camera and up vector, a straight
  image segment that is horizontal in 3D (window rows, floor lines, roof edges) spans an interpretation plane with
  normal m = r1 x r2 (r: rays of its end points); the facade containing it is vertical, so its normal is the
  horizontal part of m (:func:`classify_segments`), signed toward the camera. Per candidate sun, the log-luminance of
  facade samples is regressed on ``max(0, n . s_h)`` with the physical sign (facing the sun = brighter).
- **Shadow end**: a cast shadow starts at its occluder's base and runs AWAY from the sun. Segments that are vertical in
  3D (poles, trunks, building corners, their interpretation plane contains the up vector) whose lower end is below the
  horizon give candidate bases; unprojected onto the ground plane (camera height sets only the scale, not the
  direction), the ground is sampled along ``-s_h`` and ``+s_h`` from each base; darkness on the anti-sun side minus
  darkness on the sun side is antisymmetric in the azimuth, so it resolves exactly the 180-deg ambiguity.

Frames: OpenCV camera (x right, y down, z forward); ``up_in_cam`` is the unit world up in the camera; sun candidates
point from the scene toward the sun. Both cues only constrain the azimuth (a vertical surface's ``n . s`` is
``cos(el) cos(dphi)`` and the cos(el) scale is absorbed by the fitted gain; the shadow-end test uses ``s_h`` only).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from aias_augment.analyse.lighting.envmap import camera_ray_directions
from aias_augment.analyse.single_image import lsd_segments
from aias_augment.core.geometry import CAMERA_HEIGHT_PRIOR_M, Intrinsics
from aias_augment.core.hdr import luminance, max_channel, srgb_to_linear

__all__ = [
    "LineSegments",
    "detect_line_segments",
    "classify_segments",
    "FacadeSamples",
    "facade_samples",
    "facade_clusters",
    "vertical_surface_loglik",
    "occluder_bases",
    "ground_darkness",
    "shadow_end_scores",
    "grid_ground_azimuths",
    "default_sky_mask",
    "shadow_end_loglik",
    "SunSideCue",
    "sun_side_cue",
]

EPS = 1e-12


@dataclass(frozen=True)
class LineSegments:
    """Straight image segments with their 3D interpretation (see :func:`classify_segments`).

    endpoints_px: (S, 2, 2) (x, y) pixel coordinates of both ends; length_px: (S,);
    plane_normal_in_cam: (S, 3) unit normal of the plane through the camera centre and the segment;
    is_vertical: (S,) the plane contains the up vector (within tolerance): a vertical 3D line (or one heading straight
    away from the camera); facade_normal_in_cam: (S, 3) unit horizontal normal, toward the camera, of the vertical
    surface containing the segment if it is horizontal in 3D (rows of ``is_vertical`` or of segments too close to the
    horizon line are zero); facade_weight: (S,) in [0, 1], how well that normal is determined.
    """

    endpoints_px: np.ndarray
    length_px: np.ndarray
    plane_normal_in_cam: np.ndarray
    is_vertical: np.ndarray
    facade_normal_in_cam: np.ndarray
    facade_weight: np.ndarray

    def __len__(self) -> int:
        return int(self.length_px.shape[0])


def detect_line_segments(image_rgb_uint8: np.ndarray, min_length_px: float) -> np.ndarray:
    """Straight segments by OpenCV's LSD (a-contrario line segment detector, no tuned thresholds, standard
    refinement: :func:`~aias_augment.analyse.single_image.lsd_segments`): (S, 2, 2) (x, y) end points, only those at
    least ``min_length_px`` long."""
    import cv2

    img = np.asarray(image_rgb_uint8)
    if img.ndim != 3 or img.shape[2] != 3 or img.dtype != np.uint8:
        raise ValueError(f"detect_line_segments: expected (H, W, 3) uint8, got {img.shape} {img.dtype}")
    seg = lsd_segments(cv2.cvtColor(img, cv2.COLOR_RGB2GRAY)).reshape(-1, 2, 2)  # the camera estimate's, when shared
    length = np.linalg.norm(seg[:, 1] - seg[:, 0], axis=1)
    return seg[length >= min_length_px]


def classify_segments(
    endpoints_px: np.ndarray,
    intrinsics: Intrinsics,
    up_in_cam: np.ndarray,
    vertical_tol_deg: float = 2.0,
    min_facade_angle_deg: float = 5.0,
) -> LineSegments:
    """3D reading of image segments under a known camera (pure geometry, no image).

    A segment is vertical in 3D when the plane through the camera centre and the segment contains ``up``:
    ``|m . up| < sin(vertical_tol_deg)`` (m: the plane's unit normal). Otherwise, if it is horizontal in 3D its
    direction is ``m x up`` and the vertical surface containing it has the horizontal normal ``m_h = m - (m . up) up``
    (perpendicular to the line and to up), signed to face the camera (``m_h . ray_mid < 0``). Near the horizon line
    every horizontal 3D line projects onto the same image line and the normal is undetermined: ``|m_h|`` (the sine of
    the angle between the plane and the horizontal) below ``sin(min_facade_angle_deg)`` gives weight 0, else the weight
    is ``|m_h|`` clipped to 1.
    """
    seg = np.asarray(endpoints_px, dtype=np.float64).reshape(-1, 2, 2)
    up = np.asarray(up_in_cam, dtype=np.float64).reshape(3)
    up = up / max(float(np.linalg.norm(up)), EPS)
    Kinv = np.linalg.inv(intrinsics.K)
    ones = np.ones((len(seg), 1))
    r1 = np.hstack([seg[:, 0], ones]) @ Kinv.T
    r2 = np.hstack([seg[:, 1], ones]) @ Kinv.T
    m = np.cross(r1, r2)
    mn = np.linalg.norm(m, axis=1, keepdims=True)
    ok = mn[:, 0] > EPS  # a zero-length segment has no plane
    m = np.where(ok[:, None], m / np.maximum(mn, EPS), 0.0)
    m_up = m @ up
    vertical = ok & (np.abs(m_up) < np.sin(np.deg2rad(vertical_tol_deg)))
    m_h = m - m_up[:, None] * up
    h = np.linalg.norm(m_h, axis=1)
    facade = ok & ~vertical & (h >= np.sin(np.deg2rad(min_facade_angle_deg)))
    normal = np.where(facade[:, None], m_h / np.maximum(h, EPS)[:, None], 0.0)
    mid = r1 + r2
    normal = np.where((np.sum(normal * mid, axis=1) > 0)[:, None], -normal, normal)  # face the camera
    length = np.linalg.norm(seg[:, 1] - seg[:, 0], axis=1)
    return LineSegments(seg, length, m, vertical, normal, np.where(facade, np.clip(h, 0.0, 1.0), 0.0))


@dataclass(frozen=True)
class FacadeSamples:
    """Vertical-surface samples: unit horizontal normals (P, 3) in the camera, log linear luminance (P,), weights (P,)."""

    normals_in_cam: np.ndarray
    log_luminance: np.ndarray
    weights: np.ndarray


def facade_samples(
    image_linear: np.ndarray,
    intrinsics: Intrinsics,
    up_in_cam: np.ndarray,
    segments: LineSegments,
    exclude_mask: np.ndarray | None = None,
    min_elevation_deg: float = 2.0,
    offsets_px: tuple[float, ...] = (-4.0, -2.5, 2.5, 4.0),
    n_along: int = 9,
    min_valid_fraction: float = 0.5,
) -> FacadeSamples:
    """Luminance of the vertical surface along each facade segment (horizontal-in-3D reading of
    :func:`classify_segments`).

    Only segments whose both ends are more than ``min_elevation_deg`` above the horizon are used (below it a
    horizontal line is as likely to lie on the ground: lane marks, curbs). Pixels at ``offsets_px`` on both sides of
    ``n_along`` points along the segment are read; ``exclude_mask`` (sky) pixels are dropped; the sample is the log of
    the median linear luminance (eps 1e-4 for black), kept when at least ``min_valid_fraction`` of the reads are valid.
    Weight = segment length x normal weight.
    """
    img = np.asarray(image_linear)
    h, w = img.shape[:2]
    Y = luminance(img)  # float32 (as from a float64 copy of float32 values)
    up = np.asarray(up_in_cam, dtype=np.float64) / max(float(np.linalg.norm(up_in_cam)), EPS)
    Kinv = np.linalg.inv(intrinsics.K)
    normals, logs, weights = [], [], []
    t = (np.arange(n_along) + 0.5) / n_along
    for k in np.flatnonzero(segments.facade_weight > 0):
        p0, p1 = segments.endpoints_px[k]
        rays = np.array([[*p0, 1.0], [*p1, 1.0]]) @ Kinv.T
        rays /= np.linalg.norm(rays, axis=1, keepdims=True)
        if np.min(rays @ up) <= np.sin(np.deg2rad(min_elevation_deg)):
            continue
        along = p0[None, :] + t[:, None] * (p1 - p0)[None, :]
        d = (p1 - p0) / max(float(np.linalg.norm(p1 - p0)), EPS)
        perp = np.array([-d[1], d[0]])
        pts = (along[:, None, :] + np.asarray(offsets_px)[None, :, None] * perp[None, None, :]).reshape(-1, 2)
        u = np.round(pts[:, 0]).astype(int)
        v = np.round(pts[:, 1]).astype(int)
        inside = (u >= 0) & (u < w) & (v >= 0) & (v < h)
        u, v = u[inside], v[inside]
        if exclude_mask is not None:
            keep = ~np.asarray(exclude_mask, bool)[v, u]
            u, v = u[keep], v[keep]
        if len(u) < min_valid_fraction * len(pts):
            continue
        normals.append(segments.facade_normal_in_cam[k])
        logs.append(np.log(max(float(np.median(Y[v, u])), 1e-4)))
        weights.append(float(segments.length_px[k] * segments.facade_weight[k]))
    if not normals:
        return FacadeSamples(np.zeros((0, 3)), np.zeros(0), np.zeros(0))
    return FacadeSamples(np.array(normals), np.array(logs), np.array(weights))


def _horizontal_units(grid_in_cam: np.ndarray, up_in_cam: np.ndarray) -> np.ndarray:
    g = np.asarray(grid_in_cam, dtype=np.float64)
    gh = g - (g @ up_in_cam)[:, None] * up_in_cam
    n = np.linalg.norm(gh, axis=1, keepdims=True)
    return np.where(n > 1e-6, gh / np.maximum(n, EPS), 0.0)  # zenith candidates have no azimuth: zero vector


def facade_clusters(
    samples: FacadeSamples, up_in_cam: np.ndarray, merge_deg: float = 10.0, min_segments: int = 3
) -> FacadeSamples:
    """Group facade samples into orientation clusters, one per physical wall direction: (C, 3) mean normals, (C,)
    weighted-mean log luminance, (C,) number of segments as weights.

    Samples are sorted by the azimuth of their normal about ``up`` and split wherever two neighbours differ by more
    than ``merge_deg`` (single linkage, on the circle). A wall carries several parallel horizontal lines (floors,
    window rows, its roof and base); a cluster of fewer than ``min_segments`` segments is more likely foliage, a
    fence or a car than a wall, and is dropped.
    """
    P = len(samples.log_luminance)
    if P == 0:
        return samples
    up = np.asarray(up_in_cam, dtype=np.float64) / max(float(np.linalg.norm(up_in_cam)), EPS)
    right, fwd = _horizontal_frame(up)
    az = np.arctan2(samples.normals_in_cam @ fwd, samples.normals_in_cam @ right)
    order = np.argsort(az)
    a = az[order]
    gaps = np.diff(np.concatenate([a, a[:1] + 2.0 * np.pi]))  # gap after each sorted sample, wrapping around
    cut = gaps > np.deg2rad(merge_deg)
    if not cut.any():  # one cluster all around (only with dense, spread normals)
        groups = [order]
    else:
        start = (int(np.argmax(cut)) + 1) % P  # begin right after a gap
        rolled = np.roll(order, -start)
        cuts = np.flatnonzero(np.roll(cut, -start)) + 1
        groups = [g for g in np.split(rolled, cuts) if len(g)]
    normals, logs, counts = [], [], []
    for g in groups:
        if len(g) < min_segments:
            continue
        w = samples.weights[g] / max(float(samples.weights[g].sum()), EPS)
        n = w @ samples.normals_in_cam[g]
        normals.append(n / max(float(np.linalg.norm(n)), EPS))
        logs.append(float(w @ samples.log_luminance[g]))
        counts.append(float(len(g)))
    if not normals:
        return FacadeSamples(np.zeros((0, 3)), np.zeros(0), np.zeros(0))
    return FacadeSamples(np.array(normals), np.array(logs), np.array(counts))


def vertical_surface_loglik(
    walls: FacadeSamples, grid_in_cam: np.ndarray, up_in_cam: np.ndarray, albedo_sigma: float = 0.7
) -> tuple[np.ndarray, float]:
    """Log-likelihood (N,) of candidate suns from the brightness of walls of different orientations, and the fit's
    R^2 in [0, 1]. ``walls``: one sample per wall direction (:func:`facade_clusters`), each an independent unit.

    Model per candidate s (horizontal unit part s_h): ``log L_c = a + b max(0, n_c . s_h) + e_c`` with e_c ~ N(0,
    albedo_sigma^2) the walls' unknown albedos (ln units; 0.7 ~ a factor 2 between typical building materials), a
    and b profiled out by least squares with the physical sign ``b >= 0`` (a candidate that needs b < 0, walls facing
    it darker, gets the constant fit). ``loglik = -0.5 (cost - min cost) / albedo_sigma^2`` with cost the residual
    sum of squares: two walls whose luminances differ by d give up to d^2 / (4 albedo_sigma^2) nats. Walls that all
    face the same way carry no side information (the regressor is constant): 0 everywhere and R^2 = 0.
    """
    grid_h = _horizontal_units(grid_in_cam, np.asarray(up_in_cam, dtype=np.float64))
    N = len(grid_h)
    C = len(walls.log_luminance)
    if C < 2 or albedo_sigma <= 0:
        return np.zeros(N), 0.0
    y = walls.log_luminance - float(np.mean(walls.log_luminance))
    ss0 = float(y @ y)
    if ss0 < 1e-9:
        return np.zeros(N), 0.0
    f = np.maximum(grid_h @ walls.normals_in_cam.T, 0.0)  # (N, C)
    fc = f - f.mean(axis=1, keepdims=True)
    ff = np.sum(fc * fc, axis=1)
    fy = fc @ y
    b = np.where(ff > 1e-9, fy / np.maximum(ff, 1e-9), 0.0)  # eps: a constant regressor has no slope
    b = np.maximum(b, 0.0)
    cost = np.maximum(ss0 - b * b * ff, 0.0)
    r2 = float(np.clip(1.0 - cost.min() / ss0, 0.0, 1.0))
    return -0.5 * (cost - cost.min()) / albedo_sigma**2, r2


def occluder_bases(
    segments: LineSegments,
    intrinsics: Intrinsics,
    up_in_cam: np.ndarray,
    min_depression_deg: float = 1.0,
    line_tol_px: float = 3.0,
    occluder_halfwidth_m: float = 0.3,
    camera_height_m: float = CAMERA_HEIGHT_PRIOR_M,
) -> tuple[np.ndarray, np.ndarray]:
    """Lower end points of 3D-vertical segments that lie below the horizon by more than ``min_depression_deg``:
    candidate bases where an upright occluder meets the ground. An occluder whose edges are broken into pieces
    (stripes, windows, leaves) or seen as two edges (a pole's left and right sides) yields one base only, the lowest:
    a lower end that lies within ``max(line_tol_px, 2 x occluder_halfwidth_m`` projected at the lower base's depth)
    of another vertical segment whose own lower end is further down, and above that end, is not a ground contact.
    Returns the base pixels (B, 2) and the
    image direction of world up at each base (B, 2) (unit; the occluder extends from the base along it)."""
    up = np.asarray(up_in_cam, dtype=np.float64) / max(float(np.linalg.norm(up_in_cam)), EPS)
    Kinv = np.linalg.inv(intrinsics.K)
    sel = np.flatnonzero(segments.is_vertical)
    lows, highs, depress = [], [], []
    for k in sel:
        ends = segments.endpoints_px[k]
        rays = np.hstack([ends, np.ones((2, 1))]) @ Kinv.T
        rays /= np.linalg.norm(rays, axis=1, keepdims=True)
        lo = int(np.argmin(rays @ up))
        lows.append(ends[lo])
        highs.append(ends[1 - lo])
        depress.append(-float(rays[lo] @ up))
    # Depth of each lower end if it stood on the ground (only its scale matters: the tolerance in pixels).
    tol = [
        max(line_tol_px, 2.0 * intrinsics.fx * occluder_halfwidth_m * max(dp, 1e-6) / camera_height_m) for dp in depress
    ]
    bases, dirs = [], []
    for i in range(len(lows)):
        if depress[i] < np.sin(np.deg2rad(min_depression_deg)):
            continue
        covered = False
        for j in range(len(lows)):
            if j == i or depress[j] <= depress[i]:
                continue
            d = highs[j] - lows[j]
            L = max(float(np.linalg.norm(d)), EPS)
            rel = lows[i] - lows[j]
            # distance of base i from the (infinite) image line of segment j, and i above j's lower end
            if abs(rel[0] * d[1] - rel[1] * d[0]) / L < tol[j] and float(rel @ d) / L > -line_tol_px:
                covered = True
                break
        if covered:
            continue
        d = highs[i] - lows[i]
        bases.append(lows[i])
        dirs.append(d / max(float(np.linalg.norm(d)), EPS))
    if not bases:
        return np.zeros((0, 2)), np.zeros((0, 2))
    return np.array(bases), np.array(dirs)


def ground_darkness(
    image_rgb_uint8: np.ndarray, window_px: int = 31, lit_ratio: float = 0.8, dark_ratio: float = 0.4
) -> np.ndarray:
    """(H, W) in [0, 1]: how much darker each pixel is than its neighbourhood (median of a ``window_px`` box).

    A cast shadow lowers linear luminance by the factor 1 / (1 + sun/sky ratio), typically 0.15-0.4 on a clear day;
    0 at or above ``lit_ratio`` x the local median, 1 at or below ``dark_ratio`` x it, log-linear in between.
    """
    import cv2

    img = np.asarray(image_rgb_uint8)
    gray = cv2.cvtColor(img, cv2.COLOR_RGB2GRAY)
    k = int(window_px) | 1
    med = cv2.medianBlur(gray, k) if k <= 255 else cv2.medianBlur(gray, 255)
    y = srgb_to_linear(gray).astype(np.float64)
    ym = srgb_to_linear(med).astype(np.float64)
    r = np.log(np.maximum(y, 1e-4) / np.maximum(ym, 1e-4))  # eps: black pixels in black surroundings give r = 0
    return np.clip((np.log(lit_ratio) - r) / np.log(lit_ratio / dark_ratio), 0.0, 1.0)


def _horizontal_frame(up_in_cam: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(right, forward): horizontal unit vectors of the gravity-aligned camera frame (as ``ratio.ground_coordinates``);
    ground azimuths in this module are ``atan2(. forward, . right)``."""
    up = np.asarray(up_in_cam, dtype=np.float64)
    hint = np.array([0.0, 0.0, 1.0]) if abs(up[2]) < 0.99 else np.array([0.0, 1.0, 0.0])
    fwd = hint - (hint @ up) * up
    fwd /= np.linalg.norm(fwd)
    return np.cross(fwd, up), fwd


def grid_ground_azimuths(grid_in_cam: np.ndarray, up_in_cam: np.ndarray) -> np.ndarray:
    """Ground azimuth (rad, ``atan2(forward, right)``) of each candidate's horizontal part, (N, 3) -> (N,)."""
    up = np.asarray(up_in_cam, dtype=np.float64) / max(float(np.linalg.norm(up_in_cam)), EPS)
    right, fwd = _horizontal_frame(up)
    g = np.asarray(grid_in_cam, dtype=np.float64)
    return np.arctan2(g @ fwd, g @ right)


def _circular_nanmax(x: np.ndarray, half_width: int) -> np.ndarray:
    """Max over a circular window of +-half_width along the last axis, ignoring NaN (all-NaN windows stay NaN)."""
    out = np.full_like(x, np.nan)
    for k in range(-half_width, half_width + 1):
        out = np.fmax(out, np.roll(x, k, axis=-1))
    return out


def shadow_end_scores(
    darkness: np.ndarray,
    bases_px: np.ndarray,
    base_up_dirs_px: np.ndarray,
    intrinsics: Intrinsics,
    up_in_cam: np.ndarray,
    camera_height_m: float = CAMERA_HEIGHT_PRIOR_M,
    reach_m: tuple[float, float] = (0.4, 5.0),
    n_steps: int = 16,
    n_azimuths: int = 180,
    tolerance_deg: float = 6.0,
    occluder_halfwidth_m: float = 0.3,
    min_halfwidth_px: float = 3.0,
    min_valid: int = 3,
    contiguous: bool = True,
) -> tuple[np.ndarray, np.ndarray]:
    """Per base and sun azimuth: darkness on the ground away from the sun minus toward it, (B, A) in [-1, 1] with NaN
    where either side is unreadable; and the A sun azimuths (rad, ``atan2(forward, right)``, uniform in [-pi, pi)).

    From each base's ground point g (its ray meets the plane ``camera_height_m`` below the camera; the height only
    scales distances), ``n_steps`` points ``g + t u(alpha)``, t in ``reach_m``, are projected into the image for every
    ground direction alpha and their mean ``darkness`` is D(alpha). A thin shadow is only hit by rays within a few
    degrees of its direction, so D is max-filtered over +-``tolerance_deg`` (the sun's azimuth is then found to that
    precision). Score(sun azimuth a) = D(a + pi) - D(a): the shadow lies away from the sun. A sample is unreadable
    outside the image, at or above the horizon, or on the occluder itself: above the base and within
    ``occluder_halfwidth_m`` (projected at the base's depth, at least ``min_halfwidth_px``) of the line from the base
    along ``base_up_dirs_px``, where the upright object (poles and trunks are < 0.6 m wide), not the ground, is seen;
    the reach starts at ``reach_m[0]`` beyond the occluder's own footprint. A direction with fewer than ``min_valid``
    readable samples has no D.
    """
    H, W = darkness.shape
    up = np.asarray(up_in_cam, dtype=np.float64) / max(float(np.linalg.norm(up_in_cam)), EPS)
    right, fwd = _horizontal_frame(up)
    alphas = -np.pi + 2.0 * np.pi * np.arange(n_azimuths) / n_azimuths
    dirs = np.cos(alphas)[:, None] * right + np.sin(alphas)[:, None] * fwd  # (A, 3)
    B = len(bases_px)
    scores = np.full((B, n_azimuths), np.nan)
    if B == 0:
        return scores, alphas
    K = intrinsics.K
    Kinv = np.linalg.inv(K)
    t = np.linspace(reach_m[0], reach_m[1], n_steps)
    half = max(0, int(round(tolerance_deg / (360.0 / n_azimuths))))
    for b in range(B):
        ray = Kinv @ np.array([*bases_px[b], 1.0])
        down = -float(ray @ up)
        if down <= 1e-6:
            continue
        g = ray * camera_height_m / down  # on the ground plane
        halfwidth_px = max(min_halfwidth_px, K[0, 0] * occluder_halfwidth_m / max(float(g[2]), 1e-3))
        pts = g[None, None, :] + t[None, :, None] * dirs[:, None, :]  # (A, T, 3)
        z = pts[..., 2]
        zs = np.where(z > 1e-3, z, 1.0)
        uv = np.stack([K[0, 0] * pts[..., 0] / zs + K[0, 2], K[1, 1] * pts[..., 1] / zs + K[1, 2]], axis=-1)
        dv = uv - bases_px[b]
        ud = base_up_dirs_px[b]
        along = dv @ ud
        perp = np.abs(dv[..., 0] * ud[1] - dv[..., 1] * ud[0])
        ok = (z > 1e-3) & (uv[..., 0] >= 0) & (uv[..., 0] <= W - 1) & (uv[..., 1] >= 0) & (uv[..., 1] <= H - 1)
        ok &= ~((along > -1.0) & (perp < halfwidth_px))
        ui = np.clip(np.round(uv[..., 0]).astype(int), 0, W - 1)
        vi = np.clip(np.round(uv[..., 1]).astype(int), 0, H - 1)
        cnt = ok.sum(axis=1)
        dk = darkness[vi, ui]
        if contiguous:
            # The shadow must start at the base and continue: darkness counts only up to where the ground first turns
            # lit (running minimum along the ray over readable samples; unreadable ones neither break nor extend it).
            dk = np.minimum.accumulate(np.where(ok, dk, 1.0), axis=1)
        D = np.where(cnt >= min_valid, np.where(ok, dk, 0.0).sum(axis=1) / np.maximum(cnt, 1), np.nan)
        D = _circular_nanmax(D, half)
        scores[b] = np.roll(D, -n_azimuths // 2) - D  # D(a + pi) - D(a)
    return scores, alphas


def shadow_end_loglik(
    scores: np.ndarray,
    alphas: np.ndarray,
    grid_in_cam: np.ndarray,
    up_in_cam: np.ndarray,
    kappa: float = 20.0,
    min_bases: int = 3,
) -> tuple[np.ndarray, float]:
    """Log-likelihood (N,) of grid candidates from :func:`shadow_end_scores` and a confidence in [0, 1].

    Per sun azimuth a: the mean score over the bases readable there, shrunk toward 0 when few are (x n / (n +
    ``min_bases``)), times the bases' consistency ``|2 q(a) - 1|`` (q: fraction of readable bases whose score is
    positive; bases that split evenly carry no side information, as in clutter where dark objects, not shadows, sit
    next to many "bases"). ``loglik = kappa x that`` at each candidate's nearest azimuth (the same scale as the
    cast-shadow axis term ``kappa x strength x cos 2 dphi`` of ``estimate``). Antisymmetric under a -> a + pi by
    construction (q -> 1 - q). Confidence: the best candidate's value (0: no end stands out, 1: every base has fully
    dark ground on the same side only).
    """
    s = np.asarray(scores, dtype=np.float64)
    N = len(grid_in_cam)
    if s.size == 0:
        return np.zeros(N), 0.0
    v = np.isfinite(s)
    n = v.sum(axis=0).astype(np.float64)
    sz = np.where(v, s, 0.0)
    mean = np.where(n > 0, sz.sum(axis=0) / np.maximum(n, 1.0), 0.0)
    q = np.where(n > 0, (sz > 0).sum(axis=0) / np.maximum(n, 1.0), 0.5)
    evidence = mean * n / (n + float(min_bases)) * np.abs(2.0 * q - 1.0)
    conf = float(np.clip(evidence.max(), 0.0, 1.0))
    a = grid_ground_azimuths(grid_in_cam, up_in_cam)
    A = len(alphas)
    idx = np.round((a + np.pi) / (2.0 * np.pi) * A).astype(int) % A
    return kappa * evidence[idx], conf


@dataclass(frozen=True)
class SunSideCue:
    """Side-of-the-sun evidence of one frame on a grid of candidates.

    log_likelihood: (N,) sum of the two cues; facade_loglik, shadow_end_loglik: (N,) each; facade_r2: R^2 of the
    vertical-surface fit at its best candidate; n_facade_samples; shadow_end_confidence in [0, 1]; n_bases: candidate
    occluder bases found; confidence in [0, 1]: how decisively the two cues (combined) prefer one azimuth half-plane.
    """

    log_likelihood: np.ndarray
    facade_loglik: np.ndarray
    shadow_end_loglik: np.ndarray
    facade_r2: float
    n_facade_samples: int
    facade_orientation_spread: float
    shadow_end_confidence: float
    n_bases: int
    confidence: float


def _orientation_spread(samples: FacadeSamples) -> float:
    """1 - |weighted mean of the unit normals|: 0 when all facades face one way (no comparison possible)."""
    if len(samples.weights) < 2:
        return 0.0
    w = samples.weights / max(float(samples.weights.sum()), EPS)
    return float(np.clip(1.0 - np.linalg.norm(w @ samples.normals_in_cam), 0.0, 1.0))


def sun_side_cue(
    image_rgb_uint8: np.ndarray,
    intrinsics: Intrinsics,
    up_in_cam: np.ndarray,
    grid_in_cam: np.ndarray,
    sky_mask: np.ndarray | None = None,
    camera_height_m: float = CAMERA_HEIGHT_PRIOR_M,
    analysis_width: int = 800,
    facade_albedo_sigma: float = 0.7,
    shadow_end_kappa: float = 20.0,
) -> SunSideCue:
    """Both side cues on one frame (resampled to at most ``analysis_width`` pixels wide so that pixel tolerances mean
    the same at any input size). ``sky_mask`` (H, W) bool at the input size, excluded from facade samples."""
    import cv2

    img = np.asarray(image_rgb_uint8)
    if img.ndim != 3 or img.shape[2] != 3 or img.dtype != np.uint8:
        raise ValueError(f"sun_side_cue: expected (H, W, 3) uint8, got {img.shape} {img.dtype}")
    if (intrinsics.height, intrinsics.width) != img.shape[:2]:
        raise ValueError("sun_side_cue: intrinsics do not match the image size")
    up = np.asarray(up_in_cam, dtype=np.float64)
    up = up / max(float(np.linalg.norm(up)), EPS)
    K = intrinsics
    if img.shape[1] > analysis_width:
        s = analysis_width / img.shape[1]
        K = intrinsics.scaled(s)
        img = cv2.resize(img, (K.width, K.height), interpolation=cv2.INTER_AREA)
        if sky_mask is not None:
            sky_mask = cv2.resize(
                np.asarray(sky_mask, np.uint8), (K.width, K.height), interpolation=cv2.INTER_NEAREST
            ).astype(bool)
    min_len = max(10.0, 0.025 * img.shape[1])  # LSD also returns texture fragments; keep structural lines
    segs = classify_segments(detect_line_segments(img, min_len), K, up)
    if sky_mask is None:
        sky_mask = default_sky_mask(img, K, up)
    lin = srgb_to_linear(img)
    fs = facade_clusters(facade_samples(lin, K, up, segs, exclude_mask=sky_mask), up)
    spread = _orientation_spread(fs)
    ll_f, r2 = vertical_surface_loglik(fs, grid_in_cam, up, facade_albedo_sigma)
    bases, dirs = occluder_bases(segs, K, up, camera_height_m=camera_height_m)
    dark = ground_darkness(img)
    scores, alphas = shadow_end_scores(dark, bases, dirs, K, up, camera_height_m)
    ll_e, conf_e = shadow_end_loglik(scores, alphas, grid_in_cam, up, shadow_end_kappa)
    ll = ll_f + ll_e
    # Side decisiveness: posterior mass on the better azimuth half-plane (0.5 -> 0, 1 -> 1).
    grid_h = _horizontal_units(grid_in_cam, up)
    p = np.exp(ll - ll.max())
    p /= p.sum()
    best_h = grid_h[int(np.argmax(ll))]
    half = float(p[(grid_h @ best_h) > 0].sum())
    confidence = float(np.clip(2.0 * half - 1.0, 0.0, 1.0))
    return SunSideCue(ll, ll_f, ll_e, r2, len(fs.weights), spread, conf_e, len(bases), confidence)


def default_sky_mask(image_rgb_uint8: np.ndarray, intrinsics: Intrinsics, up_in_cam: np.ndarray) -> np.ndarray:
    """Bright, smooth, bluish or very bright pixels above the horizon: sky (the same test as ``sun``'s sky cue,
    without the smoothness of clouds requirement): (H, W) bool."""
    from scipy import ndimage

    img = np.asarray(image_rgb_uint8)
    unit = img.astype(np.float32) / 255.0
    lin = srgb_to_linear(img if img.dtype == np.uint8 else unit)  # uint8: the same values by table
    rays = camera_ray_directions(intrinsics)
    above = rays @ (np.asarray(up_in_cam) / max(float(np.linalg.norm(up_in_cam)), EPS)) > 0.0
    Y = np.maximum(luminance(lin), 1e-4)
    logY = np.log(Y)
    mean = ndimage.uniform_filter(logY, 5)
    sq = ndimage.uniform_filter(logY * logY, 5)
    local_std = np.sqrt(np.clip(sq - mean * mean, 0.0, None))
    ref = np.percentile(Y[above], 95) if above.any() else 1.0
    bluish = lin[..., 2] >= 1.05 * lin[..., 0]
    # Clipped pixels are not sky: a sunlit white facade clips, an exposed sky (away from the sun) does not.
    return above & (local_std < 0.08) & (Y > 0.15 * ref) & (max_channel(unit) < 0.98) & (bluish | (Y > 0.5 * ref))

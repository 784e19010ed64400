"""Placeable region: pixels where an object may stand.

Evidence, strongest first:
1. ``semantic`` label map with configurable placeable classes (e.g. road, sidewalk, parking): mask = label in set.
2. ``depth`` (dense stereo/RGB-D or sparse LiDAR): the pixel's 3D point lies on the ground plane within a
   tolerance that grows with depth (stereo noise ~ z^2); pixels near points that stand above the ground are
   excluded. Sparse depth is spread to neighbouring pixels (``sparse_radius_px``).
3. ``multi_frame``: a second image and the relative pose; pixels that the ground-plane homography maps onto
   matching pixels of the other frame lie on the plane (photometric consistency, for video without depth).
4. ``image`` (a single image, nothing measured): the road surface seen in the image (:func:`image_ground_region`):
   the dominant road-coloured surface of a seed zone between the (estimated) horizon and the bottom of the image,
   grown over pixels of the same colour and at most its texture (edges are texture: they cut it), kept only where
   connected to the seed, its border eroded, ground farther than ``image_max_distance_m`` left out. Parked cars,
   walls, poles and vegetation differ from the road in colour, brightness or texture and are left out; so are cast
   shadows (lost recall, not precision). Evidence "image:road_appearance"; ``PlaceableRegion.excluded`` says how
   much of the below-horizon area each step removed.
5. Prior only: every pixel below the horizon (evidence "prior:below_horizon"), also when the image region is
   smaller than ``image_min_fraction`` of the image (a texture-only or synthetic image: the record says so).
All are intersected with "below the horizon by ``horizon_margin_px``".

Measured on KITTI 06 (stereo) and DGP (LiDAR) frames: ``studies/placement/image_only/result/image_only.md``.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import cv2
import numpy as np

from aias_augment.analyse.ground import GroundPlane, depth_to_points
from aias_augment.core.config import checked_config
from aias_augment.core.geometry import Intrinsics, check_rigid

__all__ = [
    "RegionConfig",
    "PlaceableRegion",
    "placeable_region",
    "below_horizon_mask",
    "plane_homography",
    "multi_frame_plane_consistency",
    "image_ground_region",
]


@checked_config(
    {  # every field checked at construction (type hint and these bounds)
        "semantic_classes": "[0, inf)",
        "ground_tolerance_m": "[0, inf)",
        "ground_tolerance_rel": "[0, inf)",
        "obstacle_height_m": "(0, inf)",
        "horizon_margin_px": "[0, inf)",
        "sparse_radius_px": "[0, inf)",
        "sparse_fraction": "[0, 1]",
        "photometric_tolerance": "[0, inf)",
        "max_depth_m": "(0, inf]",
        "image_width_px": "[16, inf)",
        "image_seed_rows": "[0, 1] lo<hi",
        "image_seed_cols": "[0, 1] lo<hi",
        "image_luma_tol": "[0, inf)",
        "image_chroma_tol": "[0, inf)",
        "image_texture_tol": "[0, inf)",
        "image_texture_floor": "[0, inf)",
        "image_open_px": "[0, inf)",
        "image_erode_px": "[0, inf)",
        "image_min_fraction": "[0, 1]",
        "image_road_luma": "[0, 255] lo<=hi",
        "image_road_chroma": "[0, inf)",
        "image_max_distance_m": "(0, inf]",
    }
)
@dataclass(frozen=True)
class RegionConfig:
    semantic_classes: tuple[int, ...] = ()  # placeable label ids; empty = ignore the semantic map
    ground_tolerance_m: float = 0.10  # |signed distance| allowed at 0 m ...
    ground_tolerance_rel: float = 0.01  # ... plus this fraction of the depth (stereo noise grows with z)
    obstacle_height_m: float = 0.25  # a point this far above the plane is an obstacle
    horizon_margin_px: float = 5.0
    sparse_radius_px: int = 12  # spread of sparse (LiDAR) evidence; dense depth uses 0
    sparse_fraction: float = 0.2  # depth with fewer valid pixels than this is treated as sparse
    photometric_tolerance: float = 12.0  # grey levels, for multi-frame consistency
    max_depth_m: float = 60.0
    # Single image (``image_ground_region``). Tolerances are in 8-bit CIELAB units (OpenCV), at the analysis width.
    # Chosen on KITTI 06 (grey) and checked on DGP (colour): studies/placement/image_only/result/image_only.md.
    image_region: bool = True  # False: a single image gets the below-horizon prior only
    image_width_px: int = 640  # the image is analysed at most this wide
    image_seed_rows: tuple[float, float] = (0.35, 0.9)  # seed zone: fraction of the rows horizon -> bottom ...
    image_seed_cols: tuple[float, float] = (0.25, 0.75)  # ... and of the columns
    image_luma_tol: float = 25.0  # |L - L_road|
    image_chroma_tol: float = 8.0  # |a - a_road|, |b - b_road|
    image_texture_tol: float = 2.0  # local gradient <= this x the road's (+ image_texture_floor)
    image_texture_floor: float = 2.0
    image_open_px: int = 3  # opening radius: thin bridges (a shadow into a car) are cut
    image_erode_px: int = 4  # border erosion: contacts keep off the region's edge
    image_min_fraction: float = 0.01  # smaller image region -> the below-horizon prior
    image_road_luma: tuple[float, float] = (60.0, 215.0)  # L range of road-like seed colours ...
    image_road_chroma: float = 15.0  # ... and their largest chroma |(a, b) - grey|
    image_max_distance_m: float = 40.0  # farther ground (on the estimated plane) is left out


#: Evidence of a region measured in the scene (or given by the user): its mask is the ground that is there.
MEASURED_EVIDENCE = ("semantic", "depth", "multi_frame", "given")
#: Evidence of a region inferred: the image's road appearance, or every pixel below the horizon.
INFERRED_EVIDENCE = ("image:road_appearance", "prior:below_horizon")


@dataclass(frozen=True, eq=False)
class PlaceableRegion:
    mask: np.ndarray  # (H, W) bool
    evidence: str  # one of MEASURED_EVIDENCE or INFERRED_EVIDENCE
    fraction: float  # of the image
    # Image evidence: fraction of the below-horizon pixels each step excluded (why a pixel is not placeable).
    excluded: dict = field(default_factory=dict)
    # (N, 4) x1, y1, x2, y2: long straight edges off the ground (poles, rails) that may stand in front of a site
    # (analyse/thin_structures.py); empty when not looked for.
    thin_segments: np.ndarray = field(default_factory=lambda: np.zeros((0, 4), np.float32))

    @property
    def measured(self) -> bool:
        """The mask is ground measured in the scene (or given), not inferred from appearance or the horizon."""
        return self.evidence in MEASURED_EVIDENCE

    def __post_init__(self):
        if self.evidence not in MEASURED_EVIDENCE + INFERRED_EVIDENCE:
            raise ValueError(f"unknown region evidence {self.evidence!r}")
        # The region's own read-only copy: it cannot change after the analysis (placement memoises by identity).
        m = np.array(self.mask, dtype=bool, copy=True)
        m.setflags(write=False)
        object.__setattr__(self, "mask", m)
        s = np.array(self.thin_segments, dtype=np.float32, copy=True).reshape(-1, 4)
        s.setflags(write=False)
        object.__setattr__(self, "thin_segments", s)

    def to_dict(self) -> dict:
        d = {"evidence": self.evidence, "fraction": self.fraction}
        if self.excluded:
            d["excluded"] = dict(self.excluded)
        if len(self.thin_segments):
            d["thin_segments"] = [[float(v) for v in row] for row in self.thin_segments]
        return d


def below_horizon_mask(ground: GroundPlane, intrinsics: Intrinsics, margin_px: float = 0.0) -> np.ndarray:
    """(H, W) bool: pixels whose rays hit the ground in front (margin_px below the horizon line)."""
    try:
        a, b, c = ground.horizon_line(intrinsics)
    except ValueError:  # plane parallel to the image plane: either all or nothing is ground
        return np.full((intrinsics.height, intrinsics.width), ground.normal[2] < 0)
    uu = np.arange(intrinsics.width)[None, :]  # broadcast, not two full grids: the same sums, element by element
    vv = np.arange(intrinsics.height)[:, None]
    return a * uu + b * vv + c > margin_px


def _disk(radius: int) -> np.ndarray:
    return cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * radius + 1, 2 * radius + 1))


def placeable_region(
    intrinsics: Intrinsics,
    ground: GroundPlane,
    *,
    depth: np.ndarray | None = None,
    semantic: np.ndarray | None = None,
    image: np.ndarray | None = None,
    cfg: RegionConfig = RegionConfig(),
) -> PlaceableRegion:
    """Mask of pixels where an object's contact point may be (see module doc for the evidence order). ``image``
    (H, W, 3) uint8 RGB: used only when nothing is measured (no depth, no semantic classes)."""
    h, w = intrinsics.height, intrinsics.width
    below = below_horizon_mask(ground, intrinsics, cfg.horizon_margin_px)
    if semantic is not None and cfg.semantic_classes:
        sem = np.asarray(semantic)
        if sem.shape != (h, w):
            raise ValueError(f"semantic map {sem.shape} does not match image {(h, w)}")
        mask = np.isin(sem, np.asarray(cfg.semantic_classes)) & below
        return PlaceableRegion(mask, "semantic", float(mask.mean()))
    if depth is not None:
        points, rc = depth_to_points(depth, intrinsics, max_depth_m=cfg.max_depth_m)
        if len(points):
            dist = ground.signed_distance(points)
            tol = cfg.ground_tolerance_m + cfg.ground_tolerance_rel * points[:, 2]
            on_ground = np.zeros((h, w), np.uint8)
            obstacle = np.zeros((h, w), np.uint8)
            g = np.abs(dist) < tol
            o = dist > np.maximum(cfg.obstacle_height_m, tol)
            on_ground[rc[g, 0], rc[g, 1]] = 1
            obstacle[rc[o, 0], rc[o, 1]] = 1
            if len(points) < cfg.sparse_fraction * h * w and cfg.sparse_radius_px > 0:
                on_ground = cv2.dilate(on_ground, _disk(cfg.sparse_radius_px))
                obstacle = cv2.dilate(obstacle, _disk(max(1, cfg.sparse_radius_px // 2)))
            mask = on_ground.astype(bool) & ~obstacle.astype(bool) & below
            return PlaceableRegion(mask, "depth", float(mask.mean()))
    if image is not None and cfg.image_region:
        region = image_ground_region(image, ground, intrinsics, cfg, below=below)
        if region.fraction >= cfg.image_min_fraction:
            return region
        return PlaceableRegion(
            below,
            "prior:below_horizon",
            float(below.mean()),
            {"image region too small": region.fraction, **region.excluded},
        )
    return PlaceableRegion(below, "prior:below_horizon", float(below.mean()))


def _unique_bins(key: np.ndarray, n_keys: int) -> tuple[np.ndarray, np.ndarray]:
    """``np.unique(key, return_inverse=True, return_counts=True)[1:]`` for integer keys in [0, n_keys): counted
    with ``np.bincount`` when there are few possible keys (no sort), else ``np.unique``."""
    if n_keys <= max(1 << 20, 4 * key.size):  # the default tolerances give <= 11 x 33 x 33 colour bins
        per_key = np.bincount(key)
        present = np.flatnonzero(per_key)  # the keys np.unique lists, in its (ascending) order
        rank = np.zeros(per_key.size, np.intp)
        rank[present] = np.arange(present.size)
        return rank[key], per_key[present]
    _, inverse, counts = np.unique(key, return_inverse=True, return_counts=True)
    return inverse.reshape(-1), counts


def _road_mode(feat, cfg: RegionConfig) -> tuple[np.ndarray, np.ndarray]:
    """(road feature [L, a, b, gradient], inliers) of the seed zone's features, four planes (N,) (float32): the
    peak of the (L, a, b) histogram of the zone, each bin weighted by how road-like its colour is (asphalt,
    concrete: grey, neither black nor white; dark bins are mostly shadows, tyres and dark car bodies, saturated
    ones car paint), then refined by medians over the pixels within the tolerances (per plane: the medians over
    axis 0 of the (N, 4) features)."""
    tol = (cfg.image_luma_tol, cfg.image_chroma_tol, cfg.image_chroma_tol)
    q = [np.floor(f / np.float64(t)).astype(np.int64) for f, t in zip(feat[:3], tol)]  # in float64, as (N, 3) / tol
    # Unique (L, a, b) bins via one integer per bin: sorted like np.unique(q, axis=0) (lexicographic), ~10x faster.
    q = [qj - qj.min() for qj in q]
    m = int(max(qj.max() for qj in q)) + 1
    inverse, counts = _unique_bins((q[0] * m + q[1]) * m + q[2], m**3)
    centre = np.stack([np.bincount(inverse, feat[j]) / counts for j in range(3)], axis=1)
    chroma = np.hypot(centre[:, 1] - 128.0, centre[:, 2] - 128.0)
    lo, hi = cfg.image_road_luma
    prior = np.where((centre[:, 0] >= lo) & (centre[:, 0] <= hi) & (chroma <= cfg.image_road_chroma), 1.0, 0.25)

    def medians(sel: np.ndarray) -> np.ndarray:
        return np.array([np.median(f[sel]) for f in feat])

    mode = medians(inverse == np.argmax(counts * prior))
    for _ in range(3):
        ok = _similar(feat, mode, cfg)
        if not ok.any():
            break
        mode = medians(ok)
    return mode, _similar(feat, mode, cfg)


def _similar(f, road: np.ndarray, cfg: RegionConfig) -> np.ndarray:
    """Pixels of the road's colour and at most its texture, from the four feature planes [L, a, b, gradient]."""
    return (
        (np.abs(f[0] - road[0]) <= cfg.image_luma_tol)
        & (np.abs(f[1] - road[1]) <= cfg.image_chroma_tol)
        & (np.abs(f[2] - road[2]) <= cfg.image_chroma_tol)
        & (f[3] <= cfg.image_texture_tol * road[3] + cfg.image_texture_floor)
    )


def image_ground_region(
    image: np.ndarray,
    ground: GroundPlane,
    intrinsics: Intrinsics,
    cfg: RegionConfig = RegionConfig(),
    *,
    below: np.ndarray | None = None,
) -> PlaceableRegion:
    """Road surface from the image alone (see the module doc, evidence 4), below the horizon of ``ground``.
    ``below``: ``below_horizon_mask(ground, intrinsics, cfg.horizon_margin_px)`` when the caller has it."""
    h, w = intrinsics.height, intrinsics.width
    img = np.asarray(image)
    if img.shape[:2] != (h, w) or img.ndim != 3 or img.shape[2] != 3:
        raise ValueError(f"image {img.shape} does not match the camera {(h, w)} (need H x W x 3)")
    if below is None:
        below = below_horizon_mask(ground, intrinsics, cfg.horizon_margin_px)
    scale = min(1.0, cfg.image_width_px / w)
    sw, sh = max(1, round(w * scale)), max(1, round(h * scale))
    small = cv2.resize(np.ascontiguousarray(img, np.uint8), (sw, sh), interpolation=cv2.INTER_AREA)
    below_s = cv2.resize(below.astype(np.uint8), (sw, sh), interpolation=cv2.INTER_NEAREST).astype(bool)
    lab = cv2.GaussianBlur(cv2.cvtColor(small, cv2.COLOR_RGB2LAB).astype(np.float32), (0, 0), 1.5)
    gx = cv2.Sobel(lab[..., 0], cv2.CV_32F, 1, 0, ksize=3) / 8.0
    gy = cv2.Sobel(lab[..., 0], cv2.CV_32F, 0, 1, ksize=3) / 8.0
    grad = np.sqrt(gx * gx + gy * gy)
    texture = cv2.blur(grad, (7, 7))
    planes = (lab[..., 0], lab[..., 1], lab[..., 2], texture)  # the features [L, a, b, gradient], as planes
    # seed zone: rows between the horizon (at each column) and the bottom, central columns
    top = np.argmax(below_s, axis=0)  # first row below the horizon per column (0 when none)
    has = below_s.any(axis=0)
    rows = np.arange(sh)[:, None]
    span = np.where(has, sh - top, 0)[None, :]
    rel = (rows - top[None, :]) / np.maximum(span, 1)
    cols = np.arange(sw)[None, :] / max(sw - 1, 1)
    zone = (
        below_s
        & (rel >= cfg.image_seed_rows[0])
        & (rel <= cfg.image_seed_rows[1])
        & (cols >= cfg.image_seed_cols[0])
        & (cols <= cfg.image_seed_cols[1])
    )
    empty = PlaceableRegion(np.zeros((h, w), bool), "image:road_appearance", 0.0, {"no seed zone": 1.0})
    if zone.sum() < 50:
        return empty
    road, zone_ok = _road_mode([f[zone] for f in planes], cfg)
    like_road = _similar(planes, road, cfg)
    similar = like_road & below_s
    opened = cv2.morphologyEx(similar.astype(np.uint8), cv2.MORPH_OPEN, _disk(cfg.image_open_px))
    n, comp = cv2.connectedComponents(opened, connectivity=4)
    seeds = np.zeros(sh * sw, bool)
    seeds[np.flatnonzero(zone)[zone_ok]] = True
    seed_comp = comp.reshape(-1)[seeds & (opened.reshape(-1) > 0)]
    if len(seed_comp) == 0:
        return empty
    ids, counts = np.unique(seed_comp, return_counts=True)
    keep = ids[counts >= 0.1 * counts.max()]  # components holding a good part of the road seed
    connected = np.isin(comp, keep)
    closed = cv2.morphologyEx(connected.astype(np.uint8), cv2.MORPH_CLOSE, _disk(2))
    eroded = cv2.erode(closed, _disk(cfg.image_erode_px)) if cfg.image_erode_px > 0 else closed
    # vanishing geometry: near the horizon a pixel spans metres of road and the horizon estimate's error of a few
    # pixels moves the contact by tens of metres; the far end of the road is also where cars and walls close it
    # (distances only where the eroded road is: nowhere else is "far" read)
    er = eroded.astype(bool)
    vs, us = np.nonzero(er)
    uv = np.stack([(us + 0.5) / scale - 0.5, (vs + 0.5) / scale - 0.5], axis=-1).astype(np.float64)
    p = ground.intersect_pixels(uv, intrinsics) if len(uv) else np.zeros((0, 3))
    dist = np.sqrt((p[:, 0] * p[:, 0] + p[:, 1] * p[:, 1]) + p[:, 2] * p[:, 2])  # np.linalg.norm(p, axis=1), 3x faster
    far = np.zeros((sh, sw), bool)
    far[vs, us] = ~(np.isfinite(dist) & (dist <= cfg.image_max_distance_m))
    kept = er & ~far
    mask = cv2.resize(kept.astype(np.uint8), (w, h), interpolation=cv2.INTER_NEAREST).astype(bool) & below

    # why a below-horizon pixel is not placeable (each step's loss, as fractions of the below-horizon pixels)
    def frac(m):
        return round(float(m.sum()) / max(int(below_s.sum()), 1), 4)

    excluded = {
        "colour or texture unlike the road": frac(below_s & ~like_road),
        "thin or not connected to the road seed": frac(similar & ~connected),
        "eroded border": frac(closed.astype(bool) & ~er & below_s),
        "farther than image_max_distance_m": frac(er & far & below_s),
    }
    return PlaceableRegion(mask, "image:road_appearance", float(mask.mean()), excluded)


def plane_homography(ground_in_cam1: GroundPlane, cam2_from_cam1: np.ndarray, intrinsics: Intrinsics) -> np.ndarray:
    """H with x2 ~ H x1 for pixels of points on the plane: K (R - t n^T / d) K^-1 (n . X + d = 0 in cam1)."""
    T = check_rigid(cam2_from_cam1, "cam2_from_cam1")
    if abs(ground_in_cam1.d) < 1e-9:
        raise ValueError("plane passes through camera 1: its homography is degenerate")
    K = intrinsics.K
    # On the plane n.X = -d, so -n.X / d = 1 and X2 = R X1 + t (-n.X1 / d).
    H = K @ (T[:3, :3] - np.outer(T[:3, 3], ground_in_cam1.normal) / ground_in_cam1.d) @ np.linalg.inv(K)
    return H / H[2, 2]


def multi_frame_plane_consistency(
    image1: np.ndarray,
    image2: np.ndarray,
    ground_in_cam1: GroundPlane,
    cam2_from_cam1: np.ndarray,
    intrinsics: Intrinsics,
    cfg: RegionConfig = RegionConfig(),
) -> PlaceableRegion:
    """Pixels of frame 1 below the horizon whose plane-induced warp into frame 2 agrees photometrically."""

    def grey(x):
        x = np.asarray(x)
        return cv2.cvtColor(x, cv2.COLOR_RGB2GRAY) if x.ndim == 3 else x

    g1 = cv2.GaussianBlur(grey(image1).astype(np.float32), (5, 5), 1.0)
    g2 = cv2.GaussianBlur(grey(image2).astype(np.float32), (5, 5), 1.0)
    H = plane_homography(ground_in_cam1, cam2_from_cam1, intrinsics)
    # warpPerspective with WARP_INVERSE_MAP samples image2 at H x1 for every pixel x1 of frame 1.
    warped = cv2.warpPerspective(
        g2, H, (intrinsics.width, intrinsics.height), flags=cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP, borderValue=-1.0
    )
    inside = (
        cv2.warpPerspective(
            np.ones_like(g2),
            H,
            (intrinsics.width, intrinsics.height),
            flags=cv2.INTER_NEAREST | cv2.WARP_INVERSE_MAP,
            borderValue=0.0,
        )
        > 0.5
    )
    agree = inside & (np.abs(warped - g1) < cfg.photometric_tolerance)
    agree = cv2.morphologyEx(agree.astype(np.uint8), cv2.MORPH_OPEN, _disk(2)).astype(bool)
    mask = agree & below_horizon_mask(ground_in_cam1, intrinsics, cfg.horizon_margin_px)
    return PlaceableRegion(mask, "multi_frame", float(mask.mean()))

"""Placeable region: pixels where an object may stand.

Evidence, strongest first:
1. ``semantic`` label map with configurable placeable classes (e.g. road, sidewalk, parking): mask = label in set.
2. ``depth`` (dense stereo/RGB-D or sparse LiDAR): the pixel's 3D point lies on the ground plane within a
   tolerance that grows with depth (stereo noise ~ z^2); pixels near points that stand above the ground are
   excluded. Sparse depth is spread to neighbouring pixels (``sparse_radius_px``).
3. ``multi_frame``: a second image and the relative pose; pixels that the ground-plane homography maps onto
   matching pixels of the other frame lie on the plane (photometric consistency, for video without depth).
4. Prior only: every pixel below the horizon (evidence "prior:below_horizon").
All are intersected with "below the horizon by ``horizon_margin_px``".
"""
from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from .geometry import Intrinsics, check_rigid
from .ground import GroundPlane, depth_to_points

__all__ = ["RegionConfig", "PlaceableRegion", "placeable_region", "below_horizon_mask", "plane_homography",
           "multi_frame_plane_consistency"]


@dataclass(frozen=True)
class RegionConfig:
    semantic_classes: tuple[int, ...] = ()     # placeable label ids; empty = ignore the semantic map
    ground_tolerance_m: float = 0.10           # |signed distance| allowed at 0 m ...
    ground_tolerance_rel: float = 0.01         # ... plus this fraction of the depth (stereo noise grows with z)
    obstacle_height_m: float = 0.25            # a point this far above the plane is an obstacle
    horizon_margin_px: float = 5.0
    sparse_radius_px: int = 12                 # spread of sparse (LiDAR) evidence; dense depth uses 0
    sparse_fraction: float = 0.2               # depth with fewer valid pixels than this is treated as sparse
    photometric_tolerance: float = 12.0        # grey levels, for multi-frame consistency
    max_depth_m: float = 60.0


@dataclass(frozen=True, eq=False)
class PlaceableRegion:
    mask: np.ndarray      # (H, W) bool
    evidence: str         # "semantic" | "depth" | "multi_frame" | "prior:below_horizon"
    fraction: float       # of the image

    def to_dict(self) -> dict:
        return {"evidence": self.evidence, "fraction": self.fraction}


def below_horizon_mask(ground: GroundPlane, intrinsics: Intrinsics, margin_px: float = 0.0) -> np.ndarray:
    """(H, W) bool: pixels whose rays hit the ground in front (margin_px below the horizon line)."""
    vv, uu = np.mgrid[0:intrinsics.height, 0:intrinsics.width]
    try:
        a, b, c = ground.horizon_line(intrinsics)
    except ValueError:  # plane parallel to the image plane: either all or nothing is ground
        return np.full((intrinsics.height, intrinsics.width), ground.normal[2] < 0)
    return a * uu + b * vv + c > margin_px


def _disk(radius: int) -> np.ndarray:
    return cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * radius + 1, 2 * radius + 1))


def placeable_region(intrinsics: Intrinsics, ground: GroundPlane, *, depth: np.ndarray | None = None,
                     semantic: np.ndarray | None = None, cfg: RegionConfig = RegionConfig()) -> PlaceableRegion:
    """Mask of pixels where an object's contact point may be (see module doc for the evidence order)."""
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
    return PlaceableRegion(below, "prior:below_horizon", float(below.mean()))


def plane_homography(ground_in_cam1: GroundPlane, cam2_from_cam1: np.ndarray, intrinsics: Intrinsics) -> np.ndarray:
    """H with x2 ~ H x1 for pixels of points on the plane: K (R - t n^T / d) K^-1 (n . X + d = 0 in cam1)."""
    T = check_rigid(cam2_from_cam1, "cam2_from_cam1")
    if abs(ground_in_cam1.d) < 1e-9:
        raise ValueError("plane passes through camera 1: its homography is degenerate")
    K = intrinsics.K
    # On the plane n.X = -d, so -n.X / d = 1 and X2 = R X1 + t (-n.X1 / d).
    H = K @ (T[:3, :3] - np.outer(T[:3, 3], ground_in_cam1.normal) / ground_in_cam1.d) @ np.linalg.inv(K)
    return H / H[2, 2]


def multi_frame_plane_consistency(image1: np.ndarray, image2: np.ndarray, ground_in_cam1: GroundPlane,
                                  cam2_from_cam1: np.ndarray, intrinsics: Intrinsics,
                                  cfg: RegionConfig = RegionConfig()) -> PlaceableRegion:
    """Pixels of frame 1 below the horizon whose plane-induced warp into frame 2 agrees photometrically."""
    def grey(x):
        x = np.asarray(x)
        return cv2.cvtColor(x, cv2.COLOR_RGB2GRAY) if x.ndim == 3 else x

    g1 = cv2.GaussianBlur(grey(image1).astype(np.float32), (5, 5), 1.0)
    g2 = cv2.GaussianBlur(grey(image2).astype(np.float32), (5, 5), 1.0)
    H = plane_homography(ground_in_cam1, cam2_from_cam1, intrinsics)
    # warpPerspective with WARP_INVERSE_MAP samples image2 at H x1 for every pixel x1 of frame 1.
    warped = cv2.warpPerspective(g2, H, (intrinsics.width, intrinsics.height),
                                 flags=cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP, borderValue=-1.0)
    inside = cv2.warpPerspective(np.ones_like(g2), H, (intrinsics.width, intrinsics.height),
                                 flags=cv2.INTER_NEAREST | cv2.WARP_INVERSE_MAP, borderValue=0.0) > 0.5
    agree = inside & (np.abs(warped - g1) < cfg.photometric_tolerance)
    agree = cv2.morphologyEx(agree.astype(np.uint8), cv2.MORPH_OPEN, _disk(2)).astype(bool)
    mask = agree & below_horizon_mask(ground_in_cam1, intrinsics, cfg.horizon_margin_px)
    return PlaceableRegion(mask, "multi_frame", float(mask.mean()))

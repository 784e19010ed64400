"""Local features for scene retrieval: RootSIFT keypoints balanced over segmented regions of a frame.

A frame is over-segmented (Felzenszwalb graph segmentation, ``cv2.ximgproc``); SIFT keypoints are detected once and
each region keeps its strongest keypoints up to a quota that grows with the square root of its area, so large
textureless regions (road, sky, walls) still contribute words and a few busy regions cannot take every keypoint.
Descriptors are RootSIFT (Arandjelovic & Zisserman 2012): L1-normalise, then element-wise square root, so that
Euclidean distance compares them like the Hellinger kernel.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

__all__ = ["FeatureConfig", "FrameFeatures", "to_bgr", "segment_regions", "rootsift", "extract_features"]


@dataclass(frozen=True)
class FeatureConfig:
    max_side_px: int = 640  # frames are downscaled to this longest side before anything else
    seg_max_side_px: int = 320  # the segmentation runs at this (coarser) resolution; labels are upsampled
    n_features: int = 1000  # keypoints kept per frame after region balancing
    detect_factor: float = 3.0  # SIFT detects detect_factor * n_features candidates
    contrast_threshold: float = 0.02  # SIFT: lower than OpenCV's 0.04 to find words in low-contrast road/sky
    seg_sigma: float = 0.8  # Felzenszwalb smoothing
    seg_k: float = 400.0  # Felzenszwalb scale: larger -> larger regions
    seg_min_area_frac: float = 0.003  # smallest region, as a fraction of the frame area
    min_per_region: int = 3
    dense_fill: bool = True  # regions the detector leaves short of their quota get dense grid descriptors
    dense_step_px: int = 10  # grid step of the dense samples (pixels of the downscaled frame)
    dense_size_px: float = 16.0  # SIFT support size of a dense sample

    def __post_init__(self):
        if self.max_side_px < 64 or self.n_features < 8 or self.detect_factor < 1:
            raise ValueError(f"FeatureConfig: bad sizes {self}")


@dataclass(frozen=True, eq=False)
class FrameFeatures:
    """Keypoints of one frame. ``xy`` in pixels of the original frame (OpenCV convention, pixel centres integer)."""

    xy: np.ndarray  # (N, 2) float32
    desc: np.ndarray  # (N, 128) float32 RootSIFT
    region: np.ndarray  # (N,) int32 region label of each keypoint
    image_size: tuple[int, int]  # (width, height) of the original frame

    def __len__(self) -> int:
        return len(self.xy)

    def subset(self, keep: np.ndarray) -> "FrameFeatures":
        return FrameFeatures(self.xy[keep], self.desc[keep], self.region[keep], self.image_size)


def to_bgr(image: np.ndarray) -> np.ndarray:
    """uint8 BGR from grey (H, W), (H, W, 1), BGR or BGRA; other dtypes/shapes raise."""
    image = np.asarray(image)
    if image.dtype != np.uint8:
        raise ValueError(f"expected a uint8 image, got {image.dtype}")
    if image.ndim == 2 or (image.ndim == 3 and image.shape[2] == 1):
        return cv2.cvtColor(image.reshape(image.shape[:2]), cv2.COLOR_GRAY2BGR)
    if image.ndim == 3 and image.shape[2] == 3:
        return image
    if image.ndim == 3 and image.shape[2] == 4:
        return cv2.cvtColor(image, cv2.COLOR_BGRA2BGR)
    raise ValueError(f"expected an (H, W), (H, W, 3) or (H, W, 4) image, got shape {image.shape}")


def segment_regions(bgr: np.ndarray, cfg: FeatureConfig = FeatureConfig()) -> np.ndarray:
    """(H, W) int32 region labels (Felzenszwalb graph segmentation)."""
    h, w = bgr.shape[:2]
    seg = cv2.ximgproc.segmentation.createGraphSegmentation(
        sigma=cfg.seg_sigma, k=cfg.seg_k, min_size=max(16, int(cfg.seg_min_area_frac * h * w))
    )
    return seg.processImage(bgr).astype(np.int32)


def rootsift(desc: np.ndarray, eps: float = 1e-7) -> np.ndarray:
    """RootSIFT of (N, 128) SIFT descriptors; eps guards the L1 norm of an all-zero descriptor."""
    d = np.asarray(desc, np.float32)
    d = d / (np.abs(d).sum(axis=1, keepdims=True) + eps)
    return np.sqrt(np.maximum(d, 0.0))


_SIFT: dict = {}


def _sift(n: int, contrast: float):
    key = (n, contrast)
    if key not in _SIFT:
        _SIFT[key] = cv2.SIFT_create(nfeatures=n, contrastThreshold=contrast)
    return _SIFT[key]


def _quotas(area: np.ndarray, cfg: FeatureConfig) -> np.ndarray:
    w = np.sqrt(area.astype(np.float64))
    return np.maximum(cfg.min_per_region, np.floor(cfg.n_features * w / w.sum())).astype(int)


def _dense_fill(
    gray: np.ndarray,
    labels: np.ndarray,
    ids: np.ndarray,
    area: np.ndarray,
    taken: dict,
    cfg: FeatureConfig,
    det_mask: np.ndarray | None,
):
    """Dense upright SIFT samples on a grid inside regions with too few detected keypoints (textureless road,
    walls, sky): their texture still becomes words, which named-word queries ("road") need."""
    quota = _quotas(area, cfg)
    g = cfg.dense_step_px
    h_img, w_img = gray.shape
    m = int(np.ceil(cfg.dense_size_px))
    ys, xs = np.mgrid[m : h_img - m : g, m : w_img - m : g]
    ys, xs = ys.ravel(), xs.ravel()
    if len(xs) == 0:
        return None
    lab = labels[ys, xs]
    ok = np.ones(len(xs), bool) if det_mask is None else det_mask[ys, xs] > 0
    pts, regs = [], []
    for r, q in zip(ids.tolist(), quota.tolist()):
        need = q - taken.get(r, 0)
        if need <= 0:
            continue
        cand = np.nonzero((lab == r) & ok)[0]
        if len(cand) == 0:
            continue
        pick = cand[np.linspace(0, len(cand) - 1, min(need, len(cand))).round().astype(int)]
        pts.append(np.c_[xs[pick], ys[pick]])
        regs.append(np.full(len(pick), r, np.int32))
    if not pts:
        return None
    pts = np.concatenate(pts).astype(np.float32)
    kps = [cv2.KeyPoint(float(x), float(y), cfg.dense_size_px, 0.0) for x, y in pts]
    kps, desc = _sift(1, cfg.contrast_threshold).compute(gray, kps)
    if desc is None or len(kps) == 0:
        return None
    xy = np.array([k.pt for k in kps], np.float32)
    reg = labels[
        np.clip(xy[:, 1].round().astype(int), 0, h_img - 1), np.clip(xy[:, 0].round().astype(int), 0, w_img - 1)
    ]
    return xy, desc, reg.astype(np.int32)


def extract_features(
    image: np.ndarray, cfg: FeatureConfig = FeatureConfig(), mask: np.ndarray | None = None
) -> FrameFeatures:
    """Region-balanced RootSIFT of a frame; ``mask`` (H, W) bool keeps only keypoints inside it (query by region)."""
    bgr = to_bgr(image)
    H, W = bgr.shape[:2]
    s = min(1.0, cfg.max_side_px / max(H, W))
    small = (
        cv2.resize(bgr, (max(1, round(W * s)), max(1, round(H * s))), interpolation=cv2.INTER_AREA) if s < 1 else bgr
    )
    gray = cv2.cvtColor(small, cv2.COLOR_BGR2GRAY)
    t = min(1.0, cfg.seg_max_side_px / max(small.shape[:2]))
    seg_in = (
        cv2.resize(
            small, (max(1, round(small.shape[1] * t)), max(1, round(small.shape[0] * t))), interpolation=cv2.INTER_AREA
        )
        if t < 1
        else small
    )
    labels = cv2.resize(segment_regions(seg_in, cfg), (small.shape[1], small.shape[0]), interpolation=cv2.INTER_NEAREST)
    det_mask = None
    if mask is not None:
        mask = np.asarray(mask, bool)
        if mask.shape != (H, W):
            raise ValueError(f"mask shape {mask.shape} does not match the image {(H, W)}")
        det_mask = cv2.resize(
            mask.astype(np.uint8) * 255, (small.shape[1], small.shape[0]), interpolation=cv2.INTER_NEAREST
        )
    kps, desc = _sift(int(cfg.n_features * cfg.detect_factor), cfg.contrast_threshold).detectAndCompute(gray, det_mask)
    if desc is None or len(kps) == 0:
        return FrameFeatures(
            np.zeros((0, 2), np.float32), np.zeros((0, 128), np.float32), np.zeros(0, np.int32), (W, H)
        )
    xy_small = np.array([k.pt for k in kps], np.float32)
    response = np.array([k.response for k in kps], np.float32)
    ij = np.clip(np.round(xy_small).astype(int), 0, [small.shape[1] - 1, small.shape[0] - 1])
    region = labels[ij[:, 1], ij[:, 0]]
    # per-region quota proportional to sqrt(area)
    ids, area = np.unique(labels, return_counts=True)
    qmap = dict(zip(ids.tolist(), _quotas(area, cfg).tolist()))
    keep = []
    order = np.argsort(-response, kind="stable")
    taken = dict.fromkeys(ids.tolist(), 0)
    for i in order:
        r = int(region[i])
        if taken[r] < qmap[r]:
            taken[r] += 1
            keep.append(i)
    keep = np.array(sorted(keep), int)
    xy_s, desc_k, region_k = xy_small[keep], desc[keep], region[keep]
    if cfg.dense_fill:
        extra = _dense_fill(gray, labels, ids, area, taken, cfg, det_mask)
        if extra is not None:
            xy_s = np.concatenate([xy_s, extra[0]])
            desc_k = np.concatenate([desc_k, extra[1]])
            region_k = np.concatenate([region_k, extra[2]])
    # keypoint (x, y) back to original pixels with pixel-centre alignment
    xy = (xy_s + 0.5) / s - 0.5
    return FrameFeatures(xy.astype(np.float32), rootsift(desc_k), region_k.astype(np.int32), (W, H))

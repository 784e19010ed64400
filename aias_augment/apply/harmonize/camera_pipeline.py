"""Camera-pipeline matching: make an inserted object look as if the scene's camera had taken it.

Stages, in the order a camera applies them (each a pure function, composed by ``camera_match``):
  1. exposure and white balance (linear light): per-channel gains that bring the object's shades-of-grey illuminant
     estimate to its surroundings' (a ring around the mask), split into an exposure part (luminance-weighted) and a
     white-balance part, each applied with a strength in [0, 1] and clamped to +-``max_gain_stops``;
  2. atmospheric perspective (only when the object's depth is given): I = J t + A (1 - t), t = exp(-beta d), airlight A
     from the dark channel (He et al. 2009);
  3. sharpness: defocus (Gaussian) or, when the background's gradients are strongly oriented, motion blur (a line
     kernel across the dominant gradient), chosen so the object's Laplacian-to-gradient ratio matches the surroundings';
  4. noise: the background's signal-dependent noise level function sigma^2(I) = a I + b (Immerkaer's operator on flat
     pixels, robust medians per intensity bin, non-negative least squares) and the object's own; the missing variance
     is added with the caller's ``rng``;
  5. JPEG: the source's quality estimated from the quantisation lattice of its 8x8 DCT coefficients and its chroma
     subsampling from the chroma high-frequency energy; the object region is re-encoded with them on the same grid.

Limits: the gain estimate assumes the object's colour statistics resemble its surroundings' (that is what
"match" can mean without knowing its albedo), so a strongly coloured object is pulled towards its surroundings'
colour; the default strengths (exposure 0.5, white balance 0.25, fitted on training pairs) trade that off.
Blur and noise can only be added, never removed.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np
from scipy.fft import dctn
from scipy.optimize import nnls

from aias_augment.apply.harmonize.color import LUMA_WEIGHTS, linear_to_srgb, srgb_to_linear, to_uint8
from aias_augment.apply.harmonize.regions import components, context_box, mask_box, ring

# Divisions: illuminant estimates are floored at EPS_ILLUMINANT (linear units), gradient energy at EPS_GRAD.
EPS_ILLUMINANT = 1e-4
EPS_GRAD = 1e-6
# Pixels with a channel at or above this (encoded, [0, 1]) are treated as clipped and ignored in statistics.
CLIPPED = 0.98


@dataclass(frozen=True)
class CameraMatchParams:
    ring_width_frac: float = 0.5  # ring width = this x sqrt(object area in px), at least 3 px
    illuminant_norm_p: float = 6.0  # shades-of-grey Minkowski norm (1 = grey world, large = max-RGB)
    # Strengths fitted on training pairs (TraCon train + KITTI/NYU regions, never the eval images):
    # `studies/harmonization/harmonizer/train.py --config configs/harmonize_small.yaml --which camera` -> fMSE 961 -> 755 (60 pairs).
    exposure_strength: float = 0.5
    wb_strength: float = 0.25
    max_gain_stops: float = 2.0
    match_sharpness: bool = True
    max_blur_sigma_px: float = 3.0
    motion_coherence_threshold: float = 0.6  # background gradient coherence above which blur is modelled as motion
    match_noise: bool = True
    match_jpeg: bool = True
    jpeg_quality: int | None = None  # None: estimate from the image; the stage is skipped when it finds no JPEG
    atmosphere_beta_per_m: float = 0.0  # extinction coefficient (1/m); used only with an object depth
    # The background's noise is measured after its JPEG compression, which removes most of the high-frequency part
    # Immerkaer's operator sees; the object's noise is added before its re-encode, which removes it again. True: the
    # added sigma is raised so that after a re-encode at the source's quality it measures what the background does
    # (jpeg_noise_gain; False: the noise is added at the measured level, and a JPEG'd source keeps almost none).
    noise_through_jpeg: bool = False


# ------------------------------------------------------------------------------------------ 1. exposure + white balance
def illuminant(linear: np.ndarray, region: np.ndarray, p: float) -> np.ndarray:
    """Shades-of-grey estimate (mean(x^p))^(1/p) per channel over unclipped region pixels; (3,) linear units."""
    px = linear[region]
    px = px[(linear_to_srgb(px) < CLIPPED).all(axis=1)] if len(px) else px
    if len(px) == 0:
        return np.full(3, np.nan, np.float32)
    return np.power(np.mean(np.power(px, p), axis=0), 1.0 / p)


def estimate_gains(linear: np.ndarray, fg: np.ndarray, surround: np.ndarray, params: CameraMatchParams) -> np.ndarray:
    """Per-channel linear gains for the foreground; (1, 1, 1) when either region has no usable pixel."""
    p = params.illuminant_norm_p
    ill_f, ill_s = illuminant(linear, fg, p), illuminant(linear, surround, p)
    if not (np.isfinite(ill_f).all() and np.isfinite(ill_s).all()):
        return np.ones(3, np.float32)
    log_ratio = np.log(np.maximum(ill_s, EPS_ILLUMINANT)) - np.log(np.maximum(ill_f, EPS_ILLUMINANT))
    log_exposure = float(LUMA_WEIGHTS @ log_ratio)  # weights sum to 1: the luminance part of the ratio
    log_gain = params.exposure_strength * log_exposure + params.wb_strength * (log_ratio - log_exposure)
    limit = params.max_gain_stops * np.log(2.0)
    return np.exp(np.clip(log_gain, -limit, limit)).astype(np.float32)


# ------------------------------------------------------------------------------------------- 2. atmospheric perspective
def estimate_airlight(image_float: np.ndarray, patch_px: int = 15, top_fraction: float = 1e-3) -> np.ndarray:
    """He et al.'s airlight: mean colour of the pixels with the brightest dark channel (top 0.1%); (3,) encoded."""
    dark = cv2.erode(image_float.min(axis=2), np.ones((patch_px, patch_px), np.uint8))
    n = max(1, int(top_fraction * dark.size))
    idx = np.argpartition(dark.ravel(), -n)[-n:]
    return image_float.reshape(-1, 3)[idx].mean(axis=0)


def apply_atmosphere(image_float: np.ndarray, depth_m, airlight: np.ndarray, beta_per_m: float) -> np.ndarray:
    """Koschmieder's model I = J t + A (1 - t), t = exp(-beta d); ``depth_m`` scalar or (H, W)."""
    if beta_per_m < 0:
        raise ValueError(f"apply_atmosphere: beta_per_m must be >= 0, got {beta_per_m}")
    d = np.asarray(depth_m, np.float32)
    if not np.isfinite(d).all() or (d < 0).any():
        raise ValueError("apply_atmosphere: depth must be finite and >= 0")
    t = np.exp(-beta_per_m * d)
    t = t[..., None] if t.ndim == 2 else t
    return image_float * t + airlight * (1.0 - t)


# ---------------------------------------------------------------------------------------------------------- 3. blur
def sharpness_index(gray: np.ndarray, region: np.ndarray) -> float:
    """E|Laplacian| / E|gradient| over ``region``: contrast-invariant, falls as the region is blurred."""
    if region.sum() < 16:
        return float("nan")
    lap = np.abs(cv2.Laplacian(gray, cv2.CV_32F, ksize=3))[region]
    gx, gy = cv2.Sobel(gray, cv2.CV_32F, 1, 0), cv2.Sobel(gray, cv2.CV_32F, 0, 1)
    grad = np.hypot(gx, gy)[region]
    return float(lap.mean() / (grad.mean() + EPS_GRAD))


def gradient_orientation(gray: np.ndarray, region: np.ndarray) -> tuple[float, float]:
    """(coherence in [0, 1], angle of least gradient energy in radians) from the region's structure tensor."""
    gx, gy = cv2.Sobel(gray, cv2.CV_32F, 1, 0)[region], cv2.Sobel(gray, cv2.CV_32F, 0, 1)[region]
    jxx, jyy, jxy = float((gx * gx).sum()), float((gy * gy).sum()), float((gx * gy).sum())
    tr = jxx + jyy
    if tr <= EPS_GRAD:
        return 0.0, 0.0
    disc = np.sqrt(max((jxx - jyy) ** 2 + 4 * jxy**2, 0.0))
    coherence = disc / tr
    angle_max = 0.5 * np.arctan2(2 * jxy, jxx - jyy)  # direction of largest gradient energy
    return float(coherence), float(angle_max + np.pi / 2)


def motion_kernel(length_px: float, angle_rad: float) -> np.ndarray:
    size = int(np.ceil(length_px)) | 1
    k = np.zeros((size, size), np.float32)
    c, half = size // 2, (length_px - 1) / 2
    p0 = (int(round(c - half * np.cos(angle_rad))), int(round(c - half * np.sin(angle_rad))))
    p1 = (int(round(c + half * np.cos(angle_rad))), int(round(c + half * np.sin(angle_rad))))
    cv2.line(k, p0, p1, 1.0, 1)
    return k / k.sum()


def match_blur(image_float: np.ndarray, fg: np.ndarray, surround: np.ndarray, params: CameraMatchParams) -> np.ndarray:
    """Blur the foreground until its sharpness index matches the surroundings' (never sharpens)."""
    gray = image_float @ LUMA_WEIGHTS
    inner = cv2.erode(fg.astype(np.uint8), np.ones((3, 3), np.uint8)).astype(bool)  # skip the cut-out edge itself
    target, own = sharpness_index(gray, surround), sharpness_index(gray, inner)
    if not (np.isfinite(target) and np.isfinite(own)) or own <= target:
        return image_float
    coherence, angle = gradient_orientation(gray, ~fg)
    if coherence > params.motion_coherence_threshold:
        kernels = [motion_kernel(n, angle) for n in range(2, int(4 * params.max_blur_sigma_px) + 1)]
    else:
        kernels = [s for s in np.linspace(0.3, params.max_blur_sigma_px, 12)]
    # A trial blur is read on the foreground only (its pixels, and the 3x3 index filters on the inner part): it runs
    # on the foreground's box grown by the largest kernel's reach plus the filters' pixel, the same values there as
    # on the whole crop (the window's edges are the crop's, or farther from the foreground than any kernel reaches).
    reach = 2 + max(int(np.ceil(4.0 * k)) + 1 if np.isscalar(k) else max(k.shape) // 2 for k in kernels)
    rows, cols = np.flatnonzero(fg.any(axis=1)), np.flatnonzero(fg.any(axis=0))
    win = (
        slice(max(rows[0] - reach, 0), min(rows[-1] + 1 + reach, fg.shape[0])),
        slice(max(cols[0] - reach, 0), min(cols[-1] + 1 + reach, fg.shape[1])),
    )
    sub, inner_w = image_float[win], inner[win]
    best, best_err = None, abs(own - target)
    for k in kernels:
        blurred = cv2.GaussianBlur(sub, (0, 0), k) if np.isscalar(k) else cv2.filter2D(sub, -1, k)
        err = abs(sharpness_index(blurred @ LUMA_WEIGHTS, inner_w) - target)
        if err < best_err:
            best, best_err = blurred, err
    if best is None:
        return image_float
    out = image_float.copy()
    fg_w = fg[win]
    out[win][fg_w] = best[fg_w]
    return out


# --------------------------------------------------------------------------------------------------------- 4. noise
IMMERKAER = np.array([[1, -2, 1], [-2, 4, -2], [1, -2, 1]], np.float32)  # L2 norm 6


def _noise_fields(gray: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """What :func:`noise_level_function` filters ``gray`` into: Immerkaer's |response|, the smoothed grey level and
    its gradient magnitude (per pixel; any region of the same image reads them)."""
    smooth = cv2.GaussianBlur(gray, (0, 0), 1.5)
    grad = np.hypot(cv2.Sobel(smooth, cv2.CV_32F, 1, 0), cv2.Sobel(smooth, cv2.CV_32F, 0, 1))
    return np.abs(cv2.filter2D(gray, cv2.CV_32F, IMMERKAER)), smooth, grad


def noise_level_function(
    gray: np.ndarray, region: np.ndarray, bins: int = 6, *, fields: tuple | None = None
) -> tuple[float, float] | None:
    """(a, b) with sigma^2(I) = a I + b (gray in [0, 1]) from the region's flattest half; None if too few pixels.
    ``fields``: ``_noise_fields(gray)`` when the caller already has them (two regions of one image)."""
    resp, smooth, grad = _noise_fields(gray) if fields is None else fields
    inner = cv2.erode(region.astype(np.uint8), np.ones((5, 5), np.uint8)).astype(bool)
    inner &= (gray > 0.02) & (gray < CLIPPED)
    if inner.sum() < 64:
        return None
    flat = inner & (grad <= np.percentile(grad[inner], 50))
    levels, r = smooth[flat], resp[flat]
    edges = np.quantile(levels, np.linspace(0, 1, bins + 1))
    xs, ys = [], []
    for lo, hi in zip(edges[:-1], edges[1:]):
        sel = (levels >= lo) & (levels <= hi)
        if sel.sum() >= 16:
            sigma = np.median(r[sel]) / (0.6745 * 6.0)  # median |N(0, (6 sigma)^2)| = 0.6745 * 6 sigma
            xs.append(float(levels[sel].mean())), ys.append(float(sigma**2))
    if len(xs) < 2:
        return None
    (a, b), _ = nnls(np.stack([xs, np.ones(len(xs))], 1), np.asarray(ys))
    return float(a), float(b)


def _measured_sigma(gray: np.ndarray) -> float:
    """Immerkaer's noise sigma of a flat patch (mean |response| sqrt(pi / 2) / 6)."""
    r = cv2.filter2D(gray, cv2.CV_32F, IMMERKAER)[2:-2, 2:-2]
    return float(np.mean(np.abs(r)) * np.sqrt(np.pi / 2.0) / 6.0)


def jpeg_noise_gain(sigma: float, quality: int, subsample_420: bool, level: float = 0.5, iters: int = 4) -> float:
    """Factor by which noise of sigma ``sigma`` (grey, [0, 1]) must be raised before a JPEG encode at ``quality`` so
    that Immerkaer's sigma measures ``sigma`` after it (1 when it cannot be found: no noise, or none survives).
    Found on a flat 64 x 64 patch of grey ``level`` with a fixed internal generator (the caller's stream is not
    used: a measurement of the codec, the same for every call); at most 8."""
    if sigma <= 0:
        return 1.0
    noise = np.random.default_rng(0).standard_normal((64, 64, 1)).astype(np.float32)
    sampling = cv2.IMWRITE_JPEG_SAMPLING_FACTOR_420 if subsample_420 else cv2.IMWRITE_JPEG_SAMPLING_FACTOR_444
    gain = 1.0
    for _ in range(iters):
        patch = np.clip(level + gain * sigma * noise, 0, 1) * np.ones((1, 1, 3), np.float32)
        ok, buf = cv2.imencode(
            ".jpg",
            to_uint8(patch),
            [cv2.IMWRITE_JPEG_QUALITY, int(quality), cv2.IMWRITE_JPEG_SAMPLING_FACTOR, sampling],
        )
        dec = cv2.imdecode(buf, cv2.IMREAD_GRAYSCALE).astype(np.float32) / 255.0
        measured = _measured_sigma(dec)
        if not ok or measured <= 1e-6:
            return 1.0
        gain = float(np.clip(gain * sigma / measured, 1.0, 8.0))
    return gain


def match_noise(
    image_float: np.ndarray,
    fg: np.ndarray,
    rng: np.random.Generator,
    background: np.ndarray | None = None,
    jpeg: tuple[int, bool] | None = None,
) -> np.ndarray:
    """Add the noise variance the background (default: ~fg) has and the foreground lacks (per pixel, from NLFs).
    ``jpeg``: (quality, 4:2:0) of the re-encode that follows; the added noise is raised by :func:`jpeg_noise_gain`
    so that it measures the missing sigma after it."""
    gray = image_float @ LUMA_WEIGHTS
    fields = _noise_fields(gray)
    nlf_bg = noise_level_function(gray, ~fg if background is None else background, fields=fields)
    nlf_fg = noise_level_function(gray, fg, fields=fields)
    if nlf_bg is None:
        return image_float
    nlf_fg = nlf_fg or (0.0, 0.0)
    level = gray[fg]
    var_add = np.maximum((nlf_bg[0] - nlf_fg[0]) * level + (nlf_bg[1] - nlf_fg[1]), 0.0)
    gain = 1.0
    if jpeg is not None and level.size:
        gain = jpeg_noise_gain(float(np.sqrt(np.mean(var_add))), jpeg[0], jpeg[1], float(np.mean(level)))
    out = image_float.copy()
    out[fg] = np.clip(
        image_float[fg] + gain * np.sqrt(var_add)[:, None] * rng.standard_normal((level.size, 3)), 0.0, 1.0
    )
    return out.astype(np.float32)


# ---------------------------------------------------------------------------------------------------------- 5. JPEG
# IJG (libjpeg) standard luminance quantisation table, zig-zag not applied (row = vertical frequency).
IJG_LUMA = np.array(
    [
        [16, 11, 10, 16, 24, 40, 51, 61],
        [12, 12, 14, 19, 26, 58, 60, 55],
        [14, 13, 16, 24, 40, 57, 69, 56],
        [14, 17, 22, 29, 51, 87, 80, 62],
        [18, 22, 37, 56, 68, 109, 103, 77],
        [24, 35, 55, 64, 81, 104, 113, 92],
        [49, 64, 78, 87, 103, 121, 120, 101],
        [72, 92, 95, 98, 112, 100, 103, 99],
    ],
    np.float64,
)
# Low and mid frequencies: enough non-zero coefficients in natural images, and steps >= 3 even at quality 90.
_PROBE_FREQS = tuple((u, v) for u in range(5) for v in range(5) if 1 <= u + v <= 4)


def ijg_table(quality: int) -> np.ndarray:
    scale = 5000.0 / quality if quality < 50 else 200.0 - 2.0 * quality
    return np.clip(np.floor((IJG_LUMA * scale + 50.0) / 100.0), 1, 255)


_EIGHT = np.arange(8)


def _lattice_step(coeffs: np.ndarray, max_step: int = 64, min_count: int = 30, score_min: float = 0.6) -> int | None:
    """Largest step q whose multiples the coefficients sit on (mean cos(2 pi c / q) over |c| >= q/2 above score_min)."""
    best = None
    for q in range(2, max_step + 1):
        c = coeffs[np.abs(coeffs) >= q / 2]
        if c.size < min_count:
            break
        if np.mean(np.cos(2 * np.pi * c / q)) > score_min:
            best = q
    return best


def estimate_jpeg_quality(image_uint8: np.ndarray) -> int | None:
    """IJG quality (1..100) that explains the luma DCT lattice on the 8x8 grid at (0, 0); None if no JPEG trace."""
    h, w = image_uint8.shape[:2]
    if min(h, w) < 32:
        return None
    # every k-th 8x8 block in raster order, about 2000 (plenty, and a bounded cost): only those are converted to luma
    # and transformed (per block, so the same coefficients as transforming every block and keeping those)
    n_cols = w // 8
    blocks = np.arange(0, (h // 8) * n_cols, max(1, (h // 8) * n_cols // 2000))
    rows, cols = np.divmod(blocks, n_cols)
    pixels = image_uint8[(8 * rows)[:, None, None] + _EIGHT[:, None], (8 * cols)[:, None, None] + _EIGHT[None, :]]
    coef = dctn(pixels.astype(np.float64) @ np.array([0.299, 0.587, 0.114]) - 128.0, axes=(1, 2), norm="ortho")
    steps = [_lattice_step(coef[:, u, v]) for u, v in _PROBE_FREQS]
    found = [(f, s) for f, s in zip(_PROBE_FREQS, steps) if s is not None]
    if len(found) < 3:
        return None
    err = [sum(abs(ijg_table(q)[u, v] - s) / s for (u, v), s in found) for q in range(1, 101)]
    return int(np.argmin(err[::-1]) * -1 + 100)  # ties -> the highest quality


#: Blocks :func:`chroma_subsampled` reads at most: every k-th 8x8 block in raster order (all of a 640x480 image).
CHROMA_MAX_BLOCKS = 4800


def chroma_subsampled(image_uint8: np.ndarray) -> bool:
    """True when the chroma has far less energy in the upper half band than luma (4:2:0 / 4:2:2 decoding), over
    every k-th 8x8 block, at most :data:`CHROMA_MAX_BLOCKS` (the two classes' band ratios differ tenfold: a
    bounded sample decides as the whole image does, at a bounded cost)."""
    h, w = image_uint8.shape[:2]
    n_rows, n_cols = h // 8, w // 8
    if n_rows * n_cols == 0:
        return False
    blocks = np.arange(0, n_rows * n_cols, max(1, -(-n_rows * n_cols // CHROMA_MAX_BLOCKS)))
    rows, cols = np.divmod(blocks, n_cols)
    px = image_uint8[(8 * rows)[:, None, None] + _EIGHT[:, None], (8 * cols)[:, None, None] + _EIGHT[None, :]]
    rgb = px.astype(np.float64)
    y = rgb @ np.array([0.299, 0.587, 0.114])
    cb = rgb @ np.array([-0.168736, -0.331264, 0.5])

    def hf_ratio(ch):
        e = dctn(ch, axes=(1, 2), norm="ortho") ** 2  # JPEG's FDCT is the orthonormal DCT-II
        ac = e.sum(axis=(1, 2)) - e[:, 0, 0]
        return float(e[:, 4:, :].sum() + e[:, :4, 4:].sum()) / (float(ac.sum()) + EPS_GRAD)

    ry, rc = hf_ratio(y), hf_ratio(cb)
    # Measured on a KITTI crop: 4:2:0 gives rc / ry of 0.24-0.28, 4:4:4 gives 2.7-3.9 (quality 50-90).
    return ry > 1e-3 and rc < 0.6 * ry


def reapply_jpeg(image_uint8: np.ndarray, fg: np.ndarray, quality: int, subsample_420: bool) -> np.ndarray:
    """Re-encode the foreground's 16-aligned bounding region with ``quality``; background pixels are kept."""
    box = mask_box(fg)
    if box is None:
        return image_uint8
    h, w = fg.shape
    x0, y0 = (box[0] // 16) * 16, (box[1] // 16) * 16
    x1, y1 = min(w, -(-box[2] // 16) * 16), min(h, -(-box[3] // 16) * 16)
    sampling = cv2.IMWRITE_JPEG_SAMPLING_FACTOR_420 if subsample_420 else cv2.IMWRITE_JPEG_SAMPLING_FACTOR_444
    ok, buf = cv2.imencode(
        ".jpg",
        cv2.cvtColor(image_uint8[y0:y1, x0:x1], cv2.COLOR_RGB2BGR),
        [cv2.IMWRITE_JPEG_QUALITY, int(quality), cv2.IMWRITE_JPEG_SAMPLING_FACTOR, sampling],
    )
    if not ok:
        raise RuntimeError("reapply_jpeg: cv2.imencode failed")
    dec = cv2.cvtColor(cv2.imdecode(buf, cv2.IMREAD_COLOR), cv2.COLOR_BGR2RGB)
    out = image_uint8.copy()
    sub = fg[y0:y1, x0:x1]
    out[y0:y1, x0:x1][sub] = dec[sub]
    return out


# ------------------------------------------------------------------------------------------------------- composition
CONTEXT = 4.0  # each component's statistics come from a crop of this many times its box side (context_box)


def stage_window(mask_bool: np.ndarray) -> tuple[int, int, int, int] | None:
    """A window (x0, y0, x1, y1) in which :func:`camera_match` (given the JPEG quality and chroma subsampling) gives
    the whole image's bytes: it holds every component's context crop and the 16-aligned JPEG re-encode region, and
    starts on the 16 px grid (the re-encode's blocks and the crops' offsets stay where they were); None: empty."""
    boxes = [context_box(mask_box(c), mask_bool.shape, CONTEXT) for c in components(mask_bool)]
    if not boxes:
        return None
    h, w = mask_bool.shape
    mb = mask_box(mask_bool)
    x0, y0 = (min(b[0] for b in boxes) // 16) * 16, (min(b[1] for b in boxes) // 16) * 16
    x1 = min(w, max(max(b[2] for b in boxes), -(-mb[2] // 16) * 16))
    y1 = min(h, max(max(b[3] for b in boxes), -(-mb[3] // 16) * 16))
    return x0, y0, x1, y1


def camera_match(
    image_uint8: np.ndarray,
    mask_bool: np.ndarray,
    rng: np.random.Generator,
    params: CameraMatchParams = CameraMatchParams(),
    object_depth_m=None,
    chroma_420: bool | None = None,
) -> np.ndarray:
    """All stages; returns a new uint8 image (only foreground pixels differ). ``object_depth_m``: scalar or (H, W).
    ``chroma_420``: the source's chroma subsampling when known (None: estimated from ``image_uint8``).

    Each connected component is processed in its own context crop (4 x its box side): gains from its ring, blur and
    noise statistics from the crop's background, so the cost does not grow with the image size.
    """
    if image_uint8.dtype != np.uint8:
        raise ValueError(f"camera_match: expected a uint8 image, got {image_uint8.dtype}")
    srgb = image_uint8.astype(np.float32) / 255.0
    # JPEG parameters describe the source, so they are read before anything is changed.
    quality = (
        params.jpeg_quality
        if params.jpeg_quality is not None
        else (estimate_jpeg_quality(image_uint8) if params.match_jpeg else None)
    )
    airlight = estimate_airlight(srgb) if object_depth_m is not None and params.atmosphere_beta_per_m > 0 else None
    depth = None if airlight is None else np.broadcast_to(np.asarray(object_depth_m, np.float32), mask_bool.shape)
    out = srgb.copy()
    subsample = None
    if params.match_jpeg and quality:
        subsample = chroma_subsampled(image_uint8) if chroma_420 is None else chroma_420
    through = (int(quality), bool(subsample)) if params.noise_through_jpeg and subsample is not None else None
    for comp in components(mask_bool):
        x0, y0, x1, y1 = context_box(mask_box(comp), comp.shape, CONTEXT)
        fg, others = comp[y0:y1, x0:x1], mask_bool[y0:y1, x0:x1] & ~comp[y0:y1, x0:x1]
        width = max(3, int(round(params.ring_width_frac * np.sqrt(fg.sum()))))
        surround = ring(fg, width) & ~others
        lin = srgb_to_linear(out[y0:y1, x0:x1])
        lin[fg] *= estimate_gains(lin, fg, surround, params)
        crop = linear_to_srgb(lin)
        if airlight is not None:
            crop[fg] = apply_atmosphere(crop, depth[y0:y1, x0:x1], airlight, params.atmosphere_beta_per_m)[fg]
        if params.match_sharpness:
            crop = match_blur(crop, fg, surround, params)
        if params.match_noise:
            crop = match_noise(crop, fg, rng, background=~fg & ~others, jpeg=through)
        out[y0:y1, x0:x1][fg] = crop[fg]
    # only the foreground changed: the rest of ``out`` is image_uint8 / 255, which rounds back to the same bytes
    result = image_uint8.copy()
    result[mask_bool] = to_uint8(out[mask_bool])
    if params.match_jpeg and quality:
        result = reapply_jpeg(result, mask_bool, quality, subsample)
    return result

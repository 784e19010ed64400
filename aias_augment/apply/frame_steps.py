"""The frame-level steps of :func:`~aias_augment.apply.stages.apply_plan`, after the objects are composited: the
harmonizer (inside the objects' context window where that gives the same bytes), the frame stages of the stage list
(:mod:`aias_augment.core.stages`), the camera match and a monochrome camera's grey. ``cfg`` throughout: the
apply step's record (:class:`~aias_augment.apply.config.ApplyConfig`), read for its harmonizer fields."""

from __future__ import annotations

import time

import cv2
import numpy as np

from aias_augment.apply import composite as comp
from aias_augment.core.frame import changed_pixels
from aias_augment.core.report import skipped
from aias_augment.core.stages import apply_frame_stages
from aias_augment.plan.insertion import InsertionPlan


def frame_steps(result, cover_w, win, source, monochrome: bool, plan: InsertionPlan, cfg, mods: dict) -> np.ndarray:
    """The composited frame ``result`` through the harmonizer (its luminance only by ``cfg.harmonize_colour``), the
    frame stages, the camera match and a monochrome camera's grey; ``cover_w``: the objects' coverage in ``win``;
    ``source``: the input frame."""
    X0, Y0, X1, Y1 = win
    if cfg.harmonize:
        before = result[Y0:Y1, X0:X1].copy() if cfg.harmonize_colour == "luminance" else None
        result, mods["harmonize"] = _harmonize(
            result,
            cover_w,
            cfg,
            np.random.default_rng(plan.harmonize_seed),
            within=win,
            mask_origin=(X0, Y0),
            in_place=True,
        )
        if before is not None:
            result[Y0:Y1, X0:X1] = keep_chromaticity(before, result[Y0:Y1, X0:X1])
            mods["harmonize"] += "; its luminance only (the lit object's chromaticity kept)"
    else:
        mods["harmonize"] = skipped("disabled (ablation or naive paste)")
    result = apply_frame_stages(result, plan.frame_params)
    if cfg.harmonize and cfg.camera_match:
        cover = paste_window(result.shape[:2], win, cover_w)
        result, mods["camera_match"] = _camera_match(result, cover, cfg, source, plan.harmonize_seed)
    if monochrome:
        # A monochrome camera records luminance: the window's pixels (objects, shadows and the scene between them,
        # which is grey already and unchanged by this) as the camera's grey, R = G = B; the whole frame after a
        # frame stage (it changes pixels outside the window).
        _grey(result, np.s_[:, :] if plan.frame_params else np.s_[Y0:Y1, X0:X1])
        mods["colour"] = "luminance only: monochrome camera"
    return result


def frame_without_objects(image: np.ndarray, params: dict, monochrome: bool) -> np.ndarray:
    """A frame with nothing composited into it (``image``: its own copy) through the frame stages: as every other
    frame of a run is, so that the stages alone never mark the frames that got objects."""
    if not params:
        return image
    image = apply_frame_stages(image, params)
    if monochrome:
        _grey(image, np.s_[:, :])
    return image


def _grey(image: np.ndarray, sl) -> None:
    """``image[sl]`` as its grey (R = G = B), in place."""
    grey = cv2.cvtColor(np.ascontiguousarray(image[sl]), cv2.COLOR_RGB2GRAY)
    image[sl] = grey[..., None]


def paste_window(full: tuple, win: tuple, arr: np.ndarray) -> np.ndarray:
    """``arr`` (placed at ``win`` (x0, y0, x1, y1)) on a zero frame of shape ``full``, float32."""
    out = np.zeros(full + arr.shape[2:], np.float32)
    out[win[1] : win[3], win[0] : win[2]] = arr
    return out


def keep_chromaticity(before: np.ndarray, after: np.ndarray) -> np.ndarray:
    """uint8 sRGB: each pixel of ``before`` scaled in linear light to the luminance of ``after`` (chromaticity of
    ``before``, brightness of ``after``); pixels ``after`` left unchanged stay byte-identical. A channel the scaling
    would push past white is clipped there."""
    changed = changed_pixels(before, after)
    out = after.copy()
    if not changed.any():
        return out
    b, a = comp.to_linear(before[changed]), comp.to_linear(after[changed])
    w = np.array([0.2126, 0.7152, 0.0722], np.float32)
    lb, la = b @ w, a @ w
    scaled = b * (la / np.maximum(lb, 1e-6))[:, None]
    scaled = np.where((lb > 1e-6)[:, None], scaled, a)  # black before: nothing to scale, the harmonizer's pixel
    out[changed] = comp.to_uint8(scaled)
    return out


def _harmonize(
    image: np.ndarray,
    mask: np.ndarray,
    cfg,
    rng,
    within: tuple[int, int, int, int] | None = None,
    mask_box: tuple | None = None,
    *,
    mask_origin: tuple[int, int] = (0, 0),
    in_place: bool = False,
) -> tuple[np.ndarray, str]:
    """``mask``: the soft mask, placed at ``mask_origin`` (x, y) in ``image`` (0 elsewhere; by default the whole
    image's mask); ``within``: a window (x0, y0, x1, y1) known to hold every masked pixel (None: the whole image);
    ``mask_box``: the box (x0, y0, x1, y1) of the mask's non-zero pixels when the caller has it; ``in_place``: the
    fast harmonizer writes into ``image`` (the caller's own copy) instead of a new array."""
    H, W = image.shape[:2]
    ox, oy = mask_origin
    mh, mw = mask.shape
    windowed = (ox, oy, mh, mw) != (0, 0, H, W)

    def whole() -> np.ndarray:
        return paste_window((H, W), (ox, oy, ox + mw, oy + mh), mask) if windowed else mask

    try:
        from aias_augment.apply.harmonize import harmonize
    except ImportError as e:  # the harmonization package is optional at this stage of the pipeline
        return image, skipped(f"harmonizer unavailable ({e})")
    try:
        if mask_box is None:
            mask_box = _nonzero_box(mask, None if windowed else within, mask_origin)
        win, model = (None, None) if mask_box is None else _harmonize_window(mask, cfg, within, mask_box, (H, W))
        if win is None:
            return (
                harmonize(
                    image, whole(), method=cfg.harmonize_method, rng=rng, test_time_views=cfg.harmonize_test_time_views
                ),
                f"harmonized ({cfg.harmonize_method})",
            )
        x0, y0, x1, y1 = win
        soft = np.zeros((y1 - y0, x1 - x0), np.float32)  # the mask's part in the window
        ix0, iy0, ix1, iy1 = max(x0, ox), max(y0, oy), min(x1, ox + mw), min(y1, oy + mh)
        if ix1 > ix0 and iy1 > iy0:
            soft[iy0 - y0 : iy1 - y0, ix0 - x0 : ix1 - x0] = mask[iy0 - oy : iy1 - oy, ix0 - ox : ix1 - ox]
        out = image if in_place else image.copy()
        # _harmonize_window returns a window for "fast" only: harmonize()'s fast path, blended on the mask only.
        from aias_augment.apply.harmonize.fast_infer import harmonize_fast_masked

        bx0, by0, bx1, by1 = mask_box
        harmonize_fast_masked(
            model,
            image[y0:y1, x0:x1],
            soft,
            tta=cfg.harmonize_test_time_views,
            box=(bx0 - x0, by0 - y0, bx1 - x0, by1 - y0),
            out=out[y0:y1, x0:x1],
        )
        return out, f"harmonized ({cfg.harmonize_method}, in the objects' context window)"
    except FileNotFoundError as e:
        return image, skipped(str(e))


def _camera_match(
    image: np.ndarray, mask: np.ndarray, cfg, source: np.ndarray, harmonize_seed: int
) -> tuple[np.ndarray, str]:
    """The camera-pipeline stage after the colour harmonizer (``cfg.camera_match``): blur, noise and JPEG matched to
    the surroundings; its noise from its own generator ``default_rng([harmonize_seed, 1])`` (the harmonizer's stream
    is left as it was)."""
    if cfg.harmonize_method == "camera":
        return image, skipped("the harmonizer is the camera pipeline already")
    from aias_augment.apply.harmonize.api import match_camera

    out, info = match_camera(image, mask, np.random.default_rng([harmonize_seed, 1]), source_rgb_uint8=source)
    jpeg = (
        f"JPEG q{info['jpeg_quality']} {'4:2:0' if info['chroma_420'] else '4:4:4'}"
        if info["jpeg_quality"]
        else "no JPEG trace in the source: not re-encoded"
    )
    return out, f"blur, noise, {jpeg} matched to the surroundings (after {cfg.harmonize_method})"


#: The fast harmonizer's files are looked at (two ``stat``) at most this often (s): a checkpoint replaced while a
#: process runs is read within this long.
FAST_MODEL_RECHECK_S = 1.0
_FAST_MODEL: dict = {}


def _nonzero_box(
    mask: np.ndarray, within: tuple[int, int, int, int] | None = None, origin: tuple[int, int] = (0, 0)
) -> tuple[int, int, int, int] | None:
    """(x0, y0, x1, y1), x1/y1 exclusive, of ``mask``'s non-zero pixels, scanned in ``within`` (mask pixels; None:
    all of it) and shifted by ``origin`` (where the mask lies in the image); None when none is non-zero."""
    sx0, sy0, sx1, sy1 = (0, 0, mask.shape[1], mask.shape[0]) if within is None else within
    x, y, bw, bh = cv2.boundingRect((mask[sy0:sy1, sx0:sx1] > 0).view(np.uint8))
    if bw == 0:
        return None
    x0, y0 = x + sx0 + origin[0], y + sy0 + origin[1]
    return x0, y0, x0 + bw, y0 + bh


def _fast_model_and_context():
    """(model, largest context factor) of the shipped fast harmonizer, or None when its checkpoint is missing.
    ``load_fast_np`` keys the model by the files' versions; the context is read from its config."""
    now = time.monotonic()
    got = _FAST_MODEL.get("m")
    if got is not None and now - got[0] < FAST_MODEL_RECHECK_S:
        return got[1]
    from aias_augment.apply.harmonize.api import DEFAULT_CHECKPOINTS
    from aias_augment.apply.harmonize.fast_infer import TTA_CONTEXTS, load_fast_np

    path = DEFAULT_CHECKPOINTS["fast"]
    try:
        model = load_fast_np(path)
    except FileNotFoundError:
        if not path.is_file():
            _FAST_MODEL.pop("m", None)
            return None  # harmonize() raises the missing-checkpoint error with its training command
        raise
    out = (model, max(TTA_CONTEXTS + (model.cfg.context,)))
    _FAST_MODEL["m"] = (now, out)
    return out


def _harmonize_window(
    mask: np.ndarray,
    cfg,
    within: tuple[int, int, int, int] | None = None,
    mask_box: tuple | None = None,
    image_hw: tuple[int, int] | None = None,
) -> tuple[tuple[int, int, int, int] | None, object]:
    """(window, model): the window (x0, y0, x1, y1) in which the "fast" harmonizer gives the same bytes as on the
    whole image, and its NumPy model; (None, None) for other methods (they use whole-image statistics or draw per
    pixel: they get the whole image) or when there is nothing to harmonize.

    The fast harmonizer changes only masked pixels, and reads, per connected component, a square context crop of
    side ``context x`` the component's longer side, centred on it and clipped to the image. Every component lies in
    the mask's box B, so every crop lies in B grown by ``max context / 2 x`` B's longer side: a window holding that
    (clipped to the image where the crops are clipped too) gives the same crops, the same predictions, the same
    pixels (``tests/aias_augment/apply/test_stages.py``). ``mask_box``: B when the caller has it (``mask`` is then
    not read); ``image_hw``: the image's size (default: the mask's)."""
    if cfg.harmonize_method != "fast":
        return None, None
    got = _fast_model_and_context()
    if got is None:
        return None, None
    model, ctx = got
    if mask_box is None:
        mask_box = _nonzero_box(mask, within)
        if mask_box is None:
            return None, None
    bx0, by0, bx1, by1 = mask_box
    grow = int(np.ceil(ctx / 2 * max(bx1 - bx0, by1 - by0))) + 2
    h, w = mask.shape if image_hw is None else image_hw
    return (max(0, bx0 - grow), max(0, by0 - grow), min(w, bx1 + grow), min(h, by1 + grow)), model

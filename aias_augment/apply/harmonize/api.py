"""``harmonize()``: the one call the pipeline makes after compositing.

    from aias_augment.apply.harmonize import harmonize
    out = harmonize(composite_rgb_uint8, fg_mask, method="camera", rng=np.random.default_rng(0))

composite_rgb_uint8: (H, W, 3) uint8 RGB composite (the inserted objects already pasted in).
fg_mask: (H, W) float in [0, 1] (float32 or float64; bool also accepted), 1 = inserted object; soft edges allowed.
method:
  "none"     - a copy of the input;
  "reinhard" - Reinhard Lab mean/std transfer from the background (``reinhard.py``);
  "camera"   - camera-pipeline matching: exposure/WB, blur, noise, JPEG (``camera_pipeline.py``); uses ``rng``;
  "fast"     - predicted affine colour transform from a thumbnail (``fast.py``, checkpoints/harmonizer_fast.pt);
  "network"  - the paper's coarse-to-fine dilated-conv generator (``network.py``, checkpoints/harmonizer_small.pt).
rng: numpy Generator for the stochastic stages (camera noise); required for every method (None raises TypeError).
checkpoint: path of the "fast" / "network" checkpoint; None -> the shipped default. A missing checkpoint raises
  FileNotFoundError naming the training command. Loaded models are cached per process (path + mtime).

Statistics and network inputs use the binary mask ``fg_mask > 0`` (every pixel that receives any foreground);
the result is blended with the soft mask: out = composite * (1 - m) + harmonized * m, so pixels with m == 0 are
returned unchanged, bit for bit.
The input arrays are never modified; a new array is returned.
"""

from __future__ import annotations

import hashlib
from collections import OrderedDict
from dataclasses import replace
from pathlib import Path

import numpy as np

from aias_augment.apply.harmonize.camera_pipeline import (
    CameraMatchParams,
    camera_match,
    chroma_subsampled,
    estimate_jpeg_quality,
    stage_window,
)
from aias_augment.apply.harmonize.color import to_float, to_uint8
from aias_augment.apply.harmonize.reinhard import reinhard_transfer
from aias_augment.core.config import CHECKPOINT_DIR
from aias_augment.core.rng import require_rng

METHODS = ("none", "reinhard", "camera", "fast", "network")
DEFAULT_CHECKPOINTS = {
    "network": CHECKPOINT_DIR / "harmonizer_small.pt",
    "fast": CHECKPOINT_DIR / "harmonizer_fast.pt",
}
TRAIN_COMMAND = (
    "nice -n 10 .venv/bin/python -m studies.harmonization.harmonizer.train --config configs/harmonize_small.yaml "
    "--which {which} --out-{which} {path}"
)


def _validate(composite: np.ndarray, fg_mask: np.ndarray, method: str) -> np.ndarray:
    if method not in METHODS:
        raise ValueError(f"harmonize: unknown method {method!r}; choose one of {METHODS}")
    if (
        not isinstance(composite, np.ndarray)
        or composite.dtype != np.uint8
        or composite.ndim != 3
        or composite.shape[2] != 3
    ):
        shape = getattr(composite, "shape", None)
        raise ValueError(
            f"harmonize: composite must be an (H, W, 3) uint8 RGB array, got {shape} "
            f"{getattr(composite, 'dtype', type(composite).__name__)}"
        )
    if not isinstance(fg_mask, np.ndarray) or fg_mask.shape != composite.shape[:2]:
        raise ValueError(
            f"harmonize: fg_mask must be an (H, W) = {composite.shape[:2]} array, "
            f"got {getattr(fg_mask, 'shape', type(fg_mask).__name__)}"
        )
    if fg_mask.dtype == bool:
        return fg_mask.astype(np.float32)
    if not np.issubdtype(fg_mask.dtype, np.floating):
        raise ValueError(f"harmonize: fg_mask must be float in [0, 1] (or bool), got dtype {fg_mask.dtype}")
    if not np.isfinite(fg_mask).all():
        raise ValueError("harmonize: fg_mask contains NaN or Inf")
    if fg_mask.min() < 0.0 or fg_mask.max() > 1.0:
        raise ValueError(f"harmonize: fg_mask must lie in [0, 1], got [{fg_mask.min()}, {fg_mask.max()}]")
    return fg_mask.astype(np.float32)


def checkpoint_path(method: str, checkpoint: str | Path | None) -> Path:
    path = Path(checkpoint) if checkpoint is not None else DEFAULT_CHECKPOINTS[method]
    if not path.is_file():
        raise FileNotFoundError(
            f"harmonize(method={method!r}): checkpoint {path} not found. Train one with:\n  "
            + TRAIN_COMMAND.format(which=method, path=path)
        )
    return path


def harmonize(
    composite_rgb_uint8: np.ndarray,
    fg_mask: np.ndarray,
    method: str = "camera",
    rng: np.random.Generator | None = None,
    checkpoint: str | Path | None = None,
    test_time_views: bool = True,
) -> np.ndarray:
    """Harmonize the masked foreground of a composite; see the module docstring. Returns a new (H, W, 3) uint8.

    ``test_time_views``: the learnt methods average their prediction over 6 views (3 context sizes x flip); False
    uses one view, about 2x (fast) to 6x (network) quicker for under 1 point of fMSE (``studies/harmonization/harmonizer/result``)."""
    rng = require_rng(rng, "harmonize")
    soft = _validate(composite_rgb_uint8, fg_mask, method)
    hard = soft > 0.0
    if method == "none" or not hard.any():
        return composite_rgb_uint8.copy()
    image = to_float(composite_rgb_uint8)
    if method == "reinhard":
        result = reinhard_transfer(image, hard)
    elif method == "camera":
        result = to_float(camera_match(composite_rgb_uint8, hard, rng, CameraMatchParams()))
    elif method == "fast":
        from aias_augment.apply.harmonize.fast_infer import (  # NumPy inference: no torch for the fast method
            load_fast_np,
            run_fast,
        )

        result = run_fast(load_fast_np(checkpoint_path(method, checkpoint)), image, hard, tta=test_time_views)
    else:
        from aias_augment.apply.harmonize.network import load_generator, run_network

        result = run_network(load_generator(checkpoint_path(method, checkpoint)), image, hard, tta=test_time_views)
    m = soft[..., None]
    blended = to_uint8(image * (1.0 - m) + result * m)
    return np.where(m > 0, blended, composite_rgb_uint8)


#: The camera-pipeline stage run after a colour harmonizer (``InsertionConfig.camera_match``, balanced and accurate
#: presets): blur, noise, and the JPEG re-encode (the source's quality and chroma subsampling) matched to the
#: surroundings. Exposure and white balance are the colour harmonizer's job and already done: strengths 0 here, so
#: the colour is not corrected twice.
CAMERA_STAGE_PARAMS = CameraMatchParams(exposure_strength=0.0, wb_strength=0.0, noise_through_jpeg=True)


def match_camera(
    composite_rgb_uint8: np.ndarray,
    fg_mask: np.ndarray,
    rng: np.random.Generator,
    source_rgb_uint8: np.ndarray | None = None,
    params: CameraMatchParams = CAMERA_STAGE_PARAMS,
) -> tuple[np.ndarray, dict]:
    """Camera-pipeline matching of the masked foreground (``camera_pipeline.camera_match`` with ``params``), blended
    with the soft mask as :func:`harmonize` does (pixels with mask 0 are returned bit for bit). The JPEG quality and
    chroma subsampling are read from ``source_rgb_uint8`` (the image before insertion; default the composite), since
    they describe the camera, not the pasted object. Returns (new uint8 image, what was matched: ``jpeg_quality``
    (None: no JPEG trace, stage skipped), ``chroma_420``). ``rng`` draws the added noise."""
    soft = _validate(composite_rgb_uint8, fg_mask, "camera")
    hard = soft > 0.0
    src = composite_rgb_uint8 if source_rgb_uint8 is None else source_rgb_uint8
    if source_rgb_uint8 is not None and src.shape != composite_rgb_uint8.shape:
        raise ValueError(f"match_camera: source {src.shape} and composite {composite_rgb_uint8.shape} differ")
    quality, chroma_420 = params.jpeg_quality, None
    if params.match_jpeg:
        quality, chroma_420 = _source_jpeg(src, quality)
    info = {"jpeg_quality": quality if params.match_jpeg else None, "chroma_420": chroma_420}
    win = stage_window(hard)
    if win is None:
        return composite_rgb_uint8.copy(), info
    # only the window holding every component's context crop: the same bytes as the whole image (tested), less work
    x0, y0, x1, y1 = win
    comp_w, soft_w = composite_rgb_uint8[y0:y1, x0:x1], soft[y0:y1, x0:x1]
    p = replace(params, jpeg_quality=quality, match_jpeg=bool(params.match_jpeg and quality))
    fg = soft_w > 0.0
    result = camera_match(comp_w, fg, rng, p, chroma_420=chroma_420)
    m = soft_w[fg][:, None]  # the blend, on the pixels it changes (element-wise: the same bytes as on the window)
    out = composite_rgb_uint8.copy()
    out[y0:y1, x0:x1][fg] = to_uint8(to_float(comp_w[fg]) * (1.0 - m) + to_float(result[fg]) * m)
    return out, info


#: JPEG quality and chroma subsampling per source image (by content): a pure function of the bytes, ~60 ms for a
#: 640x480 frame, asked again for every insertion into the same image.
_SOURCE_JPEG: "OrderedDict[tuple, tuple]" = OrderedDict()


def _source_jpeg(src: np.ndarray, quality: int | None) -> tuple[int | None, bool | None]:
    key = (src.shape, hashlib.blake2b(np.ascontiguousarray(src).data, digest_size=16).digest(), quality)
    hit = _SOURCE_JPEG.get(key)
    if hit is None:
        q = quality if quality is not None else estimate_jpeg_quality(src)
        hit = (q, bool(chroma_subsampled(src)) if q else None)
        _SOURCE_JPEG[key] = hit
        while len(_SOURCE_JPEG) > 64:
            _SOURCE_JPEG.popitem(last=False)
    else:
        _SOURCE_JPEG.move_to_end(key)
    return hit


def harmonize_clip(
    frames: list[np.ndarray],
    fg_masks: list[np.ndarray | None],
    method: str = "fast",
    rng: np.random.Generator | None = None,
    checkpoint: str | Path | None = None,
) -> list[np.ndarray]:
    """Harmonize ONE inserted object through the frames of a clip without flicker.

    ``fg_masks[i]``: the object's soft mask in frame i (None or all-zero: the frame is returned as a copy).
    "fast": the colour transform is predicted in every frame where the object is visible and their element-wise
    median is applied to all of them (one camera, one object: one transform; per-frame predictions would flicker).
    Other methods run frame by frame (``rng`` seeds each frame's stream in order).
    """
    rng = require_rng(rng, "harmonize_clip")
    if len(frames) != len(fg_masks):
        raise ValueError(f"harmonize_clip: {len(frames)} frames but {len(fg_masks)} masks")
    softs = [None if m is None else _validate(f, m, method) for f, m in zip(frames, fg_masks)]
    visible = [i for i, m in enumerate(softs) if m is not None and (m > 0).any()]
    out = [np.asarray(f).copy() for f in frames]
    if method != "fast" or not visible:
        for i in visible:
            out[i] = harmonize(frames[i], softs[i], method, rng.spawn(1)[0], checkpoint)
        return out
    from aias_augment.apply.harmonize.fast_infer import apply_affine_np, load_fast_np, predict_affine

    model = load_fast_np(checkpoint_path(method, checkpoint))
    affine = np.median(np.stack([predict_affine(model, to_float(frames[i]), softs[i] > 0) for i in visible]), axis=0)
    for i in visible:
        image = to_float(frames[i])
        m = softs[i][..., None]
        blended = to_uint8(image * (1.0 - m) + apply_affine_np(image, affine) * m)
        out[i] = np.where(m > 0, blended, frames[i])
    return out

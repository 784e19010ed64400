"""The fast harmonizer's inference in NumPy: no torch in a worker that only inserts with the fast preset.

The model (:class:`aias_augment.apply.harmonize.fast.FastColorNet`, trained with torch) is four 3x3 stride-2 convolutions
on a 64 px thumbnail, a mean pool and a two-layer MLP: ~70 k weights. Its forward pass here is an im2col matmul per
layer in float32 (the same operations in the same order of layers; sums in another order, so values agree with
torch to ~1e-6, tested), ~0.3 ms per view against ~2 ms through torch's per-op overhead, and a worker that never
imports torch saves its ~700 MB (this wheel's CUDA build) of resident memory.

Weights come from ``<checkpoint>.npz``, exported from the torch checkpoint by
:func:`aias_augment.apply.harmonize.fast.export_npz` (``python -m aias_augment.apply.harmonize.fast
checkpoints/harmonizer_fast.pt``); the npz records the sha256 of the checkpoint it was made from and
:func:`load_fast_np` refuses a stale one (with the command to export it again).
"""

from __future__ import annotations

import functools
import hashlib
import json
import os
import threading
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from aias_augment.apply.harmonize.color import to_float, to_uint8
from aias_augment.apply.harmonize.regions import components, context_box, mask_box, resize
from aias_augment.core.config import from_dict

#: Feature pooling's denominator floor (in bottleneck pixels): an empty foreground or background pools to 0.
POOL_EPS = 1e-3
QUANTILES = (0.02, 0.1, 0.25, 0.5, 0.75, 0.9, 0.98)
# Test-time views: context factors x horizontal flip. The colour transform is predicted from each view and the
# predictions averaged (an ensemble of the same model). Measured on the 70 held-out TraCon pairs with the model
# trained here: one view fMSE -41.7 %, flip -44.1 %, 3 contexts -44.3 %, all 6 views -45.8 % vs the raw composite.
TTA_CONTEXTS = (2.0, 2.4, 2.9)
NPZ_FORMAT = "aias-fast-harmonizer-npz-v1"


@dataclass(frozen=True)
class FastConfig:
    thumbnail_px: int = 64
    channels: int = 16
    context: float = 2.4
    # Pool the last feature map over the object and over its surroundings separately (mask-weighted means) as
    # well as over the whole thumbnail: the transform depends on "object vs surroundings", which one global mean
    # mixes up. False = the first shipped architecture (global mean only).
    masked_pooling: bool = False
    hidden: int = 64
    # Luma quantiles of the object and of its surroundings (QUANTILES each) join the mean/std statistics: the
    # brightest object pixels against the scene's white level say more about exposure than means do.
    quantile_stats: bool = False
    # "luma": quantiles of luma; "rgb": of each colour channel (the object's brightest pixels per channel are a
    # white-patch estimate of its white balance, e.g. a cone's white stripe).
    quantile_channels: str = "luma"
    # Size of the square crop the model receives (0 = thumbnail_px): the CNN sees its thumbnail_px thumbnail, the
    # colour statistics are taken at this resolution, where thin bright details are not yet averaged away.
    input_px: int = 0

    def __post_init__(self):
        if self.quantile_channels not in ("luma", "rgb"):
            raise ValueError(f"FastConfig.quantile_channels must be 'luma' or 'rgb', got {self.quantile_channels!r}")
        if self.input_px and self.input_px < self.thumbnail_px:
            raise ValueError(
                f"FastConfig.input_px ({self.input_px}) must be 0 or >= thumbnail_px ({self.thumbnail_px})"
            )

    @property
    def in_px(self) -> int:
        return self.input_px or self.thumbnail_px


# ------------------------------------------------------------------------------------------------ the forward pass
def adaptive_avg_pool(x: np.ndarray, out_hw: tuple[int, int]) -> np.ndarray:
    """(C, H, W) -> (C, oh, ow): torch's ``adaptive_avg_pool2d`` (= ``interpolate(mode="area")``): output cell i
    averages input rows ``floor(i H / oh)`` to ``ceil((i + 1) H / oh)``."""
    c, h, w = x.shape
    oh, ow = out_hw
    if h % oh == 0 and w % ow == 0:
        return x.reshape(c, oh, h // oh, ow, w // ow).mean(axis=(2, 4), dtype=np.float32)
    rows = [(i * h // oh, -(-(i + 1) * h // oh)) for i in range(oh)]
    cols = [(j * w // ow, -(-(j + 1) * w // ow)) for j in range(ow)]
    out = np.empty((c, oh, ow), np.float32)
    for i, (r0, r1) in enumerate(rows):
        for j, (c0, c1) in enumerate(cols):
            out[:, i, j] = x[:, r0:r1, c0:c1].mean(axis=(1, 2))
    return out


def conv3x3_s2_relu(x: np.ndarray, weight: np.ndarray, bias: np.ndarray) -> np.ndarray:
    """(C, H, W) -> (Cout, ceil(H/2), ceil(W/2)): ``relu(conv2d(x, weight, bias, stride=2, padding=1))``;
    ``weight`` (Cout, C * 9) in torch's (c, ky, kx) order. im2col as one strided view of the padded input (copied
    once by the reshape), then one matmul."""
    c, h, w = x.shape
    ho, wo = (h + 1) // 2, (w + 1) // 2
    xp = np.zeros((c, 2 * ho + 2, 2 * wo + 2), np.float32)  # padding 1 (and one more row/column, never read)
    xp[:, 1 : h + 1, 1 : w + 1] = x
    sc, sy, sx = xp.strides
    cols = np.lib.stride_tricks.as_strided(xp, (c, 3, 3, ho, wo), (sc, sy, sx, 2 * sy, 2 * sx), writeable=False)
    out = weight @ cols.reshape(c * 9, ho * wo)
    out += bias[:, None]
    np.maximum(out, 0.0, out=out)
    return out.reshape(-1, ho, wo)


def _masked_stats(img: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """(3, H, W), (H, W) -> (12,): mean and std of the foreground colours, then of the background's."""
    out = []
    for m in (mask, 1.0 - mask):
        n = m.sum(dtype=np.float32) + np.float32(POOL_EPS)
        mean = (img * m).sum(axis=(1, 2), dtype=np.float32) / n
        var = (((img - mean[:, None, None]) ** 2) * m).sum(axis=(1, 2), dtype=np.float32) / n
        out += [mean, np.sqrt(var + np.float32(1e-8))]
    return np.concatenate(out).astype(np.float32)


def _quantiles(v: np.ndarray) -> np.ndarray:
    """(C, N), N >= 1 -> (C, len(QUANTILES)): linear interpolation between order statistics (numpy's and torch's
    default method: position q (N - 1)), from one sort instead of np.quantile's per-call machinery."""
    s = np.sort(v, axis=1)
    pos = np.asarray(QUANTILES) * (s.shape[1] - 1)
    lo = np.floor(pos).astype(np.intp)
    hi = np.minimum(lo + 1, s.shape[1] - 1)
    t = (pos - lo).astype(np.float32)
    return s[:, lo] + (s[:, hi] - s[:, lo]) * t


def _masked_quantiles(img: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """(C, H, W), (H, W) -> (2 * C * len(QUANTILES),): per-channel quantiles of the foreground, then the
    background's (0.5 where a side is empty); linear interpolation, as ``torch.quantile``."""
    x = img.reshape(img.shape[0], -1)
    m = mask.reshape(-1) > 0.5
    parts = []
    for sel in (m, ~m):
        v = x[:, sel]
        parts.append(
            _quantiles(v).reshape(-1).astype(np.float32)
            if v.shape[1]
            else np.full(len(QUANTILES) * x.shape[0], 0.5, np.float32)
        )
    return np.concatenate(parts)


#: Off: the convolutions run as NumPy matmuls (``AIAS_FAST_HARMONIZER_DNN=0``).
USE_OPENCV_DNN = os.environ.get("AIAS_FAST_HARMONIZER_DNN", "1") != "0"


def _darknet_convs(convs, shape: tuple):
    """An OpenCV DNN net of the 3x3 stride-2 padding-1 ReLU convolutions ``convs`` for input ``shape`` (C, H, W),
    written as a Darknet cfg and weights in memory (Darknet's weights file: a header, then per layer its biases and
    its (Cout, C, 3, 3) weights, as torch orders them); None when OpenCV's DNN module is missing or refuses it."""
    if not USE_OPENCV_DNN:
        return None
    try:
        c, h, w = shape
        cfg = [f"[net]\nwidth={w}\nheight={h}\nchannels={c}\n"]
        weights = [np.array([0, 2, 0], np.int32).tobytes(), np.zeros(1, np.int64).tobytes()]
        for wt, b in convs:
            cfg.append(f"[convolutional]\nfilters={wt.shape[0]}\nsize=3\nstride=2\npad=1\nactivation=relu\n")
            weights += [np.ascontiguousarray(b, np.float32).tobytes(), np.ascontiguousarray(wt, np.float32).tobytes()]
        net = cv2.dnn.readNetFromDarknet(
            np.frombuffer("\n".join(cfg).encode(), np.uint8), np.frombuffer(b"".join(weights), np.uint8)
        )
        net.setPreferableBackend(cv2.dnn.DNN_BACKEND_OPENCV)
        net.setPreferableTarget(cv2.dnn.DNN_TARGET_CPU)
        return net
    except (AttributeError, cv2.error):
        return None


@dataclass(frozen=True, eq=False)
class FastColorNetNP:
    """The fast harmonizer's weights for :meth:`forward` (see the module docstring)."""

    cfg: FastConfig
    convs: tuple[tuple[np.ndarray, np.ndarray], ...]  # (Cout, C*9) weight, (Cout,) bias per layer
    mlp: tuple[tuple[np.ndarray, np.ndarray], ...]  # (out, in) weight, (out,) bias per linear layer

    @classmethod
    def from_state_dict(cls, cfg: FastConfig, state: dict) -> "FastColorNetNP":
        """From ``FastColorNet.state_dict()`` as NumPy arrays (``features.{0,2,4,6}``, ``mlp.{0,2}``)."""

        def arr(k):
            return np.ascontiguousarray(np.asarray(state[k], np.float32))

        convs = tuple(
            (arr(f"features.{i}.weight").reshape(arr(f"features.{i}.weight").shape[0], -1), arr(f"features.{i}.bias"))
            for i in (0, 2, 4, 6)
        )
        mlp = tuple((arr(f"mlp.{i}.weight"), arr(f"mlp.{i}.bias")) for i in (0, 2))
        return cls(cfg, convs, mlp)

    def __getstate__(self):
        return {k: v for k, v in self.__dict__.items() if k != "_dnn"}  # the OpenCV nets are made per process

    def features(self, x: np.ndarray) -> np.ndarray:
        """The convolution stack on (C, H, W) float32: OpenCV's DNN module (one call, ~2x faster than the im2col
        matmuls at this size; the same weights, loaded as a Darknet stack of 3x3 stride-2 pad-1 ReLU convolutions;
        values agree with :func:`conv3x3_s2_relu` to ~1e-7, tested), else :func:`conv3x3_s2_relu` per layer. One
        net per thread (a net is not safe to run from two threads at once)."""
        net = self._dnn_net(x.shape)
        if net is None:
            for w, b in self.convs:
                x = conv3x3_s2_relu(x, w, b)
            return x
        net.setInput(x[None])
        return net.forward()[0]

    def _dnn_net(self, shape: tuple):
        local = self.__dict__.get("_dnn")
        if local is None:
            local = self.__dict__.setdefault("_dnn", threading.local())
        got = getattr(local, "nets", None)
        if got is None:
            got = local.nets = {}
        if shape not in got:
            got[shape] = _darknet_convs(self.convs, shape)
        return got[shape]

    @classmethod
    def from_torch(cls, model) -> "FastColorNetNP":
        """From a torch :class:`~aias_augment.apply.harmonize.fast.FastColorNet` (its current weights)."""
        return cls.from_state_dict(model.cfg, {k: v.detach().cpu().numpy() for k, v in model.state_dict().items()})

    def forward(self, crop: np.ndarray, mask: np.ndarray) -> np.ndarray:
        """Context crop (s, s, 3) float32 in [0, 1] and binary mask (s, s), s = ``cfg.in_px`` -> affine (3, 4) =
        [I + dM | b] (``FastColorNet.forward`` for a batch of one)."""
        t = self.cfg.thumbnail_px
        img = np.ascontiguousarray(crop.transpose(2, 0, 1), dtype=np.float32)
        m = np.asarray(mask, np.float32)
        if img.shape[1:] == (t, t):
            small, small_m = img, m
        else:
            small = adaptive_avg_pool(img, (t, t))
            small_m = (adaptive_avg_pool(m[None], (t, t))[0] > 0.5).astype(np.float32)
        h = np.concatenate([small * (1.0 - small_m), small_m[None], small * small_m])  # network_inputs
        h = self.features(np.ascontiguousarray(h, np.float32))
        f = [h.mean(axis=(1, 2), dtype=np.float32)]
        if self.cfg.masked_pooling:
            pm = adaptive_avg_pool(small_m[None], h.shape[1:])
            f.append((h * pm).sum(axis=(1, 2)) / (pm.sum() + np.float32(POOL_EPS)))
            f.append((h * (1 - pm)).sum(axis=(1, 2)) / ((1 - pm).sum() + np.float32(POOL_EPS)))
        stats = [_masked_stats(img, m)]
        if self.cfg.quantile_stats:
            if self.cfg.quantile_channels == "rgb":
                stats.append(_masked_quantiles(img, m))
            else:
                luma = 0.299 * img[0:1] + 0.587 * img[1:2] + 0.114 * img[2:3]
                stats.append(_masked_quantiles(luma.astype(np.float32), m))
        z = np.concatenate(f + stats).astype(np.float32)
        (w0, b0), (w1, b1) = self.mlp
        z = np.maximum(w0 @ z + b0, 0.0)
        delta = (w1 @ z + b1).reshape(3, 4)
        return np.eye(3, 4, dtype=np.float32) + delta


# ------------------------------------------------------------------------------------------------ weights on disk
def npz_path(checkpoint: str | Path) -> Path:
    return Path(checkpoint).with_suffix(".npz")


def file_sha256(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


@functools.lru_cache(maxsize=8)
def _load_np_cached(path: str, mtime_ns: int, checkpoint: str | None, checkpoint_mtime_ns: int) -> FastColorNetNP:
    with np.load(path) as z:
        meta = json.loads(str(z["meta"]))
        if meta.get("format") != NPZ_FORMAT:
            raise ValueError(f"{path} is not an {NPZ_FORMAT} file")
        state = {k[2:]: z[k] for k in z.files if k.startswith("w:")}
    if checkpoint is not None and file_sha256(Path(checkpoint)) != meta["source_sha256"]:
        raise ValueError(
            f"{path} was exported from another version of {checkpoint}: run `python -m "
            f"aias_augment.apply.harmonize.fast {checkpoint}` to export it again"
        )
    return FastColorNetNP.from_state_dict(from_dict(FastConfig, meta["config"]), state)


_RESOLVED: dict[str, tuple[Path, Path]] = {}


def load_fast_np(checkpoint: str | Path) -> FastColorNetNP:
    """The NumPy model of the fast-harmonizer ``checkpoint`` (a ``.pt`` path; its ``.npz`` is read, and checked
    against the ``.pt`` when that exists), once per process and file version (a call costs two ``stat``)."""
    got = _RESOLVED.get(str(checkpoint))
    if got is None:
        pt = Path(checkpoint).resolve()
        got = _RESOLVED[str(checkpoint)] = (pt, npz_path(pt))
    pt, p = got
    try:
        npz_mtime = os.stat(p).st_mtime_ns
    except FileNotFoundError:
        raise FileNotFoundError(f"{p} (export it: python -m aias_augment.apply.harmonize.fast {pt})") from None
    try:
        pt_mtime = os.stat(pt).st_mtime_ns if pt.suffix != ".npz" else None
    except FileNotFoundError:
        pt_mtime = None
    return _load_np_cached(str(p), npz_mtime, None if pt_mtime is None else str(pt), pt_mtime or 0)


# ------------------------------------------------------------------------------------------------ inference
def as_np_model(model) -> FastColorNetNP:
    """``model`` as a :class:`FastColorNetNP` (a torch FastColorNet is converted: its current weights)."""
    return model if isinstance(model, FastColorNetNP) else FastColorNetNP.from_torch(model)


def predict_affine(
    model,
    image_float: np.ndarray,
    comp: np.ndarray,
    context: float | None = None,
    flip: bool = False,
    box: tuple[int, int, int, int] | None = None,
) -> np.ndarray:
    """The (3, 4) sRGB affine ``[M | b]`` for one object (bool mask ``comp``), from its context-crop thumbnail.
    ``image_float``: the float image in [0, 1], or the uint8 image (only the crop is converted: the same values);
    ``box``: ``mask_box(comp)`` when the caller has it."""
    model = as_np_model(model)
    t = model.cfg.in_px
    x0, y0, x1, y1 = context_box(
        mask_box(comp) if box is None else box, comp.shape, model.cfg.context if context is None else context
    )
    crop, cm = image_float[y0:y1, x0:x1], comp[y0:y1, x0:x1]
    if flip:
        crop, cm = crop[:, ::-1], cm[:, ::-1]
    # The crop (as float, [0, 1]) and its mask as one 4-channel image: one resize (channels are resized alike;
    # cv2.merge: a strided NumPy write of 3 of 4 channels is ~8x slower).
    crop = to_float(crop) if crop.dtype == np.uint8 else np.ascontiguousarray(crop, np.float32)
    both = resize(cv2.merge([np.ascontiguousarray(crop), np.ascontiguousarray(cm, np.float32)]), (t, t))
    crop, cmf = both[..., :3], both[..., 3]
    m = (cmf > 0.5).astype(np.float32)
    if not m.any():
        m = (cmf > 0).astype(np.float32)
    return model.forward(crop, m)


def predict_affine_tta(
    model,
    image_float: np.ndarray,
    comp: np.ndarray,
    contexts: tuple[float, ...] = TTA_CONTEXTS,
    flip: bool = True,
    box: tuple[int, int, int, int] | None = None,
) -> np.ndarray:
    """Mean of :func:`predict_affine` over ``contexts`` x (no flip, flip)."""
    model = as_np_model(model)
    box = mask_box(comp) if box is None else box
    views = [(c, f) for c in contexts for f in ((False, True) if flip else (False,))]
    return np.mean([predict_affine(model, image_float, comp, c, f, box=box) for c, f in views], axis=0)


def apply_affine_np(pixels: np.ndarray, affine: np.ndarray) -> np.ndarray:
    """(..., 3) float sRGB, (3, 4) -> (..., 3) clipped to [0, 1]."""
    return np.clip(pixels @ affine[:, :3].T + affine[:, 3], 0.0, 1.0)


def run_fast(model, image_float: np.ndarray, mask_bool: np.ndarray, tta: bool = True) -> np.ndarray:
    """One affine per connected component, predicted from its context-crop thumbnail (averaged over the test-time
    views with ``tta``); returns a new float image."""
    model = as_np_model(model)
    out = image_float.copy()
    for comp in components(mask_bool):
        a = predict_affine_tta(model, image_float, comp) if tta else predict_affine(model, image_float, comp)
        out[comp] = apply_affine_np(out[comp], a)
    return out


def harmonize_fast_masked(
    model,
    composite_uint8: np.ndarray,
    soft_mask: np.ndarray,
    tta: bool = True,
    box: tuple[int, int, int, int] | None = None,
    out: np.ndarray | None = None,
) -> np.ndarray:
    """``harmonize(composite, soft_mask, method="fast")`` (:func:`aias_augment.apply.harmonize.api.harmonize`: the same
    bytes) with the blend computed on the masked pixels only: the composite's other pixels are returned as they are,
    so nothing is converted, blended or compared there. ``soft_mask`` (H, W) float32 in [0, 1] (checked by the
    caller). Every step is elementwise or reads the same pixels in the same order as there (the affine of each
    component on its own pixels; each context crop converted to float on its own), so the values are identical.
    ``box`` (x0, y0, x1, y1): a box holding every non-zero of ``soft_mask`` (the masks are scanned there only);
    ``out``: the array written (it may be ``composite_uint8`` itself: every crop is read before the first write);
    None: a copy of the composite."""
    model = as_np_model(model)
    H, W = soft_mask.shape
    bx0, by0, bx1, by1 = (0, 0, W, H) if box is None else box
    sm = soft_mask[by0:by1, bx0:bx1]
    hard = sm > 0
    out = composite_uint8.copy() if out is None else out
    n, labels, stats, _ = cv2.connectedComponentsWithStats(hard.view(np.uint8), connectivity=8)
    if n <= 1:
        return out
    pixels = to_float(composite_uint8[by0:by1, bx0:bx1][hard])  # (N, 3), row-major order of the mask
    result = pixels.copy()
    L, T, Wd, Ht = cv2.CC_STAT_LEFT, cv2.CC_STAT_TOP, cv2.CC_STAT_WIDTH, cv2.CC_STAT_HEIGHT
    for i in range(1, n):
        st = stats[i]
        cbox = (int(st[L]) + bx0, int(st[T]) + by0, int(st[L] + st[Wd]) + bx0, int(st[T] + st[Ht]) + by0)
        comp = np.zeros((H, W), bool)
        comp[by0:by1, bx0:bx1] = hard if n == 2 else labels == i
        a = (
            predict_affine_tta(model, composite_uint8, comp, box=cbox)
            if tta
            else predict_affine(model, composite_uint8, comp, box=cbox)
        )
        if n == 2:
            result = apply_affine_np(result, a)
        else:
            idx = labels[hard] == i
            result[idx] = apply_affine_np(result[idx], a)
    m = sm[hard].astype(np.float32)[:, None]
    out[by0:by1, bx0:bx1][hard] = to_uint8(pixels * (1.0 - m) + result * m)
    return out

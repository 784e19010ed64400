"""Fast harmonizer: a tiny CNN looks at a thumbnail of the object's context crop and predicts one affine colour
transform (3x3 matrix + offset, sRGB values) that is then applied to the foreground at full resolution.

Cost is independent of the image size except for the final per-pixel 3x4 multiply. The predictor also receives the
masked mean and standard deviation of foreground and background colours (12 numbers), the statistics a colour
transfer needs, and optionally their quantiles (luma or per channel); its last layer starts at zero so an untrained
model is the identity. The shipped model (``configs/harmonize_small.yaml``) uses per-channel quantiles and is also
the frozen global stage of the shipped network.
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch
import torch.nn.functional as F
from torch import nn

from ..config import from_dict
from .color import to_float, to_uint8
from .network import CHECKPOINT_FORMAT, POOL_EPS, load_model, masked_stats, network_inputs, to_tensor
from .regions import components, context_box, mask_box, resize

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
            raise ValueError(f"FastConfig.input_px ({self.input_px}) must be 0 or >= thumbnail_px "
                             f"({self.thumbnail_px})")

    @property
    def in_px(self) -> int:
        return self.input_px or self.thumbnail_px


QUANTILES = (0.02, 0.1, 0.25, 0.5, 0.75, 0.9, 0.98)


def masked_luma_quantiles(image: torch.Tensor, mask: torch.Tensor) -> torch.Tensor:
    """(B,3,H,W), binary (B,1,H,W) -> (B, 2 * len(QUANTILES)): luma quantiles of the foreground, then the background's
    (0.5 where a side is empty)."""
    y = 0.299 * image[:, 0:1] + 0.587 * image[:, 1:2] + 0.114 * image[:, 2:3]
    return masked_quantiles(y, mask)


def masked_quantiles(image: torch.Tensor, mask: torch.Tensor) -> torch.Tensor:
    """(B,C,H,W), binary (B,1,H,W) -> (B, 2 * C * len(QUANTILES)): per-channel quantiles of the foreground, then the
    background's (0.5 where a side is empty)."""
    x = image.flatten(2)
    m = mask[:, 0].flatten(1) > 0.5
    q = torch.tensor(QUANTILES, dtype=image.dtype)
    rows = []
    for b in range(image.shape[0]):
        parts = []
        for sel in (m[b], ~m[b]):
            v = x[b][:, sel]
            parts.append(torch.quantile(v, q, dim=1).T.flatten() if v.shape[1]
                         else torch.full((len(QUANTILES) * x.shape[1],), 0.5, dtype=image.dtype))
        rows.append(torch.cat(parts))
    return torch.stack(rows)


class FastColorNet(nn.Module):
    def __init__(self, cfg: FastConfig):
        super().__init__()
        self.cfg = cfg
        c, layers, cin = cfg.channels, [], 7
        for cout in (c, 2 * c, 4 * c, 4 * c):
            layers += [nn.Conv2d(cin, cout, 3, 2, 1), nn.ReLU()]
            cin = cout
        self.features = nn.Sequential(*layers)
        pooled = cin * (3 if cfg.masked_pooling else 1)
        per_side = len(QUANTILES) * (3 if cfg.quantile_channels == "rgb" else 1)
        stats = 12 + (2 * per_side if cfg.quantile_stats else 0)
        self.mlp = nn.Sequential(nn.Linear(pooled + stats, cfg.hidden), nn.ReLU(), nn.Linear(cfg.hidden, 12))
        nn.init.zeros_(self.mlp[-1].weight)
        nn.init.zeros_(self.mlp[-1].bias)

    def forward(self, crop: torch.Tensor, mask: torch.Tensor) -> torch.Tensor:
        """Context crop (B,3,s,s) in [0,1] and binary mask (B,1,s,s), s = ``cfg.in_px`` -> affine (B,3,4) =
        [I + dM | b]. The CNN sees the ``thumbnail_px`` thumbnail; the statistics come from the crop itself."""
        t = self.cfg.thumbnail_px
        small, small_mask = (crop, mask) if crop.shape[-2:] == (t, t) else thumbnail(crop, mask, t)
        h = self.features(network_inputs(small, small_mask))
        f = h.mean(dim=(2, 3))
        if self.cfg.masked_pooling:
            m = F.adaptive_avg_pool2d(small_mask, h.shape[-2:])
            fg = (h * m).sum(dim=(2, 3)) / (m.sum(dim=(2, 3)) + POOL_EPS)
            bg = (h * (1 - m)).sum(dim=(2, 3)) / ((1 - m).sum(dim=(2, 3)) + POOL_EPS)
            f = torch.cat([f, fg, bg], 1)
        stats = [masked_stats(crop, mask)]
        if self.cfg.quantile_stats:
            stats.append(masked_quantiles(crop, mask) if self.cfg.quantile_channels == "rgb"
                         else masked_luma_quantiles(crop, mask))
        delta = self.mlp(torch.cat([f, *stats], 1)).view(-1, 3, 4)
        eye = torch.eye(3, 4, dtype=delta.dtype).expand_as(delta)
        return eye + delta


def apply_affine(image: torch.Tensor, affine: torch.Tensor) -> torch.Tensor:
    """(B,3,H,W) sRGB in [0,1], (B,3,4) -> (B,3,H,W) clamped to [0,1]."""
    out = torch.einsum("bij,bjhw->bihw", affine[:, :, :3], image) + affine[:, :, 3, None, None]
    return out.clamp(0, 1)


def thumbnail(image: torch.Tensor, mask: torch.Tensor, size_px: int) -> tuple[torch.Tensor, torch.Tensor]:
    t = F.interpolate(image, size=(size_px, size_px), mode="area")
    m = (F.interpolate(mask, size=(size_px, size_px), mode="area") > 0.5).to(image.dtype)
    return t, m


def save_fast_checkpoint(path: str | Path, model: FastColorNet, meta: dict) -> None:
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_suffix(path.suffix + ".tmp")
    torch.save({"format": CHECKPOINT_FORMAT, "kind": "fast", "config": dataclasses.asdict(model.cfg),
                "state_dict": {k: v.detach().clone() for k, v in model.state_dict().items()}, "meta": meta}, tmp)
    tmp.replace(path)


def load_fast(path: str | Path) -> FastColorNet:
    """Load (once per process and file version) the fast harmonizer."""
    return load_model(path, "fast", FastColorNet, FastConfig)


# Test-time views: context factors x horizontal flip. The colour transform is predicted from each view and the
# predictions averaged (an ensemble of the same model). Measured on the 70 held-out TraCon pairs with the model
# trained here: one view fMSE -41.7 %, flip -44.1 %, 3 contexts -44.3 %, all 6 views -45.8 % vs the raw composite.
TTA_CONTEXTS = (2.0, 2.4, 2.9)


@torch.no_grad()
def predict_affine(model: FastColorNet, image_float: np.ndarray, comp: np.ndarray, context: float | None = None,
                   flip: bool = False) -> np.ndarray:
    """The (3, 4) sRGB affine ``[M | b]`` for one object (bool mask ``comp``), from its context-crop thumbnail."""
    t = model.cfg.in_px
    x0, y0, x1, y1 = context_box(mask_box(comp), comp.shape, model.cfg.context if context is None else context)
    crop, cm = image_float[y0:y1, x0:x1], comp[y0:y1, x0:x1]
    if flip:
        crop, cm = crop[:, ::-1], cm[:, ::-1]
    crop = resize(np.ascontiguousarray(crop), (t, t))
    m = (resize(np.ascontiguousarray(cm).astype(np.float32), (t, t)) > 0.5).astype(np.float32)
    if not m.any():
        m = (resize(np.ascontiguousarray(cm).astype(np.float32), (t, t)) > 0).astype(np.float32)
    return model(to_tensor(crop), torch.from_numpy(m)[None, None])[0].numpy()


def predict_affine_tta(model: FastColorNet, image_float: np.ndarray, comp: np.ndarray,
                       contexts: tuple[float, ...] = TTA_CONTEXTS, flip: bool = True) -> np.ndarray:
    """Mean of :func:`predict_affine` over ``contexts`` x (no flip, flip)."""
    views = [(c, f) for c in contexts for f in ((False, True) if flip else (False,))]
    return np.mean([predict_affine(model, image_float, comp, c, f) for c, f in views], axis=0)


def apply_affine_np(pixels: np.ndarray, affine: np.ndarray) -> np.ndarray:
    """(..., 3) float sRGB, (3, 4) -> (..., 3) clipped to [0, 1]."""
    return np.clip(pixels @ affine[:, :3].T + affine[:, 3], 0.0, 1.0)


@torch.no_grad()
def run_fast(model: FastColorNet, image_float: np.ndarray, mask_bool: np.ndarray, tta: bool = True) -> np.ndarray:
    """One affine per connected component, predicted from its context-crop thumbnail (averaged over the test-time
    views with ``tta``); returns a new float image."""
    out = image_float.copy()
    for comp in components(mask_bool):
        a = predict_affine_tta(model, image_float, comp) if tta else predict_affine(model, image_float, comp)
        out[comp] = apply_affine_np(out[comp], a)
    return out


@torch.no_grad()
def harmonize_fast_masked(model: FastColorNet, composite_uint8: np.ndarray, soft_mask: np.ndarray,
                          tta: bool = True) -> np.ndarray:
    """``harmonize(composite, soft_mask, method="fast")`` (:func:`aias_augment.harmonize.api.harmonize`: the same
    bytes) with the blend computed on the masked pixels only: the composite's other pixels are returned as they are,
    so nothing is converted, blended or compared there. ``soft_mask`` (H, W) float32 in [0, 1] (checked by the
    caller). Every step is elementwise or reads the same pixels in the same order as there (the affine of each
    component on its own pixels), so the values are identical."""
    hard = soft_mask > 0
    out = composite_uint8.copy()
    if not hard.any():
        return out
    image = to_float(composite_uint8)   # the context crops read it
    result = image[hard]                # (N, 3), row-major order of the mask
    pos = np.full(hard.shape, -1, np.intp)
    pos[hard] = np.arange(len(result))
    for comp in components(hard):
        a = predict_affine_tta(model, image, comp) if tta else predict_affine(model, image, comp)
        idx = pos[comp]
        result[idx] = apply_affine_np(result[idx], a)
    m = soft_mask[hard].astype(np.float32)[:, None]
    out[hard] = to_uint8(image[hard] * (1.0 - m) + result * m)
    return out

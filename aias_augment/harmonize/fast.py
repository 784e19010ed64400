"""Fast harmonizer: a tiny CNN looks at a thumbnail of the object's context crop and predicts one affine colour
transform (3x3 matrix + offset, sRGB values) that is then applied to the foreground at full resolution.

Cost is independent of the image size except for the final per-pixel 3x4 multiply. The predictor also receives the
masked mean and standard deviation of foreground and background colours (12 numbers), the statistics a colour
transfer needs; its last layer starts at zero so an untrained model is the identity.
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


QUANTILES = (0.02, 0.1, 0.25, 0.5, 0.75, 0.9, 0.98)


def masked_luma_quantiles(image: torch.Tensor, mask: torch.Tensor) -> torch.Tensor:
    """(B,3,H,W), binary (B,1,H,W) -> (B, 2 * len(QUANTILES)): luma quantiles of the foreground, then the background's
    (0.5 where a side is empty)."""
    y = (0.299 * image[:, 0] + 0.587 * image[:, 1] + 0.114 * image[:, 2]).flatten(1)
    m = mask[:, 0].flatten(1) > 0.5
    q = torch.tensor(QUANTILES, dtype=image.dtype)
    rows = []
    for b in range(image.shape[0]):
        parts = []
        for sel in (m[b], ~m[b]):
            v = y[b][sel]
            parts.append(torch.quantile(v, q) if v.numel() else torch.full_like(q, 0.5))
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
        stats = 12 + (2 * len(QUANTILES) if cfg.quantile_stats else 0)
        self.mlp = nn.Sequential(nn.Linear(pooled + stats, cfg.hidden), nn.ReLU(), nn.Linear(cfg.hidden, 12))
        nn.init.zeros_(self.mlp[-1].weight)
        nn.init.zeros_(self.mlp[-1].bias)

    def forward(self, thumbnail: torch.Tensor, mask: torch.Tensor) -> torch.Tensor:
        """Thumbnail (B,3,t,t) in [0,1] and binary mask (B,1,t,t) -> affine (B,3,4) = [I + dM | b]."""
        h = self.features(network_inputs(thumbnail, mask))
        f = h.mean(dim=(2, 3))
        if self.cfg.masked_pooling:
            m = F.adaptive_avg_pool2d(mask, h.shape[-2:])
            fg = (h * m).sum(dim=(2, 3)) / (m.sum(dim=(2, 3)) + POOL_EPS)
            bg = (h * (1 - m)).sum(dim=(2, 3)) / ((1 - m).sum(dim=(2, 3)) + POOL_EPS)
            f = torch.cat([f, fg, bg], 1)
        stats = [masked_stats(thumbnail, mask)]
        if self.cfg.quantile_stats:
            stats.append(masked_luma_quantiles(thumbnail, mask))
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
    t = model.cfg.thumbnail_px
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

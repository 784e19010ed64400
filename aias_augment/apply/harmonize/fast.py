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
import json
from pathlib import Path

import numpy as np
import torch
import torch.nn.functional as F
from torch import nn

from aias_augment.apply.harmonize.checkpoint import CHECKPOINT_FORMAT, load_model

# Inference (NumPy, no torch at run time) and the config live in fast_infer; re-exported here.
from aias_augment.apply.harmonize.fast_infer import (  # noqa: F401
    NPZ_FORMAT,
    POOL_EPS,
    QUANTILES,
    TTA_CONTEXTS,
    FastConfig,
    apply_affine_np,
    file_sha256,
    harmonize_fast_masked,
    npz_path,
    predict_affine,
    predict_affine_tta,
    run_fast,
)


def masked_stats(image: torch.Tensor, mask: torch.Tensor) -> torch.Tensor:
    """(B,3,H,W), (B,1,H,W) -> (B,12): mean and std of the foreground colours, then of the background's."""
    out = []
    for m in (mask, 1 - mask):
        n = m.sum(dim=(2, 3)) + POOL_EPS
        mean = (image * m).sum(dim=(2, 3)) / n
        var = ((image - mean[..., None, None]) ** 2 * m).sum(dim=(2, 3)) / n
        out += [mean, torch.sqrt(var + 1e-8)]
    return torch.cat(out, dim=1)


def network_inputs(composite: torch.Tensor, mask: torch.Tensor) -> torch.Tensor:
    """(B,3,H,W) composite and (B,1,H,W) binary mask -> the 7-channel input of the fast harmonizer's features and of
    the network's coarse stage (:mod:`aias_augment.apply.harmonize.network` builds on this module)."""
    return torch.cat([composite * (1 - mask), mask, composite * mask], dim=1)


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
            parts.append(
                torch.quantile(v, q, dim=1).T.flatten()
                if v.shape[1]
                else torch.full((len(QUANTILES) * x.shape[1],), 0.5, dtype=image.dtype)
            )
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
            stats.append(
                masked_quantiles(crop, mask)
                if self.cfg.quantile_channels == "rgb"
                else masked_luma_quantiles(crop, mask)
            )
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
    torch.save(
        {
            "format": CHECKPOINT_FORMAT,
            "kind": "fast",
            "config": dataclasses.asdict(model.cfg),
            "state_dict": {k: v.detach().clone() for k, v in model.state_dict().items()},
            "meta": meta,
        },
        tmp,
    )
    tmp.replace(path)
    export_npz(path)  # the NumPy weights inference reads (checked against this file's sha256)


def load_fast(path: str | Path) -> FastColorNet:
    """Load (once per process and file version) the fast harmonizer."""
    return load_model(path, "fast", FastColorNet, FastConfig)


def export_npz(checkpoint: str | Path, out: str | Path | None = None) -> Path:
    """Write the NumPy weights of a torch fast-harmonizer checkpoint (imports torch) beside it (or to ``out``)."""
    checkpoint = Path(checkpoint)
    model = load_fast(checkpoint)
    out = npz_path(checkpoint) if out is None else Path(out)
    state = {k: v.detach().cpu().numpy() for k, v in model.state_dict().items()}
    meta = {
        "format": NPZ_FORMAT,
        "config": dataclasses.asdict(model.cfg),
        "source_sha256": file_sha256(checkpoint),
        "source": checkpoint.name,
    }
    tmp = out.with_name(out.name + ".tmp.npz")
    np.savez(tmp, meta=np.array(json.dumps(meta)), **{f"w:{k}": v for k, v in state.items()})
    tmp.replace(out)
    return out


if __name__ == "__main__":
    import sys

    for ck in sys.argv[1:] or ["checkpoints/harmonizer_fast.pt"]:
        print(export_npz(ck))

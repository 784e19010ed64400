"""Training loop: warm-up plus cosine learning rate, EMA weights, deterministic batches; checkpoints carry their
config so that ``load_checkpoint`` rebuilds the exact model."""

from __future__ import annotations

import copy
import dataclasses
import logging
import math
import pickle
import time
from dataclasses import dataclass
from pathlib import Path

import torch
from torch import nn

from .config import DetectorConfig, TrainConfig, detector_config_from_dict, replace_nested
from .data import DetectionSet
from .loader import SampleTransform, TrainBatches, cache_dataset
from .model import Detector

log = logging.getLogger(__name__)


def lr_at(iteration: int, cfg: TrainConfig) -> float:
    """Linear warm-up from 0 over ``warmup_iters`` then cosine from ``lr`` down to ``lr * min_lr_ratio``."""
    if iteration < cfg.warmup_iters:
        return cfg.lr * (iteration + 1) / cfg.warmup_iters
    span = max(cfg.max_iters - cfg.warmup_iters, 1)
    progress = min((iteration - cfg.warmup_iters) / span, 1.0)
    low = cfg.lr * cfg.min_lr_ratio
    return low + (cfg.lr - low) * 0.5 * (1 + math.cos(math.pi * progress))


class ModelEMA:
    """Exponential moving average of weights and buffers; decay ramps up as ``decay * (1 - exp(-updates / tau))``
    so the early, poorly trained weights are forgotten quickly."""

    def __init__(self, model: nn.Module, decay: float, tau: float):
        self.ema = copy.deepcopy(model).eval()
        for p in self.ema.parameters():
            p.requires_grad_(False)
        self.decay, self.tau, self.updates = decay, tau, 0

    @torch.no_grad()
    def update(self, model: nn.Module):
        self.updates += 1
        d = self.decay * (1 - math.exp(-self.updates / self.tau))
        msd = model.state_dict()
        for k, v in self.ema.state_dict().items():
            if v.dtype.is_floating_point:
                v.mul_(d).add_(msd[k].detach(), alpha=1 - d)
            else:
                v.copy_(msd[k])


def build_optimizer(model: nn.Module, cfg: TrainConfig) -> torch.optim.Optimizer:
    """Weight decay on conv/linear weights only (not on BatchNorm or biases). Parameters outside ``model.backbone``
    (neck and head) get ``lr_scale = head_lr_mult``; the loop sets each group's lr to ``lr_at(it) * lr_scale``."""
    backbone = getattr(model, "backbone", None)
    in_backbone = {id(p) for p in backbone.parameters()} if backbone is not None else set()
    buckets: dict[tuple[bool, bool], list] = {}
    for module in model.modules():
        for name, p in module.named_parameters(recurse=False):
            if not p.requires_grad:
                continue
            is_weight = name == "weight" and not isinstance(module, nn.modules.batchnorm._BatchNorm)
            buckets.setdefault((id(p) in in_backbone, is_weight), []).append(p)
    groups = [
        {
            "params": params,
            "weight_decay": cfg.weight_decay if is_weight else 0.0,
            "lr_scale": 1.0 if is_backbone else cfg.head_lr_mult,
        }
        for (is_backbone, is_weight), params in sorted(buckets.items())
    ]
    if cfg.optimizer == "sgd":
        return torch.optim.SGD(groups, lr=cfg.lr, momentum=cfg.momentum, nesterov=True)
    return torch.optim.AdamW(groups, lr=cfg.lr, betas=(cfg.momentum, cfg.adam_beta2))


@dataclass(frozen=True)
class TrainResult:
    model: Detector  # EMA weights if enabled, in eval mode
    iterations: int
    images_seen: int
    train_seconds: float  # optimisation loop only
    cache_seconds: float  # decoding and resizing the training images once
    images_per_second: float
    final_losses: dict
    raw_model: Detector | None = None  # the optimised (non-EMA) weights when EMA is on, in eval mode


def train_detector(
    cfg: DetectorConfig,
    train_set: DetectionSet,
    seed: int,
    sample_transform: SampleTransform | None = None,
    device: str | torch.device = "cpu",
    log_fn=None,
    image_memo: dict | None = None,
    on_iteration=None,
    synthetic_mask=None,
) -> TrainResult:
    """Train a detector on ``train_set`` for ``cfg.train.max_iters`` iterations. Torch initialisation is seeded by
    ``seed`` through a local generator state (``torch.manual_seed`` inside ``fork_rng``). ``image_memo`` shares
    decoded training images between runs (see ``cache_dataset``). ``on_iteration(it, model, losses)`` is called
    after every step with the weights that would be returned (EMA if enabled), e.g. to record a learning curve.
    ``synthetic_mask`` (one bool per record) marks inserted images: they fill ``train.synthetic_fraction`` of the
    samples in place of real images without objects (see ``TrainBatches``)."""
    tc = cfg.train
    if cfg.model.num_classes != len(train_set.category_names):
        cfg = replace_nested(cfg, **{"model.num_classes": len(train_set.category_names)})
    torch.set_num_threads(tc.num_threads)
    t0 = time.perf_counter()
    cache = cache_dataset(train_set, tc.img_size, image_memo)
    cache_seconds = time.perf_counter() - t0
    batches = TrainBatches(
        cache,
        tc.img_size,
        tc.batch_size,
        cfg.augment,
        seed,
        sample_transform,
        tc.object_image_fraction,
        synthetic_mask,
        tc.synthetic_fraction,
    )
    with torch.random.fork_rng(devices=[]):
        torch.manual_seed(seed)
        model = Detector.from_config(cfg).to(device)
    ema = ModelEMA(model, tc.ema_decay, tc.ema_tau) if tc.ema else None
    optimizer = build_optimizer(model, tc)
    model.train()
    t1 = time.perf_counter()
    losses = {}
    for it in range(tc.max_iters):
        for g in optimizer.param_groups:
            g["lr"] = lr_at(it, tc) * g["lr_scale"]
        images, targets = batches.batch(it)
        out = model(images.to(device), targets.to(device))
        if not torch.isfinite(out["loss"]):
            raise FloatingPointError(f"non-finite loss at iteration {it}: { {k: float(v) for k, v in out.items()} }")
        optimizer.zero_grad(set_to_none=True)
        out["loss"].backward()
        grad_norm = torch.nn.utils.clip_grad_norm_(model.parameters(), tc.grad_clip)
        optimizer.step()
        if ema is not None:
            ema.update(model)
        losses = {k: float(v.detach()) for k, v in out.items()}
        losses["grad_norm"] = float(grad_norm)  # before clipping
        if log_fn is not None and (it % tc.log_every == 0 or it == tc.max_iters - 1):
            log_fn(
                f"iter {it}/{tc.max_iters} lr {lr_at(it, tc):.2e} "
                + " ".join(f"{k} {v:.3f}" for k, v in losses.items())
            )
        if on_iteration is not None:
            t_cb = time.perf_counter()
            on_iteration(it, ema.ema if ema is not None else model, losses)
            model.train()
            t1 += time.perf_counter() - t_cb  # callback time (evaluation) is not training time
    train_seconds = time.perf_counter() - t1
    final = ema.ema if ema is not None else model
    final.eval()
    model.eval()
    seen = tc.max_iters * tc.batch_size
    return TrainResult(
        final,
        tc.max_iters,
        seen,
        train_seconds,
        cache_seconds,
        seen / max(train_seconds, 1e-9),
        losses,
        model if ema is not None else None,
    )


def save_checkpoint(path: str | Path, model: Detector, category_names, meta: dict | None = None) -> None:
    """Weights together with the full detector config and category names."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    torch.save(
        {
            "format": "detection_eval/1",
            "config": dataclasses.asdict(model.cfg),
            "category_names": list(category_names),
            "state_dict": model.state_dict(),
            "meta": meta or {},
        },
        path,
    )


def load_checkpoint(path: str | Path, device="cpu") -> tuple[Detector, list[str], dict]:
    """Rebuild the model from the stored config (no pretrained download or file needed) and load its weights."""
    try:
        ckpt = torch.load(path, map_location=device, weights_only=True)
    except (pickle.UnpicklingError, RuntimeError, EOFError, KeyError, UnicodeDecodeError) as e:  # not a torch file
        raise ValueError(f"{path}: not a detection_eval checkpoint ({' '.join(str(e).split())[:200]})") from None
    if not isinstance(ckpt, dict) or ckpt.get("format") != "detection_eval/1":
        raise ValueError(f"{path}: not a detection_eval checkpoint")
    cfg = detector_config_from_dict(ckpt["config"])
    cfg = replace_nested(cfg, **{"model.pretrained": False})
    model = Detector.from_config(cfg).to(device)
    model.load_state_dict(ckpt["state_dict"])
    model.eval()
    return model, ckpt["category_names"], ckpt.get("meta", {})

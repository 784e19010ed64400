"""The harmonizers' checkpoint file: one format for both kinds ("fast": the fast harmonizer, "network": the
generator), each saved by its model's module and loaded here."""

from __future__ import annotations

import functools
from pathlib import Path

import torch
from torch import nn

from aias_augment.core.config import from_dict

CHECKPOINT_FORMAT = "aias-harmonizer-v1"


def load_checkpoint_dict(path: str | Path, kind: str) -> dict:
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(path)
    ckpt = torch.load(path, map_location="cpu", weights_only=True)
    if not isinstance(ckpt, dict) or ckpt.get("format") != CHECKPOINT_FORMAT or ckpt.get("kind") != kind:
        raise ValueError(f"{path} is not an {CHECKPOINT_FORMAT} '{kind}' checkpoint")
    return ckpt


@functools.lru_cache(maxsize=8)
def _load_model_cached(path: str, mtime_ns: int, kind: str, model_cls: type, config_cls: type) -> nn.Module:
    ckpt = load_checkpoint_dict(path, kind)
    model = model_cls(from_dict(config_cls, ckpt["config"]))
    model.load_state_dict(ckpt["state_dict"])
    return model.eval()


def load_model(path: str | Path, kind: str, model_cls: type, config_cls: type) -> nn.Module:
    """Load (once per process and file version) a checkpoint of ``kind`` into ``model_cls(config_cls(...))``."""
    p = Path(path).resolve()
    if not p.is_file():
        raise FileNotFoundError(p)
    return _load_model_cached(str(p), p.stat().st_mtime_ns, kind, model_cls, config_cls)

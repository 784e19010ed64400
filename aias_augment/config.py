"""Strict dataclass configs loaded from YAML: an unknown key is an error, never a silent no-op."""
from __future__ import annotations

import dataclasses
import os
import typing
from pathlib import Path
from typing import Any, TypeVar

import yaml

T = TypeVar("T")

REPO_ROOT = Path(__file__).resolve().parent.parent
# The shipped configs (presets, taxonomy, detector and study configs) and checkpoints. In a checkout
# ``aias_augment/_data/{configs,checkpoints}`` are symlinks to the repository's top-level folders; a built wheel holds
# copies (``[tool.setuptools.package-data]``), so an installed package loads ``preset="balanced"`` from anywhere.
PACKAGE_DATA = Path(__file__).resolve().parent / "_data"
CONFIG_DIR = PACKAGE_DATA / "configs"
CHECKPOINT_DIR = PACKAGE_DATA / "checkpoints"


def data_root() -> Path:
    """Root of the real data: ``$AIAS_DATA`` or ``../shared/data`` beside the repository."""
    env = os.environ.get("AIAS_DATA")
    return Path(env) if env else (REPO_ROOT.parent / "shared" / "data")


def from_dict(cls: type[T], data: dict[str, Any] | None, where: str = "") -> T:
    """Build dataclass ``cls`` from a mapping, recursing into nested dataclass fields.

    Raises ``KeyError`` naming the unknown keys (with the path inside the config) and ``TypeError`` for non-mappings.
    """
    data = {} if data is None else data
    where = where or cls.__name__
    if not isinstance(data, dict):
        raise TypeError(f"{where}: expected a mapping, got {type(data).__name__}")
    fields = {f.name: f for f in dataclasses.fields(cls)}
    unknown = sorted(set(data) - set(fields))
    if unknown:
        raise KeyError(f"{where}: unknown config keys {unknown}; allowed: {sorted(fields)}")
    hints = typing.get_type_hints(cls)
    kwargs = {}
    for name, value in data.items():
        tp = hints[name]
        if dataclasses.is_dataclass(tp) and isinstance(value, dict):
            value = from_dict(tp, value, f"{where}.{name}")
        elif isinstance(value, list) and (typing.get_origin(tp) is tuple or any(
                typing.get_origin(a) is tuple for a in typing.get_args(tp))):   # tuple or Optional[tuple]
            value = tuple(value)
        kwargs[name] = value
    return cls(**kwargs)


def load_config(cls: type[T], path: str | Path) -> T:
    """Load ``cls`` from a YAML file (a bare name is looked up in ``configs/``)."""
    p = Path(path)
    if not p.exists() and not p.suffix:
        p = CONFIG_DIR / f"{path}.yaml"
    if not p.exists():
        raise FileNotFoundError(f"config not found: {path}")
    with open(p) as f:
        data = yaml.safe_load(f) or {}
    return from_dict(cls, data, where=str(p))


def to_dict(obj) -> dict:
    return dataclasses.asdict(obj)

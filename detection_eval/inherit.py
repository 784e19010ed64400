"""Config files that inherit, as detectron2 and mmdetection configs do.

A YAML config may name ``_base_``: a path relative to its own folder, or a list of them. The bases are loaded
(recursively) and merged in order, then the file itself is merged over them:

- mappings merge key by key, recursively; the later one wins on a key both have;
- anything else (numbers, strings, lists) is replaced whole;
- a mapping holding ``_delete_: true`` replaces what it would merge into instead of merging (the key is dropped).

Every file goes through the bounded safe loader (:func:`aias_augment.core.config_files.load_yaml_file`). A missing
base, a cycle, or a ``_base_`` / ``_delete_`` of the wrong type raises :class:`ConfigFileError`, one line naming the
file.
"""

from __future__ import annotations

import copy
from pathlib import Path
from typing import Any

from aias_augment.core.config_files import ConfigFileError, load_yaml_file

BASE_KEY = "_base_"
DELETE_KEY = "_delete_"


def merge_configs(base: Any, child: Any, source: str = "config") -> Any:
    """``child`` merged over ``base`` (see the module docstring); neither argument is changed. A ``_delete_`` marker
    under a key that ``base`` lacks is kept (it applies when the result is merged over another base);
    :func:`load_inherited` drops what is left at the end."""
    if not isinstance(child, dict) or not isinstance(base, dict):
        return copy.deepcopy(child)
    merged = copy.deepcopy(base)
    for key, value in child.items():
        if isinstance(value, dict) and isinstance(base.get(key), dict):
            value = dict(value)
            if _delete_flag(value.pop(DELETE_KEY, False), source):
                merged[key] = _strip(value, source)
            else:
                merged[key] = merge_configs(base[key], value, source)
        else:
            merged[key] = copy.deepcopy(value)
    return merged


def _delete_flag(value: Any, source: str) -> bool:
    if not isinstance(value, bool):
        raise ConfigFileError(source, f"{DELETE_KEY} must be true or false, got {value!r}")
    return value


def _strip(data: Any, source: str) -> Any:
    """``data`` without ``_delete_`` markers (their values checked)."""
    if not isinstance(data, dict):
        return copy.deepcopy(data)
    if DELETE_KEY in data:
        _delete_flag(data[DELETE_KEY], source)
    return {k: _strip(v, source) for k, v in data.items() if k != DELETE_KEY}


def load_inherited(path: str | Path) -> dict:
    """The effective mapping of the config at ``path``: its ``_base_`` files merged under it, ``_base_`` and
    ``_delete_`` keys removed."""
    path = Path(path).resolve()
    return _strip(_load(path, ()), str(path))


def _load(path: Path, chain: tuple[Path, ...]) -> dict:
    if path in chain:
        cycle = " -> ".join(p.name for p in (*chain, path))
        raise ConfigFileError(str(chain[0]), f"_base_ cycle: {cycle}; remove one of these _base_ entries")
    data = load_yaml_file(path)
    data = {} if data is None else data
    if not isinstance(data, dict):
        raise ConfigFileError(str(path), f"expected a mapping, got {type(data).__name__}")
    bases = data.pop(BASE_KEY, [])
    if isinstance(bases, str):
        bases = [bases]
    if not isinstance(bases, list) or not all(isinstance(b, str) for b in bases):
        raise ConfigFileError(str(path), f"{BASE_KEY} must be a path or a list of paths, got {bases!r}")
    merged: dict = {}
    for base in bases:
        base_path = (path.parent / base).resolve()
        if not base_path.is_file():
            raise ConfigFileError(str(path), f"{BASE_KEY} {base!r} not found (looked for {base_path})")
        merged = merge_configs(merged, _load(base_path, (*chain, path)), str(base_path))
    return merge_configs(merged, data, str(path))

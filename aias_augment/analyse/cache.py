"""Scene analyses cached by content: an in-process LRU and, optionally, a folder of ``<scene_key>.npz`` files.

A cache never changes what is computed, only when: an entry is found by a 128-bit hash of everything the analysis
reads (:func:`scene_key`), and an entry written by another analysis version is ignored (recomputed, overwritten).
"""

from __future__ import annotations

import logging
from collections import OrderedDict
from pathlib import Path

from aias_augment.analyse.analysis import SceneAnalysis, analyse_scene, scene_key
from aias_augment.analyse.config import AnalyseConfig, analyse_config
from aias_augment.core.frame import Frame

log = logging.getLogger(__name__)


class SceneCache:
    """``get(frame, cfg)`` -> :class:`SceneAnalysis`, computed at most once per content (per process without a
    ``directory``; once for all processes and runs with one). ``max_items``: LRU size in memory. Pickles empty
    (each DataLoader worker fills its own LRU; the folder is shared)."""

    def __init__(self, max_items: int = 128, directory: str | Path | None = None):
        if max_items < 0:
            raise ValueError(f"max_items must be >= 0, got {max_items}")
        self.max_items = int(max_items)
        self.directory = None if directory is None else Path(directory)
        self._lru: OrderedDict[str, SceneAnalysis] = OrderedDict()
        self.hits = self.disk_hits = self.misses = 0

    def __getstate__(self):
        state = self.__dict__.copy()
        state["_lru"] = OrderedDict()
        state["hits"] = state["disk_hits"] = state["misses"] = 0
        return state

    def __len__(self) -> int:
        return len(self._lru)

    def get(self, frame: Frame, cfg: AnalyseConfig) -> SceneAnalysis:
        """The analysis of ``frame`` with ``cfg`` (the analysis' record, or a config that carries one)."""
        cfg = analyse_config(cfg)
        key = scene_key(frame, cfg)
        a = self._lru.get(key)
        if a is not None:
            self._lru.move_to_end(key)
            self.hits += 1
            return a
        a = self._read(key)
        if a is not None:
            self.disk_hits += 1
        else:
            self.misses += 1
            a = analyse_scene(frame, cfg, key=key)
            self._write(a)
        if self.max_items:
            self._lru[key] = a
            while len(self._lru) > self.max_items:
                self._lru.popitem(last=False)
        return a

    def _path(self, key: str) -> Path:
        return self.directory / key[:2] / f"{key}.npz"

    def _read(self, key: str) -> SceneAnalysis | None:
        if self.directory is None:
            return None
        p = self._path(key)
        if not p.exists():
            return None
        try:
            a = SceneAnalysis.load(p)
        except Exception as e:  # another version or a damaged file: recompute (and overwrite), say so
            log.info("scene cache: %s not used (%s)", p, e)
            return None
        return a if a.key == key else None

    def _write(self, a: SceneAnalysis) -> None:
        if self.directory is None:
            return
        p = self._path(a.key)
        try:
            p.parent.mkdir(parents=True, exist_ok=True)
            a.save(p)
        except OSError as e:  # a read-only or full disk must not stop training: the LRU still works
            log.warning("scene cache: cannot write %s (%s)", p, e)

"""Layer stages: what happens to one object's rendered, shaded layer before it is composited, for images and clips.

A layer stage is a module in :mod:`aias_augment.apply.layer_stages` with a ``STAGE`` object that has

- ``name``: its key in the plan's record (``layer_params``) and the :class:`InsertionConfig` field that switches it;
- ``order``: where it runs among the layer stages (ascending);
- ``enabled(cfg) -> bool``: whether ``cfg`` asks for it;
- ``draw(cfg, rng) -> dict``: its parameters for one object, plain JSON values, drawn in the plan;
- ``apply(layer, params, motion_px) -> ObjectLayer``: the layer changed; pure. ``motion_px``: the object's image
  motion during one frame interval ((2,) px, clips) or None (a still image).

The parameters are drawn from a generator of their own per (plan, object, stage), seeded by the plan's seed, so a
stage switched off or added draws nothing from the plan's stream: every other output keeps its bytes. The plan
records them and a replay applies the recorded values.
"""

from __future__ import annotations

import functools
import importlib
import pkgutil
import zlib
from dataclasses import dataclass

import numpy as np

from aias_augment.apply import layer_stages


@dataclass(frozen=True, eq=False)
class ObjectLayer:
    """One object's layer inside its window ``roi`` (x0, y0, x1, y1) of the frame: coverage ``alpha`` (h, w),
    camera depth ``depth`` (h, w; 0 where uncovered) and shaded linear RGB ``rgb`` (h, w, 3)."""

    roi: tuple[int, int, int, int]
    alpha: np.ndarray
    depth: np.ndarray
    rgb: np.ndarray


@functools.cache  # the package's modules are fixed once it is imported; every plan asks (28 us a listing)
def layer_stages_in_order() -> tuple:
    """The ``STAGE`` of every module of :mod:`aias_augment.apply.layer_stages`, by ``order``."""
    found = []
    for info in pkgutil.iter_modules(layer_stages.__path__):
        mod = importlib.import_module(f"{layer_stages.__name__}.{info.name}")
        if hasattr(mod, "STAGE"):
            found.append(mod.STAGE)
    return tuple(sorted(found, key=lambda s: (s.order, s.name)))


def draw_layer_params(cfg, plan_seed: int, n_objects: int) -> tuple[dict, ...]:
    """Per object, ``{stage name: parameters}`` of the stages ``cfg`` enables (empty dicts when none is)."""
    stages = [s for s in layer_stages_in_order() if s.enabled(cfg)]
    return tuple(
        {s.name: s.draw(cfg, np.random.default_rng([plan_seed, k, zlib.crc32(s.name.encode())])) for s in stages}
        for k in range(n_objects)
    )


def apply_layer_stages(
    layer: ObjectLayer, params: dict, frame_shape: tuple[int, int], motion_px: np.ndarray | None = None
) -> ObjectLayer:
    """``layer`` through every stage named in ``params`` (in stage order), its window kept inside the frame."""
    if not params:
        return layer
    by_name = {s.name: s for s in layer_stages_in_order()}
    unknown = sorted(set(params) - set(by_name))
    if unknown:
        raise ValueError(f"layer stages {unknown} are not in aias_augment.apply.layer_stages: cannot apply them")
    for name in sorted(params, key=lambda n: (by_name[n].order, n)):
        layer = by_name[name].apply(layer, params[name], motion_px)
        layer = _clipped(layer, frame_shape)
    return layer


def grown(layer: ObjectLayer, pad: int) -> ObjectLayer:
    """``layer`` with ``pad`` uncovered pixels added on every side (a stage that spreads the object needs room)."""
    if pad <= 0:
        return layer
    x0, y0, x1, y1 = layer.roi
    p2 = ((pad, pad), (pad, pad))
    return ObjectLayer(
        (x0 - pad, y0 - pad, x1 + pad, y1 + pad),
        np.pad(layer.alpha, p2),
        np.pad(layer.depth, p2),
        np.pad(layer.rgb, p2 + ((0, 0),)),
    )


def _clipped(layer: ObjectLayer, frame_shape: tuple[int, int]) -> ObjectLayer:
    h, w = frame_shape
    x0, y0, x1, y1 = layer.roi
    cx0, cy0, cx1, cy1 = max(x0, 0), max(y0, 0), min(x1, w), min(y1, h)
    if (cx0, cy0, cx1, cy1) == (x0, y0, x1, y1):
        return layer
    cx1, cy1 = max(cx1, cx0), max(cy1, cy0)
    sl = np.s_[cy0 - y0 : cy1 - y0, cx0 - x0 : cx1 - x0]
    return ObjectLayer((cx0, cy0, cx1, cy1), layer.alpha[sl], layer.depth[sl], layer.rgb[sl])

"""The stage list: the stages whose parameters the plan draws and records, a replay reads back, and
:func:`~aias_augment.apply.stages.apply_plan` applies to images and clip frames.

A stage is a module of this package with a ``STAGE`` object (or one given to :func:`register_stage`) that has

- ``name``: its key in the plan's record and, by convention, the config field that switches it;
- ``kind``: ``"layer"`` (one object's rendered, shaded layer before it is composited, drawn per object) or
  ``"frame"`` (the whole frame after compositing and harmonizing, before the camera's own stages: camera match,
  monochrome; drawn once per plan, and applied to every frame a plan is applied to, with or without objects, so the
  stage alone never tells a detector where something was inserted);
- ``order``: where it runs among the stages of its kind (ascending);
- ``enabled(cfg) -> bool``: whether ``cfg`` asks for it;
- ``draw(cfg, rng) -> dict``: its parameters, plain JSON values;
- ``apply``: pure. A layer stage: ``apply(layer, params, motion_px) -> ObjectLayer`` (``motion_px``: the object's
  image motion during one frame interval, (2,) px in a clip, None in a still image). A frame stage:
  ``apply(image, params) -> image`` ((H, W, 3) uint8 in and out; ``image`` itself is not written).

A new stage is one module here and the config field it reads. The parameters are drawn from a generator of their
own per (plan, object, stage) or (plan, stage), seeded by the plan's seed, so a stage switched off or added draws
nothing from the plan's stream: every other output keeps its bytes.
"""

from __future__ import annotations

import functools
import importlib
import pkgutil
import zlib
from dataclasses import dataclass
from typing import Callable

import numpy as np

KINDS = ("layer", "frame")
_REGISTERED: list = []  # stages added by register_stage, beside this package's modules


@dataclass(frozen=True, eq=False)
class ObjectLayer:
    """One object's layer inside its window ``roi`` (x0, y0, x1, y1) of the frame: coverage ``alpha`` (h, w),
    camera depth ``depth`` (h, w; 0 where uncovered) and shaded linear RGB ``rgb`` (h, w, 3)."""

    roi: tuple[int, int, int, int]
    alpha: np.ndarray
    depth: np.ndarray
    rgb: np.ndarray


@functools.cache  # the package's modules are fixed once it is imported; every plan asks (28 us a listing)
def _package_stages() -> tuple:
    found = []
    for info in pkgutil.iter_modules(__path__):
        mod = importlib.import_module(f"{__name__}.{info.name}")
        if hasattr(mod, "STAGE"):
            found.append(mod.STAGE)
    return tuple(found)


def stages_in_order(kind: str) -> tuple:
    """The stages of ``kind`` ("layer" or "frame"): this package's modules and the registered ones, by ``order``."""
    if kind not in KINDS:
        raise ValueError(f"stage kind {kind!r}: one of {KINDS}")
    found = [s for s in _package_stages() + tuple(_REGISTERED) if s.kind == kind]
    return tuple(sorted(found, key=lambda s: (s.order, s.name)))


def register_stage(stage) -> Callable[[], None]:
    """Add ``stage`` (an object with the attributes above) to the stage list, for a stage that lives outside this
    package; returns the function that removes it again."""
    if getattr(stage, "kind", None) not in KINDS:
        raise ValueError(f"stage {getattr(stage, 'name', stage)!r}: kind must be one of {KINDS}")
    taken = {s.name for s in _package_stages() + tuple(_REGISTERED)}
    if stage.name in taken:
        raise ValueError(f"a stage named {stage.name!r} is in the stage list already: give it another name")
    _REGISTERED.append(stage)
    return lambda: _REGISTERED.remove(stage)


def draw_layer_params(cfg, plan_seed: int, n_objects: int) -> tuple[dict, ...]:
    """Per object, ``{stage name: parameters}`` of the layer stages ``cfg`` enables (empty dicts when none is)."""
    stages = [s for s in stages_in_order("layer") if s.enabled(cfg)]
    return tuple(
        {s.name: s.draw(cfg, np.random.default_rng([plan_seed, k, zlib.crc32(s.name.encode())])) for s in stages}
        for k in range(n_objects)
    )


def draw_frame_params(cfg, plan_seed: int) -> dict:
    """``{stage name: parameters}`` of the frame stages ``cfg`` enables (empty when none is)."""
    return {
        s.name: s.draw(cfg, np.random.default_rng([plan_seed, zlib.crc32(s.name.encode())]))
        for s in stages_in_order("frame")
        if s.enabled(cfg)
    }


def _named(kind: str, params: dict) -> list:
    """The stages of ``kind`` that ``params`` names, in stage order; a name not in the list is refused."""
    by_name = {s.name: s for s in stages_in_order(kind)}
    unknown = sorted(set(params) - set(by_name))
    if unknown:
        raise ValueError(f"{kind} stages {unknown} are not in the stage list ({__name__}): cannot apply them")
    return sorted((by_name[n] for n in params), key=lambda s: (s.order, s.name))


def apply_layer_stages(
    layer: ObjectLayer, params: dict, frame_shape: tuple[int, int], motion_px: np.ndarray | None = None
) -> ObjectLayer:
    """``layer`` through every layer stage named in ``params`` (in stage order), its window kept inside the frame."""
    for stage in _named("layer", params):
        layer = _clipped(stage.apply(layer, params[stage.name], motion_px), frame_shape)
    return layer


def apply_frame_stages(image: np.ndarray, params: dict) -> np.ndarray:
    """``image`` (H, W, 3) uint8 through every frame stage named in ``params`` (in stage order); ``image`` itself
    when ``params`` is empty."""
    for stage in _named("frame", params):
        out = stage.apply(image, params[stage.name])
        if out.shape != image.shape or out.dtype != np.uint8:
            raise ValueError(f"frame stage {stage.name!r} returned {out.shape} {out.dtype}, not {image.shape} uint8")
        image = out
    return image


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

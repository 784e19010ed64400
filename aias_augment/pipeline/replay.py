"""Replay an insertion from its record: the same image bytes, without drawing anything.

The record's placements are frozen (pose, scale, asset name and source) and its harmonizer seed is kept; the scene
analysis is recomputed (it is a pure function of the frame) or taken from a cache, on the working copy the record
names (``working_resolution``: the bounded door's smaller copy) or on the frame itself; :func:`apply_plan` does the
rest.
"""

from __future__ import annotations

from typing import Callable

import numpy as np

from aias_augment.analyse.cache import SceneCache
from aias_augment.apply.stages import AppliedPlan, apply_plan
from aias_augment.assets.asset import DEFAULT_ASSETS, Asset, default_asset
from aias_augment.assets.deform import DeformParams, apply_deformation
from aias_augment.core.config import data_root
from aias_augment.core.frame import Frame
from aias_augment.pipeline.config import InsertionConfig
from aias_augment.pipeline.working import WorkingResolution
from aias_augment.plan.insertion import InsertionPlan, PlannedObject
from aias_augment.plan.placement import Placement


def _tuples(x):
    return tuple(_tuples(v) for v in x) if isinstance(x, (list, tuple)) else x


def placement_from_dict(d: dict) -> Placement:
    return Placement(**{k: _tuples(v) for k, v in d.items()})


def default_asset_for(p: Placement) -> Asset:
    """The asset a placement names: a procedural one rebuilt from its recorded seed, else the shared-data default
    asset of its category (the asset of ``asset_source="default"`` runs)."""
    if p.asset_source.startswith("procedural:") and "seed" in p.asset_meta:
        from aias_augment.assets.bank.procedural import procedural_asset_from_seed

        return procedural_asset_from_seed(p.category, p.asset_meta["seed"], p.asset_meta.get("look"))
    for rel in DEFAULT_ASSETS.get(p.category, []):
        a = default_asset(p.category, DEFAULT_ASSETS[p.category].index(rel))
        if a.source == p.asset_source or a.source == str(data_root() / rel):
            return a
    raise KeyError(f"no default asset for {p.category!r} from {p.asset_source!r}: pass assets= to replay")


def replay(
    record: dict,
    frame: Frame,
    cfg: InsertionConfig,
    *,
    assets: Callable[[Placement], Asset] = default_asset_for,
    scene_cache: SceneCache | None = None,
) -> AppliedPlan:
    """Re-apply ``record`` (:meth:`InsertionRecord.to_dict`, e.g. an offline ``records/NNNNNN.json``) to ``frame``
    with ``cfg`` (the run's config; a recorded ``mode`` says whether this image was a naive paste). ``assets(placement)`` returns the unscaled asset a placement was made from.
    ``frame``: the image the record was made from, with the intrinsics, depth and scene facts it was given."""
    if record.get("harmonize_seed") is None:
        raise ValueError("record has no harmonize_seed (written before plans were recorded): cannot replay")
    if "mode" in record:  # a naive_share run: this image as it was made (pipeline or naive paste)
        cfg = cfg.for_mode(record["mode"])
    wr = record.get("working_resolution")
    if wr is None:  # analysed on the image itself (also every record written before the field existed)
        analysis = (scene_cache or SceneCache(max_items=0)).get(frame, cfg)
    else:  # the bounded door's route: the analysis of its working copy, lifted to full size
        _, _, analysis = WorkingResolution.from_dict(wr).analyse(frame, cfg, scene_cache)
    objects = []
    for d in record["placements"]:
        p = placement_from_dict(d)
        base = assets(p)
        if "deformation" in p.asset_meta and "deformation" not in base.meta:  # rebuilt from its record
            base = apply_deformation(base, DeformParams.from_dict(p.asset_meta["deformation"]))
        objects.append(PlannedObject(p, base.scaled(p.scale)))
    plan = InsertionPlan(
        tuple(objects),
        int(record["harmonize_seed"]),
        len(objects),
        layer_params=tuple(dict(x) for x in record.get("layer_params", ())),
        frame_params=dict(record.get("frame_params", {})),  # the stage list's recorded draws, applied as they were
    )
    labelled = record.get("labelled_boxes_xywh") or None  # the input's boxes that occluded by depth order
    return apply_plan(frame, analysis, plan, cfg, labelled_xywh=None if labelled is None else np.array(labelled))

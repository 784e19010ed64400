"""One insertion in three steps (see ../shared/STYLE.md, "Analyse once, plan, apply"):

```
analysis = analyse_scene(frame, cfg)        # analyse.py: camera/horizon, ground, placeable region, lighting; cached
plan = plan_insertion(analysis, cfg, rng)   # plan.py:    assets, placements, harmonizer seed: every random draw
out = apply_plan(frame, analysis, plan)     # apply.py:   render, shadow, composite, harmonize, annotate: pure
```

``replay.py`` re-applies a recorded insertion (same bytes). ``cache.py`` holds :class:`SceneCache` (in-process LRU + optional on-disk folder keyed by the frame's content).
``view_cache.py`` is the fast preset's render path: per asset, views rendered once per view bin, warped into the
object's window and relit in numpy (:class:`ViewCache`, no GL call on a hit); ``projected_shadow.py`` its GL-free
shadow.
:func:`aias_augment.pipeline.insert_into_image` is the one-call wrapper over the three.
"""
from .analyse import SceneAnalysis, analyse_scene, scene_key
from .apply import AppliedPlan, apply_plan, object_shadow_ratio
from .cache import SceneCache
from .config import PRESETS, InsertionConfig, load_preset
from .plan import InsertionPlan, PlannedObject, plan_insertion
from .replay import replay
from .view_cache import ViewBinning, ViewCache, default_view_cache

__all__ = ["InsertionConfig", "PRESETS", "load_preset", "SceneAnalysis", "analyse_scene", "scene_key",
           "InsertionPlan", "PlannedObject", "plan_insertion", "AppliedPlan", "apply_plan", "object_shadow_ratio",
           "SceneCache", "replay", "ViewBinning", "ViewCache", "default_view_cache"]

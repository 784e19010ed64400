"""Step 3, pure: carry out a plan on its frame (:mod:`.stages`): render (:mod:`.render`, the only pyrender importer;
:mod:`.view_cache` and :mod:`.projected_shadow` for the fast path), shade, shadow, composite, harmonize, annotate."""

from aias_augment.core.lazy import lazy_exports

__all__ = ["apply_plan", "AppliedPlan"]
__getattr__ = lazy_exports(
    __name__,
    {
        "apply_plan": "aias_augment.apply.stages",
        "AppliedPlan": "aias_augment.apply.stages",
    },
)

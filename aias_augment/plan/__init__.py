"""Step 2: every random draw of an insertion as a frozen record (:mod:`.insertion`): where objects stand
(:mod:`.placement`, :mod:`.collision`) and, in a clip, how they stay put across frames (:mod:`.stabilize`)."""

from aias_augment.core.lazy import lazy_exports

__all__ = ["plan_insertion", "InsertionPlan", "PlannedObject"]
__getattr__ = lazy_exports(
    __name__,
    {
        "plan_insertion": "aias_augment.plan.insertion",
        "InsertionPlan": "aias_augment.plan.insertion",
        "PlannedObject": "aias_augment.plan.insertion",
    },
)

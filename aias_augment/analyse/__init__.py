"""Step 1, once per frame: what the scene offers (camera and horizon from vanishing lines, ground plane,
placeable region, lighting), cached by content. :func:`.analysis.analyse_scene` is the step's entry."""

from aias_augment.core.lazy import lazy_exports

__all__ = ["analyse_scene", "SceneAnalysis", "scene_key", "SceneCache"]
__getattr__ = lazy_exports(
    __name__,
    {
        "analyse_scene": "aias_augment.analyse.analysis",
        "SceneAnalysis": "aias_augment.analyse.analysis",
        "scene_key": "aias_augment.analyse.analysis",
        "SceneCache": "aias_augment.analyse.cache",
    },
)

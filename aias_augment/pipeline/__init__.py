"""The doors: one image (:mod:`.image`; its bounded working resolution in :mod:`.bounded`), one clip
(:mod:`.clip_objects`: several objects planned in the world, over :mod:`.clip`'s plan and per-frame stages), replay
of a recorded insertion (:mod:`.replay`), and the config with its presets (:mod:`.config`)."""

from aias_augment.core.lazy import lazy_exports

__all__ = [
    "insert_into_image",
    "insert_bounded",
    "insert_into_clip",
    "insert_objects_into_clip",
    "ClipRequest",
    "InsertionConfig",
    "load_preset",
    "PRESETS",
]
__getattr__ = lazy_exports(
    __name__,
    {
        "insert_into_image": "aias_augment.pipeline.image",
        "insert_bounded": "aias_augment.pipeline.bounded",
        "insert_into_clip": "aias_augment.pipeline.clip",
        "insert_objects_into_clip": "aias_augment.pipeline.clip_objects",
        "ClipRequest": "aias_augment.pipeline.clip_objects",
        "InsertionConfig": "aias_augment.pipeline.config",
        "load_preset": "aias_augment.pipeline.config",
        "PRESETS": "aias_augment.pipeline.config",
    },
)

"""aias-augment: photorealistic 3D object insertion for detector training data.

The top-level names are imported lazily: ``import aias_augment.bank`` must not pay for albumentations and torch.
"""
from .version import __version__ as __version__

__all__ = ["InsertObjects", "InsertionConfig", "SceneInputs", "insert_into_image", "load_preset"]


def __getattr__(name):
    if name == "InsertObjects":
        from .transform import InsertObjects
        return InsertObjects
    if name in ("InsertionConfig", "insert_into_image", "load_preset"):
        from . import pipeline
        return getattr(pipeline, name)
    if name == "SceneInputs":
        from .scene_inputs import SceneInputs
        return SceneInputs
    raise AttributeError(f"module 'aias_augment' has no attribute {name!r}")

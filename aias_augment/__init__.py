"""aias-augment: photorealistic 3D object insertion for detector training data.

The top-level names other than ``AiasError`` (whose module imports nothing) are imported lazily:
``import aias_augment.assets.bank`` must not pay for albumentations and torch.
"""

from aias_augment.core.errors import AiasError as AiasError
from aias_augment.version import __version__ as __version__

__all__ = [
    "AiasError",
    "InsertObjects",
    "InsertObjectsV2",
    "InsertionConfig",
    "SceneInputs",
    "insert_into_image",
    "load_preset",
]


def __getattr__(name):
    if name == "InsertObjects":
        from aias_augment.adapters.transform import InsertObjects

        return InsertObjects
    if name == "InsertObjectsV2":
        from aias_augment.adapters.torchvision_v2 import InsertObjectsV2

        return InsertObjectsV2
    if name in ("InsertionConfig", "insert_into_image", "load_preset"):
        from aias_augment.pipeline import image as pipeline

        return getattr(pipeline, name)
    if name == "SceneInputs":
        from aias_augment.core.scene_inputs import SceneInputs

        return SceneInputs
    raise AttributeError(f"module 'aias_augment' has no attribute {name!r}")

"""aias-augment: photorealistic 3D object insertion for detector training data."""
__version__ = "0.1.0"

from .pipeline import InsertionConfig, insert_into_image, load_preset  # noqa: E402
from .transform import InsertObjects  # noqa: E402

__all__ = ["InsertObjects", "InsertionConfig", "insert_into_image", "load_preset"]

"""aias-augment: photorealistic 3D object insertion for detector training data."""
__version__ = "0.1.0"

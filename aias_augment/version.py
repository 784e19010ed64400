"""The package version (one place: the package, its manifests and its cache keys read it here)."""

__version__ = "0.1.0"

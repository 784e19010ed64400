"""The assets' error type, below every module that raises it."""

from __future__ import annotations


class AssetError(ValueError):
    """A mesh could not be loaded or is unusable (reason in the message)."""

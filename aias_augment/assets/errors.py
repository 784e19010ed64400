"""The assets' error type, below every module that raises it."""

from __future__ import annotations

from aias_augment.core.errors import AiasError


class AssetError(AiasError, ValueError):
    """A mesh could not be loaded or is unusable (reason in the message)."""

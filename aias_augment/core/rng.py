"""Random generators are always passed in: no function of the package draws from a generator it made up itself.

A function that draws takes ``rng`` (a :class:`numpy.random.Generator`) from its caller; torch draws take an explicit
``torch.Generator`` or run inside ``torch.random.fork_rng`` so that the process-wide torch state is left as it was.
"""

from __future__ import annotations

import numpy as np


def require_rng(rng, where: str) -> np.random.Generator:
    """``rng`` if it is a numpy Generator; otherwise a TypeError naming ``where`` (a missing rng is an error, never a
    silent fixed seed)."""
    if not isinstance(rng, np.random.Generator):
        got = "nothing" if rng is None else type(rng).__name__
        raise TypeError(f"{where}: rng is required: pass a numpy Generator (e.g. np.random.default_rng(0)), got {got}")
    return rng


def systematic_sample(n: int, k: int) -> np.ndarray:
    """Indices of a draw-free sample of ``k`` of ``n`` items: all ``n`` (ascending) when ``n <= k``, else ``k`` evenly
    spaced ones from the first to the last. A statistic of pixels taken in raster order this way is a property of the
    image: it does not move with a generator's state."""
    if n < 0 or k < 1:
        raise ValueError(f"systematic_sample: need n >= 0 and k >= 1, got n={n}, k={k}")
    if n <= k:
        return np.arange(n)
    return np.linspace(0, n - 1, k).round().astype(np.int64)

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

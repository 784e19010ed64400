"""Every function that draws takes its generator from the caller: a missing rng is a TypeError naming the function,
never a silent fixed seed."""

import numpy as np
import pytest
import torch

from aias_augment.apply.harmonize import harmonize, harmonize_clip
from aias_augment.apply.harmonize.network import Critic, masked_gradient_penalty
from aias_augment.core.geometry import Intrinsics
from aias_augment.core.rng import require_rng, systematic_sample
from aias_augment.evaluation.realism.distances import kid_from_features

IMG = np.full((48, 64, 3), 128, np.uint8)
K = Intrinsics.from_fov(64, 48, 60.0)
MASK = np.zeros((48, 64), np.float32)
MASK[10:30, 20:40] = 1.0

CALLS = {
    "kid_from_features": lambda **kw: kid_from_features(np.zeros((20, 4)), np.ones((30, 4)), subset_size=10, **kw),
    "harmonize": lambda **kw: harmonize(IMG, MASK, "camera", **kw),
    "harmonize_clip": lambda **kw: harmonize_clip([IMG, IMG], [MASK, MASK], "camera", **kw),
}


@pytest.mark.parametrize("name", sorted(CALLS))
def test_missing_rng_raises_naming_the_function(name):
    # a required keyword (Python's own "missing 1 required keyword-only argument: 'rng'"), or for harmonize and
    # harmonize_clip, whose rng is positional after the defaulted method, require_rng's message
    with pytest.raises(
        TypeError,
        match=rf"{name}(\(\) missing 1 required keyword-only argument: 'rng'|: rng is "
        rf"required)",
    ):
        CALLS[name]()
    with pytest.raises(TypeError, match=rf"{name}: rng is required.*got int"):
        CALLS[name](rng=0)


@pytest.mark.parametrize("name", sorted(CALLS))
def test_same_rng_same_result(name):
    """With the generator passed, the call runs and is a function of its seed."""
    a, b = CALLS[name](rng=np.random.default_rng(5)), CALLS[name](rng=np.random.default_rng(5))
    assert _same(a, b)


def _same(a, b) -> bool:
    if isinstance(a, (list, tuple)):
        return len(a) == len(b) and all(_same(x, y) for x, y in zip(a, b))
    if isinstance(a, np.ndarray):
        return np.array_equal(a, b)
    if hasattr(a, "to_dict"):
        return _same(list(a.to_dict().items()), list(b.to_dict().items()))
    if hasattr(a, "__dataclass_fields__"):
        return all(_same(getattr(a, f), getattr(b, f)) for f in a.__dataclass_fields__)
    return a == b


def test_harmonize_needs_rng_even_when_nothing_is_drawn():
    with pytest.raises(TypeError, match="harmonize: rng is required"):
        harmonize(IMG, MASK, "none")


def test_require_rng_passes_a_generator_through():
    g = np.random.default_rng(1)
    assert require_rng(g, "x") is g


def test_gradient_penalty_needs_a_torch_generator():
    critic, mask = Critic(4), torch.ones(2, 1, 32, 32)
    real, fake = torch.zeros(2, 3, 32, 32), torch.ones(2, 3, 32, 32)
    with pytest.raises(TypeError, match="masked_gradient_penalty: generator is required"):
        masked_gradient_penalty(critic, real, fake, mask, None)
    state = torch.random.get_rng_state()
    a = masked_gradient_penalty(critic, real, fake, mask, torch.Generator().manual_seed(3))
    b = masked_gradient_penalty(critic, real, fake, mask, torch.Generator().manual_seed(3))
    assert float(a.detach()) == float(b.detach())
    assert torch.equal(torch.random.get_rng_state(), state)  # the process-wide torch state is not drawn from


@pytest.mark.parametrize(("n", "k"), [(0, 5), (3, 5), (5, 5), (10, 3), (8001, 8000), (10**6, 8000)])
def test_systematic_sample_is_evenly_spaced_and_complete(n, k):
    idx = systematic_sample(n, k)
    if n <= k:
        np.testing.assert_array_equal(idx, np.arange(n))
        return
    assert len(idx) == k and len(np.unique(idx)) == k and idx[0] == 0 and idx[-1] == n - 1
    gaps = np.diff(idx)
    assert gaps.min() >= int((n - 1) / (k - 1)) and gaps.max() <= int((n - 1) / (k - 1)) + 1


def test_systematic_sample_refuses_nonsense():
    with pytest.raises(ValueError, match="systematic_sample"):
        systematic_sample(10, 0)

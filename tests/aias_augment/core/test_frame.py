import numpy as np
import pytest

from aias_augment.core.frame import changed_pixels


@pytest.mark.parametrize("channels", [1, 3, 4])
def test_changed_pixels_are_those_with_any_channel_changed(channels):
    """The channel planes OR-ed are numpy's any over the channel axis, for every channel count; the inputs are left
    as they are."""
    rng = np.random.default_rng(channels)
    a = rng.integers(0, 256, (37, 53, channels), dtype=np.uint8)
    b = a.copy()
    flip = rng.random(a.shape) < 0.05
    b[flip] ^= 1
    got = changed_pixels(a, b)
    np.testing.assert_array_equal(got, np.any(a != b, axis=-1))
    assert got.shape == (37, 53) and got.any() and not got.all()
    assert not changed_pixels(a, a.copy()).any()

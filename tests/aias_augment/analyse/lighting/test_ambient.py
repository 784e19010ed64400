import numpy as np
import pytest

from aias_augment.analyse.lighting.ambient import achromatic_light_colour
from aias_augment.core.hdr import luminance


def _achromatic_by_pixel_rows(linear, max_chroma=0.05, min_share=0.01):
    """The light's colour from (N, 3) float64 pixel rows, each test a reduction over a pixel's 3 channels."""
    px = np.asarray(linear, np.float64).reshape(-1, 3)
    s = px.sum(1)
    ok = (px.max(1) < 0.98) & (s > 3 * 0.02)
    grey = np.abs(px[ok, :2] / s[ok, None] - 1.0 / 3.0).max(1) < max_chroma
    if grey.sum() < max(min_share * len(px), 20):
        return None
    c = np.median(px[ok][grey], axis=0)
    lum = float(luminance(c))
    return c / lum if lum > 0 and c.min() > 0 else None


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_light_colour_on_channel_planes_is_the_per_pixel_computation(dtype):
    """The grey-surface colour, computed on the three channel planes: the same numbers as the per-pixel rows (sums in
    numpy's order, maxima, per-column medians), with grey, coloured, dark and clipped pixels, odd and even counts."""
    rng = np.random.default_rng(1)
    for n in (4001, 4000):
        grey = rng.uniform(0.05, 0.9, (n, 1)) * rng.uniform(0.96, 1.04, (n, 3))
        coloured = rng.uniform(0.0, 1.0, (n // 2, 3))
        img = np.concatenate([grey, coloured, np.full((50, 3), 0.99), np.full((50, 3), 0.01)]).astype(dtype)
        got = achromatic_light_colour(img.reshape(1, -1, 3))
        want = _achromatic_by_pixel_rows(img)
        assert got is not None and got.dtype == want.dtype
        np.testing.assert_array_equal(got, want)
    assert achromatic_light_colour(rng.uniform(0, 1, (20, 20, 3)) * [1.0, 0.2, 0.1]) is None  # nothing grey

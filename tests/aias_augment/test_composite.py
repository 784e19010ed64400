import numpy as np

from aias_augment import composite as comp


def test_to_linear_is_the_iec_srgb_decoding_of_every_level():
    """The uint8 table lookup against IEC 61966-2-1 evaluated in float64 for all 256 levels, and the same values as
    the float path (``srgb_to_linear(image / 255)``) on an image."""
    k = np.arange(256) / 255.0
    iec = np.where(k <= 0.04045, k / 12.92, ((k + 0.055) / 1.055) ** 2.4)
    got = comp.to_linear(np.arange(256, dtype=np.uint8))
    assert got.dtype == np.float32
    np.testing.assert_allclose(got, iec, rtol=1e-6, atol=1e-7)
    img = np.random.default_rng(0).integers(0, 256, (7, 5, 3), dtype=np.uint8)
    assert np.array_equal(comp.to_linear(img), comp.to_linear(img.astype(np.float32)))
    assert np.array_equal(comp.to_uint8(comp.to_linear(img)), img)   # the round trip is exact on uint8

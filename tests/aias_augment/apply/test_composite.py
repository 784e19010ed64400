import numpy as np

from aias_augment.apply import composite as comp


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
    assert np.array_equal(comp.to_uint8(comp.to_linear(img)), img)  # the round trip is exact on uint8


def test_to_uint8_is_the_srgb_encoding_rounded():
    """to_uint8 against IEC 61966-2-1 encoding evaluated in float64: equal after rounding except where the float64
    value lies within float32 error of a half level; out-of-range and non-finite values clipped (NaN -> 0)."""
    rng = np.random.default_rng(2)
    x = np.concatenate([rng.random(20000), rng.random(2000) * 0.004, [0.0, 1.0, 0.0031308]]).astype(np.float32)
    xd = x.astype(np.float64)
    enc = np.where(xd <= 0.0031308, 12.92 * xd, 1.055 * xd ** (1 / 2.4) - 0.055) * 255.0
    got = comp.to_uint8(x[:, None, None].repeat(3, 2))[:, 0, 0].astype(int)
    near_half = np.abs(enc - np.floor(enc) - 0.5) < 1e-3
    assert np.array_equal(got[~near_half], np.rint(enc[~near_half]).astype(int))
    assert np.all(np.abs(got - enc) <= 0.5 + 1e-3)
    assert comp.to_uint8(np.array([[[-1.0, 2.0, 0.5]]], np.float32)).tolist() == [[[0, 255, 188]]]

"""The one sRGB curve: IEC 61966-2-1 reference values (computed here from the standard's constants in double
precision, and the published 0.5 -> 0.2140 / 0.7354 values), both ends, the round trip of every 8-bit level, and
every former curve of the package is this one."""

from __future__ import annotations

import numpy as np
import pytest

from aias_augment.core.srgb import linear_to_srgb, linear_to_srgb_uint8, srgb_to_linear


def _iec_decode(v: float) -> float:  # the standard's formula, written out in Python floats
    return v / 12.92 if v <= 0.04045 else ((v + 0.055) / 1.055) ** 2.4


@pytest.mark.parametrize(
    "encoded, linear",
    [
        (0.0, 0.0),
        (1.0, 1.0),
        (0.5, 0.21404114),  # the commonly quoted 0.5 -> 0.2140
        (0.04045, 0.04045 / 12.92),  # the two branches meet at 0.04045 -> 0.0031308
        (0.02, 0.02 / 12.92),
        (0.735356983, 0.5),  # linear 0.5 encodes to 0.7354
        (118 / 255, 0.18116424),  # 8-bit 118: mid-grey (18 %) in sRGB
    ],
)
def test_iec_61966_reference_values(encoded, linear):
    assert abs(_iec_decode(encoded) - linear) < 1e-6  # the table itself against the standard's formula
    assert srgb_to_linear(np.float32(encoded)) == pytest.approx(linear, abs=2e-7)
    assert srgb_to_linear(np.float64(encoded), dtype=np.float64) == pytest.approx(linear, abs=1e-8)
    assert linear_to_srgb(np.float32(linear)) == pytest.approx(encoded, abs=1e-6)
    # the standard's two encoding branches miss each other by 3e-8 at 0.0031308 (its constants are rounded)
    assert linear_to_srgb(np.float64(linear), dtype=np.float64) == pytest.approx(encoded, abs=5e-8)


def test_every_8bit_level_round_trips_and_uint8_is_divided_by_255():
    levels = np.arange(256, dtype=np.uint8)
    linear = srgb_to_linear(levels)
    assert linear.dtype == np.float32 and linear[0] == 0.0 and linear[255] == 1.0
    assert np.all(np.diff(linear) > 0)
    assert np.array_equal(linear, srgb_to_linear(levels.astype(np.float32) / np.float32(255.0)))
    assert np.array_equal(linear_to_srgb_uint8(linear), levels)


def test_out_of_range_and_non_finite_values_are_clipped():
    x = np.array([-0.5, np.nan, np.inf, -np.inf, 2.0], np.float32)
    assert np.array_equal(srgb_to_linear(x), [0, 0, 1, 0, 1])
    assert linear_to_srgb(x) == pytest.approx([0, 0, 1, 0, 1], abs=1e-7)  # 1.055 - 0.055 in float32: 1 - 2^-24
    assert np.array_equal(linear_to_srgb_uint8(x), [0, 0, 255, 0, 255])
    with pytest.raises(ValueError, match="uint8 or float"):
        srgb_to_linear(np.array([1000], np.uint16))


def test_the_package_has_one_curve():
    from aias_augment.apply import render
    from aias_augment.apply.harmonize import color
    from aias_augment.core import hdr

    for module in (render, color, hdr):
        assert module.srgb_to_linear is srgb_to_linear and module.linear_to_srgb is linear_to_srgb, module.__name__


def test_composite_and_shading_encode_with_it():
    from aias_augment.apply.composite import to_linear, to_uint8
    from aias_augment.apply.shading import fluorescent_gain

    rng = np.random.default_rng(0)
    lin = rng.uniform(-0.1, 1.1, (64, 3)).astype(np.float32)
    assert np.array_equal(to_uint8(lin), np.round(255 * np.clip(linear_to_srgb(lin), 0, 1)).astype(np.uint8))
    u8 = rng.integers(0, 256, (8, 8, 3), dtype=np.uint8)
    assert np.array_equal(to_linear(u8), srgb_to_linear(u8))
    # a saturated orange given by its sRGB value: the fluorescent weight reads the albedo back in sRGB
    orange_linear = srgb_to_linear(np.array([[1.0, 0.35, 0.0]]), dtype=np.float64)
    assert fluorescent_gain(orange_linear)[0] > 1.0 and fluorescent_gain(np.array([[0.5, 0.5, 0.5]]))[0] == 1.0


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_uint8_table_is_the_curve_of_the_float_levels(dtype):
    """uint8 input is decoded by a 256-entry table: every level, in any shape and memory layout, is the curve
    evaluated on the float value level / 255 (the float path), bit for bit."""
    rng = np.random.default_rng(0)
    for a in (
        np.arange(256, dtype=np.uint8),
        rng.integers(0, 256, (48, 64, 3), dtype=np.uint8),
        rng.integers(0, 256, (48, 64, 3), dtype=np.uint8)[::2, ::-3],  # not contiguous
        rng.integers(0, 256, (5,), dtype=np.uint8),
    ):
        got = srgb_to_linear(a, dtype)
        want = srgb_to_linear(a.astype(dtype) / dtype(255.0), dtype)
        assert got.dtype == dtype and got.shape == a.shape
        np.testing.assert_array_equal(got, want)
    zero_d = srgb_to_linear(np.array(200, np.uint8))
    assert (
        isinstance(zero_d, np.ndarray)
        and zero_d.shape == ()
        and zero_d == srgb_to_linear(np.float32(200) / np.float32(255))
    )

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from aias_augment.core import hdr


def test_srgb_round_trip_all_codes():
    codes = np.arange(256, dtype=np.uint8).reshape(1, -1, 1).repeat(3, axis=2)
    back = np.round(hdr.linear_to_srgb(hdr.srgb_to_linear(codes)) * 255).astype(np.uint8)
    assert np.array_equal(back, codes)


def test_srgb_known_values():
    # IEC 61966-2-1: code 128 -> 0.2158605, code 255 -> 1, linear 0.0031308 at the knee.
    assert hdr.srgb_to_linear(np.array([[[128, 255, 0]]], np.uint8))[0, 0] == pytest.approx(
        [0.2158605, 1.0, 0.0], abs=1e-6
    )


def test_inverse_tone_map_keeps_unclipped_and_expands_clipped_core():
    img = np.full((40, 40, 3), 100, np.uint8)
    img[10:30, 10:30] = 255  # a clipped 20x20 block
    out = hdr.inverse_tone_map(img, hdr.InverseToneMapParams(max_gain=50.0, core_radius_px=5.0))
    lin = hdr.srgb_to_linear(img)
    assert np.allclose(out[0:5], lin[0:5])  # far from the block: exact sRGB decode
    assert out[20, 20, 0] == pytest.approx(50.0, rel=0.05)  # deep inside: full gain
    assert 1.0 <= out[10, 20, 0] < out[15, 20, 0] < out[20, 20, 0]  # grows monotonically inward


@pytest.mark.parametrize("value", [0, 255])
def test_inverse_tone_map_extremes_finite(value):
    img = np.full((16, 24, 3), value, np.uint8)
    out = hdr.inverse_tone_map(img)
    assert np.all(np.isfinite(out)) and out.min() >= 0
    if value == 0:
        assert out.max() == 0


def test_exr_round_trip(tmp_path):
    rng = np.random.default_rng(1)
    rgb = (rng.random((8, 16, 3)) * np.array([1e-3, 1.0, 1e5])).astype(np.float32)
    hdr.write_exr(tmp_path / "a.exr", rgb)
    assert np.array_equal(hdr.read_exr(tmp_path / "a.exr"), rgb)


def test_radiance_hdr_round_trip(tmp_path):
    rng = np.random.default_rng(2)
    rgb = (rng.random((8, 16, 3)) * 1e5 + 1.0).astype(np.float32)
    hdr.write_hdr_image(tmp_path / "a.hdr", rgb)
    back = hdr.read_hdr_image(tmp_path / "a.hdr")
    # RGBE: 8-bit mantissas sharing the exponent of the largest channel -> error <= max channel / 128.
    assert np.all(np.abs(back - rgb) <= rgb.max(axis=2, keepdims=True) / 128)


def test_io_errors(tmp_path):
    with pytest.raises(FileNotFoundError):
        hdr.read_hdr_image(tmp_path / "missing.exr")
    with pytest.raises(ValueError, match="unsupported"):
        hdr.read_hdr_image(tmp_path / "x.png")
    with pytest.raises(ValueError, match="NaN"):
        hdr.write_exr(tmp_path / "n.exr", np.full((2, 2, 3), np.nan, np.float32))


def test_reads_blender_map(blender_world):
    rgb = hdr.read_hdr_image(blender_world("sunrise"))
    assert rgb.shape == (512, 1024, 3) and rgb.min() >= 0 and rgb.max() > 1e4


@settings(max_examples=40, deadline=None)
@given(st.integers(0, 255), st.integers(0, 255), st.integers(0, 255))
def test_inverse_tone_map_never_nan(r, g, b):
    img = np.zeros((6, 7, 3), np.uint8)
    img[...] = (r, g, b)
    img[2:4, 2:4] = 255
    out = hdr.inverse_tone_map(img)
    assert np.all(np.isfinite(out)) and out.min() >= 0

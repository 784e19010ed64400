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


# ------------------------------------------------------------------------------ size checked from the header
def _exr_claiming(tmp_path, width: int, height: int):
    """A small real EXR whose header's data window is rewritten to ``width`` x ``height``: its pixel data is that of
    a 16x8 image, so decoding it would allocate the claimed size and then fail; its header costs nothing."""
    import struct

    p = tmp_path / "huge.exr"
    hdr.write_exr(p, np.ones((8, 16, 3), np.float32))
    data = bytearray(p.read_bytes())
    key = b"dataWindow\0box2i\0" + struct.pack("<i", 16)
    at = data.index(key) + len(key)
    assert struct.unpack("<4i", data[at : at + 16]) == (0, 0, 15, 7)
    data[at : at + 16] = struct.pack("<4i", 0, 0, width - 1, height - 1)
    p.write_bytes(bytes(data))
    return p


def test_exr_size_from_the_header(tmp_path):
    hdr.write_exr(tmp_path / "a.exr", np.zeros((8, 16, 3), np.float32))
    assert hdr.exr_size(tmp_path / "a.exr") == (16, 8, 3)
    assert hdr.exr_size(_exr_claiming(tmp_path, 16384, 8192)) == (16384, 8192, 3)


def test_16k_exr_refused_from_the_header(tmp_path):
    from aias_augment.core.image_io import ImageTooLarge

    with pytest.raises(ImageTooLarge, match=r"huge.exr: 16384x8192 is above the 33.5544 MP limit"):
        hdr.read_hdr_image(_exr_claiming(tmp_path, 16384, 8192))


def _radiance_claiming(tmp_path, resolution: bytes):
    p = tmp_path / "huge.hdr"
    p.write_bytes(b"#?RADIANCE\nFORMAT=32-bit_rle_rgbe\n\n" + resolution + b"\n" + b"\x02\x02\x40\x00" * 4)
    return p


def test_radiance_size_from_the_header(tmp_path):
    hdr.write_hdr_image(tmp_path / "a.hdr", np.ones((8, 16, 3), np.float32))
    assert hdr.radiance_hdr_size(tmp_path / "a.hdr") == (16, 8)
    assert hdr.radiance_hdr_size(_radiance_claiming(tmp_path, b"+X 300 -Y 200")) == (300, 200)


def test_16k_radiance_hdr_refused_from_the_header(tmp_path):
    from aias_augment.core.image_io import ImageTooLarge

    with pytest.raises(ImageTooLarge, match="16384x8192 is above"):
        hdr.read_hdr_image(_radiance_claiming(tmp_path, b"-Y 8192 +X 16384"))


def test_hdr_at_the_bound_is_read(tmp_path):
    rgb = np.ones((8, 16, 3), np.float32)
    hdr.write_exr(tmp_path / "a.exr", rgb)
    assert np.array_equal(hdr.read_hdr_image(tmp_path / "a.exr", max_pixels=128), rgb)
    with pytest.raises(ValueError, match="above the"):
        hdr.read_hdr_image(tmp_path / "a.exr", max_pixels=127)


@pytest.mark.parametrize("body", [b"not an hdr", b"#?RADIANCE\n\n-Y x +X 3\n", b"#?RADIANCE\n\n-Y 2 -Y 3\n"])
def test_bad_radiance_header_one_line(tmp_path, body):
    (tmp_path / "b.hdr").write_bytes(body)
    with pytest.raises(ValueError, match="b.hdr: ") as e:
        hdr.read_hdr_image(tmp_path / "b.hdr")
    assert "\n" not in str(e.value)


def test_bad_exr_header_one_line(tmp_path):
    (tmp_path / "b.exr").write_bytes(b"\x76\x2f\x31\x01garbage")
    with pytest.raises(ValueError, match="b.exr: not a readable EXR header") as e:
        hdr.read_hdr_image(tmp_path / "b.exr")
    assert "\n" not in str(e.value)


def test_envmap_flag_refuses_a_16k_map_in_one_line(tmp_path):
    from aias_augment.cli.augment import envmap_fact
    from aias_augment.core.errors import InputError

    with pytest.raises(InputError, match=r"^--envmap .*huge.exr: .*16384x8192 is above") as e:
        envmap_fact(str(_exr_claiming(tmp_path, 16384, 8192)))
    assert "\n" not in str(e.value)


def test_max_channel_is_the_reduction_over_the_last_axis():
    rng = np.random.default_rng(0)
    for a in (rng.random((7, 9, 3), dtype=np.float32), rng.normal(size=(11, 3)), rng.integers(0, 256, (4, 5, 3))):
        np.testing.assert_array_equal(hdr.max_channel(a), a.max(axis=-1))
    a = np.array([[np.nan, 0.0, 1.0], [0.5, -0.0, 0.0]])
    np.testing.assert_array_equal(hdr.max_channel(a), a.max(axis=-1))
    with pytest.raises(ValueError, match="max_channel"):
        hdr.max_channel(np.zeros((4, 4)))


def _inverse_tone_map_whole_image(img, p):
    """inverse_tone_map's expansion computed on every pixel of the image (distance map, blur, gain)."""
    from scipy import ndimage

    unit = img.astype(np.float32) / 255.0
    linear = hdr.srgb_to_linear(unit)
    clipped = unit.max(axis=2) >= p.clip_level
    if not clipped.any():
        return linear
    dist = ndimage.distance_transform_edt(np.pad(clipped, 1))[1:-1, 1:-1]
    s = np.clip(dist / p.core_radius_px, 0.0, 1.0) ** p.gamma
    if p.smooth_sigma_px > 0:
        s = ndimage.gaussian_filter(s, p.smooth_sigma_px, mode="nearest")
    gain = 1.0 + (p.max_gain - 1.0) * np.where(clipped, s, 0.0)
    return (linear * gain[..., None].astype(np.float32)).astype(np.float32)


@pytest.mark.parametrize("sigma", [0.0, 1.5, 4.0])
def test_inverse_tone_map_on_the_clipped_box_is_the_whole_image_bit_for_bit(sigma):
    """The expansion runs on the clipped pixels' bounding box grown by one pixel: every pixel equals the whole-image
    computation, for blobs inside, at the border, far apart (a box mostly unclipped) and everywhere."""
    rng = np.random.default_rng(int(sigma * 10))
    p = hdr.InverseToneMapParams(smooth_sigma_px=sigma)
    base = rng.integers(0, 240, (60, 90, 3), dtype=np.uint8)
    images = [base.copy() for _ in range(4)]
    images[0][20:29, 30:44] = 255  # one blob inside
    images[1][0:7, 80:90, 1] = 252  # a blob at the corner, one channel
    images[2][5:9, 3:8] = 255
    images[2][50:55, 70:88] = 251  # two blobs far apart
    images[3][:] = 255  # clipped everywhere
    images.append(base)  # nothing clipped
    for img in images:
        np.testing.assert_array_equal(hdr.inverse_tone_map(img, p), _inverse_tone_map_whole_image(img, p))

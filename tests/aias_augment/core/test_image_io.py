"""The one image reader: header-checked size, typed errors, the pixels of an independent decoder."""

from __future__ import annotations

import io
import pickle
import struct
import zlib

import cv2
import numpy as np
import pytest
from PIL import Image, ImageOps

from aias_augment.core.errors import InputError
from aias_augment.core.image_io import (
    CorruptImage,
    ImageTooLarge,
    UnreadableImage,
    UnsupportedImage,
    image_size,
    read_image,
    read_image_with_notes,
)


def _picture(h=48, w=64) -> np.ndarray:
    """RGB uint8 with four distinct quadrants (orientation is visible)."""
    img = np.zeros((h, w, 3), np.uint8)
    img[: h // 2, : w // 2] = (250, 10, 10)
    img[: h // 2, w // 2 :] = (10, 250, 10)
    img[h // 2 :, : w // 2] = (10, 10, 250)
    img[h // 2 :, w // 2 :] = (240, 240, 240)
    return img


def _png_header_only(width: int, height: int) -> bytes:
    """A PNG whose IHDR says ``width`` x ``height`` and whose pixel data stops after a few bytes: decoding it would
    allocate width * height * 3 bytes and then fail; reading its header costs nothing."""

    def chunk(tag: bytes, body: bytes) -> bytes:
        return struct.pack(">I", len(body)) + tag + body + struct.pack(">I", zlib.crc32(tag + body))

    ihdr = struct.pack(">IIBBBBB", width, height, 8, 2, 0, 0, 0)
    return b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", ihdr) + chunk(b"IDAT", zlib.compress(b"\0" * 1000))


def test_rgb_png_round_trip(tmp_path):
    img = _picture()
    Image.fromarray(img).save(tmp_path / "a.png")
    out, notes = read_image_with_notes(tmp_path / "a.png", max_pixels=10_000)
    assert out.dtype == np.uint8 and out.flags.c_contiguous and np.array_equal(out, img) and notes == []
    assert image_size(tmp_path / "a.png") == (64, 48)


def test_pixel_count_refused_from_the_header_before_decoding(tmp_path):
    # 12000 x 10000 = 120 MP said by the header, 1 KB of data: a size refusal (not a corrupt-data error) proves the
    # header was checked before any decode
    p = tmp_path / "huge.png"
    p.write_bytes(_png_header_only(12000, 10000))
    with pytest.raises(ImageTooLarge, match=r"^image too large: .*huge.png: 12000x10000 = 120.0 MP, above the 50 MP"):
        read_image(p, max_pixels=50_000_000)
    with pytest.raises(ImageTooLarge):
        image_size(p, max_pixels=50_000_000)
    # allowed by the bound, the same file is corrupt
    with pytest.raises(CorruptImage):
        read_image(p, max_pixels=200_000_000)


def test_exact_bound_is_allowed(tmp_path):
    Image.fromarray(_picture(10, 20)).save(tmp_path / "a.png")
    assert read_image(tmp_path / "a.png", max_pixels=200).shape == (10, 20, 3)
    with pytest.raises(ImageTooLarge):
        read_image(tmp_path / "a.png", max_pixels=199)


def test_truncated_jpeg_is_corrupt(tmp_path):
    ok, buf = cv2.imencode(".jpg", _picture(200, 300))
    p = tmp_path / "t.jpg"
    p.write_bytes(buf.tobytes()[: len(buf) // 3])
    with pytest.raises(CorruptImage, match="^corrupt image"):
        read_image(p, max_pixels=10**6)


def test_jpeg_without_end_marker_is_corrupt(tmp_path):
    ok, buf = cv2.imencode(".jpg", _picture())
    data = buf.tobytes()
    assert data.endswith(b"\xff\xd9")
    p = tmp_path / "noeoi.jpg"
    p.write_bytes(data[:-2])
    with pytest.raises(CorruptImage):
        read_image(p, max_pixels=10**6)


def test_exif_orientation_applied(tmp_path):
    # orientation 6 (rotate 90 CW to display): PIL's exif_transpose is the independent reference
    img = _picture(40, 80)
    exif = Image.Exif()
    exif[0x0112] = 6
    p = tmp_path / "rot.jpg"
    Image.fromarray(img).save(p, quality=100, exif=exif.tobytes())
    ref = np.asarray(ImageOps.exif_transpose(Image.open(p)).convert("RGB"))
    out = read_image(p, max_pixels=10**6)
    assert out.shape == ref.shape == (80, 40, 3)
    assert np.abs(out.astype(int) - ref.astype(int)).mean() < 2


def test_16bit_png_converted_with_note(tmp_path):
    img = _picture()
    cv2.imwrite(str(tmp_path / "d.png"), img[..., ::-1].astype(np.uint16) * 257)
    out, notes = read_image_with_notes(tmp_path / "d.png", max_pixels=10**6)
    assert np.array_equal(out, img) and notes == ["16-bit image converted to 8-bit (round(v / 257))"]


def test_grey_png_converted_with_note(tmp_path):
    Image.fromarray(np.full((5, 6), 77, np.uint8)).save(tmp_path / "g.png")
    out, notes = read_image_with_notes(tmp_path / "g.png", max_pixels=10**6)
    assert out.shape == (5, 6, 3) and (out == 77).all() and notes == ["PIL mode L converted to RGB"]


def test_float_tiff_unsupported(tmp_path):
    Image.fromarray(np.full((4, 4), 0.5, np.float32)).save(tmp_path / "f.tif")
    with pytest.raises(UnsupportedImage, match="PIL mode 'F'"):
        read_image(tmp_path / "f.tif", max_pixels=10**6)


@pytest.mark.parametrize("what", ["missing", "empty", "folder", "text"])
def test_unreadable_files(tmp_path, what):
    p = tmp_path / "x.png"
    if what == "empty":
        p.write_bytes(b"")
    elif what == "folder":
        p.mkdir()
    elif what == "text":
        p.write_text("not an image")
    err = CorruptImage if what == "text" else UnreadableImage
    with pytest.raises(err) as e:
        read_image(p, max_pixels=10**6)
    assert isinstance(e.value, InputError) and isinstance(e.value, ValueError)
    assert e.value.path == str(p) and str(p) in str(e.value) and "\n" not in str(e.value)


def test_errors_pickle_with_their_fields():
    e = ImageTooLarge("3x3 too big", "/x.png")
    back = pickle.loads(pickle.dumps(e))
    assert type(back) is ImageTooLarge and back.kind == "image too large" and str(back) == str(e)
    assert back.reason == "3x3 too big" and back.path == "/x.png"


def test_pil_bytes_address_not_in_message(tmp_path):
    p = tmp_path / "bad.png"
    p.write_bytes(b"\x89PNG\r\n\x1a\n" + b"\0" * 30)
    with pytest.raises(CorruptImage) as e:
        read_image(p, max_pixels=10**6)
    assert " at 0x" not in str(e.value)


def test_image_bytes_decoded_by_pil_agree(tmp_path):
    img = _picture()
    buf = io.BytesIO()
    Image.fromarray(img).save(buf, format="PNG")
    (tmp_path / "b.png").write_bytes(buf.getvalue())
    assert np.array_equal(read_image(tmp_path / "b.png", max_pixels=10**6), np.asarray(Image.open(buf)))


def test_header_above_pils_own_ceiling_is_too_large_not_corrupt(tmp_path):
    p = tmp_path / "bomb.png"
    p.write_bytes(_png_header_only(20000, 20000))  # 400 MP: PIL refuses to open it at all
    with pytest.raises(ImageTooLarge, match=r"bomb.png: over 179 MP by its header, above the 120 MP limit"):
        read_image(p, max_pixels=120_000_000)

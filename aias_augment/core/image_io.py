"""The one image reader of the package: (H, W, 3) RGB uint8, its cost bounded from the header before any decode.

- The pixel count is read from the file's header (PIL opens lazily) and refused above ``max_pixels`` before a pixel
  is decoded: a 1.2 MB PNG of 20000x20000 costs a header read, not 1.2 GB.
- Truncated or corrupt files raise :class:`CorruptImage`: a full PIL decode with truncation errors on (libjpeg's
  warnings are not enough: OpenCV decodes a third of a JPEG and fills the rest with grey), and a JPEG must end with
  its end-of-image marker.
- The pixels are OpenCV's, turned upright by the file's EXIF orientation as PIL reads it (the tag
  ``ImageOps.exif_transpose`` uses), for every format: :func:`image_size` reports the same upright size.
- ``min_long_side`` decodes a JPEG at 1/2, 1/4 or 1/8 scale (libjpeg's DCT scaling, much faster) while its longer
  side stays >= ``min_long_side``; ``grey`` decodes one channel with OpenCV's grey decode (libpng's and libjpeg's own
  conversion); ``allow_16bit=False`` refuses 16-bit files (where a 16-bit file is a depth map, not a picture).
- 16-bit PNG/TIFF: ``round(v / 257)`` to 8 bit (the full 16-bit range maps onto 0..255); grey / palette / RGBA:
  OpenCV's colour conversion (alpha dropped); float or 32-bit integer pixels: :class:`UnsupportedImage`. Each
  conversion is returned as a note by :func:`read_image_with_notes`.

Every error is an :class:`ImageReadError` (an :class:`~aias_augment.core.errors.InputError`, so a ``ValueError``)
with ``kind`` (``"unreadable image"``, ``"corrupt image"``, ``"unsupported image"``, ``"image too large"``),
``reason`` and ``path``; its message reads ``"<kind>: <path>: <reason>"``.
"""

from __future__ import annotations

import io
import re
import warnings
from pathlib import Path

import cv2
import numpy as np

from aias_augment.core.errors import InputError

# 120 MP holds a 100-MP medium-format frame (11648x8736); decoding one costs about 10 bytes per pixel at the peak
# (the file, PIL's copy, OpenCV's copy, the RGB view): ~1.2 GB for 8-bit, ~2.5 GB for 16-bit.
DEFAULT_MAX_PIXELS = 120_000_000
EXIF_ORIENTATION = 0x0112


class ImageReadError(InputError):
    """An image that cannot be used: ``kind`` names the class of problem (what reports count), ``reason`` the detail,
    ``path`` the file (``None`` for bytes)."""

    kind = "unreadable image"

    def __init__(self, reason: str, path=None):
        self.reason, self.path = reason, None if path is None else str(path)
        super().__init__(f"{self.kind}: {self.path}: {reason}" if path is not None else f"{self.kind}: {reason}")

    def __reduce__(self):  # pickled (Ray, spawned workers) with its fields
        return (type(self), (self.reason, self.path))


class UnreadableImage(ImageReadError):
    """The file cannot be read (missing, a folder, no permission, empty) or decoded at all."""

    kind = "unreadable image"


class CorruptImage(ImageReadError):
    """Truncated or corrupt data: a decoder error, a decoder warning, a JPEG without its end-of-image marker."""

    kind = "corrupt image"


class UnsupportedImage(ImageReadError):
    """A readable image whose pixels are not 8- or 16-bit integers (float, 32-bit integer)."""

    kind = "unsupported image"


class ImageTooLarge(ImageReadError):
    """More pixels (from the header) than the reader was allowed to decode."""

    kind = "image too large"


def _read_bytes(path: Path) -> bytes:
    try:
        data = path.read_bytes()
    except OSError as e:
        raise UnreadableImage(str(e.strerror or e), path) from None
    if not data:
        raise UnreadableImage("empty file", path)
    return data


def _pil_detail(e: Exception) -> str:
    # PIL names an in-memory file by its address ("<_io.BytesIO object at 0x7f...>"): not reproducible, dropped
    return f"{type(e).__name__}: " + re.sub(r"<[^<>]* at 0x[0-9a-fA-F]+>", "the file", str(e))


def _header(data: bytes, path: Path, max_pixels: int) -> tuple[int, int]:
    """(width, height) from the header alone; :class:`ImageTooLarge` above ``max_pixels``."""
    from PIL import Image

    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", Image.DecompressionBombWarning)  # the bound is ours, checked below
            with Image.open(io.BytesIO(data)) as im:
                width, height = im.size
    except Image.DecompressionBombError:  # PIL's own ceiling, 2 x Image.MAX_IMAGE_PIXELS: it gives no size
        ceiling = 2 * (Image.MAX_IMAGE_PIXELS or 0)
        raise ImageTooLarge(
            f"over {ceiling / 1e6:.0f} MP by its header, above the {min(max_pixels, ceiling) / 1e6:g} MP limit "
            "(resize it first)",
            path,
        ) from None
    except Exception as e:  # PIL raises OSError, SyntaxError, ValueError... for unrecognised or broken headers
        raise CorruptImage(_pil_detail(e), path) from None
    if width * height > max_pixels:
        raise ImageTooLarge(
            f"{width}x{height} = {width * height / 1e6:.1f} MP, above the {max_pixels / 1e6:g} MP limit "
            "(resize it first)",
            path,
        )
    return width, height


def _orientation(im) -> int:
    """EXIF orientation (1..8; 1 for none or an invalid value) of an open PIL image, as ``ImageOps.exif_transpose``
    reads it. A PNG's eXIf chunk is in ``im.info`` once read: PIL's ``getexif`` would decode the whole PNG to look
    past the pixel data, so a PNG is looked up in what has been read."""
    if im.format == "PNG":
        raw = im.info.get("exif")
        if not raw:
            return 1
        from PIL import Image

        exif = Image.Exif()
        exif.load(raw)
    else:
        exif = im.getexif()
    value = exif.get(EXIF_ORIENTATION, 1)
    return value if value in range(1, 9) else 1


def upright(img: np.ndarray, orientation: int) -> np.ndarray:
    """``img`` (H, W[, C]) as displayed for EXIF ``orientation`` 1..8 (PIL's ``exif_transpose`` transforms)."""
    if orientation in (5, 6, 7, 8):
        img = np.swapaxes(img, 0, 1)  # transpose; then a flip makes each rotation
    flip_rows, flip_cols = {
        1: (False, False),
        2: (False, True),
        3: (True, True),
        4: (True, False),
        5: (False, False),
        6: (False, True),
        7: (True, True),
        8: (True, False),
    }[orientation]
    if flip_rows:
        img = img[::-1]
    if flip_cols:
        img = img[:, ::-1]
    return np.ascontiguousarray(img)


def image_size(path, *, max_pixels: int = DEFAULT_MAX_PIXELS) -> tuple[int, int]:
    """(width, height) of the image :func:`read_image` returns for ``path`` (EXIF orientation applied), from its
    header without decoding a pixel; :class:`ImageReadError` as :func:`read_image`."""
    path = Path(path)
    data = _read_bytes(path)
    width, height = _header(data, path, max_pixels)
    return (height, width) if _header_orientation(data) in (5, 6, 7, 8) else (width, height)


def _header_orientation(data: bytes) -> int:
    from PIL import Image

    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # the header was read once already; its warnings are read_image's
            with Image.open(io.BytesIO(data)) as im:
                return _orientation(im)
    except Exception:  # a broken EXIF block: read_image refuses the file as corrupt
        return 1


def _full_decode_mode(data: bytes, path: Path) -> tuple[str, int]:
    """Decode every pixel with PIL, truncation and decoder warnings as errors; returns the PIL mode and the EXIF
    orientation."""
    from PIL import Image, ImageFile

    ImageFile.LOAD_TRUNCATED_IMAGES = False
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("error")  # PIL's decoder warnings (e.g. corrupt EXIF) become errors
            warnings.simplefilter("ignore", Image.DecompressionBombWarning)  # size checked from the header
            with Image.open(io.BytesIO(data)) as im:
                im.verify()
            with Image.open(io.BytesIO(data)) as im:
                im.load()
                return im.mode, _orientation(im)
    except Exception as e:
        raise CorruptImage(_pil_detail(e), path) from None


_REDUCED = ((8, cv2.IMREAD_REDUCED_COLOR_8), (4, cv2.IMREAD_REDUCED_COLOR_4), (2, cv2.IMREAD_REDUCED_COLOR_2))
_EIGHT_BIT_MODES = ("RGB", "I;16", "I;16B", "I;16L")
_GREY_MODES = ("L", "I;16", "I;16B", "I;16L")


def _decode_flags(width: int, height: int, min_long_side: int | None, grey: bool) -> int:
    """OpenCV flags: any depth, orientation left to :func:`upright`, the smallest JPEG scale keeping the longer side
    >= ``min_long_side`` (the grey variant of each reduced flag is the colour one less 1)."""
    flags = cv2.IMREAD_GRAYSCALE if grey else cv2.IMREAD_COLOR
    if min_long_side:
        for factor, reduced in _REDUCED:
            if max(width, height) / factor >= min_long_side:
                flags = reduced - 1 if grey else reduced
                break
    return flags | cv2.IMREAD_ANYDEPTH | cv2.IMREAD_IGNORE_ORIENTATION


def read_image_with_notes(
    path,
    *,
    max_pixels: int = DEFAULT_MAX_PIXELS,
    min_long_side: int | None = None,
    grey: bool = False,
    allow_16bit: bool = True,
) -> tuple[np.ndarray, list[str]]:
    """:func:`read_image` and the conversions made to reach RGB uint8, as sentences (empty for an 8-bit RGB file,
    or an 8-bit grey one with ``grey``)."""
    path = Path(path)
    data = _read_bytes(path)
    width, height = _header(data, path, max_pixels)
    mode, orientation = _full_decode_mode(data, path)
    if data[:2] == b"\xff\xd8" and b"\xff\xd9" not in data[-4096:]:
        raise CorruptImage("JPEG without end-of-image marker (truncated)", path)
    if mode in ("F", "I") or mode.startswith("BGR"):
        raise UnsupportedImage(
            f"PIL mode {mode!r} (float or 32-bit integer pixels are refused; convert to 8- or 16-bit first)", path
        )
    flags = _decode_flags(width, height, min_long_side, grey)
    img = cv2.imdecode(np.frombuffer(data, np.uint8), flags)
    if img is None or img.size == 0:
        raise UnreadableImage("OpenCV cannot decode it", path)
    notes = []
    if img.dtype == np.uint16:
        if not allow_16bit:
            raise UnsupportedImage("16-bit pixels where an 8-bit picture is expected (a depth map?)", path)
        img = np.round(img.astype(np.float32) / 257.0).astype(np.uint8)
        notes.append("16-bit image converted to 8-bit (round(v / 257))")
    elif img.dtype != np.uint8:
        raise UnsupportedImage(f"{img.dtype} pixels (only 8- and 16-bit integer images)", path)
    if mode not in (_GREY_MODES if grey else _EIGHT_BIT_MODES):
        notes.append(f"PIL mode {mode} converted to {'grey' if grey else 'RGB'}")
    if min(img.shape[:2]) < 1:
        raise UnreadableImage(f"size {img.shape[1]}x{img.shape[0]}", path)
    return upright(img if grey or img.ndim != 3 else cv2.cvtColor(img, cv2.COLOR_BGR2RGB), orientation), notes


def read_image(
    path,
    *,
    max_pixels: int = DEFAULT_MAX_PIXELS,
    min_long_side: int | None = None,
    grey: bool = False,
    allow_16bit: bool = True,
) -> np.ndarray:
    """The image at ``path`` as (H, W, 3) RGB uint8, or (H, W) uint8 with ``grey``, turned upright by its EXIF
    orientation; the pixel count is checked from the header before decoding (:class:`ImageTooLarge` above
    ``max_pixels``); truncated or corrupt data raises :class:`CorruptImage`, a missing or empty file
    :class:`UnreadableImage`, float pixels (or 16-bit ones without ``allow_16bit``) :class:`UnsupportedImage`.
    ``min_long_side`` lets a JPEG decode at 1/2, 1/4 or 1/8 scale while its longer side stays >= that."""
    return read_image_with_notes(
        path, max_pixels=max_pixels, min_long_side=min_long_side, grey=grey, allow_16bit=allow_16bit
    )[0]

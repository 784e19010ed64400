"""High dynamic range helpers: sRGB <-> linear, inverse tone mapping, EXR / Radiance .hdr input and output.

Conventions:
- "linear" images are float32 (H, W, 3) RGB with the sRGB / Rec.709 primaries, in relative radiance units (an 8-bit
  value of 255 maps to 1.0 before any highlight expansion). Nothing here knows absolute exposure.
- EXR files are read and written with the OpenEXR bindings (``OpenEXR.File``); Radiance ``.hdr`` with OpenCV, which
  reads and writes RGBE. Both return / accept RGB (not OpenCV's BGR).
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy import ndimage

from aias_augment.core.image_io import ImageTooLarge
from aias_augment.core.srgb import linear_to_srgb, linear_to_srgb_uint8, srgb_to_linear

__all__ = [
    "srgb_to_linear",
    "linear_to_srgb",
    "luminance",
    "max_channel",
    "InverseToneMapParams",
    "inverse_tone_map",
    "tone_map_to_uint8",
    "read_exr",
    "exr_size",
    "radiance_hdr_size",
    "MAX_HDR_PIXELS",
    "write_exr",
    "read_radiance_hdr",
    "write_radiance_hdr",
    "read_hdr_image",
    "write_hdr_image",
    "HDR_SUFFIXES",
]

#: Rec.709 / sRGB luminance weights for linear RGB.
LUMINANCE_WEIGHTS = np.array([0.2126, 0.7152, 0.0722], dtype=np.float32)
HDR_SUFFIXES = (".exr", ".hdr")
# 8192x4096 (an "8K" equirectangular map, 0.4 GB as float32 RGB) is the largest HDR image decoded: an environment map
# is used for its light, which a 2K map already resolves (the sun disc is ~0.5 deg); a 16K map (1.6 GB decoded, past
# 8 GB through the lighting) is refused from its header, before any pixel is read.
MAX_HDR_PIXELS = 8192 * 4096


def _check_hdr_size(path: Path, width: int, height: int, max_pixels: int, samples: float = 1.0) -> None:
    if width < 1 or height < 1:
        raise ValueError(f"{path}: empty image ({width}x{height}) in its header")
    if width * height * samples > max_pixels:
        extra = f" x {samples * 3:g} channels / 3" if samples != 1.0 else ""
        raise ImageTooLarge(
            f"{width}x{height}{extra} is above the {max_pixels / 1e6:g} MP limit of an HDR image (8192x4096); "
            "downsample it first (e.g. oiiotool IN --resize 4096x2048 -o OUT)",
            path,
        )


def _as_unit_float(image: np.ndarray) -> np.ndarray:
    """uint8 -> [0, 1] float32; float input is taken as already in [0, 1] (clipped there)."""
    img = np.asarray(image)
    if img.dtype == np.uint8:
        return img.astype(np.float32) / 255.0
    if not np.issubdtype(img.dtype, np.floating):
        raise ValueError(f"expected uint8 or float image, got {img.dtype}")
    return np.clip(np.nan_to_num(img.astype(np.float32), nan=0.0), 0.0, 1.0)


def max_channel(rgb: np.ndarray) -> np.ndarray:
    """Each pixel's largest channel, (*, 3) -> (*,): ``rgb.max(axis=-1)`` as two element-wise maxima (numpy reduces
    a 3-long last axis pixel by pixel, ~30x slower); NaN propagates as there."""
    a = np.asarray(rgb)
    if a.ndim == 0 or a.shape[-1] != 3:
        raise ValueError(f"max_channel: expected (*, 3) values, got {a.shape}")
    return np.maximum(np.maximum(a[..., 0], a[..., 1]), a[..., 2])


def luminance(rgb_linear: np.ndarray) -> np.ndarray:
    """Rec.709 luminance of linear RGB, (*, 3) -> (*,)."""
    return np.asarray(rgb_linear, dtype=np.float32) @ LUMINANCE_WEIGHTS


def tone_map_to_uint8(linear: np.ndarray, exposure: float | None = None, percentile: float = 99.0) -> np.ndarray:
    """Display helper: scale linear radiance so that ``percentile`` maps to 1 (or multiply by ``exposure``), sRGB encode."""
    lin = np.nan_to_num(np.asarray(linear, dtype=np.float32), nan=0.0, posinf=0.0, neginf=0.0)
    if exposure is None:
        ref = float(np.percentile(luminance(lin), percentile))
        exposure = 1.0 / max(ref, 1e-8)
    return linear_to_srgb_uint8(lin * exposure)


@dataclass(frozen=True)
class InverseToneMapParams:
    """Expansion of clipped highlights (an "expand map" in the spirit of Banterle et al. 2008).

    A pixel is clipped when its largest sRGB channel is >= ``clip_level``. Inside each clipped region the linear value is
    multiplied by ``1 + (max_gain - 1) * s``, where ``s`` in [0, 1] grows with the distance from the region border
    (``s = min(1, dist_px / core_radius_px) ** gamma``) and is smoothed by a Gaussian of ``smooth_sigma_px`` so that the
    boost has no seam. ``max_gain`` is what a saturated sun core is assumed to exceed the clip level by (LDR footage of
    the sun is clipped by 10^3..10^5; the default is conservative and leaves the sun direction to other estimators).
    """

    clip_level: float = 250.0 / 255.0
    max_gain: float = 50.0
    core_radius_px: float = 6.0
    gamma: float = 2.0
    smooth_sigma_px: float = 1.5

    def __post_init__(self):
        if not 0.0 < self.clip_level <= 1.0:
            raise ValueError(f"clip_level must be in (0, 1], got {self.clip_level}")
        if not self.max_gain >= 1.0:
            raise ValueError(f"max_gain must be >= 1, got {self.max_gain}")
        if self.core_radius_px <= 0 or self.gamma <= 0 or self.smooth_sigma_px < 0:
            raise ValueError("core_radius_px and gamma must be > 0, smooth_sigma_px >= 0")


def inverse_tone_map(image: np.ndarray, params: InverseToneMapParams = InverseToneMapParams()) -> np.ndarray:
    """LDR image (uint8 or float in [0, 1], sRGB-encoded, (H, W, 3)) -> linear HDR float32 (H, W, 3), >= 0, finite.

    Unclipped pixels are exactly :func:`srgb_to_linear`; clipped ones are expanded (see :class:`InverseToneMapParams`).
    An all-white image is one clipped region and gets the full gain in its interior; an all-black one stays 0.
    """
    img = np.asarray(image)
    if img.ndim != 3 or img.shape[2] != 3:
        raise ValueError(f"inverse_tone_map: expected (H, W, 3), got {img.shape}")
    if img.dtype == np.uint8:  # the curve and the clip test of img / 255 (float32), by 256-entry tables
        linear = srgb_to_linear(img)
        clipped = (np.arange(256, dtype=np.float32) / np.float32(255.0) >= params.clip_level)[max_channel(img)]
    else:
        unit = _as_unit_float(img)
        linear = srgb_to_linear(unit)
        clipped = max_channel(unit) >= params.clip_level
    if not clipped.any() or params.max_gain == 1.0:
        return linear
    # Only clipped pixels are expanded: the work runs on their bounding box grown by one pixel, the same numbers as on
    # the whole image. Outside the box nothing is clipped, so the nearest unclipped pixel of a clipped one is in the
    # box or its one-pixel ring, and the blurred map is 0 there (its first and last rows and columns, which the
    # blur's "nearest" border repeats, are unclipped: 0 as well).
    rows, cols = np.flatnonzero(clipped.any(axis=1)), np.flatnonzero(clipped.any(axis=0))
    box = (
        slice(max(rows[0] - 1, 0), min(rows[-1] + 2, img.shape[0])),
        slice(max(cols[0] - 1, 0), min(cols[-1] + 2, img.shape[1])),
    )
    clipped = clipped[box]
    # Distance to the nearest unclipped pixel; an image that is clipped everywhere counts its border as the edge.
    padded = np.pad(clipped, 1, constant_values=False)
    dist = ndimage.distance_transform_edt(padded)[1:-1, 1:-1]
    s = np.clip(dist / params.core_radius_px, 0.0, 1.0) ** params.gamma
    if params.smooth_sigma_px > 0:
        s = ndimage.gaussian_filter(s, params.smooth_sigma_px, mode="nearest")
    s = np.where(clipped, s, 0.0)
    gain = 1.0 + (params.max_gain - 1.0) * s
    linear[box] = (linear[box] * gain[..., None].astype(np.float32)).astype(np.float32)
    return linear


# ----------------------------------------------------------------------------------------------------------- file IO


def exr_size(path: str | Path) -> tuple[int, int, int]:
    """(width, height, channels) of an OpenEXR file's first part, from its header alone (the data window)."""
    import OpenEXR

    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"EXR not found: {path}")
    try:
        header = OpenEXR.File(str(path), header_only=True).header()
        (x0, y0), (x1, y1) = (np.asarray(v, dtype=np.int64) for v in header["dataWindow"])
        channels = len(header["channels"])
    except Exception as e:  # the bindings raise RuntimeError, KeyError... on a file that is no EXR
        raise ValueError(f"{path}: not a readable EXR header ({' '.join(str(e).split())})") from None
    return int(x1 - x0 + 1), int(y1 - y0 + 1), channels


def read_exr(path: str | Path, *, max_pixels: int = MAX_HDR_PIXELS) -> np.ndarray:
    """Read an OpenEXR file's RGB as float32 (H, W, 3). Accepts a packed 'RGB'/'RGBA' channel or separate R, G, B.
    The size (every channel counted: all are decoded) is checked from the header first: :class:`ImageTooLarge` above
    ``max_pixels`` RGB pixels."""
    import OpenEXR

    path = Path(path)
    width, height, n_channels = exr_size(path)
    _check_hdr_size(path, width, height, max_pixels, samples=max(n_channels, 3) / 3)
    with OpenEXR.File(str(path)) as f:
        channels = f.channels()
        if "RGB" in channels:
            rgb = np.asarray(channels["RGB"].pixels)
        elif "RGBA" in channels:
            rgb = np.asarray(channels["RGBA"].pixels)[..., :3]
        elif all(c in channels for c in "RGB"):
            rgb = np.stack([np.asarray(channels[c].pixels) for c in "RGB"], axis=-1)
        elif "Y" in channels:
            y = np.asarray(channels["Y"].pixels)
            rgb = np.stack([y, y, y], axis=-1)
        else:
            raise ValueError(f"{path}: no RGB or Y channels (found {sorted(channels)})")
    return np.ascontiguousarray(rgb, dtype=np.float32)


def write_exr(path: str | Path, rgb: np.ndarray, half: bool = False) -> None:
    """Write float RGB (H, W, 3) as a ZIP-compressed scanline EXR (float32, or half with ``half=True``)."""
    import OpenEXR

    rgb = np.asarray(rgb)
    if rgb.ndim != 3 or rgb.shape[2] != 3:
        raise ValueError(f"write_exr: expected (H, W, 3), got {rgb.shape}")
    if not np.all(np.isfinite(rgb)):
        raise ValueError("write_exr: image contains NaN or Inf")
    data = np.ascontiguousarray(rgb, dtype=np.float16 if half else np.float32)
    header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    with OpenEXR.File(header, {"RGB": data}) as f:
        f.write(str(path))


_RADIANCE_RESOLUTION = re.compile(rb"^([-+])([XY]) +(\d+) +([-+])([XY]) +(\d+)$")


def radiance_hdr_size(path: str | Path) -> tuple[int, int]:
    """(width, height) of a Radiance ``.hdr`` file from its header (the resolution line after the blank line)."""
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"HDR not found: {path}")
    with open(path, "rb") as f:
        head = f.read(1 << 16)
    if not head.startswith((b"#?", b"#?RADIANCE", b"#?RGBE")) or b"\n\n" not in head:
        raise ValueError(f"{path}: not a Radiance HDR file (no '#?' signature or header end in the first 64 KB)")
    line = head.split(b"\n\n", 1)[1].split(b"\n", 1)[0].strip()
    m = _RADIANCE_RESOLUTION.match(line)
    if not m or m[2] == m[5]:
        raise ValueError(f"{path}: bad Radiance resolution line {line[:40]!r}")
    first, second = int(m[3]), int(m[6])
    return (second, first) if m[2] == b"Y" else (first, second)


def read_radiance_hdr(path: str | Path, *, max_pixels: int = MAX_HDR_PIXELS) -> np.ndarray:
    """Read a Radiance RGBE ``.hdr`` file as float32 RGB (H, W, 3) with OpenCV, its size checked from the header
    first (:class:`ImageTooLarge` above ``max_pixels``)."""
    import cv2

    path = Path(path)
    width, height = radiance_hdr_size(path)
    _check_hdr_size(path, width, height, max_pixels)
    bgr = cv2.imread(str(path), cv2.IMREAD_ANYDEPTH | cv2.IMREAD_COLOR)
    if bgr is None:
        raise ValueError(f"{path}: OpenCV could not decode it as Radiance HDR")
    return np.ascontiguousarray(bgr[..., ::-1], dtype=np.float32)


def write_radiance_hdr(path: str | Path, rgb: np.ndarray) -> None:
    """Write float RGB (H, W, 3) as Radiance RGBE (8-bit mantissa: ~1% relative precision; negatives are clipped to 0)."""
    import cv2

    rgb = np.asarray(rgb, dtype=np.float32)
    if rgb.ndim != 3 or rgb.shape[2] != 3:
        raise ValueError(f"write_radiance_hdr: expected (H, W, 3), got {rgb.shape}")
    if not np.all(np.isfinite(rgb)):
        raise ValueError("write_radiance_hdr: image contains NaN or Inf")
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    if not cv2.imwrite(str(path), np.ascontiguousarray(np.clip(rgb, 0, None)[..., ::-1])):
        raise OSError(f"OpenCV failed to write {path}")


def read_hdr_image(path: str | Path, *, max_pixels: int = MAX_HDR_PIXELS) -> np.ndarray:
    """Read an EXR or Radiance .hdr by suffix; negative values (compression noise) are clipped to 0. The size is
    checked from the header before decoding (:class:`ImageTooLarge` above ``max_pixels``)."""
    suffix = Path(path).suffix.lower()
    if suffix == ".exr":
        rgb = read_exr(path, max_pixels=max_pixels)
    elif suffix == ".hdr":
        rgb = read_radiance_hdr(path, max_pixels=max_pixels)
    else:
        raise ValueError(f"unsupported HDR file type {suffix!r} for {path}; expected one of {HDR_SUFFIXES}")
    if not np.isfinite(rgb).all():
        raise ValueError(f"{path}: contains NaN or Inf pixels")
    return np.maximum(rgb, 0.0, out=rgb)


def write_hdr_image(path: str | Path, rgb: np.ndarray) -> None:
    suffix = Path(path).suffix.lower()
    if suffix == ".exr":
        write_exr(path, rgb)
    elif suffix == ".hdr":
        write_radiance_hdr(path, rgb)
    else:
        raise ValueError(f"unsupported HDR file type {suffix!r} for {path}; expected one of {HDR_SUFFIXES}")

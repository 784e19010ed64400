"""A views file (``views.json``) read for :mod:`aias_augment.assets.reconstruct`, its cost bounded before decoding.

``{"ground_z": 0.0 | null, "views": [{"image": PATH, "mask": PATH | null, "box": [x0, y0, x1, y1] | null, "K": 3x3,
"cam_from_object": 4x4 (optional)}, ...]}``, paths relative to the file.

Every entry is checked before a pixel is decoded: K a finite 3x3 with positive focal lengths, a pose a finite rigid
4x4, each image's pixel count read from its header (the package's reader, :mod:`aias_augment.core.image_io`,
refuses more than its ``DEFAULT_MAX_PIXELS``). A photo is then worked on at most at :data:`MAX_VIEW_PIXELS` (and all
views together at :data:`MAX_TOTAL_PIXELS`): larger ones are downscaled by area averaging with their K, mask and box,
which keeps the hull's cost (a distance transform, a render and a GrabCut per view) bounded: two 6000x4000 photos
cost as much as two 1730x1150 ones.
"""

from __future__ import annotations

import json
import logging
from pathlib import Path

import cv2
import numpy as np

from aias_augment.core.geometry import Intrinsics

log = logging.getLogger(__name__)

#: Working pixels of one view: a 1 m object 3 m away spans ~400 px of a 1730x1150 photo at a 50 degree field of
#: view, several times what a 128-voxel hull resolves.
MAX_VIEW_PIXELS = 2_000_000
#: Working pixels of all views together: about 1.5 GB of per-view buffers (RGB, mask, distance field, grey).
MAX_TOTAL_PIXELS = 64_000_000
MAX_VIEWS = 512


def _matrix(value, shape: tuple[int, ...], name: str) -> np.ndarray:
    try:
        m = np.asarray(value, float)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be a {'x'.join(map(str, shape))} array of numbers") from None
    if m.shape != shape:
        raise ValueError(f"{name} must be {'x'.join(map(str, shape))}, got shape {m.shape}")
    if not np.isfinite(m).all():
        raise ValueError(f"{name} has NaN or infinite entries")
    return m


def _intrinsics(value) -> np.ndarray:
    K = _matrix(value, (3, 3), "K")
    if not (K[0, 0] > 0 and K[1, 1] > 0):
        raise ValueError(f"K needs positive focal lengths, got fx {K[0, 0]:g}, fy {K[1, 1]:g}")
    return K


def _pose(value) -> np.ndarray | None:
    if value is None:
        return None
    T = _matrix(value, (4, 4), "cam_from_object")
    R = T[:3, :3]
    if not np.allclose(T[3], [0, 0, 0, 1]) or not np.allclose(R.T @ R, np.eye(3), atol=1e-3) or np.linalg.det(R) < 0:
        raise ValueError("cam_from_object must be a rigid transform (rotation, translation, last row 0 0 0 1)")
    return T


def _scaled(rgb: np.ndarray, mask: np.ndarray | None, K: np.ndarray, max_pixels: int):
    """The view at most ``max_pixels``: area-averaged, K scaled about pixel centres, the mask at half coverage."""
    h, w = rgb.shape[:2]
    if h * w <= max_pixels:
        return rgb, mask, K, 1.0
    s = float(np.sqrt(max_pixels / (h * w)))
    size = (max(1, int(w * s)), max(1, int(h * s)))
    sx, sy = size[0] / w, size[1] / h
    rgb = cv2.resize(rgb, size, interpolation=cv2.INTER_AREA)
    if mask is not None:
        mask = cv2.resize(mask.astype(np.float32), size, interpolation=cv2.INTER_AREA) > 0.5
    K = K.copy()
    K[0] *= sx
    K[1] *= sy
    K[0, 2] += 0.5 * sx - 0.5  # pixel centres: (c + 0.5) s - 0.5
    K[1, 2] += 0.5 * sy - 0.5
    return rgb, mask, K, (sx + sy) / 2


def _spec(path: Path) -> tuple[list[dict], float | None]:
    try:
        spec = json.loads(path.read_bytes().decode("utf-8"))
    except (OSError, UnicodeDecodeError, ValueError, RecursionError) as e:  # RecursionError: nested too deep
        raise ValueError(f"{path}: not a readable views file ({type(e).__name__}: {e})") from None
    views = spec.get("views") if isinstance(spec, dict) else None
    if not isinstance(views, list) or not all(isinstance(e, dict) for e in views):
        raise ValueError(f'{path}: a views file is {{"views": [{{"image": ..., "K": ...}}, ...]}}')
    if len(views) > MAX_VIEWS:
        raise ValueError(f"{path}: at most {MAX_VIEWS} views, got {len(views)}")
    gz = spec.get("ground_z", 0.0)
    if gz is not None and not (isinstance(gz, (int, float)) and np.isfinite(gz)):
        raise ValueError(f"{path}: ground_z must be a finite number or null, got {gz!r}")
    return views, None if gz is None else float(gz)


def read_views(path) -> tuple[list[tuple[np.ndarray, np.ndarray, Intrinsics, np.ndarray | None]], float | None]:
    """The photos of a views file as (image, mask, intrinsics, pose or None), downscaled to the pixel bounds above (a
    view without a mask is segmented by GrabCut from its box). Bad entries: ValueError naming the file and view.
    Either every view has its pose or none has (then SfM finds them)."""
    from aias_augment.assets.view_masks import View, grabcut_mask
    from aias_augment.core.image_io import DEFAULT_MAX_PIXELS, image_size, read_image

    path = Path(path)
    entries, ground_z = _spec(path)
    max_pixels = min(MAX_VIEW_PIXELS, MAX_TOTAL_PIXELS // max(len(entries), 1))
    out = []
    for i, e in enumerate(entries):
        try:
            if not isinstance(e.get("image"), str):
                raise ValueError("needs an 'image' path")
            K, pose = _intrinsics(e.get("K")), _pose(e.get("cam_from_object"))
            image_size(path.parent / e["image"], max_pixels=DEFAULT_MAX_PIXELS)  # from the header: refused early
            rgb = read_image(path.parent / e["image"], max_pixels=DEFAULT_MAX_PIXELS)
            mask = None
            if e.get("mask"):
                mask = read_image(path.parent / e["mask"], max_pixels=DEFAULT_MAX_PIXELS)[..., 0] > 127
                if mask.shape != rgb.shape[:2]:
                    raise ValueError(
                        f"mask {e['mask']} is {mask.shape[1]}x{mask.shape[0]}, image {e['image']} "
                        f"{rgb.shape[1]}x{rgb.shape[0]}"
                    )
            elif not e.get("box"):
                raise ValueError("needs a mask or a box")
            rgb, mask, K, s = _scaled(rgb, mask, K, max_pixels)
            if s != 1.0:
                log.info("%s: view %d downscaled by %.3f to %dx%d", path, i, s, rgb.shape[1], rgb.shape[0])
            if mask is None:
                mask = grabcut_mask(rgb, _matrix(e["box"], (4,), "box") * s)
            h, w = mask.shape
            intr = Intrinsics(K[0, 0], K[1, 1], K[0, 2], K[1, 2], w, h)
            if pose is not None:
                View(rgb, mask, intr, pose)  # checks sizes and the mask
            out.append((rgb, mask, intr, pose))
        except (KeyError, ValueError, TypeError) as err:
            raise ValueError(f"{path}: view {i}: {err}") from None
    if len(out) < 2:
        raise ValueError(f"{path}: needs at least two views, got {len(out)}")
    if len({o[3] is None for o in out}) > 1:
        raise ValueError(f"{path}: some views have cam_from_object and some do not: give all or none")
    return out, ground_z

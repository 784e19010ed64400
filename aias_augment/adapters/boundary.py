"""Boundary checks of the offline augmentation: inputs (images, YOLO and COCO labels, arguments) and outputs.

Every problem is either a clear error (raised :class:`InputError`, the CLI exits non-zero) or a *named, counted*
problem: a dict ``{"kind", "file", "line", "reason"}`` that ends up in ``report.json``. Kinds that skip the whole
image are in :data:`IMAGE_SKIP_KINDS`; the others (clipped / dropped boxes, conversions) only change one box or say
what was done to the pixels.

Image conversions (explicit, recorded as a ``converted`` note):
- 16-bit PNG/TIFF: ``round(v / 257)`` to 8 bit (the full 16-bit range maps onto 0..255);
- grey / palette / RGBA: OpenCV's colour conversion (alpha dropped);
- float images and anything else that is not 8- or 16-bit integer: refused (a named skip).
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from aias_augment.core.errors import AiasError, InputError
from aias_augment.core.frame import changed_pixels
from aias_augment.core.image_io import DEFAULT_MAX_PIXELS, ImageReadError, image_size, read_image_with_notes

IMAGE_SKIP_KINDS = (
    "unreadable image",
    "corrupt image",
    "unsupported image",
    "image too large",
    "garbage label line",
    "class id out of range",
    "non-finite box",
    "unknown category id",
    "image size mismatch",
)
BOX_POLICIES = ("clip", "drop")


class ImageSkip(AiasError, ValueError):
    """Bad input that skips one image: ``kind`` (one of :data:`IMAGE_SKIP_KINDS`: what reports count), ``reason``,
    and where it was found (``file``, ``line``) when known. The message reads ``"<kind>: [<file>[:<line>]: ]<reason>"``;
    code reads the fields."""

    def __init__(self, kind: str, reason: str, file=None, line: int | None = None):
        if kind not in IMAGE_SKIP_KINDS:
            raise ValueError(f"ImageSkip kind must be one of {IMAGE_SKIP_KINDS}, got {kind!r}")
        where = "" if file is None else (f"{file}:{line}: " if line is not None else f"{file}: ")
        super().__init__(f"{kind}: {where}{reason}")
        self.kind, self.reason, self.file, self.line = kind, reason, None if file is None else str(file), line

    def __reduce__(self):  # pickled (Ray, spawned workers) with its fields
        return (ImageSkip, (self.kind, self.reason, self.file, self.line))


def problem(kind: str, file, reason: str, line: int | None = None) -> dict:
    return {"kind": kind, "file": str(file), "line": line, "reason": reason}


def format_problem(p: dict) -> str:
    where = p["file"] + (f":{p['line']}" if p.get("line") else "")
    return f"{where}: {p['kind']}: {p['reason']}"


# ----------------------------------------------------------------------------------------------------- images
def read_image_checked(path, max_pixels: int = DEFAULT_MAX_PIXELS) -> tuple[np.ndarray, list[dict]]:
    """Decode ``path`` to (H, W, 3) uint8 RGB with :func:`~aias_augment.core.image_io.read_image_with_notes` (pixel
    count checked from the header, truncated or corrupt files refused, EXIF orientation applied), or raise
    :class:`ImageSkip` of the reader's kind. Returns the image and the conversion notes."""
    try:
        img, notes = read_image_with_notes(path, max_pixels=max_pixels)
    except ImageReadError as e:
        raise ImageSkip(e.kind, e.reason) from None
    return img, [problem("converted", path, n) for n in notes]


def check_float_image(image: np.ndarray) -> np.ndarray:
    """A float array as an image: NaN/Inf refused; values in [0, 1] scaled by 255, values in [0, 255] rounded;
    anything else refused. Returns uint8."""
    a = np.asarray(image)
    if a.dtype == np.uint8:
        return a
    if not np.issubdtype(a.dtype, np.floating):
        raise ValueError(f"image dtype {a.dtype} is not supported (uint8, or float in [0, 1] or [0, 255])")
    if not np.isfinite(a).all():
        raise ValueError(f"float image has {int((~np.isfinite(a)).sum())} NaN/Inf pixels")
    lo, hi = float(a.min()), float(a.max())
    if lo >= 0 and hi <= 1:
        return np.round(a * 255).astype(np.uint8)
    if lo >= 0 and hi <= 255:
        return np.round(a).astype(np.uint8)
    raise ValueError(f"float image values in [{lo}, {hi}]: neither [0, 1] nor [0, 255]")


# ------------------------------------------------------------------------------------------------------ boxes
def check_box(
    x: float, y: float, w: float, h: float, width: float, height: float, policy: str, file, line, notes: list
) -> list[float] | None:
    """One box (xywh, same units as ``width``/``height``) against the image: non-finite raises
    ``ImageSkip("non-finite box", ...)``; zero/negative size is dropped; outside the image clipped or dropped
    (``policy``). Appends a note for every change; returns the box or None (dropped)."""
    if not all(math.isfinite(v) for v in (x, y, w, h)):
        raise ImageSkip("non-finite box", f"{[x, y, w, h]}")
    if w <= 0 or h <= 0:
        notes.append(problem("box dropped: zero or negative size", file, f"w={w:g} h={h:g}", line))
        return None
    x0, y0, x1, y1 = max(x, 0.0), max(y, 0.0), min(x + w, width), min(y + h, height)
    if (x0, y0, x1, y1) == (x, y, x + w, y + h):
        return [x, y, w, h]
    if policy == "drop" or x1 <= x0 or y1 <= y0:
        why = "outside the image" if x1 <= x0 or y1 <= y0 else "crosses the image border (--boxes drop)"
        notes.append(problem("box dropped: outside the image", file, f"{[x, y, w, h]} {why}", line))
        return None
    notes.append(problem("box clipped to the image", file, f"{[x, y, w, h]} -> {[x0, y0, x1 - x0, y1 - y0]}", line))
    return [x0, y0, x1 - x0, y1 - y0]


def parse_yolo_labels(path: Path, class_names: list[str] | None, policy: str = "clip") -> tuple[list, list]:
    """``class cx cy w h`` normalised rows -> (rows as string tokens, notes). Raises :class:`ImageSkip`
    for a garbage line, a class id out of range (negative, or >= len(class_names)) or a non-finite number; the
    message names the file and line."""
    rows, notes = [], []
    for n, raw in enumerate(path.read_text(errors="replace").splitlines(), 1):
        if not raw.strip():
            continue
        tok = raw.split()
        try:
            if len(tok) != 5:
                raise ValueError
            c = float(tok[0])
            cx, cy, bw, bh = map(float, tok[1:])
        except ValueError:
            raise ImageSkip(
                "garbage label line", f"expected 'class cx cy w h', got {raw.strip()[:80]!r}", path, n
            ) from None
        if not math.isfinite(c) or c != int(c) or c < 0 or (class_names and c >= len(class_names)):
            names = f"{len(class_names)} class names" if class_names else "no class names"
            raise ImageSkip("class id out of range", f"class {tok[0]} ({names})", path, n)
        try:
            box = check_box(cx - bw / 2, cy - bh / 2, bw, bh, 1.0, 1.0, policy, path, n, notes)
        except ImageSkip as e:
            raise ImageSkip(e.kind, f"{e.reason} at {path}:{n}", line=n) from None
        if box is None:
            continue
        if box == [cx - bw / 2, cy - bh / 2, bw, bh]:
            rows.append(tok)
        else:
            x, y, w, h = box
            rows.append([tok[0], repr(x + w / 2), repr(y + h / 2), repr(w), repr(h)])
    return rows, notes


def check_coco(data: dict, json_path) -> None:
    """Whole-file problems of a COCO json: raise :class:`InputError` (missing keys, duplicate image or annotation
    ids, duplicate category ids)."""
    if not isinstance(data, dict) or not isinstance(data.get("images"), list):
        raise InputError(f"{json_path}: not a COCO dataset (no 'images' list)")
    for key, what in (("images", "image"), ("annotations", "annotation"), ("categories", "category")):
        ids = [x.get("id") for x in data.get(key, [])]
        if None in ids:
            raise InputError(f"{json_path}: a {what} without an 'id'")
        seen, dup = set(), []
        for i in ids:
            if i in seen:
                dup.append(i)
            seen.add(i)
        if dup:
            raise InputError(
                f"{json_path}: duplicate {what} ids {sorted(set(dup))[:10]} (refused: annotations "
                f"would be attached to the wrong {what})"
            )


# --------------------------------------------------------------------------------------------------- arguments
def known_categories() -> set[str]:
    from aias_augment.assets.asset import DEFAULT_ASSETS
    from aias_augment.assets.bank.procedural import CATEGORY_SPECS

    known = set(DEFAULT_ASSETS) | set(CATEGORY_SPECS)
    try:
        from aias_augment.assets.bank import get_bank

        known |= set(get_bank().categories())
    except Exception:  # no bank installed: defaults and procedural only
        pass
    return known


def check_categories(categories) -> None:
    if not categories:
        raise InputError("no categories to insert")
    known = known_categories()
    unknown = [c for c in categories if c not in known]
    if unknown:
        raise InputError(f"unknown categories {unknown}; known: {sorted(known)}")


# ----------------------------------------------------------------------------------------------------- outputs
def check_output_record(rec: dict, out_dir: Path) -> list[str]:
    """What is wrong with one written record before it goes into annotations.json (empty: fine): the image file
    exists with the recorded size, every box finite, inside the image with w, h > 0, mask areas consistent."""
    errs = []
    p = out_dir / "images" / rec["file_name"]
    if not p.is_file():
        return [f"image file {p.name} missing"]
    try:
        size = image_size(p)
    except ImageReadError as e:
        return [f"image file {p.name}: {e.kind}: {e.reason}"]
    if size != (rec["width"], rec["height"]):
        errs.append(f"image is {size[0]}x{size[1]}, record says {rec['width']}x{rec['height']}")
    W, H = rec["width"], rec["height"]
    eps = 1e-6
    for b in rec["boxes"]:
        x, y, w, h = b
        if (
            not all(math.isfinite(v) for v in b)
            or w <= 0
            or h <= 0
            or x < -eps
            or y < -eps
            or x + w > W + eps
            or y + h > H + eps
        ):
            errs.append(f"box {b} not inside the {W}x{H} image with w, h > 0")
    if len(rec["boxes"]) != len(rec["labels"]) or len(rec["boxes"]) != len(rec["inserted"]):
        errs.append("boxes, labels and inserted flags differ in length")
    from pycocotools import mask as mask_utils

    for a in rec.get("annotations", []):
        if a.get("visible_box_xywh") is None:
            continue
        rle = dict(a["rle"])
        if isinstance(rle.get("counts"), str):
            rle["counts"] = rle["counts"].encode()
        area = float(mask_utils.area(rle))
        if area <= 0 or abs(area - float(a["area"])) > 0.5:
            errs.append(f"annotation area {a['area']} != mask area {area}")
        bx, by, bw, bh = mask_utils.toBbox(rle)
        vx, vy, vw, vh = a["visible_box_xywh"]
        if bx < vx - 1 or by < vy - 1 or bx + bw > vx + vw + 1 or by + bh > vy + vh + 1:
            errs.append(f"mask {[float(bx), float(by), float(bw), float(bh)]} outside its box {a['visible_box_xywh']}")
    return errs


def check_coco_file(path: Path, images_dir: Path) -> None:
    """The written COCO file, re-read by pycocotools: unique ids, every referenced file exists, boxes inside."""
    from aias_augment.core.coco_io import load_coco

    coco = load_coco(path)
    ds = coco.dataset
    for key in ("images", "annotations", "categories"):
        ids = [x["id"] for x in ds[key]]
        if len(ids) != len(set(ids)):
            raise AssertionError(f"{path}: duplicate {key} ids")
    for im in ds["images"]:
        if not (images_dir / im["file_name"]).is_file():
            raise AssertionError(f"{path}: image {im['file_name']} does not exist")
    for a in ds["annotations"]:
        im = coco.imgs[a["image_id"]]
        x, y, w, h = a["bbox"]
        if (
            not (
                w > 0
                and h > 0
                and x >= -1e-6
                and y >= -1e-6
                and x + w <= im["width"] + 1e-6
                and y + h <= im["height"] + 1e-6
            )
            or a["area"] <= 0
        ):
            raise AssertionError(f"{path}: annotation {a['id']} box {a['bbox']} area {a['area']} invalid")


# ------------------------------------------------------------------------------- per-sample inputs of the transform
class SampleSkip(AiasError, ValueError):
    """A sample :class:`~aias_augment.adapters.transform.InsertObjects` leaves unchanged. ``kind``: a stable reason (the key
    under ``counts["skipped"]``); the message adds what was found."""

    def __init__(self, kind: str, detail: str = ""):
        super().__init__(f"{kind}: {detail}" if detail else kind)
        self.kind = kind


#: Tolerance of the [0, 1] range of float images (one float32 rounding step above 1 is still "1").
FLOAT_RANGE_EPS = 1e-6


def image_for_insertion(image) -> tuple[np.ndarray, "callable", str | None]:
    """The transform's image boundary: ``(rgb, restore, conversion)``.

    Accepted (anything else raises :class:`SampleSkip`, never a silent clip):
    - (H, W), (H, W, 1), (H, W, 3), (H, W, 4); alpha is kept, grey gets the luminance of the inserted pixels;
    - uint8 as is;
    - uint16: ``round(v / 257)`` to 8 bit for the insertion; inserted pixels are written back as ``v8 * 257``;
    - float16/32/64 in [0, 1] (albumentations' float convention): ``round(v * 255)``; written back as ``v8 / 255``.
      A float image with NaN/Inf, or with values outside [0, 1] (e.g. a [0, 255] float image: divide it by 255),
      is refused.

    ``rgb``: (H, W, 3) uint8. ``restore(out_rgb)``: the output in the input's shape and dtype; every pixel the
    insertion did not change is the input's own value, bit for bit (so no image is quantised by passing through).
    ``conversion``: None for uint8 RGB(A)/grey, else what was converted (a key of ``counts["converted"]``).
    """
    img = np.asarray(image)
    orig = img
    if img.ndim == 2:
        img = img[..., None]
    if img.ndim != 3 or img.shape[2] not in (1, 3, 4):
        raise SampleSkip("unsupported image shape", f"{orig.shape} (need (H, W), (H, W, 1), (H, W, 3) or (H, W, 4))")
    if img.shape[0] < 1 or img.shape[1] < 1:
        raise SampleSkip("empty image", f"shape {orig.shape}")
    conversion = None
    if img.dtype == np.uint8:
        u8 = img
    elif img.dtype == np.uint16:
        u8 = np.round(img.astype(np.float32) / 257.0).astype(np.uint8)
        conversion = "uint16 -> 8 bit (round(v / 257))"
    elif np.issubdtype(img.dtype, np.floating) and img.dtype.itemsize <= 8:
        finite = np.isfinite(img)
        if not finite.all():
            raise SampleSkip("float image with NaN/Inf", f"{int((~finite).sum())} of {finite.size} values")
        lo, hi = float(img.min()), float(img.max())
        if lo < -FLOAT_RANGE_EPS or hi > 1.0 + FLOAT_RANGE_EPS:
            raise SampleSkip(
                "float image outside [0, 1]",
                f"values in [{lo:g}, {hi:g}]; float images must be in [0, 1] (albumentations' "
                f"convention): divide a [0, 255] float image by 255, or pass uint8",
            )
        u8 = np.round(np.clip(img.astype(np.float32), 0.0, 1.0) * 255.0).astype(np.uint8)
        conversion = f"{img.dtype} in [0, 1] -> 8 bit (round(v * 255))"
    else:
        raise SampleSkip("unsupported dtype", f"{img.dtype} (uint8, uint16, or float in [0, 1])")
    c = u8.shape[2]
    rgb = np.ascontiguousarray(np.repeat(u8, 3, axis=2) if c == 1 else u8[..., :3])

    def restore(out_rgb: np.ndarray) -> np.ndarray:
        out_rgb = np.asarray(out_rgb)
        if c == 3 and img.dtype == np.uint8:
            # uint8 RGB: the output is already in the input's form (an unchanged pixel is the input's own bytes)
            return np.ascontiguousarray(out_rgb)
        changed = changed_pixels(out_rgb, rgb)
        result = img.copy()
        if changed.any():
            px = out_rgb[changed]  # (N, 3) uint8
            if c == 1:
                lum = px.astype(np.float32) @ np.array([0.299, 0.587, 0.114], np.float32)
                px = np.clip(np.round(lum), 0, 255).astype(np.uint8)[:, None]
            if img.dtype == np.uint16:
                vals = px.astype(np.uint16) * np.uint16(257)
            elif img.dtype != np.uint8:
                vals = (px.astype(np.float32) / 255.0).astype(img.dtype)
            else:
                vals = px
            if c == 4:
                result[..., :3][changed] = vals
            else:
                result[changed] = vals
        if orig.ndim == 2:
            result = result[..., 0]
        return np.ascontiguousarray(result)

    return rgb, restore, conversion


def check_sample_targets(data: dict, height: int, width: int) -> None:
    """The per-sample targets ``camera_k`` and ``depth`` of one call: :class:`SampleSkip` when depth comes without
    the intrinsics that unproject it (the depth would be ignored and the placeable region found empty), or a
    target has the wrong shape."""
    K, depth = data.get("camera_k"), data.get("depth")
    if K is not None and np.asarray(K).shape != (3, 3):
        raise SampleSkip("camera_k not 3x3", f"shape {np.asarray(K).shape}")
    if depth is not None:
        if K is None:
            raise SampleSkip(
                "depth without camera_k", "depth cannot be unprojected without the intrinsics; pass camera_k with it"
            )
        if np.asarray(depth).shape != (height, width):
            raise SampleSkip("depth shape mismatch", f"{np.asarray(depth).shape} for a {height}x{width} image")


def nothing_inserted_reason(record: dict) -> str:
    """Why a call inserted nothing (``InsertionRecord.to_dict()``): the stages that were skipped and the placement
    search's commonest rejection."""
    from collections import Counter

    notes = record.get("modules", {})
    skipped = [f"{k} {notes[k]}" for k in record.get("skipped_stages", ())]
    rejected = Counter()
    for r in record.get("placement_reports", []):
        rejected.update((r or {}).get("rejected", {}))
    if rejected:
        why, _ = rejected.most_common(1)[0]
        skipped.append(f"placements rejected, most often: {why}")
    return "; ".join(skipped) or "no object placed"


class TransformCounts:
    """What :class:`~aias_augment.adapters.transform.InsertObjects` did with its calls, in this process: ``calls`` (the
    applied ones), ``inserted`` (images with >= 1 new box), ``objects`` (new boxes), ``skipped`` (image left
    unchanged, by reason), ``nothing_inserted`` (ran, placed nothing, by reason), ``converted`` (inputs converted,
    by conversion). Each reason is logged at WARNING the 1st, 10th, 100th, ... time (an epoch of odd images does
    not flood the log)."""

    def __init__(self):
        self.calls = self.inserted = self.objects = 0
        self.skipped: dict[str, int] = {}
        self.nothing_inserted: dict[str, int] = {}
        self.converted: dict[str, int] = {}

    def _bump(self, table: dict, key: str) -> int:
        table[key] = table.get(key, 0) + 1
        return table[key]

    def skip(self, error: Exception, log) -> None:
        self.calls += 1
        kind = error.kind if isinstance(error, SampleSkip) else f"{type(error).__name__}: {str(error)[:160]}"
        n = self._bump(self.skipped, kind)
        if _log_now(n):
            log.warning(
                "InsertObjects: image left unchanged (%s); %d time(s) for this reason, %d skipped in all",
                error if isinstance(error, SampleSkip) else kind,
                n,
                self.total_skipped,
            )

    def convert(self, conversion: str) -> None:
        self._bump(self.converted, conversion)

    def result(self, n_objects: int, record: dict | None, log) -> None:
        self.calls += 1
        if n_objects:
            self.inserted += 1
            self.objects += n_objects
            return
        why = nothing_inserted_reason(record or {})
        n = self._bump(self.nothing_inserted, why)
        if _log_now(n):
            log.warning("InsertObjects: nothing inserted (%s); %d time(s) for this reason", why, n)

    @property
    def total_skipped(self) -> int:
        return sum(self.skipped.values())

    def to_dict(self) -> dict:
        return {
            "calls": self.calls,
            "inserted": self.inserted,
            "objects": self.objects,
            "skipped": dict(self.skipped),
            "nothing_inserted": dict(self.nothing_inserted),
            "converted": dict(self.converted),
        }

    def __repr__(self) -> str:
        return f"TransformCounts({self.to_dict()})"


def _log_now(n: int) -> bool:
    return n >= 1 and 10 ** int(math.log10(n)) == n

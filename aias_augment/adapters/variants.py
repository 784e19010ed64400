"""Insertion variants: at most K insertions per image, the training loop's fast path.

``InsertObjects(variants_per_image=K)`` gives each image a fixed set of K insertions instead of a new one per call:
a call draws ``j`` in ``[0, K)`` with its generator and returns variant ``j`` of the image. Variant ``j`` is the
full pipeline's output (analysis, plan, apply: nothing is approximated) for the plan drawn from a generator seeded
by ``(seed, j, key)``, where ``key`` (:func:`variant_key`) is a 128-bit hash of everything the insertion reads: image
bytes, ``camera_k``, depth, scene facts, the existing boxes, the config and the asset bank. So a variant is a pure
function of the sample, ``seed`` and ``j``; which variant a call gets is the call's own draw.

A variant is kept as the window of pixels the insertion changed (:class:`Variant`) with its boxes and record:
applying it is a copy of the image and a paste of the window (~0.1 ms at 320x320), against ~15-30 ms for a fresh
fast insertion on a warm scene cache. The :class:`VariantCache` (an LRU in memory by bytes, and with a folder, files
every DataLoader worker and later run reads) changes when a variant is computed, never its pixels: a hit and a miss
give the same bytes (tested).

The trade is variety, and it is the user's to make: over training an image shows at most K different insertions
(K = None: a new one per call, the default). ``InsertObjects.warm(images, variants=True)`` computes all K variants
before training, so that no epoch pays for one; without it, variants are computed when first drawn (an image needs
about K / p calls before all its variants exist).

Not part of the key: ``min_visibility`` (a variant stores the existing boxes' visible fractions; the call decides
which to keep) and the existing boxes' labels (the insertion does not read them).
"""

from __future__ import annotations

import dataclasses
import json
import logging
import os
from collections import OrderedDict
from pathlib import Path

import numpy as np
import xxhash

from aias_augment.analyse.analysis import hash_value
from aias_augment.apply.view_cache import write_atomic
from aias_augment.core.envmap import EnvironmentMap
from aias_augment.core.frame import changed_pixels

log = logging.getLogger(__name__)

#: Bump when what an insertion computes changes: it is part of every key (so of each variant's generator: a bump
#: changes which insertions the variants are).
VARIANT_FORMAT = 2
#: Bump when how a variant is stored in its file changes: files of another version are not read (computed again).
FILE_FORMAT = 3
#: A variant file's first bytes; then the header's length (4 bytes, little-endian), the header (JSON) and the
#: bytes it lists, in its order (see :func:`variant_to_bytes`).
FILE_MAGIC = b"aias-variant\n"


def variant_key_prefix(cfg=None, assets=None, seed: int = 0):
    """The part of :func:`variant_key` that is fixed for a transform (config, asset bank, seed, versions): a
    hash object to pass as ``prefix`` (copied, never changed). ``cfg``: the InsertionConfig (its repr is complete:
    no arrays in it); ``assets``: ``{category: [paths]}`` or None. xxh3-128, not sha256: the key is computed at
    every call and hashes the image (0.01 ms for 320x320x3 against 0.16 for sha256); 128 bits make an accidental
    collision negligible (a cache of your own data, not a defence against crafted inputs)."""
    from aias_augment.version import __version__

    h = xxhash.xxh3_128(f"aias-variant v{VARIANT_FORMAT} package {__version__} seed {int(seed)}".encode())
    for name, v in (("cfg", repr(cfg)), ("assets", repr(sorted((assets or {}).items())))):
        h.update(name.encode())
        hash_value(h, v)
    return h


def variant_key(
    image: np.ndarray, *, camera_k=None, depth=None, scene=None, existing_xywh=None, references=None, prefix=None
) -> str:
    """xxh3-128 (hex) of everything a variant depends on except its index: ``prefix`` (from
    :func:`variant_key_prefix`; None: its defaults), image bytes, K, depth, scene facts (``scene``: SceneInputs)
    and the existing boxes. The stream hashed is ``image:<dtype><shape>``, the bytes, then for each of K, depth and
    the boxes ``<name>:None`` or ``<name>:<dtype><shape>`` and its bytes, then the scene's fields, then, when any
    existing box is of an inserted kind (``references``: one bool per box), which ones. It is computed at every
    variant call: an image alone (the common case in a training loop) is three updates."""
    h = (prefix if prefix is not None else variant_key_prefix()).copy()
    a = np.ascontiguousarray(image)
    h.update(f"image:{a.dtype}{a.shape}".encode())
    h.update(a if a.dtype != object else repr(a.tolist()).encode())
    if camera_k is None and depth is None and (existing_xywh is None or len(existing_xywh) == 0):
        h.update(b"K:Nonedepth:Noneboxes:None")
    else:
        for name, v in (
            ("K", None if camera_k is None else np.asarray(camera_k, np.float64)),
            ("depth", depth),
            (
                "boxes",
                None if existing_xywh is None or len(existing_xywh) == 0 else np.asarray(existing_xywh, np.float64),
            ),
        ):
            if v is None:
                h.update(f"{name}:None".encode())
            else:
                a = np.ascontiguousarray(v)
                h.update(f"{name}:{a.dtype}{a.shape}".encode())
                h.update(memoryview(a).cast("B") if a.dtype != object else repr(a.tolist()).encode())
    if scene is not None:  # SceneInputs: arrays by their bytes (the repr of a large array elides its middle)
        for f in dataclasses.fields(scene):
            v = getattr(scene, f.name)
            h.update(f"scene:{f.name}".encode())
            hash_value(h, v if isinstance(v, (np.ndarray, EnvironmentMap)) or v is None else repr(v))
    if references is not None and any(references):
        h.update(b"references:" + np.packbits(np.asarray(references, bool)).tobytes())
    return h.hexdigest()


def plain_image_key(image: np.ndarray, prefix) -> str:
    """:func:`variant_key` of a C-contiguous (H, W, 3) uint8 image without K, depth, scene facts or boxes (what a
    training loop passes), with ``prefix`` from :func:`variant_key_prefix`: the same stream, its text built
    without NumPy's dtype and shape reprs (their Python code costs more than hashing the pixels right after a
    JPEG decode has left the caches cold)."""
    h = prefix.copy()
    h.update(b"image:uint8(%d, %d, 3)" % image.shape[:2])
    h.update(image)
    h.update(b"K:Nonedepth:Noneboxes:None")
    return h.hexdigest()


def variant_rng(seed: int, j: int, key: str) -> np.random.Generator:
    """The generator variant ``j`` of the sample with ``key`` is planned with (independent of the call's)."""
    return np.random.default_rng([int(seed), int(j), int(key[:16], 16)])


class Variant:
    """One insertion into one image, kept as what it changed.

    window: (y0, y1, x0, x1) of the pixels the insertion changed ((0, 0, 0, 0): none); pixels: the output there
    ((y1-y0, x1-x0, 3) uint8); inserted_bboxes (K, 4) COCO xywh and inserted_labels: the new boxes;
    existing_visibility (N,): visible fraction of each existing box under what was drawn; record: the insertion's
    :class:`~aias_augment.pipeline.image.InsertionRecord` (replayable).

    ``encoded``: the new boxes as an albumentations Compose's bbox processor encodes them, by ``(height, width,
    bbox format)``: (K, 4) float32, or False (the processor itself must look at them); filled by
    :class:`~aias_augment.adapters.transform.InsertObjects` when it makes the variant (for its image's size and each
    format) and when a call needs another. Stored with the variant (as bytes, made arrays when first used).

    Stored as plain data (:func:`variant_to_bytes`: raw array bytes, the record as JSON that is only parsed when
    ``record`` is read): a hit from the folder reads one file and rebuilds three arrays on its bytes, and never the
    record's objects unless someone asks for it. A variant read back is immutable (its arrays are read-only views
    of the file's bytes). Pickled (between processes) as the same bytes."""

    __slots__ = (
        "window",
        "pixels",
        "inserted_bboxes",
        "inserted_labels",
        "existing_visibility",
        "_record",
        "_record_json",
        "encoded",
    )

    def __init__(
        self,
        window,
        pixels: np.ndarray,
        inserted_bboxes: np.ndarray,
        inserted_labels,
        existing_visibility: np.ndarray,
        record,
    ):
        self.window = tuple(int(x) for x in window)
        self.pixels = np.ascontiguousarray(pixels, np.uint8)
        self.inserted_bboxes = np.asarray(inserted_bboxes, np.float64).reshape(-1, 4)
        self.inserted_labels = tuple(inserted_labels)
        self.existing_visibility = np.asarray(existing_visibility, np.float64).reshape(-1)
        self._record = record
        self._record_json = None
        self.encoded = {}

    @classmethod
    def from_result(cls, image: np.ndarray, result) -> "Variant":
        """The variant of an :class:`~aias_augment.pipeline.image.InsertionResult` made from ``image``."""
        changed = changed_pixels(result.image, image)
        rows, cols = np.flatnonzero(changed.any(axis=1)), np.flatnonzero(changed.any(axis=0))
        if len(rows) == 0:
            window = (0, 0, 0, 0)
        else:
            window = (int(rows[0]), int(rows[-1]) + 1, int(cols[0]), int(cols[-1]) + 1)
        y0, y1, x0, x1 = window
        return cls(
            window,
            result.image[y0:y1, x0:x1],
            result.inserted_bboxes,
            result.inserted_labels,
            result.record.existing_visibility,
            result.record,
        )

    @property
    def record(self):
        """The insertion's record (rebuilt from its JSON on first read for a variant read from a file)."""
        if self._record is None and self._record_json is not None:
            from aias_augment.pipeline.image import InsertionRecord

            d = json.loads(self._record_json)
            self._record = None if d is None else InsertionRecord.from_dict(d)
        return self._record

    def record_json(self) -> bytes:
        """The record as stored: the JSON of ``InsertionRecord.to_dict`` (``null`` for none)."""
        if self._record_json is None:
            self._record_json = json.dumps(None if self._record is None else self._record.to_dict()).encode()
        return self._record_json

    def __reduce__(self):
        return (variant_from_bytes, (variant_to_bytes(self),))

    @property
    def nbytes(self) -> int:
        return self.pixels.nbytes + self.inserted_bboxes.nbytes + self.existing_visibility.nbytes + 2048

    def result(
        self, image: np.ndarray, existing_xywh: np.ndarray, labels: list, min_visibility: float = 0.0
    ) -> "VariantResult":
        """The result of this variant on ``image`` (the same bytes the variant was made from; not modified): a
        copy with the window pasted, boxes as :func:`~aias_augment.pipeline.image.assemble_result` orders them (the
        fields of an :class:`~aias_augment.pipeline.image.InsertionResult`)."""
        n = len(existing_xywh)
        if len(self.existing_visibility) != n:
            raise ValueError(f"variant made with {len(self.existing_visibility)} existing boxes, called with {n}")
        out = image.copy()
        y0, y1, x0, x1 = self.window
        out[y0:y1, x0:x1] = self.pixels
        if n == 0:
            return VariantResult(out, self.inserted_bboxes, list(self.inserted_labels), _NO_KEEP, self)
        keep = self.existing_visibility >= min_visibility
        boxes = np.asarray(existing_xywh, np.float64).reshape(-1, 4)
        return VariantResult(
            out,
            np.concatenate([boxes[keep], self.inserted_bboxes], axis=0),
            [lab for lab, k in zip(labels, keep) if k] + list(self.inserted_labels),
            keep,
            self,
        )


_NO_KEEP = np.zeros(0, bool)
_NO_KEEP.flags.writeable = False


def variant_to_bytes(v: Variant, key: str = "", j: int = -1) -> bytes:
    """``v`` as plain data: :data:`FILE_MAGIC`, the header's length (u32 little-endian), a JSON header, then the
    bytes it lists, in order: pixels (uint8), inserted boxes (float64), existing visibility (float64), each stored
    encoding that is not False (float32, K x 4) and the record's JSON. The header holds the xxh3-64 of those bytes
    (a damaged file is found, not pasted). ``key`` and ``j`` name the variant the bytes are for (a file read under
    another name is not used)."""
    encoded, parts = [], [v.pixels.tobytes(), v.inserted_bboxes.tobytes(), v.existing_visibility.tobytes()]
    for (h, w, fmt), g in v.encoded.items():
        encoded.append([int(h), int(w), str(fmt), g is not False])
        if g is not False:
            parts.append(g if isinstance(g, bytes) else np.asarray(g, np.float32).tobytes())
    rec = v.record_json()
    parts.append(rec)
    payload = b"".join(parts)
    header = json.dumps(
        {
            "format": FILE_FORMAT,
            "key": key,
            "j": int(j),
            "window": list(v.window),
            "pixels": list(v.pixels.shape),
            "boxes": len(v.inserted_bboxes),
            "existing": len(v.existing_visibility),
            "labels": list(v.inserted_labels),
            "encoded": encoded,
            "record": len(rec),
            "xxh3_64": xxhash.xxh3_64_hexdigest(payload),
        }
    ).encode()
    return b"".join([FILE_MAGIC, len(header).to_bytes(4, "little"), header, payload])


def _count(x, name: str) -> int:
    if type(x) is not int or x < 0:
        raise ValueError(f"{name}: {str(x)[:40]} is not a count")
    return x


def variant_from_bytes(data: bytes, key: str | None = None, j: int | None = None) -> Variant:
    """The :class:`Variant` of :func:`variant_to_bytes` (arrays as read-only views of ``data``, the record kept as
    JSON until read). Only data is parsed, nothing is executed; anything but such bytes (another format version,
    another ``key``/``j`` when given, a size or a type that does not add up) raises ValueError."""
    m = len(FILE_MAGIC)
    if data[:m] != FILE_MAGIC or len(data) < m + 4:
        raise ValueError("not a variant file")
    n = int.from_bytes(data[m : m + 4], "little")
    try:
        h = json.loads(data[m + 4 : m + 4 + n])
    except (ValueError, RecursionError) as e:  # not UTF-8, not JSON, nested too deep
        raise ValueError(f"header: {type(e).__name__}: {e}") from None
    if not isinstance(h, dict):
        raise ValueError(f"header is a {type(h).__name__}")
    if h.get("format") != FILE_FORMAT:
        raise ValueError(f"format {str(h.get('format'))[:10]}, not {FILE_FORMAT}")
    if (key is not None and h.get("key") != key) or (j is not None and h.get("j") != j):
        raise ValueError(f"holds {str(h.get('key'))[:40]}_{str(h.get('j'))[:10]}")
    window = h.get("window")
    if not isinstance(window, list) or len(window) != 4:
        raise ValueError("window is not 4 numbers")
    y0, y1, x0, x1 = (_count(x, "window") for x in window)
    shape = h.get("pixels")
    if y1 < y0 or x1 < x0 or shape != [y1 - y0, x1 - x0, 3]:
        raise ValueError(f"pixels {str(shape)[:40]} for window {window}")
    k, e = _count(h.get("boxes"), "boxes"), _count(h.get("existing"), "existing")
    labels, encoded = h.get("labels"), h.get("encoded")
    if not isinstance(labels, list) or len(labels) != k or not all(isinstance(x, str) for x in labels):
        raise ValueError(f"labels are not {k} names")
    if not isinstance(encoded, list) or not all(
        isinstance(g, list)
        and len(g) == 4
        and type(g[0]) is int
        and type(g[1]) is int
        and isinstance(g[2], str)
        and isinstance(g[3], bool)
        for g in encoded
    ):
        raise ValueError("encoded is not a list of [height, width, format, stored]")
    sizes = [(y1 - y0) * (x1 - x0) * 3, 32 * k, 8 * e] + [16 * k for g in encoded if g[3]]
    sizes.append(_count(h.get("record"), "record"))
    offsets = [m + 4 + n]
    for size in sizes:
        offsets.append(offsets[-1] + size)
    if offsets[-1] != len(data):
        raise ValueError(f"{len(data)} bytes, the header lists {offsets[-1]}")
    if xxhash.xxh3_64_hexdigest(memoryview(data)[offsets[0] :]) != h.get("xxh3_64"):
        raise ValueError("checksum differs")
    v = Variant.__new__(Variant)
    v.window = (y0, y1, x0, x1)
    v.pixels = np.frombuffer(data, np.uint8, sizes[0], offsets[0]).reshape(shape)
    v.inserted_bboxes = np.frombuffer(data, np.float64, 4 * k, offsets[1]).reshape(k, 4)
    v.inserted_labels = tuple(labels)
    v.existing_visibility = np.frombuffer(data, np.float64, e, offsets[2])
    v._record = None
    v._record_json = data[offsets[-2] : offsets[-1]]
    v.encoded, i = {}, 3
    for hh, ww, fmt, stored in encoded:
        v.encoded[(hh, ww, fmt)] = data[offsets[i] : offsets[i + 1]] if stored else False
        i += stored
    return v


class VariantResult:
    """A variant applied to its image: the fields of an :class:`~aias_augment.pipeline.image.InsertionResult`
    (``image``, ``bboxes``, ``labels``, ``inserted_bboxes``, ``inserted_labels``, ``keep_existing``, ``record``)
    and the ``variant`` itself. The boxes are the variant's own read-only arrays (not copies); ``record`` is
    the variant's (rebuilt when read)."""

    __slots__ = ("image", "bboxes", "labels", "inserted_bboxes", "inserted_labels", "keep_existing", "variant")

    def __init__(self, image, bboxes, labels, keep_existing, variant: Variant):
        self.image, self.bboxes, self.labels = image, bboxes, labels
        self.inserted_bboxes = variant.inserted_bboxes
        self.inserted_labels = list(variant.inserted_labels)
        self.keep_existing = keep_existing
        self.variant = variant

    @property
    def record(self):
        return self.variant.record


class VariantCache:
    """Variants by ``(key, j)``: an LRU in memory of at most ``max_bytes`` and, with a ``directory``, one file per
    variant (``<dir>/<key[:2]>/<key>_<j>.variant``, :func:`variant_to_bytes`, written atomically) shared by
    processes and runs. The files are plain data, so a folder on a shared disk runs nothing whoever wrote into it;
    a file that is not a variant of this version and name (damaged, planted, older) is logged, counted in
    ``unreadable`` and computed again (then overwritten). Pickles empty (each DataLoader worker fills its own LRU;
    the folder is shared)."""

    def __init__(self, max_bytes: int = 128 * 2**20, directory: str | Path | None = None):
        if max_bytes < 0:
            raise ValueError(f"max_bytes must be >= 0, got {max_bytes}")
        self.max_bytes = int(max_bytes)
        self.directory = None if directory is None else Path(directory)
        self._dirname = None if directory is None else str(directory)
        self._lru: OrderedDict[tuple[str, int], Variant] = OrderedDict()
        self.nbytes = 0
        self.hits = self.disk_hits = self.misses = self.unreadable = 0

    def __getstate__(self):
        state = self.__dict__.copy()
        state["_lru"] = OrderedDict()
        state["nbytes"] = state["hits"] = state["disk_hits"] = state["misses"] = state["unreadable"] = 0
        return state

    def __len__(self) -> int:
        return len(self._lru)

    def _file(self, key: str, j: int) -> str:
        return f"{self._dirname}/{key[:2]}/{key}_{j}.variant"

    def get(self, key: str, j: int) -> Variant | None:
        """The variant if this process or the folder holds it, else None (counted as a miss)."""
        v = self._lru.get((key, j))
        if v is not None:
            self._lru.move_to_end((key, j))
            self.hits += 1
            return v
        v = self._read(key, j)
        if v is None:
            self.misses += 1
            return None
        self.disk_hits += 1
        self._remember(key, j, v)
        return v

    def put(self, key: str, j: int, v: Variant) -> None:
        self._remember(key, j, v)
        if self.directory is not None:
            write_atomic(Path(self._file(key, j)), variant_to_bytes(v, key, j))

    def _remember(self, key: str, j: int, v: Variant) -> None:
        if v.nbytes > self.max_bytes:
            return
        old = self._lru.pop((key, j), None)
        if old is not None:
            self.nbytes -= old.nbytes
        self._lru[(key, j)] = v
        self.nbytes += v.nbytes
        while self.nbytes > self.max_bytes:
            _, gone = self._lru.popitem(last=False)
            self.nbytes -= gone.nbytes

    def _read(self, key: str, j: int) -> Variant | None:
        if self._dirname is None:
            return None
        try:  # one open, fstat and read (no exists() first, no buffered file object: this is the call path)
            fd = os.open(self._file(key, j), os.O_RDONLY)
        except OSError:
            return None
        try:
            data = os.read(fd, os.fstat(fd).st_size)
        except OSError:
            return None
        finally:
            os.close(fd)
        try:
            return variant_from_bytes(data, key, j)
        except ValueError as e:  # damaged, planted or another version's: computed again (and overwritten)
            self.unreadable += 1
            log.warning("variant cache: %s not used (%s)", self._file(key, j), e)
            return None

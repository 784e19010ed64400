"""The asset bank at scale: importers, catalog, validation, cache, variety and procedural debris.

Typical use (the pipeline)::

    from aias_augment.assets.bank import get_bank
    bank = get_bank()                       # catalog from the cache, or discovered from the installed sources
    asset = bank.sample("traffic_cone", rng) # a real-size, jittered Asset (canonical frame)

Sources: Sweet Home 3D catalogs (``/usr/share/sweethome3d/furniture/*.sh3f``), gazebo models
(``$AIAS_DATA/meshes/gazebo_models``), folders with YAML sidecars, procedural generators. ``aias-assets import``
loads every mesh once, validates it and fills the cache; without it, meshes are imported lazily on first use.
"""

from __future__ import annotations

import logging
from collections import OrderedDict
from dataclasses import replace
from pathlib import Path

import numpy as np
import trimesh

from aias_augment.assets.asset import Asset, AssetError
from aias_augment.assets.bank.cache import MeshCache, default_cache_dir, source_stamp
from aias_augment.assets.bank.catalog import CatalogRecord, load_catalog
from aias_augment.assets.bank.gazebo import IMPORTER_VERSION as GAZEBO_VERSION
from aias_augment.assets.bank.gazebo import default_gazebo_dir, load_gazebo_parts, read_gazebo_records
from aias_augment.assets.bank.meshio import part_texture_image
from aias_augment.assets.bank.procedural import CATEGORY_SPECS, ProceduralSpec, generate
from aias_augment.assets.bank.sh3f import DEFAULT_SH3F_DIR, find_sh3f_files, load_sh3f_parts, read_sh3f_catalog
from aias_augment.assets.bank.sh3f import IMPORTER_VERSION as SH3F_VERSION
from aias_augment.assets.bank.sidecar import load_sidecar_parts, read_sidecar_records
from aias_augment.assets.bank.taxonomy import Taxonomy, load_taxonomy
from aias_augment.assets.bank.validate import check_size
from aias_augment.assets.bank.variety import VarietyConfig, apply_variety, sample_variety

log = logging.getLogger(__name__)

__all__ = [
    "AssetBank",
    "get_bank",
    "discover_records",
    "import_records",
    "import_record",
    "CatalogRecord",
    "PROCEDURAL_SPECS",
    "catalog_path",
]

_LOADERS = {"sh3f": load_sh3f_parts, "gazebo": load_gazebo_parts, "sidecar": load_sidecar_parts}
IMPORT_VERSION = 2  # 2: crease-angle vertex normals at import (assets.crease_normals)

#: Procedural debris and cones: (generator, category, height range in metres, catalog records whose texture it borrows).
PROCEDURAL_SPECS: dict[str, tuple[ProceduralSpec, tuple[str, ...]]] = {
    "procedural:stone": (
        ProceduralSpec("stone", "rock", (0.05, 0.4)),
        ("sh3f:Blend Swap CC-0#rock1", "sh3f:Blend Swap CC-0#rock2", "sh3f:Blend Swap CC-0#rock3"),
    ),
    "procedural:concrete_block": (
        ProceduralSpec("concrete_block", "concrete_block", (0.12, 0.3)),
        ("gazebo:cinder_block",),
    ),
    "procedural:crumpled_sheet": (ProceduralSpec("crumpled_sheet", "debris", (0.02, 0.15)), ()),
    "procedural:traffic_cone": (CATEGORY_SPECS["traffic_cone"], ()),  # a seeded family, texture drawn
}


def catalog_path(cache_dir: str | Path | None = None) -> Path:
    return Path(cache_dir or default_cache_dir()) / "catalog.json"


def _record_stamp(r: CatalogRecord) -> str:
    if r.importer == "sh3f":
        src = r.params["archive"]
        extra = (SH3F_VERSION, r.params["member"], r.dimensions_m, r.params.get("model_rotation"))
    elif r.importer == "gazebo":
        src = Path(r.params["model_dir"]) / "model.sdf"
        extra = (GAZEBO_VERSION,)
    elif r.importer == "sidecar":
        src = r.params["mesh"]
        extra = (r.params.get("height_m"), r.params.get("scale"), r.params.get("up_axis"))
    else:
        raise ValueError(f"record {r.id}: importer {r.importer!r} has no cached mesh")
    return source_stamp(src, IMPORT_VERSION, *extra)


def _procedural_records(taxonomy: Taxonomy) -> list[CatalogRecord]:
    out = []
    for rid, (spec, tex) in PROCEDURAL_SPECS.items():
        lo, hi = spec.height_range_m
        out.append(
            CatalogRecord(
                id=rid,
                name=f"procedural {spec.generator}",
                category=spec.category,
                dimensions_m=None,
                importer="procedural",
                source=rid,
                licence="generated",
                procedural=True,
                status="ok",
                textured=bool(tex),
                params={"generator": spec.generator, "height_range_m": [lo, hi], "texture_from": list(tex)},
            )
        )
    return out


def discover_records(
    *,
    sh3f_dir: str | Path | None = DEFAULT_SH3F_DIR,
    gazebo_dir: str | Path | None = "default",
    sidecar_dirs: tuple[str | Path, ...] = (),
    procedural: bool = True,
    taxonomy: Taxonomy | None = None,
) -> tuple[list[CatalogRecord], list[str]]:
    """Catalog records of every source found, read from the catalogs' metadata only (fast, no mesh loading)."""
    taxonomy = taxonomy or load_taxonomy()
    records: list[CatalogRecord] = []
    skipped: list[str] = []
    if sh3f_dir:
        for f in find_sh3f_files(sh3f_dir):
            try:
                recs, sk = read_sh3f_catalog(f, taxonomy)
            except AssetError as e:
                skipped.append(str(e))
                continue
            records += recs
            skipped += sk
    if gazebo_dir:
        records += read_gazebo_records(default_gazebo_dir() if gazebo_dir == "default" else gazebo_dir, taxonomy)
    for d in sidecar_dirs:
        recs, sk = read_sidecar_records(d, taxonomy)
        records += recs
        skipped += sk
    if procedural:
        records += _procedural_records(taxonomy)
    for s in skipped:
        log.warning("skipped: %s", s)
    return records, skipped


def _textured(parts) -> bool:
    return any(part_texture_image(p) is not None for p in parts)


def import_record(
    record: CatalogRecord, cache: MeshCache, taxonomy: Taxonomy, *, force: bool = False
) -> tuple[CatalogRecord, tuple[trimesh.Trimesh, ...] | None]:
    """Load (from the cache, or import, validate and cache) one record's parts; the record comes back updated
    (measured dimensions, triangle count, textured, status and notes). A rejected record returns parts None."""
    if record.importer == "procedural":
        return record, None
    try:
        key = cache.key(record.id, _record_stamp(record))
    except (OSError, KeyError) as e:
        return replace(record, status="rejected", notes=(f"source unavailable: {e}",)), None
    hit = None if force else cache.load(key)
    parts, notes = hit if hit is not None else (None, [])
    fresh = hit is None
    try:
        if fresh:
            parts, notes = _LOADERS[record.importer](record)
        b = np.array([p.bounds for p in parts])
        extents = tuple(float(x) for x in b[:, 1].max(0) - b[:, 0].min(0))
        # checked on cache hits too: the category (taxonomy) may have changed since the mesh was cached
        check_size(np.array(extents), record.category, taxonomy.height_range_m(record.category), where=record.source)
    except AssetError as e:
        log.warning("rejected %s: %s", record.id, e)
        return replace(record, status="rejected", notes=(str(e),)), None
    except (ValueError, OSError, KeyError, IndexError) as e:  # broken files surface as these from zip/PIL/trimesh
        reason = f"{record.source}: unreadable ({type(e).__name__}: {e})"
        log.warning("rejected %s: %s", record.id, reason)
        return replace(record, status="rejected", notes=(reason,)), None
    if fresh and cache.save(key, list(parts), notes):
        notes = notes + ["texture downscaled to at most 2048 px"]
    status = "repaired" if notes else "ok"
    return replace(
        record,
        dimensions_m=extents,
        triangle_count=int(sum(len(p.faces) for p in parts)),
        textured=_textured(parts),
        status=status,
        notes=tuple(notes),
    ), parts


def import_records(
    records: list[CatalogRecord],
    cache: MeshCache,
    taxonomy: Taxonomy | None = None,
    *,
    force: bool = False,
    progress: bool = True,
) -> list[CatalogRecord]:
    """Import every record (cache hits are cheap); returns the updated records in the same order."""
    taxonomy = taxonomy or load_taxonomy()
    out = []
    it = records
    if progress:
        from tqdm import tqdm

        it = tqdm(records, desc="import", unit="asset")
    for r in it:
        out.append(import_record(r, cache, taxonomy, force=force)[0])
    return out


class AssetBank:
    """Catalog records + lazily loaded, cached meshes; ``sample`` gives a real-size jittered asset of a category."""

    def __init__(
        self,
        records: list[CatalogRecord],
        cache: MeshCache,
        taxonomy: Taxonomy | None = None,
        variety: VarietyConfig = VarietyConfig(),
        memo_size: int = 32,
    ):
        self.taxonomy = taxonomy or load_taxonomy()
        self.cache = cache
        self.variety = variety
        self._records: dict[str, CatalogRecord] = {r.id: r for r in records}
        self._memo: OrderedDict[str, tuple[trimesh.Trimesh, ...]] = OrderedDict()
        self._memo_size = memo_size
        self._textures: dict[str, object] = {}
        self.skipped: list[str] = []

    def __len__(self) -> int:
        return len(self._records)

    def records(self, category: str | None = None, *, usable_only: bool = True) -> list[CatalogRecord]:
        return [
            r
            for r in self._records.values()
            if (category is None or r.category == category) and (r.usable or not usable_only)
        ]

    def record(self, record_id: str) -> CatalogRecord:
        if record_id not in self._records:
            raise KeyError(f"no asset {record_id!r} in the bank")
        return self._records[record_id]

    def categories(self) -> list[str]:
        return sorted({r.category for r in self._records.values() if r.usable})

    def _parts(self, record: CatalogRecord) -> tuple[trimesh.Trimesh, ...]:
        if record.id in self._memo:
            self._memo.move_to_end(record.id)
            return self._memo[record.id]
        updated, parts = import_record(record, self.cache, self.taxonomy)
        self._records[record.id] = updated
        if parts is None:
            raise AssetError(f"{record.id}: {'; '.join(updated.notes)}")
        self._memo[record.id] = parts
        while len(self._memo) > self._memo_size:
            self._memo.popitem(last=False)
        return parts

    def _texture_for(self, record_ids: tuple[str, ...]):
        for rid in record_ids:
            if rid in self._textures:
                return self._textures[rid]
            if rid not in self._records:
                continue
            try:
                parts = self._parts(self._records[rid])
            except AssetError:
                continue
            imgs = [
                p.visual.material.image
                for p in parts
                if getattr(getattr(p.visual, "material", None), "image", None) is not None
            ]
            if imgs:
                img = max(imgs, key=lambda im: im.size[0] * im.size[1])
                self._textures[rid] = img
                return img
        return None

    def load(self, record_id: str, rng: np.random.Generator | None = None) -> Asset:
        """The asset at catalog size (no jitter). Procedural records need ``rng``."""
        r = self.record(record_id)
        if r.importer == "procedural":
            if rng is None:
                raise ValueError(f"{record_id} is procedural: pass a numpy Generator")
            spec, tex_ids = PROCEDURAL_SPECS[r.id]
            tex = self._texture_for(tex_ids)
            a = generate(spec, rng, tex, name=r.name)
            return Asset(
                a.name,
                a.category,
                a.meshes,
                a.source,
                a.licence,
                True,
                {**a.meta, "record_id": r.id, "texture_from": tex_ids if tex is not None else ()},
            )
        parts = self._parts(r)
        r = self._records[record_id]
        return Asset(
            r.name,
            r.category,
            tuple(parts),
            r.source,
            r.licence,
            r.procedural,
            {"record_id": r.id, "catalog_dimensions_m": r.dimensions_m, "creator": r.creator},
        )

    def sample(self, category: str, rng: np.random.Generator, *, max_tries: int = 5) -> Asset:
        """A random asset of ``category``, scale/colour jittered within the category's real size range.

        An asset that fails to import is marked rejected, logged and counted in ``skipped``; another is drawn.
        """
        failures: list[str] = []
        for _ in range(max_tries):
            cands = sorted(self.records(category), key=lambda r: r.id)
            if not cands:
                break
            r = cands[int(rng.integers(len(cands)))]
            try:
                asset = self.load(r.id, rng)
            except AssetError as e:
                self.skipped.append(str(e))
                failures.append(str(e))
                log.warning("bank.sample: skipped %s", e)
                continue
            params = sample_variety(asset.height_m, self.taxonomy.height_range_m(category), self.variety, rng)
            return apply_variety(asset, params)
        if failures:
            raise AssetError(f"bank.sample({category!r}): {len(failures)} candidate(s) failed to load: {failures[-3:]}")
        raise KeyError(f"no usable asset of category {category!r}; available: {self.categories()}")


_BANKS: dict[str, AssetBank] = {}


def get_bank(cache_dir: str | Path | None = None, *, refresh: bool = False) -> AssetBank:
    """The process-wide bank for ``cache_dir`` (default ``$AIAS_CACHE`` or ``~/.cache/aias_augment``).

    Uses the imported catalog (``<cache_dir>/catalog.json``, written by ``aias-assets import``) when present, else
    discovers the installed sources from their metadata (meshes are then imported on first use).
    """
    root = Path(cache_dir) if cache_dir is not None else default_cache_dir()
    key = str(root.resolve())
    if key in _BANKS and not refresh:
        return _BANKS[key]
    taxonomy = load_taxonomy()
    cat = catalog_path(root)
    if cat.is_file():
        records = load_catalog(cat)
    else:
        records, _ = discover_records(taxonomy=taxonomy)
    _BANKS[key] = AssetBank(records, MeshCache(root), taxonomy)
    return _BANKS[key]

"""Catalog records of the asset bank and the catalog file (JSON) that lists them.

A record is what is known about an asset without loading its mesh (id, category, real dimensions, source, licence)
plus what an import measured (triangle count, textured, status and the repair/rejection notes).
Dimensions are in the canonical object frame: metres, (x, y, z) = (width, depth, height), z up.
"""

from __future__ import annotations

import dataclasses
import json
import os
from dataclasses import dataclass, field
from pathlib import Path

__all__ = ["CatalogRecord", "save_catalog", "load_catalog", "CATALOG_VERSION"]

CATALOG_VERSION = 1
STATUSES = ("pending", "ok", "repaired", "rejected")


@dataclass(frozen=True)
class CatalogRecord:
    id: str  # unique, stable: "<importer>:<source id>"
    name: str
    category: str  # project taxonomy (configs/taxonomy.yaml)
    dimensions_m: tuple[float, float, float] | None  # width, depth, height (x, y, z); None = unknown until imported
    importer: str  # sh3f | gazebo | sidecar | procedural
    source: str  # file or archive member the mesh comes from
    licence: str = ""
    creator: str = ""
    source_category: str = ""
    tags: tuple[str, ...] = ()
    triangle_count: int | None = None
    textured: bool | None = None
    procedural: bool = False
    status: str = "pending"  # pending (not imported yet), ok, repaired, rejected
    notes: tuple[str, ...] = ()  # repairs done or the rejection reason
    params: dict = field(default_factory=dict)  # importer-specific (model rotation, scale, generator name, ...)

    def __post_init__(self):
        if self.status not in STATUSES:
            raise ValueError(f"record {self.id}: status must be one of {STATUSES}, got {self.status!r}")
        if self.dimensions_m is not None:
            d = tuple(float(v) for v in self.dimensions_m)
            if len(d) != 3 or not all(v > 0 and v < float("inf") for v in d):
                raise ValueError(f"record {self.id}: dimensions_m must be 3 positive finite numbers, got {d}")
            object.__setattr__(self, "dimensions_m", d)

    @property
    def usable(self) -> bool:
        return self.status != "rejected"

    @property
    def height_m(self) -> float | None:
        return None if self.dimensions_m is None else self.dimensions_m[2]

    def to_json(self) -> dict:
        return dataclasses.asdict(self)

    @classmethod
    def from_json(cls, d: dict) -> "CatalogRecord":
        names = {f.name for f in dataclasses.fields(cls)}
        unknown = set(d) - names
        if unknown:
            raise KeyError(f"catalog record: unknown keys {sorted(unknown)}")
        d = dict(d)
        for k in ("tags", "notes"):
            d[k] = tuple(d.get(k, ()))
        if d.get("dimensions_m") is not None:
            d["dimensions_m"] = tuple(d["dimensions_m"])
        return cls(**d)


def save_catalog(records: list[CatalogRecord], path: str | Path) -> Path:
    """Write records atomically (temp file + rename) so a killed import never leaves a half catalog."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    ids = [r.id for r in records]
    if len(set(ids)) != len(ids):
        dup = sorted({i for i in ids if ids.count(i) > 1})
        raise ValueError(f"duplicate record ids: {dup[:5]}")
    tmp = path.with_suffix(path.suffix + f".tmp{os.getpid()}")
    with open(tmp, "w") as f:
        json.dump({"version": CATALOG_VERSION, "records": [r.to_json() for r in records]}, f, indent=1)
    os.replace(tmp, path)
    return path


def load_catalog(path: str | Path) -> list[CatalogRecord]:
    path = Path(path)
    with open(path) as f:
        data = json.load(f)
    if not isinstance(data, dict) or data.get("version") != CATALOG_VERSION:
        raise ValueError(f"{path}: not a catalog file of version {CATALOG_VERSION}")
    return [CatalogRecord.from_json(r) for r in data["records"]]

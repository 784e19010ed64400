"""The project's category taxonomy (``configs/taxonomy.yaml``): COCO-style names, real height ranges, name rules."""

from __future__ import annotations

import re
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path

from aias_augment.core.config import CONFIG_DIR, from_dict
from aias_augment.core.config_files import load_yaml_file

__all__ = ["CategorySpec", "Taxonomy", "load_taxonomy"]


@dataclass(frozen=True)
class CategorySpec:
    height_range_m: tuple[float, float]
    names: tuple[str, ...] = ()
    exclude_tags: tuple[str, ...] = ()

    def __post_init__(self):
        lo, hi = self.height_range_m
        if not (0 < lo < hi):
            raise ValueError(f"height_range_m must satisfy 0 < lo < hi, got {self.height_range_m}")


@dataclass(frozen=True)
class Taxonomy:
    categories: dict[str, CategorySpec]
    fallback: str
    fallback_by_source_category: dict[str, str]

    def __post_init__(self):
        missing = {self.fallback, *self.fallback_by_source_category.values()} - set(self.categories)
        if missing:
            raise ValueError(f"taxonomy: fallback categories {sorted(missing)} are not defined under `categories`")
        self._compiled  # validate the regular expressions at load time

    @property
    def _compiled(self) -> list[tuple[str, re.Pattern, frozenset]]:
        cached = self.__dict__.get("_rules")
        if cached is None:
            cached = []
            for cat, spec in self.categories.items():
                for pat in spec.names:
                    try:
                        cached.append((cat, re.compile(pat, re.IGNORECASE), frozenset(spec.exclude_tags)))
                    except re.error as e:
                        raise ValueError(f"taxonomy: bad pattern {pat!r} for {cat}: {e}") from e
            object.__setattr__(self, "_rules", cached)
        return cached

    def classify(self, name: str, tags: tuple[str, ...] = (), source_category: str = "") -> str:
        """Category of an asset from its name (whole-name regex match), its tags and its catalog category."""
        key = " ".join(name.strip().lower().split())
        tag_set = {t.strip().lower() for t in tags}
        for cat, rx, excluded in self._compiled:
            if rx.fullmatch(key) and not (excluded & tag_set):
                return cat
        return self.fallback_by_source_category.get(source_category.strip().lower(), self.fallback)

    def height_range_m(self, category: str) -> tuple[float, float]:
        if category not in self.categories:
            raise KeyError(f"unknown category {category!r}; known: {sorted(self.categories)}")
        return tuple(self.categories[category].height_range_m)


def _parse(data: dict, where: str) -> Taxonomy:
    allowed = {"categories", "fallback", "fallback_by_source_category"}
    unknown = set(data) - allowed
    if unknown:
        raise KeyError(f"{where}: unknown keys {sorted(unknown)}; allowed: {sorted(allowed)}")
    cats = {
        name: from_dict(
            CategorySpec,
            {k: tuple(v) if isinstance(v, list) else v for k, v in spec.items()},
            f"{where}.categories.{name}",
        )
        for name, spec in (data.get("categories") or {}).items()
    }
    return Taxonomy(
        cats,
        data.get("fallback", "other"),
        {k.lower(): v for k, v in (data.get("fallback_by_source_category") or {}).items()},
    )


@lru_cache(maxsize=4)
def load_taxonomy(path: str | Path | None = None) -> Taxonomy:
    """Load the taxonomy (default ``configs/taxonomy.yaml``); unknown keys and bad patterns raise."""
    p = Path(path) if path else CONFIG_DIR / "taxonomy.yaml"
    return _parse(load_yaml_file(p) or {}, str(p))  # bounded: size, UTF-8, alias expansion

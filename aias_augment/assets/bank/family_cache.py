"""A finite procedural family: N members of a category's generator, drawn once from a recorded seed.

``asset_source="procedural"`` makes a new seeded asset per object (:func:`procedural_asset`): every object is a new
mesh, so the view cache never hits and every insertion pays a mesh and a GL render. A finite family keeps most of
the variety at cache speed: member ``i`` of the family ``(category, members, seed)`` is the procedural asset of the
seed :func:`member_seed(seed, i) <member_seed>` (the same asset in every process, worker and epoch), built once per
process and kept by :class:`ProceduralFamily` (a bounded LRU), so the view cache, which keys its views by the asset
object, finds its views again. Per object only the member index is drawn (one ``integers`` draw of the call's
generator, as the continuous draw takes one for its seed).

A member's ``meta`` carries its ``seed`` (so :func:`procedural_asset_from_seed` rebuilds the same mesh, as a
continuous draw's record does) and ``family`` (``category``, ``members``, ``seed``, ``index``): a record names both.
"""

from __future__ import annotations

from collections import OrderedDict

import numpy as np

from aias_augment.assets.asset import Asset
from aias_augment.assets.bank.procedural import CATEGORY_SPECS, procedural_asset_from_seed

__all__ = ["MAX_MEMBERS", "ProceduralFamily", "member_seed", "default_family"]

#: Upper bound on a family's size (beyond it a finite family stops paying: members are rarely seen twice).
MAX_MEMBERS = 65536


def member_seed(family_seed: int, index: int) -> int:
    """The generator seed of member ``index`` of the family drawn from ``family_seed`` (numpy's SeedSequence of the
    pair: independent streams per member, the same in every process)."""
    state = np.random.SeedSequence([int(family_seed), int(index)]).generate_state(2, np.uint32)
    return int((int(state[0]) << 31) | (int(state[1]) >> 1))  # < 2**63, as procedural_asset's seeds


class ProceduralFamily:
    """``members`` procedural assets of ``category`` drawn from ``seed``. :meth:`member` builds member ``i`` on
    first use and keeps the last ``max_assets`` members used (LRU); ``built`` and ``hits`` count builds and reuses.
    Pickles empty (each DataLoader worker builds its own members, the same ones)."""

    def __init__(self, category: str, members: int, seed: int, max_assets: int = 256):
        if category not in CATEGORY_SPECS:
            raise ValueError(f"no procedural generator for {category!r}; known: {sorted(CATEGORY_SPECS)}")
        if not (1 <= int(members) <= MAX_MEMBERS):
            raise ValueError(f"family members must be in [1, {MAX_MEMBERS}], got {members}")
        if int(seed) < 0:
            raise ValueError(f"family seed must be >= 0, got {seed}")
        if int(max_assets) < 1:
            raise ValueError(f"max_assets must be >= 1, got {max_assets}")
        self.category, self.members, self.seed = category, int(members), int(seed)
        self.max_assets = int(max_assets)
        self._lru: OrderedDict[int, Asset] = OrderedDict()
        self.built = self.hits = 0

    def __getstate__(self):
        state = self.__dict__.copy()
        state["_lru"] = OrderedDict()
        state["built"] = state["hits"] = 0
        return state

    def __len__(self) -> int:
        return len(self._lru)

    def draw_index(self, rng: np.random.Generator) -> int:
        """A member index, uniform over the family (one draw of ``rng``)."""
        return int(rng.integers(self.members))

    def member(self, index: int) -> Asset:
        """Member ``index`` (unscaled, canonical frame); the same object while it stays in the LRU."""
        i = int(index)
        if not (0 <= i < self.members):
            raise IndexError(f"member {index} of a family of {self.members}")
        got = self._lru.get(i)
        if got is not None:
            self._lru.move_to_end(i)
            self.hits += 1
            return got
        a = procedural_asset_from_seed(self.category, member_seed(self.seed, i))
        fam = {"category": self.category, "members": self.members, "seed": self.seed, "index": i}
        got = Asset(a.name, a.category, a.meshes, a.source, a.licence, True, {**a.meta, "family": fam})
        self.built += 1
        self._lru[i] = got
        while len(self._lru) > self.max_assets:
            self._lru.popitem(last=False)
        return got

    def sample(self, rng: np.random.Generator) -> Asset:
        """The member of one index drawn from ``rng``."""
        return self.member(self.draw_index(rng))


_FAMILIES: OrderedDict[tuple, ProceduralFamily] = OrderedDict()
#: Families kept by :func:`default_family` (a config rarely names more than one per category).
MAX_FAMILIES = 8


def default_family(category: str, members: int, seed: int) -> ProceduralFamily:
    """The process-wide :class:`ProceduralFamily` of ``(category, members, seed)`` (its member LRU as large as the
    family, up to 256), the one the planner draws from when ``InsertionConfig.family_members`` is set; the last
    :data:`MAX_FAMILIES` families used are kept."""
    key = (category, int(members), int(seed))
    fam = _FAMILIES.get(key)
    if fam is None:
        fam = _FAMILIES[key] = ProceduralFamily(category, members, seed, max_assets=min(int(members), 256))
        while len(_FAMILIES) > MAX_FAMILIES:
            _FAMILIES.popitem(last=False)
    _FAMILIES.move_to_end(key)
    return fam

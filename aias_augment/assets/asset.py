"""Mesh assets: load textured meshes (OBJ+MTL, DAE, GLB/GLTF, PLY), normalise to the canonical object frame.

Canonical object frame: metres, z up, centred in x/y on the bounding box, resting on z = 0 (the contact plane).
Units are read from the file, never guessed: COLLADA ``<unit meter=...>`` and ``<up_axis>``, gazebo ``model.sdf``
``<scale>``, or an explicit ``scale``/``up_axis`` given by the caller (sidecar metadata).
"""

from __future__ import annotations

import copy
import logging
import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from aias_augment.assets.errors import AssetError
from aias_augment.assets.meshes import (
    CREASE_ANGLE_DEG,
    MESH_SUFFIXES,
    axis_rotation_to_z_up,
    crease_normals,
    gazebo_visual_mesh,
    load_mesh_file,
    normalise_meshes,
    read_collada_unit,
    scene_parts,
)
from aias_augment.core.config import data_root
from aias_augment.core.errors import InputError

if TYPE_CHECKING:  # imported where used: trimesh (~0.16 s with networkx) only when meshes are read
    import trimesh

log = logging.getLogger(__name__)

__all__ = [
    "CATEGORY_HEIGHT_RANGE_M",
    "CREASE_ANGLE_DEG",
    "DEFAULT_ASSETS",
    "MESH_SUFFIXES",
    "PLAUSIBLE_HEIGHT_M",
    "Asset",
    "AssetError",
    "PathAssets",
    "axis_rotation_to_z_up",
    "bank_entry_meta",
    "crease_normals",
    "default_asset",
    "gazebo_visual_mesh",
    "load_asset",
    "load_mesh_file",
    "normalise_meshes",
    "plausible_scale",
    "read_collada_unit",
    "scene_parts",
]


#: Real-world height ranges (metres) per category, used to sample a physically plausible scale.
CATEGORY_HEIGHT_RANGE_M: dict[str, tuple[float, float]] = {
    "traffic_cone": (0.45, 0.92),
    "barrel": (0.9, 1.1),
    "barrier": (0.8, 1.1),
    "concrete_block": (0.15, 0.25),
    "fire_hydrant": (0.6, 0.9),
    "car": (1.35, 1.9),
    "parking_block": (0.1, 0.2),
    "cow": (1.2, 1.6),
}


#: Default asset per category in the shared data folder (relative to ``data_root()``).
DEFAULT_ASSETS: dict[str, list[str]] = {
    "traffic_cone": ["meshes/gazebo_models/construction_cone"],
    "barrel": ["meshes/gazebo_models/construction_barrel"],
    "barrier": ["meshes/gazebo_models/jersey_barrier"],
    "concrete_block": ["meshes/gazebo_models/cinder_block"],
    "fire_hydrant": ["meshes/gazebo_models/fire_hydrant"],
    "car": ["meshes/gazebo_models/hatchback", "meshes/gazebo_models/suv"],
    "parking_block": ["meshes/gazebo_models/drc_practice_yellow_parking_block"],
}


#: Plausible heights (metres) of categories that have no sampling range in :data:`CATEGORY_HEIGHT_RANGE_M`.
PLAUSIBLE_HEIGHT_M = {
    "person": (1.0, 2.1),
    "pedestrian": (1.0, 2.1),
    "child": (0.7, 1.6),
    "bicycle": (0.8, 1.3),
    "motorcycle": (0.9, 1.6),
    "truck": (2.5, 4.5),
    "bus": (2.7, 4.3),
    "dog": (0.3, 0.9),
    "stroller": (0.8, 1.2),
    "traffic_light": (0.6, 6.0),
    "sign": (0.3, 3.5),
}


def plausible_scale(height_m: float, category: str) -> tuple[float, str | None]:
    """A mesh ``height_m`` tall for ``category`` (units unknown): (scale to apply, warning or None). Metres when the
    height is in the category's plausible range (3x margin); else the unit (cm, mm, in, dm, km) whose height lands
    closest to the middle of the range; none: InputError."""
    if not math.isfinite(height_m) or height_m <= 0:
        raise InputError(f"mesh for {category!r} has height {height_m}")
    lo, hi = CATEGORY_HEIGHT_RANGE_M.get(category) or PLAUSIBLE_HEIGHT_M.get(category) or (0.05, 30.0)
    mid, lo, hi = math.sqrt(lo * hi), lo / 3, hi * 3
    if lo <= height_m <= hi:
        return 1.0, None
    fits = [
        (abs(math.log(height_m * s / mid)), unit, s)
        for unit, s in (
            ("centimetres", 0.01),
            ("millimetres", 0.001),
            ("inches", 0.0254),
            ("decimetres", 0.1),
            ("kilometres", 1e3),
        )
        if lo <= height_m * s <= hi
    ]
    if not fits:
        raise InputError(
            f"mesh for {category!r} is {height_m:g} units tall; no unit (m, cm, mm, in, dm, km) gives a "
            f"height in [{lo:.3g}, {hi:.3g}] m (give its scale explicitly)"
        )
    _, unit, s = min(fits)
    return s, (
        f"mesh for {category!r} is {height_m:g} units tall: implausible in metres; guessed {unit}, "
        f"rescaled by {s:g} to {height_m * s:.3g} m"
    )


class _ScaledMeshes(Sequence):
    """The meshes of :meth:`Asset.scaled`, made on first read: new vertices, shared faces, the given normals (a
    uniform scale keeps unit normals: no recompute at a seam) and a shallow copy of the visual (the texture is not
    copied). The fast path never reads them (it draws and shadows the root's meshes times the scale), so a sample
    does not pay for building them (~0.25 ms per call). Pickles as the tuple of meshes."""

    __slots__ = ("_base", "_factor", "_built")

    def __init__(self, base, factor: float):
        self._base, self._factor, self._built = base, factor, None

    def _meshes(self) -> tuple:
        import trimesh

        if self._built is None:
            self._built = tuple(
                trimesh.Trimesh(
                    vertices=np.asarray(m.vertices) * self._factor,
                    faces=m.faces,
                    vertex_normals=m.vertex_normals,
                    visual=copy.copy(m.visual),
                    process=False,
                )
                for m in self._base
            )
        return self._built

    def __len__(self) -> int:
        return len(self._base)

    def __getitem__(self, i):
        return self._meshes()[i]

    def __iter__(self):
        return iter(self._meshes())

    def __reduce__(self):
        return (tuple, (self._meshes(),))


def hull_vertices(points: np.ndarray) -> np.ndarray:
    """The vertices of the convex hull of ``points`` (N, 3); all of them when the hull is flat (a plane, a line)."""
    from scipy.spatial import ConvexHull, QhullError

    pts = np.asarray(points, float).reshape(-1, 3)
    try:
        return pts[ConvexHull(pts).vertices]
    except (QhullError, ValueError):  # fewer than 4 points, or all in a plane
        return pts


@dataclass(frozen=True, eq=False)
class Asset:
    """A renderable object in the canonical frame (metres, z up, on z = 0).

    ``meshes`` keeps one trimesh per material so textures survive (no atlas packing).
    """

    name: str
    category: str
    meshes: tuple[trimesh.Trimesh, ...]
    source: str
    licence: str = ""
    procedural: bool = False
    meta: dict = field(default_factory=dict)
    # Provenance for the renderer: an asset made by ``scaled`` is ``render_scale`` x its unscaled ``render_root``, so
    # the renderer draws the root's cached GPU mesh through a scale matrix instead of uploading a copy per call.
    render_root: "Asset | None" = field(default=None, repr=False, compare=False)
    render_scale: float = field(default=1.0, repr=False, compare=False)

    @property
    def bounds_m(self) -> np.ndarray:
        """(2, 3) min/max corners in the object frame (computed once per asset: an asset's meshes are not changed
        after it is made; trimesh re-hashes the vertices at each ``bounds``, ~0.2 ms per call)."""
        b = self.__dict__.get("_bounds_m")
        if b is None:
            known = getattr(self.meshes, "bounds_m", None)  # meshes made on first read know their bounds
            if known is not None:
                b = known()
            else:
                bb = np.array([m.bounds for m in self.meshes])
                b = np.stack([bb[:, 0].min(0), bb[:, 1].max(0)])
            self.__dict__["_bounds_m"] = b  # a memo, not a field: the dataclass stays frozen and compares the same
        return b.copy()

    @property
    def extents_m(self) -> np.ndarray:
        b = self.bounds_m
        return b[1] - b[0]

    @property
    def height_m(self) -> float:
        return float(self.extents_m[2])

    @property
    def reference_height_m(self) -> float:
        """The height a category's size range refers to: the height, or for a deformed variant (a crushed cone, a
        cone on its side) its source's (``meta["reference_height_m"]``, see :mod:`aias_augment.assets.deform`)."""
        return float(self.meta.get("reference_height_m", self.height_m))

    def corners_m(self) -> np.ndarray:
        """(8, 3) corners of the axis-aligned bounding box in the object frame (read-only; made once per asset)."""
        c = self.__dict__.get("_corners_m")
        if c is None:
            lo, hi = self.bounds_m
            c = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])])
            c.setflags(write=False)
            self.__dict__["_corners_m"] = c
        return c

    def outline_m(self) -> np.ndarray:
        """(N, 3) points in the object frame whose projection bounds the projected object in any view from in front
        of it: the vertices of its meshes' convex hull (a perspective projection's extremes over a convex solid lie
        at its vertices), so their projected box is the object's mask-tight box, where :meth:`corners_m` gives the
        bounding box's (a cone's tip is a point, its box's top face is as wide as its base). Read-only; made once
        per asset, a scaled copy's from its root's."""
        o = self.__dict__.get("_outline_m")
        if o is None:
            if self.render_root is not None:
                o = self.render_root.outline_m() * self.render_scale
            else:
                known = getattr(self.meshes, "outline_m", None)  # meshes made on first read know their outline
                o = known() if known is not None else hull_vertices(np.concatenate([m.vertices for m in self.meshes]))
            o = np.array(o, float)
            o.setflags(write=False)
            self.__dict__["_outline_m"] = o
        return o

    def scaled(self, factor: float) -> "Asset":
        """Uniformly scaled copy about the contact point (origin); stays on z = 0."""
        if not np.isfinite(factor) or factor <= 0:
            raise AssetError(f"scale factor must be positive and finite, got {factor}")
        root = self.render_root if self.render_root is not None else self
        out = Asset(
            self.name,
            self.category,
            _ScaledMeshes(self.meshes, float(factor)),
            self.source,
            self.licence,
            self.procedural,
            {
                **self.meta,
                "scale": self.meta.get("scale", 1.0) * factor,
                **(
                    {"reference_height_m": self.meta["reference_height_m"] * factor}
                    if "reference_height_m" in self.meta
                    else {}
                ),
            },
            root,
            self.render_scale * float(factor),
        )
        # Its bounds are this asset's times the (positive) factor, exactly: min/max commute with the product.
        out.__dict__["_bounds_m"] = self.bounds_m * float(factor)
        return out

    @property
    def triangle_count(self) -> int:
        return int(sum(len(m.faces) for m in self.meshes))


def load_asset(
    path: str | Path,
    *,
    category: str = "object",
    name: str | None = None,
    scale: float | None = None,
    up_axis: str | None = None,
    licence: str = "",
) -> Asset:
    """Load a mesh file or a gazebo model folder (``model.sdf``) as a canonical :class:`Asset`."""
    path = Path(path)
    if path.is_dir():
        if not (path / "model.sdf").is_file():
            raise AssetError(f"{path}: a folder asset needs a model.sdf (gazebo layout)")
        mesh_path, sdf_scale = gazebo_visual_mesh(path)
        # gazebo meshes are in the model's z-up frame; the COLLADA unit still applies.
        meshes = load_mesh_file(mesh_path, scale=sdf_scale * (scale or 1.0), up_axis=up_axis or "Z_UP")
        if not licence and (path.parent / "LICENSE").exists():
            licence = "CC-BY-3.0 (gazebo_models)"
    else:
        meshes = load_mesh_file(path, scale=scale, up_axis=up_axis)
    return Asset(name or path.stem, category, normalise_meshes(meshes), str(path), licence)


def bank_entry_meta(path: str | Path) -> dict:
    """What a bank folder's ``bank.json`` (written by ``aias-assets from-labels`` / ``deform``) records about the
    mesh file ``path``: its source, its deformation and the height its size range refers to (a cone lying on its
    side is a cone of its source's height); {} for a file outside such a folder. The index is JSON: read, never run."""
    import json

    path = Path(path)
    index = path.parent / "bank.json"
    if not index.is_file():
        return {}
    try:
        entries = json.loads(index.read_text())["report"]["assets"]
    except (OSError, ValueError, KeyError, TypeError) as e:
        raise AssetError(f"{index}: unreadable bank index ({e})") from None
    keys = ("source_image", "source_box_xyxy", "lift_mode", "deformation", "reference_height_m")
    for e in entries:
        if e.get("file") == path.name:
            return {k: e[k] for k in keys if k in e}
    return {}


_CACHE: dict[tuple, Asset] = {}


def default_asset(category: str, index: int = 0) -> Asset:
    """The default asset of a category from the shared data folder (cached per process)."""
    if category not in DEFAULT_ASSETS:
        raise KeyError(f"no default asset for category {category!r}; known: {sorted(DEFAULT_ASSETS)}")
    rel = DEFAULT_ASSETS[category][index % len(DEFAULT_ASSETS[category])]
    key = (category, rel)
    if key not in _CACHE:
        _CACHE[key] = load_asset(data_root() / rel, category=category, name=Path(rel).name)
    return _CACHE[key]


class PathAssets:
    """A small asset source from user paths: ``{"stroller": ["my/stroller.obj", ...]}``.

    ``scales``/``up_axes`` optionally give the unit scale and up axis per path for files that do not declare them.
    Every file is loaded once at construction, so a file that cannot be read, converted or sized for its category is
    an :class:`AssetError` naming it here rather than a skip at every later call; a copy sent to another process
    reloads its files on first use.
    """

    def __init__(
        self, paths: dict[str, list[str]], scales: dict[str, float] | None = None, up_axes: dict[str, str] | None = None
    ):
        if not paths:
            raise ValueError("PathAssets needs at least one category")
        self.paths = {c: [str(p) for p in ps] for c, ps in paths.items()}
        for c, ps in self.paths.items():
            if not ps:
                raise ValueError(f"PathAssets: category {c!r} has no paths")
        missing = [p for ps in self.paths.values() for p in ps if not Path(p).exists()]
        if missing:
            raise AssetError(f"PathAssets: mesh paths do not exist: {missing}")
        self.scales = scales or {}
        self.up_axes = up_axes or {}
        self._loaded: dict[str, Asset] = {}
        for c, ps in self.paths.items():
            for p in ps:
                try:
                    self._load(c, p)
                except AssetError as e:
                    raise AssetError(f"PathAssets: category {c!r}: {e}") from e

    def categories(self) -> list[str]:
        return sorted(self.paths)

    def _load(self, category: str, p: str) -> Asset:
        if p not in self._loaded:
            asset = load_asset(p, category=category, scale=self.scales.get(p), up_axis=self.up_axes.get(p))
            if p not in self.scales:  # units unknown: an implausible height is rescaled with a warning, or refused
                s, warning = plausible_scale(asset.height_m, category)
                if warning:
                    log.warning("%s: %s", p, warning)
                    asset = load_asset(p, category=category, scale=s, up_axis=self.up_axes.get(p))
                    asset.meta["unit_guess"] = warning
            asset.meta.update(bank_entry_meta(p))
            self._loaded[p] = asset
        return self._loaded[p]

    def sample(self, category: str, rng: np.random.Generator) -> Asset:
        if category not in self.paths:
            return default_asset(category)
        return self._load(category, self.paths[category][int(rng.integers(len(self.paths[category])))])

    def __getstate__(self):  # pickles without loaded meshes (reloaded lazily in each worker)
        return {"paths": self.paths, "scales": self.scales, "up_axes": self.up_axes, "_loaded": {}}

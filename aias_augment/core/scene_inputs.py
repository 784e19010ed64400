"""Typed scene inputs: what a caller knows about a scene besides the image, K and depth.

:class:`SceneInputs` holds the facts the analysis, the planner and the lighting read (where objects may stand,
measured points, existing 3D boxes, position/time/orientation for the sun, ...), each typed and checked against
the image before anything runs, so a wrong shape or a misspelt key is an error at the call, not a silently ignored
input. ``insert_into_image(..., scene=SceneInputs(...))`` takes it; the older ``meta=`` dict is still accepted and
is split by :meth:`SceneInputs.from_meta` into these facts and free-form provenance (source path, frame id, ...),
which the pipeline carries but never reads. A key that is not a fact but within a typo of one (``placable_mask``)
is refused with the name it probably meant.
"""

from __future__ import annotations

import difflib
from dataclasses import dataclass, fields
from datetime import datetime
from typing import Any, Mapping

import numpy as np

from aias_augment.core.envmap import EnvironmentMap
from aias_augment.core.oriented_box import OrientedBox


@dataclass(frozen=True, eq=False)
class SceneInputs:
    """Scene facts, all optional. Arrays are (H, W) for the image they come with.

    placeable_mask: (H, W) bool, where objects may stand (e.g. road pixels); replaces the estimated region.
    ground_mask: (H, W) bool, ground pixels for the lighting's lit/shadowed ground ratio.
    semantic: (H, W) integer label map (the placeable region keeps to ground-like labels).
    lidar_points_in_cam: (N, 3) finite points in metres, camera frame (3D collision checks, local ground refit).
    boxes_in_cam: existing 3D boxes (:class:`aias_augment.plan.collision.OrientedBox`) objects must not intersect.
    indoor: the scene is indoors (no sun, no sky model).
    lat, lon, utc: position (degrees) and time (ISO string or datetime) for the solar position; all three or none.
    heading_deg, pitch_deg, roll_deg: camera orientation (heading clockwise from north; level camera = 0 pitch/roll).
    enu_from_cam, enu_from_world, world_from_env: 3x3 rotations (camera / world frame to East-North-Up; an HDR
        environment map's frame to the world).
    up_in_world: (3,) the world's up direction.
    envmap: the scene's HDR environment map: an :class:`aias_augment.core.envmap.EnvironmentMap` (its own
        ``world_from_env`` places it; for a single image the world is the camera frame) or an (H, 2H, 3) linear
        radiance array (placed by ``world_from_env``, default identity). The lighting is read from it (source
        'envmap': its brightest compact light as the sun, the rest as ambient) instead of estimated from the image.
    """

    placeable_mask: np.ndarray | None = None
    ground_mask: np.ndarray | None = None
    semantic: np.ndarray | None = None
    lidar_points_in_cam: np.ndarray | None = None
    boxes_in_cam: tuple = ()
    indoor: bool | None = None
    lat: float | None = None
    lon: float | None = None
    utc: str | datetime | None = None
    heading_deg: float | None = None
    pitch_deg: float | None = None
    roll_deg: float | None = None
    enu_from_cam: np.ndarray | None = None
    enu_from_world: np.ndarray | None = None
    world_from_env: np.ndarray | None = None
    up_in_world: np.ndarray | None = None
    envmap: Any = None

    # ------------------------------------------------------------------------------------------------ conversion

    @classmethod
    def fact_names(cls) -> tuple[str, ...]:
        return tuple(f.name for f in fields(cls))

    @classmethod
    def from_meta(cls, meta: Mapping[str, Any] | None) -> tuple["SceneInputs", dict]:
        """Split a ``meta`` dict into (facts, provenance). Keys that name a fact become fields (a ``None`` value
        means "not given"); a key one typo away from a fact name raises ``ValueError`` naming it; every other key is
        provenance, returned unchanged."""
        names = cls.fact_names()
        facts, provenance = {}, {}
        for key, value in (meta or {}).items():
            if key in names:
                if value is not None:
                    facts[key] = tuple(value) if key == "boxes_in_cam" else value
                continue
            close = difflib.get_close_matches(str(key), names, n=1, cutoff=0.85)
            if close:
                raise ValueError(
                    f"meta key {key!r} is not a scene input; did you mean {close[0]!r}? "
                    f"(scene inputs: {', '.join(names)})"
                )
            provenance[key] = value
        return cls(**facts), provenance

    def as_meta(self) -> dict:
        """The given facts as the ``meta`` keys the analysis, planner and lighting read (absent ones left out)."""
        out = {}
        for f in fields(self):
            v = getattr(self, f.name)
            if v is None or (f.name == "boxes_in_cam" and not v):
                continue
            out[f.name] = list(v) if f.name == "boxes_in_cam" else v
        return out

    def is_empty(self) -> bool:
        return not self.as_meta()

    # ------------------------------------------------------------------------------------------------ checks

    def checked(self, image_hw: tuple[int, int]) -> "SceneInputs":
        """Every given fact checked against an image of ``image_hw`` (H, W): a ``ValueError`` naming the fact and
        what was expected, else the facts with arrays in their canonical dtypes (masks bool, points float64)."""
        h, w = image_hw
        new = {}
        for name in ("placeable_mask", "ground_mask"):
            m = getattr(self, name)
            if m is not None:
                new[name] = _mask(name, m, (h, w))
        if self.semantic is not None:
            s = np.asarray(self.semantic)
            if s.shape != (h, w) or not (np.issubdtype(s.dtype, np.integer) or s.dtype == bool):
                raise ValueError(
                    f"scene input 'semantic' must be an ({h}, {w}) integer label map, got {s.shape} {s.dtype}"
                )
            new["semantic"] = s
        if self.lidar_points_in_cam is not None:
            p = np.asarray(self.lidar_points_in_cam, dtype=np.float64)
            if p.ndim != 2 or p.shape[1] != 3 or not np.all(np.isfinite(p)):
                raise ValueError(
                    f"scene input 'lidar_points_in_cam' must be (N, 3) finite metres, got {p.shape}"
                    + ("" if p.ndim != 2 or p.shape[1] != 3 else " with non-finite values")
                )
            new["lidar_points_in_cam"] = p
        if self.boxes_in_cam:
            bad = [type(b).__name__ for b in self.boxes_in_cam if not isinstance(b, OrientedBox)]
            if bad:
                raise ValueError(f"scene input 'boxes_in_cam' must hold OrientedBox objects, got {bad[:3]}")
        if self.indoor is not None and not isinstance(self.indoor, (bool, np.bool_)):
            raise ValueError(f"scene input 'indoor' must be a bool, got {self.indoor!r}")
        given = [k for k in ("lat", "lon", "utc") if getattr(self, k) is not None]
        if given and len(given) < 3:
            raise ValueError(
                f"scene inputs 'lat', 'lon' and 'utc' go together (the solar position needs all "
                f"three), got only {given}"
            )
        if self.lat is not None and not -90.0 <= _finite("lat", self.lat) <= 90.0:
            raise ValueError(f"scene input 'lat' must lie in [-90, 90] degrees, got {self.lat}")
        if self.lon is not None and not -180.0 <= _finite("lon", self.lon) <= 360.0:
            raise ValueError(f"scene input 'lon' must lie in [-180, 360] degrees, got {self.lon}")
        if self.utc is not None and not isinstance(self.utc, (str, datetime)):
            raise ValueError(f"scene input 'utc' must be an ISO time string or a datetime, got {self.utc!r}")
        if isinstance(self.utc, str):
            _utc("utc", self.utc)
        for name in ("heading_deg", "pitch_deg", "roll_deg"):
            if getattr(self, name) is not None:
                _finite(name, getattr(self, name))
        for name in ("enu_from_cam", "enu_from_world", "world_from_env"):
            r = getattr(self, name)
            if r is not None:
                new[name] = _rotation(name, r)
        if self.up_in_world is not None:
            u = np.asarray(self.up_in_world, dtype=np.float64)
            if u.shape != (3,) or not np.all(np.isfinite(u)) or np.linalg.norm(u) < 1e-9:
                raise ValueError(f"scene input 'up_in_world' must be a finite non-zero 3-vector, got {u!r}")
            new["up_in_world"] = u
        if self.envmap is not None:
            new["envmap"] = _envmap(self.envmap, new.get("world_from_env"))
        return SceneInputs(**{**{f.name: getattr(self, f.name) for f in fields(self)}, **new})


def _mask(name: str, m, hw: tuple[int, int]) -> np.ndarray:
    a = np.asarray(m)
    if a.shape != hw:
        raise ValueError(f"scene input {name!r} must be {hw} (the image's H, W), got {a.shape}")
    if a.dtype == bool:
        return a
    if np.issubdtype(a.dtype, np.integer) and a.size and a.min() >= 0 and a.max() <= 1:
        return a.astype(bool)
    raise ValueError(
        f"scene input {name!r} must be a bool (or 0/1 integer) mask, got dtype {a.dtype}"
        + (f" with values in [{a.min()}, {a.max()}]" if a.size and np.issubdtype(a.dtype, np.number) else "")
    )


def _finite(name: str, v) -> float:
    try:
        f = float(v)
    except (TypeError, ValueError):
        raise ValueError(f"scene input {name!r} must be a number, got {v!r}") from None
    if not np.isfinite(f):
        raise ValueError(f"scene input {name!r} must be finite, got {v!r}")
    return f


def _utc(name: str, s: str) -> None:
    """``s`` parses as the solar position parses it (:func:`aias_augment.analyse.lighting.sun.solar_direction_enu`)."""
    import pandas as pd

    try:
        ts = pd.Timestamp(s)
    except (ValueError, TypeError, OverflowError) as e:
        raise ValueError(
            f"scene input {name!r} must be an ISO time string (e.g. 2024-06-01T12:00:00Z), got {s!r} ({e})"
        ) from None
    if pd.isna(ts):
        raise ValueError(f"scene input {name!r} must be an ISO time string (e.g. 2024-06-01T12:00:00Z), got {s!r}")


def _envmap(v, world_from_env):
    """An EnvironmentMap as it is, or one made of an (H, 2H, 3) radiance array and ``world_from_env``."""
    if isinstance(v, EnvironmentMap):
        return v
    if not isinstance(v, np.ndarray):
        raise ValueError(
            f"scene input 'envmap' must be an EnvironmentMap or an (H, 2H, 3) radiance array, got {type(v).__name__}"
        )
    if v.ndim != 3 or v.shape[2] != 3 or v.shape[1] != 2 * v.shape[0]:
        raise ValueError(f"scene input 'envmap' must be (H, 2H, 3) equirectangular radiance, got {v.shape}")
    try:
        return EnvironmentMap(v, np.eye(3) if world_from_env is None else world_from_env)
    except ValueError as e:
        raise ValueError(f"scene input 'envmap': {e}") from None


def _rotation(name: str, r) -> np.ndarray:
    a = np.asarray(r, dtype=np.float64)
    if a.shape != (3, 3) or not np.all(np.isfinite(a)):
        raise ValueError(f"scene input {name!r} must be a finite 3x3 rotation, got shape {a.shape}")
    if not np.allclose(a @ a.T, np.eye(3), atol=1e-4) or np.linalg.det(a) < 0:
        raise ValueError(f"scene input {name!r} is not a rotation (R R^T != I or det < 0)")
    return a


def scene_meta(meta: Mapping[str, Any] | None, scene: SceneInputs | None, image_hw: tuple[int, int]) -> dict:
    """The ``meta`` dict the pipeline's stages read, from a caller's ``meta`` and/or ``scene``: the facts checked
    against the image (``ValueError`` on any problem), provenance passed through. Facts may come from one of the
    two, not both."""
    if not meta and scene is None:  # nothing given: nothing to check (the common case, at every call)
        return {}
    facts, provenance = SceneInputs.from_meta(meta)
    if scene is not None:
        if not isinstance(scene, SceneInputs):
            raise ValueError(f"scene must be a SceneInputs, got {type(scene).__name__}")
        if not facts.is_empty():
            raise ValueError(f"scene facts given twice: scene= and meta keys {sorted(facts.as_meta())}")
        facts = scene
    return {**provenance, **facts.checked(image_hw).as_meta()}

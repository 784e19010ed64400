"""An object's size in the image: the box height of an upright object standing on a ground pixel, the size
target an object draws, the ground pixels where it has that size, and the scene's candidate pixels kept for the
next plan on the same analysis."""

from __future__ import annotations

import hashlib
from collections import OrderedDict

import numpy as np

from aias_augment.analyse.ground import GroundPlane
from aias_augment.core.geometry import Intrinsics, project_points
from aias_augment.plan.placement_config import PlacementConfig

__all__ = [
    "GROUND_CANDIDATES",
    "GroundCandidates",
    "box_heights_at_pixels",
    "box_heights_from_bases",
    "candidates_for_box_height",
    "draw_box_height_target",
    "predicted_box_heights_px",
]


def draw_box_height_target(cfg: PlacementConfig, rng: np.random.Generator) -> float | None:
    """Target box height / image height for one object, or None when the config sets no target."""
    if cfg.box_height_frac_samples:
        base = cfg.box_height_frac_samples[int(rng.integers(len(cfg.box_height_frac_samples)))]
        return float(np.clip(base * np.exp(rng.normal(0.0, cfg.box_height_jitter)), 1e-3, 1.0))
    if cfg.box_height_frac_range is not None:
        return float(rng.uniform(*cfg.box_height_frac_range))
    return None


def predicted_box_heights_px(
    uv: np.ndarray, object_height_m: float, ground: GroundPlane, intrinsics: Intrinsics
) -> np.ndarray:
    """(N, 2) ground pixels -> (N,) image height in pixels of a vertical segment of ``object_height_m`` standing on
    the ground there (its base and top projected); nan where the ray misses the ground or the top is behind the
    camera. An object's box is about this high (a cone's box is its height; wide objects add a little)."""
    return box_heights_at_pixels(uv, np.full(len(uv), float(object_height_m)), ground, intrinsics)


def candidates_for_box_height(
    cand: np.ndarray,
    target_frac: float,
    object_height_m: float,
    ground: GroundPlane,
    intrinsics: Intrinsics,
    tolerance: float,
    pred: np.ndarray | None = None,
) -> tuple[np.ndarray, str]:
    """Flat pixel indices of ``cand`` whose predicted box height is within ``tolerance`` (relative) of
    ``target_frac * height``; when none is, the 2 % nearest to it (and a note saying so). ``pred``: the
    candidates' :func:`predicted_box_heights_px` when already known."""
    if pred is None:
        v, u = np.divmod(cand, intrinsics.width)
        pred = predicted_box_heights_px(np.c_[u, v].astype(np.float64), object_height_m, ground, intrinsics)
    target = target_frac * intrinsics.height
    rel = np.abs(pred / target - 1.0)
    rel[~np.isfinite(rel)] = np.inf
    ok = rel <= tolerance
    if ok.any():
        return cand[ok], f" (target {target:.0f} px)"
    finite = np.isfinite(rel)
    if not finite.any():
        return cand, f" (target {target:.0f} px: no ground pixel predicts a size, target ignored)"
    n = max(1, int(0.02 * finite.sum()))
    nearest = np.argsort(rel)[:n]
    return cand[nearest], f" (target {target:.0f} px not reachable in this scene: nearest sizes used)"


def box_heights_at_pixels(
    uv: np.ndarray, heights_m: np.ndarray, ground: GroundPlane, intrinsics: Intrinsics
) -> np.ndarray:
    """:func:`predicted_box_heights_px` with one object height per pixel."""
    return box_heights_from_bases(ground.intersect_pixels(uv, intrinsics), heights_m, ground, intrinsics)


def box_heights_from_bases(
    base: np.ndarray, heights_m: np.ndarray, ground: GroundPlane, intrinsics: Intrinsics
) -> np.ndarray:
    """(N,) image heights of vertical segments of ``heights_m`` (N,) standing at the ground points ``base`` (N, 3)."""
    top = base + heights_m[:, None] * ground.normal[None, :]
    out = np.full(len(base), np.nan)
    ok = np.all(np.isfinite(base), axis=1) & np.isfinite(heights_m) & (base[:, 2] > 0.05) & (top[:, 2] > 0.05)
    if ok.any():
        ub, _ = project_points(base[ok], intrinsics.K)
        ut, _ = project_points(top[ok], intrinsics.K)
        out[ok] = np.abs(ub[:, 1] - ut[:, 1])
    return out


class GroundCandidates:
    """The candidate contact pixels of a scene (below the horizon margin, inside the region) and their predicted
    box heights per object height, for the last few scenes. Planning on the same analysis again (a training loop's
    next epoch) then skips the full-frame pixel grid. Keyed by the plane, the intrinsics, the margin and the
    region's bytes (a digest, so a mask changed in place is a new key): the arrays are those a fresh computation
    gives, so the draws and results are the same with or without a hit."""

    def __init__(self, max_entries: int = 32):
        self.max_entries = max_entries
        self._entries: OrderedDict = OrderedDict()
        self._digests: OrderedDict = OrderedDict()  # id -> (mask, digest) of read-only masks that own their data

    def _region_digest(self, region_mask) -> tuple:
        m = region_mask
        # A read-only array that owns its memory (PlaceableRegion's mask) cannot change: digested once.
        frozen = isinstance(m, np.ndarray) and not m.flags.writeable and m.base is None
        if frozen:
            got = self._digests.get(id(m))
            if got is not None and got[0] is m:
                return got[1]
        a = np.ascontiguousarray(np.asarray(m, bool))
        digest = (a.shape, hashlib.blake2b(np.packbits(a).tobytes(), digest_size=16).digest())
        if frozen:
            self._digests[id(m)] = (m, digest)
            while len(self._digests) > self.max_entries:
                self._digests.popitem(last=False)
        return digest

    def _key(self, ground: GroundPlane, intrinsics: Intrinsics, region_mask, margin: float) -> tuple:
        region = None if region_mask is None else self._region_digest(region_mask)
        return (
            tuple(np.asarray(ground.normal, float).tolist()),
            float(ground.d),
            intrinsics.width,
            intrinsics.height,
            float(intrinsics.fx),
            float(intrinsics.fy),
            float(intrinsics.cx),
            float(intrinsics.cy),
            float(margin),
            region,
        )

    def get(self, ground: GroundPlane, intrinsics: Intrinsics, region_mask, margin: float) -> dict:
        key = self._key(ground, intrinsics, region_mask, margin)
        entry = self._entries.get(key)
        if entry is None:
            w, h = intrinsics.width, intrinsics.height
            try:
                horizon = ground.horizon_line(intrinsics)
            except ValueError:
                horizon = None
            allowed = np.ones((h, w), bool)
            if horizon is not None:
                # broadcast rows and columns: the same sums, element by element, as on a full pixel grid
                uu, vv = np.arange(w)[None, :], np.arange(h)[:, None]
                allowed &= horizon[0] * uu + horizon[1] * vv + horizon[2] > margin
            if region_mask is not None:
                allowed &= np.asarray(region_mask, bool)
            cand = np.flatnonzero(allowed)
            cand.setflags(write=False)
            entry = {"cand": cand, "pred": {}}
            self._entries[key] = entry
            while len(self._entries) > self.max_entries:
                self._entries.popitem(last=False)
        else:
            self._entries.move_to_end(key)
        return entry

    def predicted(self, entry: dict, object_height_m: float, ground: GroundPlane, intrinsics: Intrinsics) -> np.ndarray:
        """The candidates' :func:`predicted_box_heights_px` for ``object_height_m``: their ground points are kept
        (heights are continuous draws: one projection per call, from the same points a fresh computation gives)."""
        base = entry["pred"].get("base")
        if base is None:
            v, u = np.divmod(entry["cand"], intrinsics.width)
            base = ground.intersect_pixels(np.c_[u, v].astype(np.float64), intrinsics)
            base.setflags(write=False)
            entry["pred"]["base"] = base
        return box_heights_from_bases(base, np.full(len(base), float(object_height_m)), ground, intrinsics)


GROUND_CANDIDATES = GroundCandidates()

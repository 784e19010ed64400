"""The fast render path: an asset's views rendered once per view bin, warped and relit per sample without GL.

A *view* of an asset is what a camera looking at the asset's centre sees: albedo, normals (object frame), depth and
coverage, rendered by :func:`aias_augment.apply.render.render_object_window` (2x supersampled) for the centre of a bin of

- the view direction in the object frame (the unit vector from the object's centre to the camera): azimuth about
  the object's up axis in steps of ``azimuth_step_deg``, elevation in steps of ``elevation_step_deg``;
- the nearness ``u = r / d`` (bounding-sphere radius over the distance to the centre), in steps of ``nearness_step``:
  perspective foreshortening depends on it; a uniformly scaled asset at a scaled distance has the same view, so the
  asset's scale is not part of the key;
- the resolution: the smallest power of two >= the projected bounding-sphere diameter, between ``min_px`` and
  ``max_px``, so that a view is only ever shrunk (by at most 2x) when it is warped into the image.

Per sample the view of the sample's bin is mapped into the image by one homography (exact for a camera rotating
about its centre: the image camera vs a virtual camera at the same place looking at the object; the distance
inside the bin is a scale about the object's centre), all inside the object's window; the only approximation is
the bin itself (the view from the bin's centre direction and nearness instead of the sample's). The layers are then
shaded with :func:`aias_augment.apply.shading.shade_object`, the function the full render path uses.

Binning error (``benchmarks/bench_view_cache.py`` -> ``results/bench/view_cache.md``: 200 cones placed by the fast
preset's planner on TraCon images at 640x480, against a full 4x-supersampled render, both shaded by
``shade_object``): the warp's geometry is exact (silhouette centroids agree within ~0.2 px, areas within ~1.5 %);
what differs is the view direction, up to half a bin away, and one more resampling. :data:`DEFAULT_BINNING` (7.5 deg
azimuth, 4 deg elevation, nearness 0.04): median shading error 4.0 sRGB levels over the object, median box IoU 1.00,
worst 0.94 for boxes >= 40 px. Bins of (15 deg, 5 deg, 0.05) warm up about twice as fast (hit rate 0.56 vs 0.26
after 150 objects) for 5.5 levels; (30 deg, 8 deg, 0.08): 7.4 levels, worst box IoU 0.89. The finer bins are the
default: the error is what the issue bounds, the warm-up is paid once per process.

The cache (:class:`ViewCache`) is a bounded LRU in memory (bytes, not entries), per process; like the scene cache it
never changes what is computed, only when: a view is a deterministic render of (asset, bin), so a hit and a miss
give the same bytes. With a ``directory`` (``InsertObjects(scene_cache=DIR)`` puts it in ``DIR/views``) the views
are also kept on disk, by the asset's content digest (:func:`asset_digest`: meshes, normals, UVs, textures,
materials, binning, package version) and bin, so that every DataLoader worker and later run reads a view one of them
rendered (and ``InsertObjects.warm`` can render them beforehand); a view read from disk is the same array.

Rotationally symmetric assets (:func:`rotational_symmetry_order`: the mesh, its normals and its texture colours map
onto themselves under a turn of 360/n deg about the up axis, n dividing the azimuth bins) share one sector of views:
a sample's azimuth bin is turned back into the first sector, and the pose is turned with it (the same object, so the
same image: exact up to the check's tolerance). The default traffic cone (a 12-sided body on a square base) has
n = 4: 12 azimuth bins instead of 48, so a training loop's cache warms 4x sooner, with the same binning error.
"""

from __future__ import annotations

import hashlib
import io
import json
import logging
import math
import os
from collections import OrderedDict
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from aias_augment.apply.render import RenderLayers, render_object_window
from aias_augment.apply.view_bins import (
    DEFAULT_BINNING,
    CachedView,
    ViewBinning,
    bin_direction,
    centre_and_radius,
    view_key,
    view_rotation,
)
from aias_augment.assets.asset import Asset
from aias_augment.core.geometry import Intrinsics, make_rigid

log = logging.getLogger(__name__)

__all__ = [
    "ViewBinning",
    "DEFAULT_BINNING",
    "CachedView",
    "ViewCache",
    "default_view_cache",
    "view_key",
    "render_from_view_cache",
    "warp_from_view_cache",
    "WarpedView",
    "rotational_symmetry_order",
    "asset_digest",
]


class ViewCache:
    """Bounded LRU of :class:`CachedView` by :func:`view_key`, ``max_bytes`` of layers in memory. Counts ``hits``
    and ``misses`` (renders). Pickles empty (each DataLoader worker fills its own)."""

    def __init__(
        self, max_bytes: int = 128 * 2**20, binning: ViewBinning = DEFAULT_BINNING, directory: str | Path | None = None
    ):
        if max_bytes < 0:
            raise ValueError(f"max_bytes must be >= 0, got {max_bytes}")
        self.max_bytes = int(max_bytes)
        self.binning = binning
        self.directory = None if directory is None else Path(directory)
        self.disk_hits = 0
        self._digests: dict[int, tuple[str, Asset]] = {}
        self._lru: OrderedDict[tuple, tuple[CachedView, Asset]] = OrderedDict()
        self.nbytes = 0
        self.hits = self.misses = 0
        self._symmetry: dict[int, tuple[int, Asset]] = {}

    def __getstate__(self):
        state = self.__dict__.copy()
        state["_lru"] = OrderedDict()
        state["_symmetry"] = {}
        state["_digests"] = {}
        state["nbytes"] = state["hits"] = state["misses"] = state["disk_hits"] = 0
        return state

    def __len__(self) -> int:
        return len(self._lru)

    def symmetry_order(self, root: Asset) -> int:
        """:func:`rotational_symmetry_order` of ``root`` for this cache's azimuth bins, computed once per asset."""
        got = self._symmetry.get(id(root))
        if got is None or got[1] is not root:
            if len(self._symmetry) > 256:  # procedural assets are new objects each time: keep the memo bounded
                self._symmetry.clear()
            folder = self._asset_folder(root)
            order = None
            if folder is not None and (folder / "symmetry.json").exists():
                try:
                    order = int(json.loads((folder / "symmetry.json").read_text())["order"])
                except (OSError, ValueError, KeyError):
                    order = None
            if order is None:
                order = rotational_symmetry_order(root, self.binning, self)
                if folder is not None:
                    write_atomic(folder / "symmetry.json", json.dumps({"order": order}).encode())
            got = self._symmetry[id(root)] = (order, root)
        return got[0]

    def _asset_folder(self, root: Asset) -> Path | None:
        """``directory / asset_digest(root)``, or None (no directory, or a procedural asset drawn anew per object; a
        finite family's member, ``meta["family"]``, is reused and keeps its views on disk)."""
        if self.directory is None or (root.procedural and "family" not in root.meta):
            return None
        got = self._digests.get(id(root))
        if got is None or got[1] is not root:
            if len(self._digests) > 256:
                self._digests.clear()
            got = self._digests[id(root)] = (asset_digest(root, self.binning), root)
        return self.directory / got[0]

    def _read(self, root: Asset, key: tuple) -> CachedView | None:
        folder = self._asset_folder(root)
        p = None if folder is None else folder / ("_".join(map(str, key)) + ".npz")
        if p is None or not p.exists():
            return None
        try:
            with np.load(p) as z:
                return CachedView(
                    np.ascontiguousarray(z["premultiplied"]),
                    tuple(int(v) for v in z["roi"]),
                    z["K_view"],
                    float(z["distance"]),
                )
        except Exception as e:  # a damaged or partly written file: render again (and overwrite)
            log.info("view cache: %s not used (%s)", p, e)
            return None

    def _write(self, root: Asset, key: tuple, view: CachedView) -> None:
        folder = self._asset_folder(root)
        if folder is None:
            return
        buf = io.BytesIO()
        np.savez(
            buf,
            premultiplied=view.premultiplied,
            roi=np.array(view.roi),
            K_view=view.K_view,
            distance=np.float64(view.distance),
        )
        write_atomic(folder / ("_".join(map(str, key)) + ".npz"), buf.getvalue())

    def get(self, root: Asset, key: tuple) -> CachedView:
        """The view of ``root`` (an unscaled asset) for ``key`` (from :func:`view_key`), rendered on a miss."""
        self.symmetry_order(root)  # decided before any view is shared (its probe views are cached as any other)
        return self._get_unshared(root, key)

    def _get_unshared(self, root: Asset, key: tuple) -> CachedView:
        full_key = (id(root),) + key
        hit = self._lru.get(full_key)
        if hit is not None and hit[1] is root:  # the entry holds its asset: its id cannot be reused while it lives
            self._lru.move_to_end(full_key)
            self.hits += 1
            return hit[0]
        view = self._read(root, key)
        if view is not None:
            self.disk_hits += 1
        else:
            self.misses += 1
            view = render_view(root, key, self.binning)
            self._write(root, key, view)
        if view.nbytes <= self.max_bytes:
            self._lru[full_key] = (view, root)
            self.nbytes += view.nbytes
            while self.nbytes > self.max_bytes:
                _, (old, _) = self._lru.popitem(last=False)
                self.nbytes -= old.nbytes
        return view


def write_atomic(path: Path, data: bytes) -> None:
    """Write ``data`` to ``path`` through a temporary file (readers never see half a file); an unwritable disk is
    logged, not raised (the in-memory cache still works)."""
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        tmp = path.with_name(f"{path.name}.{os.getpid()}.tmp")
        tmp.write_bytes(data)
        tmp.replace(path)
    except OSError as e:
        log.warning("cache: cannot write %s (%s)", path, e)


#: Bump when what a view holds or how it is rendered changes (old folders are then not read).
VIEW_FORMAT = 1


def asset_digest(asset: Asset, binning: ViewBinning = DEFAULT_BINNING) -> str:
    """A content digest of what a view of ``asset`` depends on: every mesh's vertices, triangles, vertex normals,
    UVs and visual (texture pixels, material colours, vertex/face colours), the binning, :data:`VIEW_FORMAT` and the
    package version. Two assets with the same digest render the same views."""
    from aias_augment.version import __version__

    h = hashlib.sha256(f"{VIEW_FORMAT}|{__version__}|{binning}".encode())
    for m in asset.meshes:
        for arr in (m.vertices, m.faces, m.vertex_normals):
            a = np.ascontiguousarray(arr)
            h.update(str((a.dtype, a.shape)).encode())
            h.update(a.tobytes())
        vis = m.visual
        h.update(type(vis).__name__.encode())
        uv = getattr(vis, "uv", None)
        if uv is not None:
            h.update(np.ascontiguousarray(uv, np.float64).tobytes())
        for name in ("vertex_colors", "face_colors"):
            if getattr(vis, "kind", None) in ("vertex", "face") and name[:4] == vis.kind[:4]:
                h.update(np.ascontiguousarray(getattr(vis, name)).tobytes())
        mat = getattr(vis, "material", None)
        if mat is not None:
            for name in (
                "baseColorFactor",
                "diffuse",
                "ambient",
                "specular",
                "glossiness",
                "metallicFactor",
                "roughnessFactor",
                "emissiveFactor",
                "alphaMode",
                "doubleSided",
            ):
                v = getattr(mat, name, None)
                h.update(f"{name}={None if v is None else np.asarray(v).tolist()}".encode())
            for name in ("baseColorTexture", "image"):
                img = getattr(mat, name, None)
                if img is not None:
                    h.update(f"{name}:{img.mode}:{img.size}".encode())
                    h.update(img.tobytes())
    return h.hexdigest()[:32]


_DEFAULT: dict = {}


def default_view_cache() -> ViewCache:
    """The process-wide view cache used when the caller passes none (one per process: it pickles empty)."""
    if "cache" not in _DEFAULT:
        _DEFAULT["cache"] = ViewCache()
    return _DEFAULT["cache"]


#: Tolerances of :func:`rotational_symmetry_order`: vertex positions (fraction of the bounding-sphere radius); the
#: turned views against the view it should equal: coverage (fraction of the covered pixels that differ by > 0.5),
#: albedo (sRGB levels, mean over the covered pixels), normals (mean angle, deg). Within the binning error the
#: cache already accepts: a view is rendered from up to half a bin away, which turns a round object's normals by up
#: to 3.75 deg (median 4 sRGB levels after shading, results/bench/view_cache.md). The default cone, turned by 90
#: deg: 0 coverage pixels differ, albedo 0.35-0.47 levels, normals 1.5-2.0 deg (its triangulation is not symmetric:
#: the smoothed vertex normals differ a little).
SYMMETRY_TOL_POSITION = 1e-4
SYMMETRY_TOL_COVERAGE = 0.01
SYMMETRY_TOL_ALBEDO_LEVELS = 2.0
SYMMETRY_TOL_NORMAL_DEG = 3.0
#: The views compared by the check: (elevation bin, nearness bin, px) of a road camera's typical view.
_SYMMETRY_PROBES = ((2, 2, 64), (5, 2, 64))


def _vertices_symmetric(asset: Asset, angle: float, tol: float) -> bool:
    from scipy.spatial import cKDTree

    c, s_ = math.cos(angle), math.sin(angle)
    Rz = np.array([[c, -s_, 0.0], [s_, c, 0.0], [0.0, 0.0, 1.0]])
    for m in asset.meshes:
        v = np.asarray(m.vertices, np.float64)
        if len(v) and cKDTree(v).query(v @ Rz.T)[0].max() > tol:
            return False
    return True


def _views_match(a: CachedView, b: CachedView, angle: float) -> bool:
    """``b`` (rendered from ``angle`` further round) shows what ``a`` shows: same coverage, albedo, and normals once
    turned back by ``angle`` (the views' normals are in the object frame)."""
    if a.premultiplied.shape != b.premultiplied.shape or a.roi != b.roi:
        return False
    pa, pb = a.premultiplied, b.premultiplied
    ca, cb = pa[..., 7], pb[..., 7]
    both = (ca > 0.5) & (cb > 0.5)
    if not both.any() or np.mean(np.abs(ca - cb) > 0.5) * ca.size > SYMMETRY_TOL_COVERAGE * max((ca > 0.5).sum(), 1):
        return False
    from aias_augment.apply.render import linear_to_srgb

    al_a = linear_to_srgb(pa[both][:, :3] / ca[both][:, None]) * 255.0
    al_b = linear_to_srgb(pb[both][:, :3] / cb[both][:, None]) * 255.0
    if np.abs(al_a - al_b).mean() > SYMMETRY_TOL_ALBEDO_LEVELS:
        return False
    c, s_ = math.cos(-angle), math.sin(-angle)
    Rz = np.array([[c, -s_, 0.0], [s_, c, 0.0], [0.0, 0.0, 1.0]])
    na, nb = pa[both][:, 3:6], pb[both][:, 3:6] @ Rz.T
    cos = np.sum(na * nb, -1) / np.maximum(np.linalg.norm(na, axis=-1) * np.linalg.norm(nb, axis=-1), 1e-9)
    return float(np.degrees(np.arccos(np.clip(cos, -1.0, 1.0))).mean()) <= SYMMETRY_TOL_NORMAL_DEG


def rotational_symmetry_order(
    asset: Asset, binning: ViewBinning = DEFAULT_BINNING, cache: "ViewCache | None" = None
) -> int:
    """The largest n dividing the azimuth bins such that the asset turned by 360/n deg about its up axis (z, through
    the origin: the canonical frame centres the bounding box in x/y) looks the same; 1 when none does (and for
    procedural assets: each is new, its views are never reused). Checked in two steps: the vertex positions map
    onto themselves (:data:`SYMMETRY_TOL_POSITION`: cheap, rules out most n), then the views the cache would share
    are rendered and compared (:data:`_SYMMETRY_PROBES`, azimuth bin 1 against bin 1 + 48/n: coverage, albedo and
    normals within the ``SYMMETRY_TOL_*`` bounds): the check is on what is rendered, texture and normals included
    (a mesh whose triangulation or texture breaks the symmetry fails it). Costs 2 renders per surviving n, once per
    asset; the probe views go into ``cache``."""
    if asset.procedural:
        return 1
    n_az = int(round(360.0 / binning.azimuth_step_deg))
    c_obj, radius = centre_and_radius(asset)
    if radius <= 0 or np.hypot(c_obj[0], c_obj[1]) > SYMMETRY_TOL_POSITION * radius:
        return 1
    for n in sorted((d for d in range(2, n_az + 1) if n_az % d == 0), reverse=True):
        angle = 2.0 * math.pi / n
        if not _vertices_symmetric(asset, angle, SYMMETRY_TOL_POSITION * radius):
            continue
        ok = True
        for ie, iu, px in _SYMMETRY_PROBES:
            keys = [(1, ie, iu, px), (1 + n_az // n, ie, iu, px)]
            va, vb = (
                (cache._get_unshared(asset, k) if cache is not None else render_view(asset, k, binning)) for k in keys
            )
            if not _views_match(va, vb, angle):
                ok = False
                break
        if ok:
            return n
    return 1


def render_view(root: Asset, key: tuple, binning: ViewBinning = DEFAULT_BINNING) -> CachedView:
    """Render the view of ``root`` for ``key`` (the one GL call of the fast path, made on a cache miss)."""
    ia, ie, iu, px = key
    c_obj, r = centre_and_radius(root)
    u_b = (iu + 0.5) * binning.nearness_step
    d0 = r / u_b
    v_b = bin_direction(ia, ie, binning)
    R_v = view_rotation(v_b)
    view_from_object = make_rigid(R_v, -R_v @ (c_obj + d0 * v_b))
    # The bounding sphere (angular radius asin(u_b)) spans px pixels; 2 px of margin each side.
    f0 = (px / 2.0) / math.tan(math.asin(u_b))
    size = px + 4
    c = (size - 1) / 2.0
    K_view = Intrinsics(f0, f0, c, c, size, size)
    roi, rl = render_object_window(root, view_from_object, K_view, ssaa=binning.ssaa)
    cov = rl.alpha
    n_obj = rl.normals_in_cam @ R_v  # camera -> object frame: n_obj = R_v^T n_cam, row-wise n_cam @ R_v
    off = np.where(cov > 0, rl.depth - d0, 0.0)
    pre = np.concatenate(
        [rl.albedo_linear * cov[..., None], n_obj * cov[..., None], (off * cov)[..., None], cov[..., None]], axis=-1
    ).astype(np.float32)
    return CachedView(np.ascontiguousarray(pre), roi, K_view.K, d0)


def render_from_view_cache(
    asset: Asset,
    cam_from_object: np.ndarray,
    intrinsics: Intrinsics,
    cache: ViewCache | None = None,
    znear: float = 0.05,
) -> tuple[tuple[int, int, int, int], RenderLayers] | None:
    """(roi, layers) as :func:`aias_augment.apply.render.render_object_window` returns them, from the view cache; None
    when the view cache does not apply to this pose (see :func:`view_key`: the caller renders in full)."""
    got = warp_from_view_cache(asset, cam_from_object, intrinsics, cache, znear)
    return None if got is None else (got.roi, got.layers())


@dataclass(frozen=True, eq=False)
class WarpedView:
    """A view warped into the image, as pixel lists: ``roi`` (x0, y0, x1, y1); ``alpha`` and ``depth`` (h, w)
    float32 over the roi (0 outside the object); ``inside`` (h, w) bool, the covered pixels; ``albedo`` and
    ``normals`` (N, 3) float32 (linear albedo, unit camera-frame normals or 0) of the ``inside`` pixels in
    row-major order. Shading reads the pixel lists only (:func:`aias_augment.apply.shading.shade_pixels`)."""

    roi: tuple[int, int, int, int]
    alpha: np.ndarray
    depth: np.ndarray
    inside: np.ndarray
    albedo: np.ndarray
    normals: np.ndarray

    @classmethod
    def from_layers(cls, roi: tuple[int, int, int, int], layers: RenderLayers) -> "WarpedView":
        """The pixel lists of a render's ``layers`` over ``roi`` (the covered pixels: coverage > 0)."""
        inside = layers.alpha > 0
        return cls(
            tuple(int(v) for v in roi),
            layers.alpha,
            layers.depth,
            inside,
            np.ascontiguousarray(layers.albedo_linear[inside], np.float32),
            np.ascontiguousarray(layers.normals_in_cam[inside], np.float32),
        )

    def layers(self) -> RenderLayers:
        """The full-roi :class:`RenderLayers` (0 outside the object)."""
        h, w = self.alpha.shape
        albedo = np.zeros((h, w, 3), np.float32)
        normals = np.zeros((h, w, 3), np.float32)
        albedo[self.inside] = self.albedo
        normals[self.inside] = self.normals
        return RenderLayers(albedo, self.alpha, self.depth, normals)


def warp_from_view_cache(
    asset: Asset,
    cam_from_object: np.ndarray,
    intrinsics: Intrinsics,
    cache: ViewCache | None = None,
    znear: float = 0.05,
) -> WarpedView | None:
    """The cached view of ``asset`` warped to ``cam_from_object`` (:class:`WarpedView`), or None when the view cache
    does not apply to this pose (see :func:`view_key`: the caller renders in full)."""
    cache = cache if cache is not None else default_view_cache()
    b = cache.binning
    root = asset.render_root if asset.render_root is not None else asset
    s = float(asset.render_scale) if asset.render_root is not None else 1.0
    R = cam_from_object[:3, :3]
    t_root = cam_from_object[:3, 3] / s  # the root asset at t / s projects exactly as the scaled asset at t
    T_root = make_rigid(R, t_root)
    key = view_key(root, T_root, intrinsics, b, znear / s)
    if key is None:
        return None
    order = cache.symmetry_order(root)
    if order > 1:  # turn the pose back into the first sector of views: the same object, the same image
        sector = int(round(360.0 / b.azimuth_step_deg)) // order
        turn = key[0] // sector
        if turn:
            phi = turn * 2.0 * math.pi / order
            R = R @ np.array([[math.cos(phi), -math.sin(phi), 0.0], [math.sin(phi), math.cos(phi), 0.0], [0, 0, 1.0]])
            T_root = make_rigid(R, t_root)
            key = (key[0] - turn * sector,) + tuple(key[1:])
    view = cache.get(root, key)
    c_obj, _ = centre_and_radius(root)
    c_cam = R @ c_obj + t_root
    d = math.sqrt(float(c_cam @ c_cam))
    R_e = view_rotation(-(R.T @ c_cam) / d)  # a virtual camera here looking at the centre, object up = image up
    # view pixel -> image pixel: K R R_e^T (the rotation about the camera centre) after scaling the view about its
    # principal point by d0 / d (the distance within the bin: the object's centre plane scales as 1 / distance).
    Kv = view.K_view
    sc = view.distance / d
    x0v, y0v = view.roi[:2]
    fx, fy = sc / Kv[0, 0], sc / Kv[1, 1]  # the inverse of the scaled view intrinsics, then the roi's offset
    Kv_inv_roi = np.array([[fx, 0.0, fx * (x0v - Kv[0, 2])], [0.0, fy, fy * (y0v - Kv[1, 2])], [0.0, 0.0, 1.0]])
    H = intrinsics.K @ R @ R_e.T @ Kv_inv_roi
    hv, wv = view.premultiplied.shape[:2]
    corners = np.array([[-0.5, -0.5, 1], [wv - 0.5, -0.5, 1], [-0.5, hv - 0.5, 1], [wv - 0.5, hv - 0.5, 1]]) @ H.T
    if (corners[:, 2] <= 1e-9).any():
        return None
    uv = corners[:, :2] / corners[:, 2:]
    (umin, vmin), (umax, vmax) = uv.min(0).tolist(), uv.max(0).tolist()
    W, Hh = intrinsics.width, intrinsics.height
    x0, y0 = min(max(math.floor(umin), 0), W), min(max(math.floor(vmin), 0), Hh)
    x1, y1 = min(max(math.ceil(umax) + 1, 0), W), min(max(math.ceil(vmax) + 1, 0), Hh)
    if x1 <= x0 or y1 <= y0:
        z = np.zeros((0, 0), np.float32)
        return WarpedView(
            (0, 0, 0, 0),
            z,
            z.copy(),
            np.zeros((0, 0), bool),
            np.zeros((0, 3), np.float32),
            np.zeros((0, 3), np.float32),
        )
    H_win = H.copy()
    H_win[0] -= x0 * H[2]
    H_win[1] -= y0 * H[2]
    size = (x1 - x0, y1 - y0)
    # All eight layers in one warp (OpenCV interpolates each channel alike: the values of two 4-channel warps).
    warped = cv2.warpPerspective(
        view.premultiplied, H_win, size, flags=cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT
    )
    inside = warped[..., 7] > 1e-3  # eps: below it the warped coverage is interpolation round-off of empty texels
    px = warped[inside]
    cov_in = px[:, 7]
    w = np.maximum(cov_in, np.float32(1e-3))
    albedo = px[:, :3] / w[:, None]
    n_obj = px[:, 3:6]
    n_len = np.sqrt(np.einsum("ij,ij->i", n_obj, n_obj))[:, None]
    n_cam = np.where(n_len > 1e-6, (n_obj / np.maximum(n_len, np.float32(1e-6))) @ R.T.astype(np.float32), 0.0)
    # z-depth: (distance to the centre + the view's depth offset), along the ray to the centre, in the asset's units.
    depth = np.zeros(inside.shape, np.float32)
    depth[inside] = s * (d + px[:, 6] / w) * (c_cam[2] / d)
    cov = np.zeros(inside.shape, np.float32)
    cov[inside] = np.minimum(cov_in, np.float32(1.0))
    return WarpedView(
        (x0, y0, x1, y1),
        cov,
        depth,
        inside,
        albedo.astype(np.float32, copy=False),
        n_cam.astype(np.float32, copy=False),
    )

"""Procedural traffic cones drawn without GL: rays cast in NumPy against the cone's own surface of revolution.

A procedural cone (:func:`aias_augment.assets.bank.procedural.make_traffic_cone`) is the rings of
:func:`~aias_augment.assets.bank.procedural.cone_sections`: a base (a superellipse prism, square or round, with a flat
top) and a body whose radius is piecewise linear in height. Rays are intersected exactly with that shape in the object
frame: the body as truncated cones (a quadratic per segment), the base's side as its superellipse (Newton's steps
along the ray), its top as a plane. The nearest hit gives the layers
:func:`aias_augment.apply.render.render_object_window` gives: linear albedo (the cone's texture sampled at the hit's
(u, v) on the power-of-two mipmap level with a texel per sample; a family cone draws that level directly,
:func:`~aias_augment.assets.bank.procedural.cone_texture`, never its full texture or mesh), coverage, z-depth and
normals (the mesh's smooth normals: interpolated along the profile between rings, the superellipse's gradient on the
base's side).

Every object is drawn at its own pose, so there is no view bin and no warp: a new cone per object costs what a cached
view costs, without the render its first view needs. A small window gets ``ssaa`` x ``ssaa`` rays in every pixel; a
larger one one ray per pixel and ``ssaa`` x ``ssaa`` only along its outline (the same coverage), so a near cone costs
its area plus its outline's sub-samples. Differences to the GL render of the same mesh: the body's cross-section is
the exact circle (the mesh's is a 64-gon: 0.1 % of the radius), the 4 mm bevel of the base's top edge is left out
(under a pixel for cones below ~150 px) and normals are not quantised to 8 bits.
"""

from __future__ import annotations

import functools
from collections.abc import Callable
from dataclasses import dataclass, field

import cv2
import numpy as np

from aias_augment.apply.render import RenderLayers, crop_intrinsics, supersampled_layers, window_roi
from aias_augment.apply.view_cache import WarpedView
from aias_augment.assets.asset import Asset
from aias_augment.core.geometry import Intrinsics, norm3, project_points
from aias_augment.core.srgb import srgb_to_linear

__all__ = ["ConeShape", "cone_shape", "raycast_cone", "raycast_cone_window", "RAYCAST_SSAA"]

#: Rays per pixel side of the fast path's ray-cast objects (as the view cache's views: anti-aliased edges).
RAYCAST_SSAA = 2
#: Sides of the base's prism (the mesh's ``segments``).
BASE_SIDES = 64
#: Newton steps onto the base's superellipse side (quadratic convergence from the bounding square: 8 leave < 1e-9 of
#: its half-width for rays that do not graze it).
NEWTON_STEPS = 8
#: Rays per chunk: bounds the temporaries of a large window (a near cone at 4K) to a few hundred MB.
CHUNK_RAYS = 1 << 17
#: Sides of the polygons circumscribing the body's rings in the hull that bounds which rays are cast.
HULL_SIDES = 16
#: Grids of fewer rays are cast whole: their misses cost less than rasterising the hull.
HULL_MIN_RAYS = 4096
#: Window pixels from which only the outline is supersampled (see :func:`raycast_cone_window`): below it one pass of
#: ``ssaa``^2 rays per pixel costs less than two passes (a pass's fixed cost is ~0.6 ms of NumPy calls; measured
#: crossover near 2000 px, 45x40).
ADAPTIVE_MIN_PIXELS = 2048


@dataclass(frozen=True)
class ConeShape:
    """The rings of one procedural cone (unscaled root, metres): the body's profile (z, r, texture v) going up, its
    per-ring smooth normals in the (radial, up) plane, the base (half-width ``a``, superellipse ``n``, top ``zb``,
    texture row ``v_base``) and the base's 64-gon, plus the cone's texture: ``texture_size`` (W, H) of its full
    image and ``texture_at`` (W, H) -> that mipmap level, float32 sRGB in [0, 1] (see :func:`_texture_level`)."""

    body_z: np.ndarray
    body_r: np.ndarray
    body_v: np.ndarray
    ring_normals: np.ndarray  # (R, 2): (radial, z), unit
    segments: np.ndarray  # (S, 4): the profile's straight pieces (z0, r0, z1, r1), collinear rings merged
    a: float
    n: float
    a_top: float
    zb: float
    v_base: float
    polygon: np.ndarray  # (BASE_SIDES, 2) CCW
    texture_size: tuple[int, int]
    texture_at: Callable[[tuple[int, int]], np.ndarray]
    height: float
    levels: dict = field(default_factory=dict, compare=False, repr=False)  # the levels drawn so far, by size

    @functools.cached_property
    def hulls(self) -> tuple[np.ndarray, np.ndarray]:
        """Point sets whose convex hulls together hold the cone (:func:`_hulls`)."""
        return _hulls(self.body_z, self.body_r, self.a, self.zb)


def _hulls(body_z: np.ndarray, body_r: np.ndarray, a: float, zb: float) -> tuple[np.ndarray, np.ndarray]:
    """Two point sets (object frame) whose convex hulls together hold the cone: the base's square prism (the
    superellipse inside it), and per body ring a polygon circumscribing its circle (the body between two rings is
    inside the hull of their circles). Apart, the wide flat base does not widen the body's hull."""
    m = HULL_SIDES
    phi = (np.arange(m) + 0.5) * (2 * np.pi / m)
    ring = np.c_[np.cos(phi), np.sin(phi)] / np.cos(np.pi / m)  # its edges touch the unit circle
    body = [np.c_[ring * r, np.full(m, z)] if r > 0 else np.array([[0.0, 0.0, z]]) for z, r in zip(body_z, body_r)]
    base = np.array([[x, y, z] for x in (-a, a) for y in (-a, a) for z in (0.0, zb)])
    return base, np.concatenate(body)


def _ring_normals(z: np.ndarray, r: np.ndarray) -> np.ndarray:
    """Per-ring smooth normals (radial, z) of a profile, as the mesh's area-weighted vertex normals: the outward
    normals of the segments on each side, each weighted by its slant length times its mean radius; a pole (r = 0 at
    the top) points up."""
    dz, dr = np.diff(z), np.diff(r)
    seg = np.stack([dz, -dr], axis=1) * ((r[:-1] + r[1:]) / 2.0)[:, None]  # |(dz, -dr)| is the slant length
    acc = np.zeros((len(z), 2))
    acc[:-1] += seg
    acc[1:] += seg
    if r[-1] <= 0:
        acc[-1] = (0.0, 1.0)
    return acc / np.maximum(np.linalg.norm(acc, axis=1, keepdims=True), 1e-12)


def _merged_segments(z: np.ndarray, r: np.ndarray) -> np.ndarray:
    """The profile's pieces (z0, r0, z1, r1), consecutive collinear ones merged (the body's straight part is many
    rings for the texture's and normals' sake, one cone for intersection)."""
    out = []
    for k in range(len(z) - 1):
        if z[k + 1] <= z[k]:
            continue
        if out:
            z0, r0, z1, r1 = out[-1]
            cross = (z1 - z0) * (r[k + 1] - r[k]) - (r1 - r0) * (z[k + 1] - z[k])
            if z1 == z[k] and r1 == r[k] and abs(cross) <= 1e-9 * (z1 - z0) * (z[k + 1] - z[k]):
                out[-1] = (z0, r0, z[k + 1], r[k + 1])
                continue
        out.append((z[k], r[k], z[k + 1], r[k + 1]))
    return np.array(out, float)


def cone_shape(asset: Asset) -> ConeShape | None:
    """The :class:`ConeShape` of ``asset`` (or of its unscaled root), or None when it is not an undeformed procedural
    traffic cone whose mesh has the bounds its parameters give (then it is rendered from its mesh)."""
    root = asset.render_root if asset.render_root is not None else asset
    meta = root.meta
    if not root.procedural or meta.get("generator") != "traffic_cone" or "deformation" in meta or "tipped" in meta:
        return None
    got = root.__dict__.get("_cone_shape")
    if got is not None:
        return got
    from aias_augment.assets.bank.procedural import CONE_TEXTURE_SIZE, ConeMeshes, cone_sections  # trimesh: cones only

    try:
        h = float(meta["height_m"])
        if isinstance(root.meshes, ConeMeshes):  # a cone of the family: its rings made once, each level at its size
            sections, texture_size, texture_at = root.meshes.sections(), CONE_TEXTURE_SIZE, root.meshes.texture_level
        else:  # a cone loaded with its mesh: its image, area-averaged
            sections = cone_sections(meta, h)
            image = root.meshes[0].visual.material.image.convert("RGB")
            texture_size, texture_at = image.size, functools.partial(_image_level, np.asarray(image, np.uint8))
    except (KeyError, TypeError, AttributeError, IndexError):
        return None
    base_side, base_top, body = sections[1], sections[2], np.array(sections[3], float)
    a, n, zb = float(base_side[0][1]), float(base_side[0][2]), float(base_top[0][0])
    lo, hi = root.bounds_m
    if abs(hi[2] - h) > 1e-6 * h or abs(lo[2]) > 1e-6 * h or abs((hi[0] - lo[0]) / 2.0 - a) > 1e-6 * h:
        return None
    theta = np.linspace(0.0, 2 * np.pi, BASE_SIDES + 1)[:-1]
    rr = a * (np.abs(np.cos(theta)) ** n + np.abs(np.sin(theta)) ** n) ** (-1.0 / n)
    shape = ConeShape(
        body_z=body[:, 0],
        body_r=body[:, 1],
        body_v=body[:, 3],
        ring_normals=_ring_normals(body[:, 0], body[:, 1]),
        segments=_merged_segments(body[:, 0], body[:, 1]),
        a=a,
        n=n,
        a_top=float(base_top[0][1]),
        zb=zb,
        v_base=float(base_side[0][3]),
        polygon=np.c_[rr * np.cos(theta), rr * np.sin(theta)],
        texture_size=tuple(texture_size),
        texture_at=texture_at,
        height=h,
    )
    root.__dict__["_cone_shape"] = shape  # a memo, as the asset's bounds: its meshes never change
    return shape


@dataclass(frozen=True)
class _Rays:
    """Rays from one origin (the camera's centre in the object frame): its coordinates (scalars) and, per ray, the
    direction (N, 3) and its two horizontal products that every upright test reads."""

    ox: float
    oy: float
    oz: float
    d: np.ndarray
    dxy2: np.ndarray  # dx^2 + dy^2
    odd: np.ndarray  # ox dx + oy dy

    @classmethod
    def of(cls, origin: np.ndarray, d: np.ndarray) -> "_Rays":
        ox, oy, oz = (np.float64(v) for v in origin)
        return cls(ox, oy, oz, d, d[:, 0] ** 2 + d[:, 1] ** 2, ox * d[:, 0] + oy * d[:, 1])

    def subset(self, keep: np.ndarray) -> "_Rays":
        return _Rays(self.ox, self.oy, self.oz, self.d[keep], self.dxy2[keep], self.odd[keep])


def _body_hits(r: _Rays, shape: ConeShape, z_span: tuple[np.ndarray, np.ndarray] | None = None) -> np.ndarray:
    """Per ray the nearest t > 0 on the body (inf: none): each segment of the profile a truncated cone, solved for
    every (ray, segment) pair at once.

    ``z_span``: per ray the lowest and highest z it reaches inside the body's bounding cylinder (see
    :func:`_meets_cylinder`); a ray is then paired only with the segments its span reaches (a hit on a segment lies
    inside that cylinder): a contiguous run of the profile, one to three segments for most rays."""
    n_rays, segs = len(r.d), shape.segments
    best = np.full(n_rays, np.inf)
    if n_rays == 0:
        return best
    if z_span is None:
        lo, count = np.zeros(n_rays, np.intp), np.full(n_rays, len(segs))
    else:
        tol = 1e-9 * max(float(shape.height), 1e-9)  # the span's own rounding, far above it
        lo = np.searchsorted(segs[:, 2] + tol, z_span[0], side="left")  # first segment with zc + tol >= z_lo
        hi = np.searchsorted(segs[:, 0] - tol, z_span[1], side="right")  # past the last with za - tol <= z_hi
        count = np.where(np.isnan(z_span[0]) | np.isnan(z_span[1]), 0, np.maximum(hi - lo, 0))
    rays = np.flatnonzero(count)
    if len(rays) == 0:
        return best
    count = count[rays]
    start = np.cumsum(count) - count  # each ray's first pair
    ray = np.repeat(rays, count)
    seg = np.repeat(lo[rays] - start, count) + np.arange(len(ray))
    za, ra, zc, rc = segs[seg].T
    dz = r.d[ray, 2]
    m = (rc - ra) / (zc - za)
    A = ra + m * (r.oz - za)  # the radius at the ray's z, linear in t: A + B t
    B = m * dz
    qa, qb, qc = r.dxy2[ray] - B * B, r.odd[ray] - A * B, (r.ox**2 + r.oy**2) - A * A
    disc = qb * qb - qa * qc
    ok = disc >= 0
    sq = np.sqrt(np.where(ok, disc, 0.0))
    with np.errstate(divide="ignore", invalid="ignore"):
        lin = np.abs(qa) < 1e-12
        t1 = np.where(lin, -qc / (2 * qb), (-qb - sq) / qa)
        t2 = np.where(lin, np.inf, (-qb + sq) / qa)
    pair = np.full(len(ray), np.inf)
    for t in (np.minimum(t1, t2), np.maximum(t1, t2)):
        zt = r.oz + t * dz
        valid = ok & (t > 0) & (zt >= za) & (zt <= zc) & (A + B * t >= 0) & np.isfinite(t)
        pair = np.where(valid & (t < pair), t, pair)
    best[rays] = np.minimum.reduceat(pair, start)
    return best


def _base_side_hits(r: _Rays, shape: ConeShape) -> np.ndarray:
    """Per ray the t > 0 where it enters the base's superellipse prism |x/a|^n + |y/a|^n <= 1 through its side (inf:
    none). Along a ray f(t) = |x/a|^n + |y/a|^n - 1 is convex, and f >= 0 where the ray enters the square |x|, |y| <=
    a that holds the superellipse: Newton's steps from there rise monotonically to the first root (a ray that only
    grazes the square stops descending with f > 0: a miss)."""
    a, n, d = shape.a, shape.n, r.d
    ox, oy, dx, dy = r.ox / a, r.oy / a, d[:, 0] / a, d[:, 1] / a
    with np.errstate(divide="ignore", invalid="ignore"):
        tx0, tx1 = (-1.0 - ox) / dx, (1.0 - ox) / dx
        ty0, ty1 = (-1.0 - oy) / dy, (1.0 - oy) / dy
    tx0, tx1 = (
        np.where(dx == 0, -np.inf if abs(ox) <= 1 else np.inf, np.minimum(tx0, tx1)),
        np.where(dx == 0, np.inf if abs(ox) <= 1 else -np.inf, np.maximum(tx0, tx1)),
    )
    ty0, ty1 = (
        np.where(dy == 0, -np.inf if abs(oy) <= 1 else np.inf, np.minimum(ty0, ty1)),
        np.where(dy == 0, np.inf if abs(oy) <= 1 else -np.inf, np.maximum(ty0, ty1)),
    )
    t = np.maximum(tx0, ty0)
    live = (t <= np.minimum(tx1, ty1)) & (t > 0)
    t = np.where(live, t, 0.0)
    i = np.flatnonzero(live)  # the rays still descending, their own copies of the step's inputs
    ti, oxi, oyi, dxi, dyi = t[i], ox, oy, dx[i], dy[i]
    for _ in range(NEWTON_STEPS):
        if len(i) == 0:
            break
        x, y = oxi + ti * dxi, oyi + ti * dyi
        (fx, gx), (fy, gy) = _power_and_slope(x, n), _power_and_slope(y, n)
        f = fx + fy - 1.0
        df = n * (gx * dxi + gy * dyi)
        down = df < 0  # still descending toward the root
        if not down.all():
            live[i[~down]] = False
            t[i] = ti  # the stopped rays keep where they stopped
            i, ti, f, df, dxi, dyi = i[down], ti[down], f[down], df[down], dxi[down], dyi[down]
        step = ti - np.maximum(f, 0.0) / df
        moved = step != ti  # a ray its step leaves where it was is at its fixed point: every later step repeats it
        if not moved.all():
            t[i] = step
            i, step, dxi, dyi = i[moved], step[moved], dxi[moved], dyi[moved]
        ti = step
    t[i] = ti
    x, y = ox + t * dx, oy + t * dy
    close = np.abs(_power_and_slope(x, n)[0] + _power_and_slope(y, n)[0] - 1.0) <= 1e-4
    zt = r.oz + t * d[:, 2]
    return np.where(live & close & (zt >= 0) & (zt <= shape.zb), t, np.inf)


def _power_and_slope(x: np.ndarray, n: float) -> tuple[np.ndarray, np.ndarray]:
    """(|x|^n, sign(x) |x|^(n-1)): by products where ``n`` is an even integer up to 16 (the square base's 8; a few
    ulp from ``pow``, several times faster), else by powers."""
    if n == int(n) and int(n) % 2 == 0 and 2 <= n <= 16:
        x2 = x * x
        if n == 2:
            return x2, x
        even = x2  # x^(n-2) = (x^2)^(n/2-1)
        for _ in range(int(n) // 2 - 2):
            even = even * x2
        return even * x2, x * even
    ax = np.abs(x)
    return ax**n, np.sign(x) * ax ** (n - 1)


def _base_top_hits(r: _Rays, shape: ConeShape) -> np.ndarray:
    """Per ray the t > 0 where it meets the base's flat top (inf: none)."""
    d = r.d
    with np.errstate(divide="ignore", invalid="ignore"):
        t = (shape.zb - r.oz) / d[:, 2]
    x, y = r.ox + t * d[:, 0], r.oy + t * d[:, 1]
    inside = _power_and_slope(x / shape.a_top, shape.n)[0] + _power_and_slope(y / shape.a_top, shape.n)[0] <= 1.0
    return np.where((d[:, 2] < 0) & (t > 0) & inside, t, np.inf)


def _meets_cylinder(
    r: _Rays, radius: float, z0: float, z1: float, *, with_span: bool = False
) -> np.ndarray | tuple[np.ndarray, tuple[np.ndarray, np.ndarray]]:
    """Rays (t > 0) that pass through the upright cylinder of ``radius`` about the z axis between ``z0`` and ``z1``:
    a conservative test before the exact ones. ``with_span``: also per ray the lowest and highest z of its path
    inside the cylinder (t from 0 on)."""
    R = radius * (1 + 1e-6)
    qa, qb, dz = r.dxy2, r.odd, r.d[:, 2]
    qc = r.ox**2 + r.oy**2 - R * R
    disc = qb * qb - qa * qc
    with np.errstate(divide="ignore", invalid="ignore"):
        sq = np.sqrt(np.maximum(disc, 0.0))
        c0 = np.where(qa > 0, (-qb - sq) / qa, -np.inf if qc <= 0 else np.inf)
        c1 = np.where(qa > 0, (-qb + sq) / qa, np.inf if qc <= 0 else -np.inf)
        ta, tb = (z0 - r.oz) / dz, (z1 - r.oz) / dz
    flat = dz == 0
    inside = z0 <= r.oz <= z1
    s0 = np.where(flat, -np.inf if inside else np.inf, np.minimum(ta, tb))
    s1 = np.where(flat, np.inf if inside else -np.inf, np.maximum(ta, tb))
    lo, hi = np.maximum(c0, s0), np.minimum(c1, s1)
    meets = (disc >= 0) & (lo <= hi) & (hi > 0)
    if not with_span:
        return meets
    with np.errstate(invalid="ignore"):  # inf * 0 on rays that miss (their span is not read)
        za, zb = r.oz + np.maximum(lo, 0.0) * dz, r.oz + hi * dz
    return meets, (np.minimum(za, zb), np.maximum(za, zb))


def _surface(p: np.ndarray, kind: np.ndarray, shape: ConeShape) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(normals (N, 3) in the object frame, texture u, texture v) at hit points ``p`` on surface ``kind`` (0 body,
    1 base side, 2 base top)."""
    x, y, z = p[:, 0], p[:, 1], p[:, 2]
    rho = np.hypot(x, y)
    cx, sy = np.where(rho > 0, x / np.maximum(rho, 1e-12), 1.0), np.where(rho > 0, y / np.maximum(rho, 1e-12), 0.0)
    nr = np.interp(z, shape.body_z, shape.ring_normals[:, 0])
    nz = np.interp(z, shape.body_z, shape.ring_normals[:, 1])
    nrm = np.stack([nr * cx, nr * sy, nz], axis=1)
    side = kind == 1
    if side.any():  # the superellipse's gradient, horizontal
        gx, gy = _power_and_slope(x[side], shape.n)[1], _power_and_slope(y[side], shape.n)[1]
        g = np.stack([gx, gy, np.zeros_like(gx)], axis=1)
        nrm[side] = g / np.maximum(norm3(g, keepdims=True), 1e-30)
    nrm[kind == 2] = (0.0, 0.0, 1.0)
    nrm /= np.maximum(norm3(nrm, keepdims=True), 1e-12)
    u = np.mod(np.arctan2(y, x), 2 * np.pi) / (2 * np.pi)
    v = np.where(kind == 0, np.interp(z, shape.body_z, shape.body_v), shape.v_base)
    return nrm, u, v


def _image_level(image: np.ndarray, size: tuple[int, int]) -> np.ndarray:
    """A uint8 sRGB texture image as float32 in [0, 1] at ``size`` (W, H): area-averaged, as a mipmap level."""
    tex = image.astype(np.float32) / 255.0
    return tex if size == (image.shape[1], image.shape[0]) else cv2.resize(tex, size, interpolation=cv2.INTER_AREA)


def _texture_level(shape: ConeShape, body_px: float) -> np.ndarray:
    """The texture (float32 sRGB in [0, 1]) at the mipmap level for ``body_px`` samples over the body's height: the
    smallest power-of-two reduction that keeps at least one texel per sample (never enlarged, never under 4 texels
    a side). Levels are made once per cone, so a cone seen at many sizes (a clip) reuses each level's texels."""
    tw, th = shape.texture_size
    rows = th * (shape.body_v[-1] - shape.body_v[0])
    k = int(np.floor(np.log2(rows / max(body_px, 1.0)))) if body_px < rows else 0
    k = max(0, min(k, int(np.log2(max(min(tw, th) // 4, 1)))))
    size = (tw >> k, th >> k)
    got = shape.levels.get(size)
    if got is None:
        got = shape.levels[size] = shape.texture_at(size)
    return got


def _sample(tex: np.ndarray, u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Bilinear lookup at texture (u, v) (v = 0 at the image's bottom row), wrapping round in u."""
    th, tw = tex.shape[:2]
    n = len(u)
    if n == 0:
        return np.zeros((0, 3), np.float32)
    cols = 1024  # OpenCV's remap takes maps under 32767 rows: the lookups as a block of this width
    rows = -(-n // cols)
    mx = np.zeros(rows * cols, np.float32)
    my = np.zeros(rows * cols, np.float32)
    mx[:n] = u * tw - 0.5
    my[:n] = np.clip((1.0 - v) * th - 0.5, 0.0, th - 1.0)
    out = cv2.remap(tex, mx.reshape(rows, cols), my.reshape(rows, cols), cv2.INTER_LINEAR, borderMode=cv2.BORDER_WRAP)
    return out.reshape(-1, 3)[:n]


def _cast(
    shape: ConeShape, origin: np.ndarray, dirs: np.ndarray, tex: np.ndarray, R: np.ndarray, t: np.ndarray, s: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The rays ``dirs`` (object frame, from ``origin``) against the cone: (index of each ray that hits, its surface
    kind (0 body, 1 base side, 2 base top), linear albedo, camera-frame normal, z-depth), chunk by chunk."""
    base_radius = float(np.hypot(*shape.polygon.T).max())
    got = []
    for c0 in range(0, len(dirs), CHUNK_RAYS):
        rays = _Rays.of(origin, dirs[c0 : c0 + CHUNK_RAYS])
        on_body, (z_lo, z_hi) = _meets_cylinder(rays, float(shape.body_r.max()), shape.zb, shape.height, with_span=True)
        on_base = _meets_cylinder(rays, base_radius, 0.0, shape.zb)
        keep = on_body | on_base
        idx = c0 + np.flatnonzero(keep)
        rays, on_body, on_base, z_lo, z_hi = rays.subset(keep), on_body[keep], on_base[keep], z_lo[keep], z_hi[keep]
        d = rays.d
        hits = np.full((len(d), 3), np.inf)
        hits[on_body, 0] = _body_hits(rays.subset(on_body), shape, (z_lo[on_body], z_hi[on_body]))
        on_base_rays = rays.subset(on_base)
        hits[on_base, 1] = _base_side_hits(on_base_rays, shape)
        hits[on_base, 2] = _base_top_hits(on_base_rays, shape)
        kind = np.argmin(hits, axis=1)
        th = hits[np.arange(len(d)), kind]
        hit = np.isfinite(th)
        idx, d, kind, th = idx[hit], d[hit], kind[hit], th[hit]
        p = origin + th[:, None] * d
        n_obj, u, v = _surface(p, kind, shape)
        got.append((idx, kind, srgb_to_linear(_sample(tex, u, v)), n_obj @ R.T, s * (p @ R[2] + t[2])))
    return tuple(np.concatenate(parts) for parts in zip(*got))


def _ray_dirs(K: Intrinsics, R: np.ndarray, us: np.ndarray, vs: np.ndarray, *, grid: bool = False) -> np.ndarray:
    """Object-frame directions (R^T d, row-wise) of the rays through window points (``us``, ``vs``), OpenCV
    coordinates of the window's camera ``K``; ``grid``: through every (v, u) of the two axes, row by row."""
    if grid:
        us, vs = us[None, :], vs[:, None]
    y = (vs - K.cy) / K.fy
    a = (us - K.cx) / K.fx - (K.K[0, 1] / K.fx) * y
    if grid:
        a, y = a.ravel(), np.broadcast_to(y, a.shape).ravel()
    return np.stack([a, y, np.ones(len(a))], axis=1) @ R


def _cast_grid(shape: ConeShape, origin, K: Intrinsics, R, t, s, us, vs, tex) -> tuple:
    """:func:`_cast` of the rays through every (v, u) of the window axes ``us``, ``vs`` (row by row), the hits'
    indices into that grid: only the grid points inside the projected hulls of the cone (:attr:`ConeShape.hulls`,
    one grid step wider) are cast, the others cannot meet it."""
    mask = _hull_mask(shape, R, t, K, us, vs) if len(us) * len(vs) >= HULL_MIN_RAYS else None
    if mask is None:
        return _cast(shape, origin, _ray_dirs(K, R, us, vs, grid=True), tex, R, t, s)
    iv, ju = np.nonzero(mask)
    got = _cast(shape, origin, _ray_dirs(K, R, us[ju], vs[iv]), tex, R, t, s)
    return ((iv * len(us) + ju)[got[0]], *got[1:])


def _hull_mask(shape: ConeShape, R, t, K: Intrinsics, us, vs) -> np.ndarray | None:
    """(len(vs), len(us)) bool: the grid points (window coordinates ``us``, ``vs``, evenly spaced) that the cone's
    projected hulls (:attr:`ConeShape.hulls`) cover, grown by one grid step (rasterisation's and rounding's margin);
    None where a hull is not all in front of the camera or projects too far out to rasterise (cast every point)."""
    if len(us) < 2 or len(vs) < 2:
        return None
    mask = np.zeros((len(vs), len(us)), np.uint8)
    step = np.array([us[1] - us[0], vs[1] - vs[0]])
    for pts in shape.hulls:
        pts = pts @ R.T + t
        if (pts[:, 2] <= 1e-6).any():
            return None
        g = (project_points(pts, K.K)[0] - (us[0], vs[0])) / step
        if not np.isfinite(g).all() or np.abs(g).max() > 8 * max(len(us), len(vs)) + 64:
            return None
        cv2.fillConvexPoly(mask, cv2.convexHull(np.round(g * 16).astype(np.int32)), 1, lineType=cv2.LINE_8, shift=4)
    return cv2.dilate(mask, np.ones((3, 3), np.uint8)) > 0


def _layers_of(n: int, got: tuple, ssaa: int, shape: tuple[int, int]) -> RenderLayers:
    """The pixel layers of ``n`` samples laid out as a grid of ``shape`` (rows, cols of samples) with ``ssaa`` x
    ``ssaa`` samples per pixel, from :func:`_cast`'s hits."""
    idx, _, albedo_hit, normal_hit, depth_hit = got
    covered = np.zeros(n, np.float32)
    albedo = np.zeros((n, 3), np.float32)
    normals = np.zeros((n, 3), np.float32)
    depth = np.zeros(n, np.float32)
    covered[idx] = 1.0
    albedo[idx] = albedo_hit
    normals[idx] = normal_hit
    depth[idx] = depth_hit
    rows, cols = shape
    return supersampled_layers(
        covered.reshape(rows, cols),
        albedo.reshape(rows, cols, 3),
        normals.reshape(rows, cols, 3),
        depth.reshape(rows, cols),
        ssaa,
    )


def raycast_cone_window(
    asset: Asset,
    cam_from_object: np.ndarray,
    intrinsics: Intrinsics,
    *,
    ssaa: int = 2,
    znear: float = 0.05,
    everywhere: bool = False,
) -> tuple[tuple[int, int, int, int], RenderLayers] | None:
    """(roi, layers) as :func:`aias_augment.apply.render.render_object_window` returns them, ray-cast; None when
    ``asset`` is not a procedural cone (:func:`cone_shape`) or a bounding-box corner is not in front of the camera
    (the caller renders the mesh).

    Windows of :data:`ADAPTIVE_MIN_PIXELS` or more are supersampled where it changes a pixel: one ray through each
    pixel's centre first; the pixels whose 3x3 neighbourhood is not all one surface (the silhouette, the base's
    edges) and those inside the base's outline that their centre ray misses (its rim can be thinner than a pixel)
    then get ``ssaa`` x ``ssaa`` rays; the others keep their centre sample. Both read the mipmap level with a texel
    per sub-sample, where a pixel's centre falls between the texels its sub-samples read, so a centre sample is
    their bilinear mean. The ray count then follows the object's area plus ``ssaa``^2 times its outline's. Smaller
    windows, and every window with ``everywhere``, get ``ssaa`` x ``ssaa`` rays in every pixel (the reference the
    outline pass approximates: the same coverage, tested)."""
    shape = cone_shape(asset)
    if shape is None:
        return None
    s = float(asset.render_scale) if asset.render_root is not None else 1.0
    R = np.asarray(cam_from_object[:3, :3], np.float64)
    t = np.asarray(cam_from_object[:3, 3], np.float64) / s  # the root at t / s projects as the scaled asset at t
    corners = asset.corners_m()
    zc = corners @ R[2] + cam_from_object[2, 3]
    if (zc <= znear).any():
        return None
    roi = window_roi(corners, cam_from_object, intrinsics, 2.0, znear)
    x0, y0, x1, y1 = roi
    if x1 <= x0 or y1 <= y0:
        z = np.zeros((0, 0), np.float32)
        return (0, 0, 0, 0), RenderLayers(np.zeros((0, 0, 3), np.float32), z, z.copy(), np.zeros((0, 0, 3), np.float32))
    K = crop_intrinsics(intrinsics, roi)
    origin = -R.T @ t
    h0, w0 = y1 - y0, x1 - x0
    everywhere = everywhere or ssaa == 1 or h0 * w0 < ADAPTIVE_MIN_PIXELS
    # the level with a texel per sub-sample in both passes: a centre sample there reads the texels its sub-samples
    # would (bilinear at the centre of their 2x2 block), so the two passes share the texels and the grain
    body_px = (shape.body_z[-1] - shape.body_z[0]) / max(float(np.mean(zc)) / s, 1e-9) * K.fy * ssaa
    tex = _texture_level(shape, body_px)
    # sub-sample centres in the window's OpenCV coordinates, as the GL path's supersampled camera puts them
    us = (np.arange(w0 * ssaa) + 0.5) / ssaa - 0.5
    vs = (np.arange(h0 * ssaa) + 0.5) / ssaa - 0.5
    if everywhere:
        got = _cast_grid(shape, origin, K, R, t, s, us, vs, tex)
        return roi, _layers_of(len(us) * len(vs), got, ssaa, (h0 * ssaa, w0 * ssaa))
    got = _cast_grid(shape, origin, K, R, t, s, np.arange(w0, dtype=float), np.arange(h0, dtype=float), tex)
    layers = _layers_of(h0 * w0, got, 1, (h0, w0))
    surface = np.zeros(h0 * w0, np.uint8)  # 0 none, 1 + the surface's kind
    surface[got[0]] = got[1] + 1
    surface = surface.reshape(h0, w0)
    box = np.ones((3, 3), np.uint8)
    # outside the window counts as no surface: an object cut by the image's edge is supersampled along the cut
    edges = cv2.dilate(surface, box) != cv2.erode(surface, box, borderType=cv2.BORDER_CONSTANT, borderValue=0)
    # the base's rim can be a strip thinner than a pixel between two rows of centres (a far cone seen level), wider
    # than the body: every centre that misses inside its square prism's outline (a pixel wider) is supersampled too
    prism = shape.hulls[0] @ R.T + t  # the base's square prism
    outline = cv2.convexHull(np.round(project_points(prism, K.K)[0] * 16).astype(np.int32))
    near_base = np.zeros((h0, w0), np.uint8)
    cv2.fillConvexPoly(near_base, outline, 1, lineType=cv2.LINE_8, shift=4)
    edges |= (cv2.dilate(near_base, box) > 0) & (surface == 0)
    py, px = np.nonzero(edges)
    if len(py):
        # the edge pixels as one strip of ssaa x ssaa blocks: row i of a block is sub-row i, its column j sub-column j
        sub_v = np.repeat(vs[py[None, :] * ssaa + np.arange(ssaa)[:, None]], ssaa, axis=1)  # (ssaa, n ssaa)
        sub_u = np.tile(us[(px[:, None] * ssaa + np.arange(ssaa)[None, :]).ravel()], (ssaa, 1))  # (ssaa, n ssaa)
        got = _cast(shape, origin, _ray_dirs(K, R, sub_u.ravel(), sub_v.ravel()), tex, R, t, s)
        edge = _layers_of(sub_u.size, got, ssaa, sub_u.shape)
        for full, part in zip(
            (layers.albedo_linear, layers.alpha, layers.depth, layers.normals_in_cam),
            (edge.albedo_linear, edge.alpha, edge.depth, edge.normals_in_cam),
        ):
            full[py, px] = part[0]
    return roi, layers


def raycast_cone(
    asset: Asset, cam_from_object: np.ndarray, intrinsics: Intrinsics, *, ssaa: int = RAYCAST_SSAA, znear: float = 0.05
) -> WarpedView | None:
    """:func:`raycast_cone_window` as the pixel lists the fast path shades (:class:`WarpedView`); None where it
    does not apply."""
    got = raycast_cone_window(asset, cam_from_object, intrinsics, ssaa=ssaa, znear=znear)
    return None if got is None else WarpedView.from_layers(*got)

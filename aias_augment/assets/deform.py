"""Seeded physical variants of an asset: dented, crushed, bent or knocked over, textures and real size kept.

Choosing (:func:`sample_deformation`, every random draw from the ``numpy.random.Generator`` passed in) is split from
doing (:func:`apply_deformation`, pure): :class:`DeformParams` is a JSON-able record, so a variant replays byte for
byte from it (an insertion record's ``asset_meta["deformation"]``, a bank's ``bank.json``).

Every deformation moves vertices by a smooth function of their *position* alone (a rigid turn for ``knocked_over``),
never of their index or normal. Vertices that a texture seam splits sit at one position, so they move together: a
mesh whose geometry was closed stays closed, and the UVs, materials and faces are untouched. Nothing is scaled, so
the variant keeps its source's metric size: a crush lowers the top by exactly its amount, a dent never moves a
point by more than its depth.

- ``dent``: 1-3 dents, each a compactly supported (Wendland C2) push of depth ``d`` into the surface along the
  inward normal at a surface point, over a radius ``r`` (a barrel hit by a car, a kicked cone).
- ``crush``: the top pressed down by ``amount`` of the height, more at the top than at the base (z' = z (1 - a z /
  H)), the middle bulging sideways by ``bulge`` and the whole leaning by a shear (a flattened cone, a crushed car
  roof).
- ``bend``: the object bent about a horizontal axis by ``angle`` over its height, as a circular arc (a bent post).
- ``knocked_over``: turned 90 deg about a horizontal axis and settled on the face of its convex hull that then
  faces the ground (a cone lying on its side, a barrel on its flank).
- ``fracture``: broken in two along a tilted plane at ``cut_height`` of the height: the base stands, the top lies
  on its side beside it (settled like ``knocked_over``), ``gap`` of the size away towards ``fall_azimuth``. The cut
  faces are closed (the section's outline triangulated) in the colour the surface has along the cut, so each piece
  is as closed as its source; the rest of the surface keeps its UVs. 0-4 flat chips of that colour lie scattered
  around it (``debris``: position, length, yaw each); they add a little material the source did not have.

Falling over as it happens (a clip's toppling object, :func:`tipped`): the rigid object turns about the edge of its
base on the side it falls to, which stays on the ground, until another point of its convex hull touches the ground
(:func:`topple_rest_angle`: a cube lands on a face at 90 deg, a cone on its side line beyond 90 deg).
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Literal, get_args

import numpy as np

from aias_augment.assets.asset import Asset, normalise_meshes
from aias_augment.core.config import checked_config

Kind = Literal["dent", "crush", "bend", "knocked_over", "fracture"]
KINDS: tuple[str, ...] = get_args(Kind)

#: What makes sense per category (a car does not bend or lie on its side in a road scene; a cone can do all).
CATEGORY_KINDS: dict[str, tuple[str, ...]] = {
    "traffic_cone": ("dent", "crush", "bend", "knocked_over", "fracture"),
    "barrel": ("dent", "crush", "knocked_over", "fracture"),
    "car": ("dent", "crush"),
    "barrier": ("dent", "fracture"),
    "concrete_block": ("dent", "fracture"),
    "fire_hydrant": ("dent", "bend"),
}


@checked_config(
    {
        "dent_count": "[1, inf) lo<=hi",
        "dent_radius_frac": "(0, 1] lo<=hi",
        "dent_depth_frac": "(0, 1] lo<=hi",
        "crush_amount": "[0, 0.8] lo<=hi",
        "crush_bulge": "[0, 1] lo<=hi",
        "crush_max_lean": "[0, 0.5]",
        "bend_angle_deg": "[0, 90] lo<=hi",
        "fracture_height": "(0, 1) lo<=hi",
        "fracture_tilt_deg": "[0, 60]",
        "fracture_gap": "[0, 1] lo<=hi",
        "fracture_debris": "[0, inf) lo<=hi",
        "debris_size_frac": "(0, 1] lo<=hi",
    }
)
@dataclass(frozen=True)
class DeformConfig:
    """Ranges the draws of :func:`sample_deformation` come from (uniform within each)."""

    kinds: tuple[Kind, ...] = ()  # allowed kinds; empty: the category's (:data:`CATEGORY_KINDS`), else all
    dent_count: tuple[int, int] = (1, 3)
    dent_radius_frac: tuple[float, float] = (0.15, 0.35)  # of the object's largest extent
    dent_depth_frac: tuple[float, float] = (0.15, 0.4)  # of the dent's radius
    crush_amount: tuple[float, float] = (0.2, 0.5)  # of the height the top comes down
    crush_bulge: tuple[float, float] = (0.1, 0.3)  # sideways growth at mid-height, relative
    crush_max_lean: float = 0.15  # horizontal shift of the top, relative to the height
    bend_angle_deg: tuple[float, float] = (10.0, 35.0)
    fracture_height: tuple[float, float] = (0.35, 0.7)  # of the height, where the cut crosses the axis
    fracture_tilt_deg: float = 30.0  # most the cut plane leans from level
    fracture_gap: tuple[float, float] = (0.05, 0.3)  # between the base and the fallen top, of the largest extent
    fracture_debris: tuple[int, int] = (0, 4)  # chips scattered around a fracture
    debris_size_frac: tuple[float, float] = (0.04, 0.1)  # a chip's length, of the largest extent


@dataclass(frozen=True)
class DeformParams:
    """One drawn deformation, in the source's canonical frame (metres, z up, resting on z = 0)."""

    kind: str
    # dent: one (cx, cy, cz, nx, ny, nz, radius_m, depth_m) per dent; (nx, ny, nz) points into the object
    dents: tuple[tuple[float, ...], ...] = ()
    # crush: fraction of the height the top comes down, mid-height bulge, lean of the top (x, y) per metre of height
    crush_amount: float = 0.0
    crush_bulge: float = 0.0
    lean: tuple[float, float] = (0.0, 0.0)
    # bend: horizontal direction of the bend (radians from +x) and total angle over the height (radians)
    bend_azimuth: float = 0.0
    bend_angle: float = 0.0
    # knocked_over: the rotation (row-major 3x3) applied before settling on z = 0
    rotation: tuple[float, ...] = ()
    # fracture: the cut plane (point on the axis, upward unit normal), where the top falls and how far from the base
    cut: tuple[float, ...] = ()
    fall_azimuth: float = 0.0
    gap: float = 0.0
    # fracture: chips on the ground, each (x, y, length m, yaw) in the source's frame
    debris: tuple[tuple[float, ...], ...] = ()
    source_height_m: float = 0.0  # the undeformed height: what the category's size range refers to
    meta: dict = field(default_factory=dict, compare=False)

    def __post_init__(self):
        if self.kind not in KINDS:
            raise ValueError(f"DeformParams.kind {self.kind!r} not in {KINDS}")

    def to_dict(self) -> dict:
        d = asdict(self)
        d.pop("meta")
        return {
            k: (list(map(list, v)) if k in ("dents", "debris") else list(v) if isinstance(v, tuple) else v)
            for k, v in d.items()
        }

    @classmethod
    def from_dict(cls, d: dict) -> DeformParams:
        return cls(
            kind=str(d["kind"]),
            dents=tuple(tuple(float(x) for x in dent) for dent in d.get("dents", ())),
            crush_amount=float(d.get("crush_amount", 0.0)),
            crush_bulge=float(d.get("crush_bulge", 0.0)),
            lean=tuple(float(x) for x in d.get("lean", (0.0, 0.0))),
            bend_azimuth=float(d.get("bend_azimuth", 0.0)),
            bend_angle=float(d.get("bend_angle", 0.0)),
            rotation=tuple(float(x) for x in d.get("rotation", ())),
            cut=tuple(float(x) for x in d.get("cut", ())),
            fall_azimuth=float(d.get("fall_azimuth", 0.0)),
            gap=float(d.get("gap", 0.0)),
            debris=tuple(tuple(float(x) for x in chip) for chip in d.get("debris", ())),
            source_height_m=float(d.get("source_height_m", 0.0)),
        )


def _merged_geometry(asset: Asset):
    """All parts' triangles as one mesh with coincident vertices merged (texture seams closed)."""
    import trimesh

    verts = np.concatenate([np.asarray(m.vertices, np.float64) for m in asset.meshes])
    offs = np.cumsum([0] + [len(m.vertices) for m in asset.meshes[:-1]])
    faces = np.concatenate([np.asarray(m.faces) + o for m, o in zip(asset.meshes, offs)])
    g = trimesh.Trimesh(verts, faces, process=False)
    g.merge_vertices(digits_vertex=6)
    return g


def geometry_is_watertight(asset: Asset) -> bool:
    """Whether the asset's surface is closed once texture seams (duplicated vertices) are merged."""
    return bool(_merged_geometry(asset).is_watertight)


def sample_deformation(
    asset: Asset, rng: np.random.Generator, cfg: DeformConfig = DeformConfig(), kind: str | None = None
) -> DeformParams:
    """Draw one deformation of ``asset`` (``kind``, else one of ``cfg.kinds`` / the category's kinds)."""
    kinds = cfg.kinds or CATEGORY_KINDS.get(asset.category, KINDS)
    if kind is None:
        kind = kinds[int(rng.integers(len(kinds)))]
    elif kind not in KINDS:
        raise ValueError(f"unknown deformation kind {kind!r}; choose from {KINDS}")
    size = float(asset.extents_m.max())
    h = asset.height_m
    if kind == "dent":
        g = _merged_geometry(asset)
        n = int(rng.integers(cfg.dent_count[0], cfg.dent_count[1] + 1))
        # surface points drawn by area, so a dent lands anywhere on the surface, not where vertices are dense
        # faces that look down (the underside, a base plate) are not where a car or a kick hits
        area = np.asarray(g.area_faces, float) * (np.asarray(g.face_normals)[:, 2] > -0.3)
        fidx = rng.choice(len(area), size=n, p=area / area.sum())
        ab = rng.uniform(size=(n, 2))
        ab = np.where(ab.sum(axis=1, keepdims=True) > 1, 1 - ab, ab)  # uniform on the triangle
        tri = np.asarray(g.triangles)[fidx]
        pts = tri[:, 0] + ab[:, :1] * (tri[:, 1] - tri[:, 0]) + ab[:, 1:] * (tri[:, 2] - tri[:, 0])
        dents = []
        for p, fi in zip(pts, fidx):
            normal = -np.asarray(g.face_normals[fi], float)  # inward
            r = size * float(rng.uniform(*cfg.dent_radius_frac))
            d = r * float(rng.uniform(*cfg.dent_depth_frac))
            dents.append((*map(float, p), *map(float, normal), r, d))
        return DeformParams("dent", dents=tuple(dents), source_height_m=h)
    if kind == "crush":
        phi = float(rng.uniform(-math.pi, math.pi))
        lean = float(rng.uniform(0.0, cfg.crush_max_lean))
        return DeformParams(
            "crush",
            crush_amount=float(rng.uniform(*cfg.crush_amount)),
            crush_bulge=float(rng.uniform(*cfg.crush_bulge)),
            lean=(lean * math.cos(phi), lean * math.sin(phi)),
            source_height_m=h,
        )
    if kind == "bend":
        return DeformParams(
            "bend",
            bend_azimuth=float(rng.uniform(-math.pi, math.pi)),
            bend_angle=math.radians(float(rng.uniform(*cfg.bend_angle_deg))),
            source_height_m=h,
        )
    if kind == "fracture":
        lean_az, tilt = (
            float(rng.uniform(-math.pi, math.pi)),
            math.radians(float(rng.uniform(0, cfg.fracture_tilt_deg))),
        )
        n = np.array([math.sin(tilt) * math.cos(lean_az), math.sin(tilt) * math.sin(lean_az), math.cos(tilt)])
        lo, hi = asset.bounds_m
        centre = np.array([(lo[0] + hi[0]) / 2, (lo[1] + hi[1]) / 2, h * float(rng.uniform(*cfg.fracture_height))])
        fall_azimuth, gap = float(rng.uniform(-math.pi, math.pi)), float(rng.uniform(*cfg.fracture_gap))
        chips = []
        for _ in range(int(rng.integers(cfg.fracture_debris[0], cfg.fracture_debris[1] + 1))):
            r, a = size * float(rng.uniform(0.3, 0.7)), float(rng.uniform(-math.pi, math.pi))
            length = size * float(rng.uniform(*cfg.debris_size_frac))
            chips.append((r * math.cos(a), r * math.sin(a), length, float(rng.uniform(-math.pi, math.pi))))
        return DeformParams(
            "fracture",
            cut=(*map(float, centre), *map(float, n)),
            fall_azimuth=fall_azimuth,
            gap=gap,
            debris=tuple(chips),
            source_height_m=h,
        )
    phi = float(rng.uniform(-math.pi, math.pi))  # knocked over: fall towards a random horizontal direction
    axis = np.array([-math.sin(phi), math.cos(phi), 0.0])
    return DeformParams(
        "knocked_over", rotation=tuple(_settle(asset, _axis_angle(axis, math.pi / 2)).ravel()), source_height_m=h
    )


def _axis_angle(axis: np.ndarray, angle: float) -> np.ndarray:
    a = np.asarray(axis, float) / np.linalg.norm(axis)
    K = np.array([[0, -a[2], a[1]], [a[2], 0, -a[0]], [-a[1], a[0], 0]])
    return np.eye(3) + math.sin(angle) * K + (1 - math.cos(angle)) * K @ K


def _settle(asset: Asset, R: np.ndarray) -> np.ndarray:
    """``R`` followed by the smallest turn that lays the convex-hull face nearest to facing down flat on the ground
    (a rigid object at rest touches the ground with a face of its hull)."""
    g = _merged_geometry(asset)
    hull = g.convex_hull
    normals = hull.face_normals @ R.T
    down = np.array([0.0, 0.0, -1.0])
    n = normals[int(np.argmax(normals @ down))]
    axis = np.cross(n, down)
    s = float(np.linalg.norm(axis))
    if s < 1e-12:
        return R
    return _axis_angle(axis, math.atan2(s, float(n @ down))) @ R


def _fall_frame(asset: Asset, azimuth: float):
    """(convex hull, fall direction f, pivot p on z = 0, f's azimuth): a rigid object tips over an edge of its
    base's convex outline, the one whose outward normal is nearest to ``azimuth`` (a round base has one edge per
    facet: any direction, near enough)."""
    from scipy.spatial import ConvexHull

    hull_mesh = _merged_geometry(asset).convex_hull
    hull = np.asarray(hull_mesh.vertices, float)
    base = hull[hull[:, 2] <= hull[:, 2].min() + BASE_BAND_FRAC * asset.height_m][:, :2]
    outline = ConvexHull(base).equations  # rows (nx, ny, c): outward unit normal, n . x + c = 0 on the edge
    want = np.array([math.cos(azimuth), math.sin(azimuth)])
    nx, ny, c = outline[int(np.argmax(outline[:, :2] @ want))]
    f = np.array([nx, ny, 0.0])
    return hull_mesh, f, -c * f, math.atan2(ny, nx)


#: Hull points this close to the lowest one (a fraction of the height) form the base the object pivots on.
BASE_BAND_FRAC = 0.02
#: Most successive edges a falling object rolls over before it rests (a cone on a square plate needs two).
MAX_FALL_SEGMENTS = 8


def fall_segments(asset: Asset, azimuth: float) -> tuple[np.ndarray, float, list[tuple[np.ndarray, float]]]:
    """How the knocked object falls: (fall direction f, its azimuth, [(pivot point on z = 0, angle), ...]).

    The fall is planar: the object turns about horizontal lines across ``f``. In the plane of ``f`` and up, a hull
    point at (u, w) from the pivot touches the ground when w cos t = u sin t, so at t = atan2(w, u); the first of
    them ends the turn. The object rests there when its centre of mass (the convex hull's) lies over the points on
    the ground; otherwise it goes on turning about the farthest of them (a cone on a square plate lands on the
    plate's rim, then rolls onto its side)."""
    hull_mesh, f, p, az = _fall_frame(asset, azimuth)
    hull = np.asarray(hull_mesh.vertices, float)
    pts = np.c_[hull @ f, hull[:, 2]]  # (u, w) in the fixed plane of the fall
    centre = np.asarray(hull_mesh.center_mass, float)
    com = np.array([centre @ f, centre[2]])
    tol = 1e-9 * max(asset.height_m, 1e-9)
    pivot = np.array([p @ f, 0.0])
    segments = []
    for _ in range(MAX_FALL_SEGMENTS):
        d = pts - pivot
        free = (d[:, 1] > tol) | (d[:, 0] < -tol)  # points on the pivot line never leave the ground
        t = float(np.arctan2(d[free, 1], d[free, 0]).min())
        rot = np.array([[math.cos(t), math.sin(t)], [-math.sin(t), math.cos(t)]])  # (u, w): top towards +u
        pts, com = pivot + d @ rot.T, pivot + rot @ (com - pivot)
        pts[:, 1] = np.maximum(pts[:, 1], 0.0)  # rounding: what touches is on the ground
        segments.append((pivot[0] * f, t))
        ground_u = pts[pts[:, 1] <= tol, 0]
        if com[0] <= ground_u.max() + tol:
            break
        pivot = np.array([ground_u.max(), 0.0])
    return f, az, segments


def topple_rest_angle(asset: Asset, azimuth: float) -> float:
    """The total angle (radians) an object knocked over towards ``azimuth`` has turned when it rests
    (:func:`fall_segments`)."""
    return float(sum(t for _, t in fall_segments(asset, azimuth)[2]))


def tipped(asset: Asset, azimuth: float, angle: float, fall=None) -> tuple[Asset, np.ndarray]:
    """``asset`` knocked over towards ``azimuth`` (radians from its +x axis; the base edge it tips over, in
    ``meta["tipped"]["azimuth"]``) and turned by ``angle`` (0 .. :func:`topple_rest_angle`) about the edges it
    rolls over (:func:`fall_segments`): the pivot stays on the ground and nothing goes below it. Returned like every
    asset (x/y centred on its bounds, lowest point on z = 0) with ``origin`` (3,), where its origin lies in
    ``asset``'s frame: the turned object stands at ``object_from_tipped = translation(origin)``. ``fall``: this
    asset's :func:`fall_segments` for ``azimuth`` when the caller has it (a clip turns one object in every frame)."""
    f, azimuth, segments = fall_segments(asset, azimuth) if fall is None else fall
    axis = np.cross([0.0, 0.0, 1.0], f)  # turning about it brings +z towards f
    T = np.eye(4)
    left = float(angle)
    for pivot, t in segments:
        step = min(t, left)
        if step <= 0:
            break
        R = _axis_angle(axis, step)
        turn = np.eye(4)
        turn[:3, :3], turn[:3, 3] = R, pivot - R @ pivot
        T = turn @ T
        left -= step
    lo, hi = _transformed_bounds(asset, T)
    origin = np.array([(lo[0] + hi[0]) / 2, (lo[1] + hi[1]) / 2, lo[2]])
    T[:3, 3] -= origin
    meshes = []
    for m in asset.meshes:
        c = m.copy(include_cache=True)
        c.apply_transform(T)  # a rigid motion: trimesh turns the cached vertex normals with it
        meshes.append(c)
    ref = float(asset.meta.get("reference_height_m", asset.height_m))
    out = Asset(
        f"{asset.name}_tipped{math.degrees(angle):.1f}",
        asset.category,
        tuple(meshes),
        asset.source,
        asset.licence,
        asset.procedural,
        {**asset.meta, "tipped": {"azimuth": float(azimuth), "angle": float(angle)}, "reference_height_m": ref},
    )
    return out, origin


def _transformed_bounds(asset: Asset, T: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    v = np.concatenate([np.asarray(m.vertices, float) for m in asset.meshes]) @ T[:3, :3].T + T[:3, 3]
    return v.min(0), v.max(0)


def _wendland(t: np.ndarray) -> np.ndarray:
    t = np.clip(t, 0.0, 1.0)
    return (1.0 - t) ** 4 * (4.0 * t + 1.0)


def _displace(v: np.ndarray, p: DeformParams) -> np.ndarray:
    """The deformation as a function of position: (N, 3) -> (N, 3)."""
    v = np.asarray(v, np.float64)
    if p.kind == "dent":
        out = v.copy()
        for cx, cy, cz, nx, ny, nz, r, d in p.dents:
            dist = np.linalg.norm(v - np.array([cx, cy, cz]), axis=1)
            out += _wendland(dist / r)[:, None] * (d * np.array([nx, ny, nz]))[None, :]
        out[:, 2] = np.maximum(out[:, 2], np.minimum(v[:, 2], 0.0))  # nothing is pushed into the ground
        return out
    if p.kind == "crush":
        H = max(p.source_height_m, 1e-9)
        t = np.clip(v[:, 2] / H, 0.0, 1.0)
        z = v[:, 2] * (1.0 - p.crush_amount * t)
        grow = 1.0 + p.crush_bulge * p.crush_amount * np.sin(np.pi * t)
        x = v[:, 0] * grow + p.lean[0] * z
        y = v[:, 1] * grow + p.lean[1] * z
        return np.c_[x, y, z]
    if p.kind == "bend":
        if abs(p.bend_angle) < 1e-9:
            return v.copy()
        H = max(p.source_height_m, 1e-9)
        d = np.array([math.cos(p.bend_azimuth), math.sin(p.bend_azimuth), 0.0])
        side = np.array([-d[1], d[0], 0.0])
        u = v @ d  # offset along the bend direction
        w = v @ side
        R = H / p.bend_angle  # radius of the arc the axis follows
        theta = p.bend_angle * v[:, 2] / H
        u2 = R - (R - u) * np.cos(theta)
        z2 = (R - u) * np.sin(theta)
        return u2[:, None] * d[None, :] + w[:, None] * side[None, :] + z2[:, None] * np.array([0.0, 0.0, 1.0])
    R = np.asarray(p.rotation, float).reshape(3, 3)
    return v @ R.T


def _fractured(asset: Asset, p: DeformParams) -> list:
    """The two pieces of a fracture (see the module doc): each part's mesh cut by the plane (UVs kept), each piece
    closed by the triangulated section of the whole surface, the top turned onto its side beside the base."""
    import trimesh

    point, normal = np.asarray(p.cut[:3], float), np.asarray(p.cut[3:], float)
    merged = _merged_geometry(asset)
    section = merged.section(plane_origin=point, plane_normal=normal)
    if section is None:
        raise ValueError(f"fracture of {asset.name}: the cut plane misses the object")
    planar, to_3d = section.to_2D()
    colour = _cut_colour(asset, point, normal)
    caps = []
    for polygon in planar.polygons_full:
        v2, f2 = trimesh.creation.triangulate_polygon(polygon)
        v3 = trimesh.transform_points(np.c_[v2, np.zeros(len(v2))], to_3d)
        cap = trimesh.Trimesh(v3, f2, process=False)
        if cap.face_normals.size and float(np.mean(cap.face_normals @ normal)) < 0:
            cap.invert()  # faces +normal: the base's lid; the top's is the same turned over
        cap.visual = trimesh.visual.ColorVisuals(cap, face_colors=np.tile(colour, (len(cap.faces), 1)))
        caps.append(cap)
    if not caps:
        raise ValueError(f"fracture of {asset.name}: the section has no closed outline")
    lower = [m.slice_plane(point, -normal) for m in asset.meshes]
    upper = [m.slice_plane(point, normal) for m in asset.meshes]
    lower = [m for m in lower if len(m.faces)] + caps
    top_caps = []
    for cap in caps:
        c = cap.copy()
        c.invert()
        top_caps.append(c)
    upper = [m for m in upper if len(m.faces)] + top_caps
    top = Asset("top", asset.category, tuple(upper), asset.source)
    f = np.array([math.cos(p.fall_azimuth), math.sin(p.fall_azimuth), 0.0])
    R = _settle(top, _axis_angle(np.cross([0.0, 0.0, 1.0], f), math.pi / 2))
    T = np.eye(4)
    T[:3, :3] = R
    lo, hi = _transformed_bounds(top, T)
    base_lo, base_hi = _transformed_bounds(Asset("base", asset.category, tuple(lower), asset.source), np.eye(4))
    # beside the base along f: the top's near side p.gap of the size beyond the base's far side
    reach = float(np.sum(np.maximum(base_lo[:2] * f[:2], base_hi[:2] * f[:2])))  # the base's far side along f
    near = float(np.sum(np.minimum(lo[:2] * f[:2], hi[:2] * f[:2])))  # the top's side nearest the base
    shift = f * (reach + p.gap * float(asset.extents_m.max()) - near)
    T[:3, 3] = shift - np.array([0.0, 0.0, lo[2]])
    turned = []
    for m in upper:
        c = m.copy(include_cache=True)
        c.apply_transform(T)
        turned.append(c)
    chips = []
    for x, y, length, yaw in p.debris:  # flat chips of the broken material on the ground around the break
        chip = trimesh.creation.box(extents=(length, 0.6 * length, 0.3 * length))
        turn = _axis_angle(np.array([0.0, 0.0, 1.0]), yaw)
        place = np.eye(4)
        place[:3, :3], place[:3, 3] = turn, (x, y, 0.15 * length)
        chip.apply_transform(place)
        chip.visual = trimesh.visual.ColorVisuals(chip, face_colors=np.tile(colour, (len(chip.faces), 1)))
        chips.append(chip)
    return lower + turned + chips


def _cut_colour(asset: Asset, point: np.ndarray, normal: np.ndarray) -> np.ndarray:
    """RGBA uint8: the median colour of the surface's vertices within 2 % of the height of the cut plane (the
    material the break shows), mid grey where the surface has no colour there."""
    colours, near = [], []
    for m in asset.meshes:
        try:
            c = np.asarray(m.visual.to_color().vertex_colors, np.uint8)
        except (AttributeError, ValueError):
            continue
        if len(c) != len(m.vertices):
            continue
        d = np.abs((np.asarray(m.vertices) - point) @ normal)
        colours.append(c[:, :4]), near.append(d <= 0.02 * asset.height_m)
    if colours:
        c, k = np.concatenate(colours), np.concatenate(near)
        if k.any():
            rgb = np.median(c[k, :3].astype(float), axis=0)
            return np.r_[np.round(rgb), 255].astype(np.uint8)
    return np.array([128, 128, 128, 255], np.uint8)


def apply_deformation(asset: Asset, p: DeformParams) -> Asset:
    """A new asset: ``asset`` deformed by ``p`` (pure; UVs, faces and materials kept), re-centred in x/y on its
    bounding box and resting on z = 0. ``meta["deformation"]`` records ``p``; ``meta["reference_height_m"]`` is the
    source's height, which the placement's size range refers to (a cone on its side is still a cone of that
    height)."""
    if p.kind == "fracture":
        meshes = _fractured(asset, p)
    else:
        meshes = []
        for m in asset.meshes:
            c = m.copy()
            c.vertices = _displace(np.asarray(m.vertices), p)
            meshes.append(c)
    ref = float(asset.meta.get("reference_height_m", asset.height_m))
    return Asset(
        f"{asset.name}_{p.kind}",
        asset.category,
        normalise_meshes(meshes),
        asset.source,
        asset.licence,
        asset.procedural,
        {**asset.meta, "deformation": p.to_dict(), "reference_height_m": ref},
    )


def write_variants(asset: Asset, params: list[DeformParams], out: str | Path) -> list[dict]:
    """Write each variant of ``asset`` into the bank folder ``out`` (:func:`aias_augment.assets.bank.folder.add_to_bank`:
    ``NNNN.glb`` and its ``bank.json`` entry with the deformation record). Returns the new entries."""
    from aias_augment.assets.bank.folder import add_to_bank

    out_entries = []
    for p in params:
        variant = apply_deformation(asset, p)
        entry = {
            "reference_height_m": round(variant.reference_height_m, 4),
            "source": asset.source,
            "deformation": p.to_dict(),
        }
        out_entries.append(add_to_bank(out, variant, entry))
    return out_entries

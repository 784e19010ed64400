"""Procedural generators for rare road debris that has no good mesh, labelled ``procedural=True``.

- ``stone``: a noise-displaced, flattened icosphere, box-projected UVs, textured with a real photo texture
  (the rock textures of the furniture catalogs when available).
- ``concrete_block``: a box with chipped (noise-displaced) corners, textured with a real concrete texture.
- ``crumpled_sheet``: a folded, crumpled thin sheet (plastic/cardboard/metal), double sided.
- ``traffic_cone``: a seeded family of cones (and delineator posts): colour, proportions, 0-3 reflective bands,
  square or round base, dirt; a smooth surface of revolution with a drawn texture, every draw recorded in ``meta``.
  Its parts carry materials (``meta["parts"]``, :mod:`aias_augment.apply.shading`): the body glossy plastic, the
  sleeves retroreflective sheeting (with a fine prism-cell texture), the base matte rubber.
Each generator draws its size from the category's real range and all randomness from the passed generator.
"""

from __future__ import annotations

import functools
from collections.abc import Sequence
from dataclasses import dataclass

import cv2
import numpy as np
import trimesh
from PIL import Image

from aias_augment.assets.asset import Asset, normalise_meshes
from aias_augment.assets.cone_look import ConeLook

__all__ = [
    "GENERATORS",
    "CATEGORY_SPECS",
    "ProceduralSpec",
    "ConeLook",
    "ConeMeshes",
    "cone_texture",
    "generate",
    "procedural_asset",
    "procedural_asset_from_seed",
    "procedural_asset_like",
    "make_stone",
    "make_concrete_block",
    "make_crumpled_sheet",
    "make_traffic_cone",
]


@dataclass(frozen=True)
class ProceduralSpec:
    generator: str  # stone | concrete_block | crumpled_sheet | traffic_cone
    category: str
    height_range_m: tuple[float, float]


def _box_uv(vertices: np.ndarray, normals: np.ndarray, tile_m: float) -> np.ndarray:
    """Box projection: each vertex takes the two coordinates orthogonal to its dominant normal axis (in tiles)."""
    ax = np.argmax(np.abs(normals), axis=1)
    u = np.where(ax == 0, vertices[:, 1], vertices[:, 0])
    v = np.where(ax == 2, vertices[:, 1], vertices[:, 2])
    return np.c_[u, v] / tile_m


def _textured(mesh: trimesh.Trimesh, texture: Image.Image | None, colour_rgba, tile_m: float) -> trimesh.Trimesh:
    if texture is None:
        mat = trimesh.visual.material.SimpleMaterial(diffuse=np.asarray(colour_rgba, np.uint8))
        mesh.visual = trimesh.visual.TextureVisuals(material=mat)
        return mesh
    # unshare vertices so that each face gets consistent box-projected UVs
    m = trimesh.Trimesh(
        mesh.vertices[mesh.faces].reshape(-1, 3), np.arange(len(mesh.faces) * 3).reshape(-1, 3), process=False
    )
    fn = np.repeat(mesh.face_normals, 3, axis=0)
    uv = _box_uv(m.vertices, fn, tile_m)
    mat = trimesh.visual.material.SimpleMaterial(image=texture, diffuse=np.array([255, 255, 255, 255], np.uint8))
    return trimesh.Trimesh(
        m.vertices, m.faces, vertex_normals=fn, visual=trimesh.visual.TextureVisuals(uv=uv, material=mat), process=False
    )


def _smooth_noise(dirs: np.ndarray, rng: np.random.Generator, n_waves: int, freq: float) -> np.ndarray:
    """Sum of random plane waves over unit directions: a cheap smooth noise on the sphere, zero mean, in ~[-1, 1]."""
    k = rng.normal(size=(n_waves, 3)) * freq
    ph = rng.uniform(0, 2 * np.pi, n_waves)
    amp = 1.0 / (1.0 + np.linalg.norm(k, axis=1))
    out = (np.sin(dirs @ k.T + ph) * amp).sum(1)
    return out / max(np.abs(out).max(), 1e-9)  # eps: guard an all-zero noise


def make_stone(rng: np.random.Generator, height_m: float, texture: Image.Image | None = None) -> trimesh.Trimesh:
    sphere = trimesh.creation.icosphere(subdivisions=3)
    dirs = sphere.vertices / np.linalg.norm(sphere.vertices, axis=1, keepdims=True)
    r = 1.0 + 0.25 * _smooth_noise(dirs, rng, 12, 2.5) + 0.06 * _smooth_noise(dirs, rng, 24, 7.0)
    v = dirs * r[:, None] * rng.uniform([0.8, 0.6, 0.45], [1.3, 1.0, 0.7])  # flatter than wide, like a resting stone
    v[:, 2] = np.maximum(v[:, 2], v[:, 2].min() * 0.6)  # flattened contact face
    m = trimesh.Trimesh(v, sphere.faces, process=False)
    m.apply_scale(height_m / np.ptp(m.vertices[:, 2]))
    return _textured(m, texture, (118, 112, 104, 255), tile_m=max(height_m, 0.05))


def make_concrete_block(
    rng: np.random.Generator, height_m: float, texture: Image.Image | None = None
) -> trimesh.Trimesh:
    ext = np.array([rng.uniform(1.5, 2.5), rng.uniform(0.8, 1.3), 1.0]) * height_m
    box = trimesh.creation.box(extents=ext).subdivide().subdivide()
    v = box.vertices.copy()
    rel = np.abs(v) / (ext / 2)
    corner = np.clip((rel.min(1) - 0.5) * 2, 0, 1)  # 1 on edges/corners, 0 towards face centres
    v -= np.sign(v) * corner[:, None] * rng.uniform(0, 0.12, size=v.shape) * height_m  # chipped edges
    m = trimesh.Trimesh(v, box.faces, process=False)
    return _textured(m, texture, (150, 148, 142, 255), tile_m=0.4)


def make_crumpled_sheet(
    rng: np.random.Generator, height_m: float, texture: Image.Image | None = None, colour_rgba=None
) -> trimesh.Trimesh:
    n = 24
    size = rng.uniform(0.4, 1.0)
    xs, ys = np.meshgrid(np.linspace(-size / 2, size / 2, n), np.linspace(-size / 2, size / 2, n))
    pts = np.c_[xs.ravel(), ys.ravel()]
    z = np.zeros(len(pts))
    for _ in range(6):  # folds: ridges along random lines
        d = rng.normal(size=2)
        d /= np.linalg.norm(d)
        z += rng.uniform(0.3, 1.0) * np.abs(np.sin((pts @ d) * rng.uniform(4, 12) + rng.uniform(0, np.pi)))
    z += 0.2 * rng.normal(size=len(pts))  # crumples
    z = (z - z.min()) / max(np.ptp(z), 1e-9) * height_m  # eps: a flat draw stays flat
    faces = []
    for i in range(n - 1):
        for j in range(n - 1):
            a, b, c, d2 = i * n + j, i * n + j + 1, (i + 1) * n + j, (i + 1) * n + j + 1
            faces += [[a, b, d2], [a, d2, c]]
    faces = np.array(faces)
    top = trimesh.Trimesh(np.c_[pts, z], faces, process=False)
    both = trimesh.Trimesh(np.r_[top.vertices, top.vertices], np.r_[faces, faces[:, ::-1] + len(pts)], process=False)
    if colour_rgba is None:
        colour_rgba = [(200, 200, 195, 255), (60, 90, 160, 255), (170, 130, 85, 255), (40, 40, 40, 255)][
            int(rng.integers(4))
        ]
    return _textured(both, texture, colour_rgba, tile_m=size)


# --- traffic cones: a seeded family (cones and delineator posts) ------------------------------------------------

#: Body colours (sRGB) and their probabilities: fluorescent orange dominates real cones.
CONE_COLOURS: dict[str, tuple[tuple[int, int, int], float]] = {
    "orange": ((255, 72, 18), 0.55),  # TraCon's real cone bodies: median hue ~8 deg
    "red_orange": ((246, 44, 24), 0.27),
    "red": ((210, 28, 34), 0.06),
    "yellow": ((252, 196, 8), 0.07),
    "lime": ((190, 226, 24), 0.05),
}
CONE_TEXTURE_SIZE = (256, 512)  # (width, height) of the drawn texture image
_V_BASE = (0.0, 0.1)  # texture rows (v, 0 = image bottom) of the base's solid colour
_V_BODY = (0.14, 1.0)  # texture rows of the body: v linear in height from the base top to the tip


def _wrapped_blur(x: np.ndarray, sigma: float) -> np.ndarray:
    """Gaussian blur, periodic along x (columns wrap around the surface of revolution's seam)."""
    pad = int(3 * sigma) + 1
    y = cv2.GaussianBlur(
        cv2.copyMakeBorder(x, 0, 0, pad, pad, cv2.BORDER_WRAP), (0, 0), sigma, borderType=cv2.BORDER_REFLECT
    )
    return y[:, pad:-pad]


def _weighted_index(rng: np.random.Generator, p) -> int:
    """An index drawn with weights ``p``: ``Generator.choice(len(p), p=p / sum(p))``'s own arithmetic (its cumulative
    sum normalised by its last entry, one ``random()`` draw, searched from the right), the same draw of ``rng`` and
    the same index, without its argument checks (the weights are this module's constants)."""
    p = np.asarray(p, float)
    cdf = (p / p.sum()).cumsum()
    cdf /= cdf[-1]
    return int(cdf.searchsorted(rng.random(), side="right"))


def _choice(rng: np.random.Generator, table: dict):
    keys = list(table)
    return keys[_weighted_index(rng, [table[k][1] if isinstance(table[k], tuple) else table[k] for k in keys])]


def _superellipse(theta: np.ndarray, n: float) -> np.ndarray:
    """Radius factor of the superellipse |x|^n + |y|^n = 1 along directions theta (n = 2: circle, large: square)."""
    c, s = np.abs(np.cos(theta)), np.abs(np.sin(theta))
    return (c**n + s**n) ** (-1.0 / n)


def _ring_xy(solid: list[tuple[float, float]], segments: int) -> tuple[np.ndarray, np.ndarray]:
    """(x, y), each (K, segments): the vertices of K rings of radius r and superellipse exponent n (``solid``: (r, n)
    per ring, r > 0) at the ``segments`` angles of a loft's ring (the seam column left out)."""
    theta = np.linspace(0.0, 2 * np.pi, segments + 1)[:-1]
    shapes = {n: _superellipse(theta, n) for n in {n for _, n in solid}}  # rings share a few exponents
    rr = np.array([r for r, _ in solid]).reshape(-1, 1) * np.stack([shapes[n] for _, n in solid] or [theta])
    return rr * np.cos(theta), rr * np.sin(theta)


def _rings(sections: list[list[tuple[float, float, float, float]]], segments: int):
    """The rings of :func:`_loft`'s sections: per section, a list of (z, r, v, positions) with positions the ring's
    (segments, 3) vertices without the seam column, or None for a pole (r == 0, one vertex on the axis)."""
    x, y = _ring_xy([(r, sn) for sec in sections for _, r, sn, _ in sec if r > 0], segments)
    out, k = [], 0
    for sec in sections:
        rings = []
        for z, r, _, v in sec:
            if r <= 0:
                rings.append((z, r, v, None))
                continue
            ring = np.empty((segments, 3))
            ring[:, 0], ring[:, 1], ring[:, 2] = x[k], y[k], z
            rings.append((z, r, v, ring))
            k += 1
        out.append(rings)
    return out


def _loft_sections(sections: list[list[tuple[float, float, float, float]]], segments: int):
    """Per section of :func:`_loft`'s surface: its vertex positions, faces (outward, CCW; indices into the
    section's own vertices), the vertex ids of each ring (a pole's one vertex) and the UVs."""
    u = np.linspace(0.0, 2 * np.pi, segments + 1) / (2 * np.pi)
    j = np.arange(segments)
    for sec in _rings(sections, segments):
        ids, pos, uv, n = [], [], [], 0
        for z, r, v, xyz in sec:
            if xyz is None:
                ids.append(np.array([n]))
                pos.append(np.array([[0.0, 0.0, z]]))
                uv.append(np.array([[0.5, v]]))
                n += 1
            else:
                ring = np.empty((segments + 1, 3))  # the seam column repeats column 0
                ring[:-1] = xyz
                ring[-1] = ring[0]
                ids.append(np.arange(n, n + segments + 1))
                pos.append(ring)
                uv.append(np.column_stack([u, np.full(segments + 1, v)]))
                n += segments + 1
        sf = []
        for a, b in zip(ids[:-1], ids[1:]):
            if len(a) == 1 and len(b) == 1:
                continue
            if len(a) == 1:  # bottom pole: fan, outward = down
                sf.append(np.column_stack([np.full(segments, a[0]), b[j + 1], b[j]]))
            elif len(b) == 1:  # top pole
                sf.append(np.column_stack([a[j], a[j + 1], np.full(segments, b[0])]))
            else:  # per column j: (a_j, a_j+1, b_j+1) then (a_j, b_j+1, b_j)
                quad = np.empty((segments, 2, 3), np.int64)
                quad[:, 0, 0], quad[:, 0, 1], quad[:, 0, 2] = a[j], a[j + 1], b[j + 1]
                quad[:, 1, 0], quad[:, 1, 1], quad[:, 1, 2] = a[j], b[j + 1], b[j]
                sf.append(quad.reshape(-1, 3))
        yield np.concatenate(pos), np.concatenate(sf).astype(np.int64), ids, np.concatenate(uv)


def _loft(
    sections: list[list[tuple[float, float, float, float]]], segments: int
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """A closed surface of revolution from smooth ``sections``, each a list of rings (z, r, superellipse n, v)
    going up; consecutive sections share their end/start ring position but not vertices, so the normals break
    there (creases). A ring with r == 0 is a pole (one vertex). Returns vertices, faces (outward, CCW), vertex
    normals (smooth within a section, seamless across the UV seam) and UVs (u = angle, v as given)."""
    verts, faces, normals, uvs = [], [], [], []
    base = 0
    for pos, sf, ids, uv in _loft_sections(sections, segments):
        # smooth normals on the geometric vertices (seam column merged into column 0), area weighted
        geo = np.arange(len(pos))
        for ring in ids:
            if len(ring) > 1:
                geo[ring[-1]] = ring[0]
        tri = pos[sf]
        fn = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])  # length = 2 x area
        acc = np.zeros_like(pos)
        for k in range(3):
            np.add.at(acc, geo[sf[:, k]], fn)
        acc = acc[geo]
        nrm = acc / np.maximum(np.linalg.norm(acc, axis=1, keepdims=True), 1e-12)  # eps: isolated vertex
        verts.append(pos)
        faces.append(sf + base)
        normals.append(nrm)
        uvs.append(uv)
        base += len(pos)
    return np.concatenate(verts), np.concatenate(faces), np.concatenate(normals), np.concatenate(uvs)


def loft_triangles(sections: list[list[tuple[float, float, float, float]]], segments: int) -> np.ndarray:
    """(F, 3, 3) the triangles of :func:`_loft`'s surface (the same vertices, faces in the same order), without
    its normals and UVs."""
    return np.concatenate([pos[sf] for pos, sf, _, _ in _loft_sections(sections, segments)])


def _apply_look(p: dict, look: ConeLook, h: float) -> dict:
    """``p`` with the body colour, base colour (and its brightness, when measured) and sleeves of ``look``; the
    sleeves evenly spaced on the body's upper part (real cones carry them there), shape, base shape, dirt and wear
    as drawn."""
    lo, hi = (0.18, 0.88) if p["shape"] == "cone" else (0.45, 0.95)
    zb = p["base_height_m"]
    body_h = h - zb
    bands = []
    if look.bands:
        slot = (hi - lo) / look.bands
        w = min(look.band_width_frac, slot * 0.8)
        for i in range(look.bands):
            c = lo + slot * (i + 0.5)
            bands.append([zb + body_h * (c - w / 2), zb + body_h * (c + w / 2)])
    return {
        **p,
        "colour": "fitted",
        "colour_rgb": [float(c) for c in look.colour_rgb],
        "base_colour": look.base_colour,
        **({} if look.base_value is None else {"base_value": float(look.base_value)}),
        "bands_z_m": bands,
        "band_colour": "white",
    }


def cone_params(rng: np.random.Generator, h: float, look: ConeLook | None = None) -> dict:
    """Every shape/colour/wear parameter of one cone, drawn from ``rng`` (lengths in metres, z from the ground);
    with ``look``, its colours and sleeves are the look's (the same draws of ``rng`` either way)."""
    shape = "delineator" if h >= 0.7 and rng.random() < 0.15 else "cone"
    colour_name = _choice(rng, CONE_COLOURS)
    rgb = np.array(CONE_COLOURS[colour_name][0], float) * rng.uniform(0.92, 1.0) + rng.normal(0, 6, 3)
    base_shape = "square" if rng.random() < 0.7 else "round"
    base_colour = _choice(rng, {"black": 0.45, "body": 0.45, "grey": 0.1})
    if shape == "cone":
        base_half = h * rng.uniform(0.24, 0.33)
        base_h = h * rng.uniform(0.03, 0.06)
        r_bottom = min(h * rng.uniform(0.15, 0.21), base_half * 0.9)
        r_top = h * rng.uniform(0.025, 0.05)
        n_bands = _weighted_index(rng, [0.15, 0.37, 0.38, 0.10])
        lo, hi = 0.18, 0.88  # bands lie on this part of the body (fraction of the body height)
        w_range = {1: (0.14, 0.28), 2: (0.09, 0.2), 3: (0.07, 0.12)}.get(n_bands, (0, 0))
    else:
        base_half = h * rng.uniform(0.18, 0.25)
        base_h = h * rng.uniform(0.05, 0.08)
        r_bottom = h * rng.uniform(0.04, 0.06)
        r_top = r_bottom * rng.uniform(0.75, 0.95)
        n_bands = 1 + _weighted_index(rng, [0.2, 0.5, 0.3])
        lo, hi = 0.45, 0.95
        w_range = (0.05, 0.1)
        base_colour = "black" if rng.random() < 0.8 else base_colour
    body_h = h - base_h
    bands = []
    if n_bands:
        slot = (hi - lo) / n_bands
        for i in range(n_bands):  # one band per slot (non-overlapping), jittered inside it
            w = min(rng.uniform(*w_range), slot * 0.8)
            c = lo + slot * (i + 0.5) + rng.uniform(-1, 1) * (slot - w) * 0.3
            bands.append((base_h + body_h * (c - w / 2), base_h + body_h * (c + w / 2)))
    band_colour = "white" if rng.random() < 0.75 else "silver"
    p = {
        "shape": shape,
        "colour": colour_name,
        "colour_rgb": [float(x) for x in np.clip(rgb, 0, 255)],
        "base_shape": base_shape,
        "base_colour": base_colour,
        "base_half_width_m": float(base_half),
        "base_height_m": float(base_h),
        "body_bottom_radius_m": float(r_bottom),
        "top_radius_m": float(r_top),
        "band_colour": band_colour,
        "bands_z_m": [[float(a), float(b)] for a, b in bands],
        "dirt": float(rng.uniform(0.05, 0.45) if rng.random() < 0.35 else 0.0),  # most real cones are clean
        "wear_seed": int(rng.integers(2**31 - 1)),
    }
    return p if look is None else _apply_look(p, look, h)


#: Texture rows per pass of :func:`cone_texture`'s per-texel arithmetic: a block's colours stay in the CPU cache
#: through all of its steps.
_TEXTURE_BLOCK_ROWS = 64


@functools.lru_cache(maxsize=64)
def _prism_cells(size: tuple[int, int]) -> np.ndarray:
    """The retroreflective sheeting's prism cells as a brightness factor over the texture ((h, w) at ``size`` =
    (w, h)): a fine diamond lattice, its period (8 texels of the full texture) dividing the width so that it closes
    round the seam and keeps the cone's 4-fold symmetry; area-averaged at a smaller size, as a mipmap level."""
    tw, th = CONE_TEXTURE_SIZE
    i, c = np.arange(th)[:, None], np.arange(tw)[None, :]
    cell = (np.abs((i + c) % 8 - 3.5) + np.abs((i - c) % 8 - 3.5)) / 7.0  # 0 at a cell's centre
    f = 1 + 0.06 * (0.5 - cell)
    if size != (tw, th):
        f = cv2.resize(f, size, interpolation=cv2.INTER_AREA)
    f.setflags(write=False)
    return f


def _area_rows(x: np.ndarray, rows: int) -> np.ndarray:
    """Per-row values (n, C) area-averaged to ``rows`` rows (as a mipmap level averages texels)."""
    return x if rows == len(x) else cv2.resize(x, (x.shape[1], rows), interpolation=cv2.INTER_AREA)


def cone_texture(
    p: dict, h: float, photo: Image.Image | None = None, size: tuple[int, int] = CONE_TEXTURE_SIZE
) -> np.ndarray:
    """The cone's texture (float64 sRGB in [0, 1], (rows, cols, 3)) at ``size`` = (cols, rows), at most
    :data:`CONE_TEXTURE_SIZE`: base colour at the bottom rows, the body above it with v linear in height, bands
    where ``p['bands_z_m']`` says (retroreflective: a sparkle grain and prism cells), slight colour noise, dirt
    (darker, desaturated blotches, more near the ground) and scuffs; ``photo``, when given, modulates the grime.

    A smaller ``size`` is the full texture's mipmap level drawn directly: the same cone (its rows' colours, the
    low-frequency noise, the blotches and scuffs are the same fields, area-averaged), its texel-scale grain drawn at
    the level with the spread an area average of the full grain has. So a far cone costs what its pixels need."""
    tw, th = CONE_TEXTURE_SIZE
    sw, sh = int(size[0]), int(size[1])
    if not (1 <= sw <= tw and 1 <= sh <= th):
        raise ValueError(f"texture size {size} outside 1..{CONE_TEXTURE_SIZE}")
    shrink = np.sqrt(tw * th / (sw * sh))  # 1 / the spread of an area average of unit white noise
    rng = np.random.default_rng(p["wear_seed"])  # the fields that make this cone (the same at every size)
    noise = np.random.default_rng([p["wear_seed"], 1])  # the texel grain (drawn at the size asked)
    v = 1.0 - (np.arange(th) + 0.5) / th  # full row -> v (image row 0 is v = 1)
    zb = p["base_height_m"]
    z = zb + (v - _V_BODY[0]) / (_V_BODY[1] - _V_BODY[0]) * (h - zb)  # row -> height on the body
    body = np.asarray(p["colour_rgb"], float) / 255.0
    band = np.zeros(th, bool)
    for a, b in p["bands_z_m"]:
        band |= (z >= a) & (z <= b)
    band &= v >= _V_BODY[0]
    white = np.array([0.96, 0.96, 0.95]) if p["band_colour"] == "white" else np.array([0.84, 0.85, 0.86])
    base_rgb = {"black": np.array([0.07, 0.07, 0.07]), "grey": np.array([0.22, 0.22, 0.23]), "body": body * 0.85}[
        p["base_colour"]
    ]
    if p.get("base_value") is not None:  # measured on a photo's cone: the class colour at that V beside the body's
        base_rgb = np.minimum(base_rgb * (p["base_value"] * body.max() / base_rgb.max()), 1.0)
    row_rgb = np.empty((th, 3))  # each row's colour before the noise: body, band or base
    row_rgb[:] = body
    row_rgb[band] = white
    row_rgb[v < (_V_BASE[1] + _V_BODY[0]) / 2] = base_rgb
    ground = np.clip(1.2 - (z - zb) / (0.5 * (h - zb)), 0.2, 1.0)  # dirtier near the ground
    rows = _area_rows(np.column_stack([row_rgb, band, ground]), sh)
    row_rgb, band_f, ground = rows[:, :3], rows[:, 3], rows[:, 4:5]
    # the cone's fields: smooth low-frequency colour noise, then the dirt's blotches and scuffs
    low = _wrapped_blur(rng.normal(0, 1, (th // 8, tw // 8)), 2.0)
    low = cv2.resize(low / max(low.std(), 1e-9), (sw, sh))  # eps: flat noise
    dirt = p["dirt"] > 0
    if dirt:
        blot = _wrapped_blur(rng.normal(0, 1, (th // 4, tw // 4)), 3.0)  # patchy, periodic around the cone
        blot = cv2.resize(np.clip(blot / max(blot.std(), 1e-9) * 0.6 + 0.1, 0, 1), (sw, sh))  # eps: flat noise
        if photo is not None:
            blot = blot * (0.5 + np.asarray(photo.convert("L").resize((sw, sh)), float) / 255.0)
        grime = np.array([0.28, 0.24, 0.2])  # brownish road dirt
        scuffs = []  # short dark horizontal streaks: (rows, cols, factor) on the full texture
        for _ in range(int(p["dirt"] * 40)):
            r0, c0 = rng.integers(th), rng.integers(tw)
            ln, wd = rng.integers(4, 30), rng.integers(1, 3)
            scuffs.append((slice(r0, r0 + wd), slice(c0, c0 + ln), rng.uniform(0.55, 0.85)))
    # the texel grain: fine colour noise, and the bands' sparkle (rows partly in a band get part of it)
    grain = noise.normal(0, 1 / shrink, (sh, sw))
    band_rows = np.flatnonzero(band_f > 0)
    sparkle = noise.normal(0, 1, (len(band_rows), sw)) * (np.sqrt(band_f[band_rows]) / shrink)[:, None]
    cells = _prism_cells((sw, sh))
    img = np.empty((sh, sw, 3))
    for r0 in range(0, sh, _TEXTURE_BLOCK_ROWS):
        r = slice(r0, min(sh, r0 + _TEXTURE_BLOCK_ROWS))
        blk = img[r]
        np.multiply((1 + 0.04 * low[r] + 0.015 * grain[r])[..., None], row_rgb[r, None, :], out=blk)
        k = (band_rows >= r.start) & (band_rows < r.stop)
        if k.any():
            i = band_rows[k]
            bf = band_f[i, None]
            img[i] *= ((1 + 0.03 * sparkle[k]) * (1 + bf * (cells[i] - 1)))[..., None]
        if dirt:
            d = np.clip(p["dirt"] * blot[r] * ground[r], 0, 0.85)[..., None]
            grey = ((blk[..., 0] + blk[..., 1]) + blk[..., 2])[..., None] / 3
            # desaturate, darken: (img (1 - d/2) + grey d/2) (1 - 0.45 d) + 0.15 grime d
            blk *= 1 - 0.5 * d
            blk += grey * 0.5 * d
            blk *= 1 - 0.45 * d
            blk += grime * 0.15 * d
    if dirt and scuffs:
        if (sw, sh) == (tw, th):
            for rows_, cols_, f in scuffs:
                img[rows_, cols_] *= f
        else:  # their area-average at the level, on the level's rows they touch (elsewhere it is exactly 1)
            k = th // sh  # a power-of-two level: each level row averages k full rows (and k columns)
            lv = sorted({r // k for rows_, _, _ in scuffs for r in range(rows_.start, min(rows_.stop, th))})
            at = {r: j for j, r in enumerate(lv)}
            field = np.ones((len(lv) * k, tw))
            for rows_, cols_, f in scuffs:
                for r in range(rows_.start, min(rows_.stop, th)):
                    field[at[r // k] * k + r % k, cols_] *= f
            img[lv] *= cv2.resize(field, (sw, len(lv)), interpolation=cv2.INTER_AREA)[..., None]
    return np.clip(img, 0.0, 1.0, out=img)


def _cone_texture(p: dict, h: float, photo: Image.Image | None) -> Image.Image:
    """The full texture image (:func:`cone_texture` at :data:`CONE_TEXTURE_SIZE`, 8-bit), the mesh's material."""
    img = cone_texture(p, h, photo)
    img *= 255
    img += 0.5
    return Image.fromarray(img.astype(np.uint8))


def cone_sections(p: dict, h: float) -> list[list[tuple[float, float, float, float]]]:
    """The cone's surface of revolution as :func:`_loft` takes it: sections of rings (z, r, superellipse n, texture
    v) going up, for the parameters ``p`` (:func:`cone_params`) and total height ``h``: the base's bottom face, its
    side with a small bevel, its top face out to the body, then the body (a slight concave flare, straight to the
    cap, a rounded top closing at a pole). The mesh and the ray-cast render draw these same rings."""
    zb, a, r0, rt = p["base_height_m"], p["base_half_width_m"], p["body_bottom_radius_m"], p["top_radius_m"]
    n_base = 8.0 if p["base_shape"] == "square" else 2.0
    vb = _V_BASE[1] * 0.5  # base rows of the texture
    body_v = lambda z: _V_BODY[0] + (z - zb) / (h - zb) * (_V_BODY[1] - _V_BODY[0])  # noqa: E731
    edge = min(0.004 * h / 0.7, zb * 0.3)  # small bevel on the base's top edge
    base = [
        [(0.0, 0.0, n_base, vb), (0.0, a, n_base, vb)],  # bottom face
        [(0.0, a, n_base, vb), (zb - edge, a, n_base, vb), (zb, a - edge, n_base, vb)],  # side, bevel
        [(zb, a - edge, n_base, vb), (zb, r0 * 1.02, 2.0, vb)],
    ]  # top face, out to the body
    # body: a slight concave flare at the bottom (real cones widen into the base), then straight to the cap
    cap_h = rt * (1.0 if p["shape"] == "cone" else 0.9)
    z_cap = h - cap_h
    flare_h = min(0.06 * (h - zb), 0.3 * (z_cap - zb))
    zs = [zb, zb + 0.25 * flare_h, zb + flare_h] + list(np.linspace(zb + flare_h, z_cap, 12)[1:])
    rs = [r0 * 1.02, r0 * 1.0 + 0.0, r0 * 0.985]
    slope = (r0 * 0.985 - rt) / max(z_cap - (zb + flare_h), 1e-9)
    rs += [r0 * 0.985 - slope * (zz - zb - flare_h) for zz in zs[3:]]
    body = [(zz, rr, 2.0, body_v(zz)) for zz, rr in zip(zs, rs)]
    phi = np.linspace(0, np.pi / 2, 7)[1:]  # rounded top: a quarter ellipse from the side to the tip
    body += [
        (z_cap + cap_h * np.sin(f), rt * np.cos(f) if f < np.pi / 2 else 0.0, 2.0, body_v(z_cap + cap_h * np.sin(f)))
        for f in phi
    ]
    return base + [body]


def _cone_record(p: dict, h: float, segments: int) -> dict:
    """What a cone's ``meta`` records besides its draws ``p``: height, segments, the parts and their materials."""
    parts = [{"name": "base", "z_m": [0.0, p["base_height_m"]], "material": "matte_rubber"}]
    parts += [{"name": "sleeve", "z_m": list(b), "material": "retroreflective"} for b in p["bands_z_m"]]
    return {
        **p,
        "height_m": h,
        "segments": int(segments),
        "parts": parts,
        "material": "glossy_plastic",  # the body: everything no part names
    }


def _cone_mesh(p: dict, h: float, image: Image.Image, segments: int) -> trimesh.Trimesh:
    verts, faces, normals, uv = _loft(cone_sections(p, h), segments)
    mat = trimesh.visual.material.SimpleMaterial(image=image, diffuse=np.array([255, 255, 255, 255], np.uint8))
    return trimesh.Trimesh(
        verts, faces, vertex_normals=normals, process=False, visual=trimesh.visual.TextureVisuals(uv=uv, material=mat)
    )


def make_traffic_cone(
    rng: np.random.Generator,
    height_m: float,
    texture: Image.Image | None = None,
    segments: int = 64,
    look: ConeLook | None = None,
) -> trimesh.Trimesh:
    """One traffic cone (or, for tall draws, sometimes a slim delineator post) of total height ``height_m``: a
    smooth surface of revolution on a square (rounded-corner) or round base, with a drawn texture. All parameters
    come from ``rng`` and are stored in ``mesh.metadata['procedural_params']`` (band heights in metres above the
    ground contact). ``texture``: an optional photo that modulates the dirt; ``look``: colours and sleeves to draw
    (:class:`ConeLook`)."""
    h = float(height_m)
    p = cone_params(rng, h, look)
    m = _cone_mesh(p, h, _cone_texture(p, h, texture), segments)
    m.metadata["procedural_params"] = _cone_record(p, h, segments)
    return m


class ConeMeshes(Sequence):
    """The meshes of a procedural cone (one, in the canonical frame, as :func:`generate` normalises them), made on
    first read from its draws ``p``. The ray-cast render needs only the texture (:meth:`texture`) and the bounds
    (:meth:`bounds_m`, exact: the mesh's own), so a fast call that ray-casts a new cone never builds its mesh
    (~3 ms). Pickles as its recipe."""

    __slots__ = ("params", "height", "photo", "segments", "_sections", "_texture", "_built")

    def __init__(self, params: dict, height: float, photo: Image.Image | None, segments: int = 64):
        self.params, self.height, self.photo, self.segments = params, float(height), photo, int(segments)
        self._sections, self._texture, self._built = None, None, None

    def texture(self) -> Image.Image:
        """The cone's texture image (:func:`_cone_texture`), made once."""
        if self._texture is None:
            self._texture = _cone_texture(self.params, self.height, self.photo)
        return self._texture

    def texture_level(self, size: tuple[int, int]) -> np.ndarray:
        """The texture at ``size`` (W, H) as float32 sRGB in [0, 1]: the full image's own texels at full size, else
        that mipmap level drawn directly (:func:`cone_texture`)."""
        if tuple(size) == CONE_TEXTURE_SIZE:
            return np.asarray(self.texture(), np.float32) / np.float32(255.0)
        return cone_texture(self.params, self.height, self.photo, size).astype(np.float32)

    def sections(self) -> list:
        """The cone's rings (:func:`cone_sections`), made once."""
        if self._sections is None:
            self._sections = cone_sections(self.params, self.height)
        return self._sections

    def bounds_m(self) -> np.ndarray:
        """(2, 3) the built mesh's bounds, from its rings alone: min/max over the ring vertices (each the product
        :func:`_ring_xy` gives the mesh), then the shift that :func:`normalise_meshes` applies (a sum, which
        keeps the order of floats, so min/max commute with it)."""
        lo, hi, shift = self._extent()
        return np.stack([lo + shift, hi + shift])

    def _extent(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(lo, hi, shift): the loft's vertex bounds (min/max over :meth:`_vertices`) and the translation
        :func:`normalise_meshes` applies to them. A ring vertex's x is ``(r s) c`` (its radius r, the exponent's
        factor s and cos c of its angle), each product rounded: monotonic in r at every angle, so over the rings of
        one exponent x and y reach their extremes on the narrowest or the widest ring, whose vertices are the only
        ones made (the same products, so the same floats)."""
        rings = [ring for sec in self.sections() for ring in sec]
        by_n: dict[float, list[float]] = {}
        for _, r, sn, _ in rings:
            if r > 0:
                by_n.setdefault(sn, []).append(r)
        x, y = _ring_xy([(f(rs), sn) for sn, rs in by_n.items() for f in (min, max)], self.segments)
        z = [zz for zz, _, _, _ in rings]
        lo = np.array([x.min(), y.min(), min(z)])
        hi = np.array([x.max(), y.max(), max(z)])
        if any(r <= 0 for _, r, _, _ in rings):  # a pole: a vertex on the axis
            lo[:2], hi[:2] = np.minimum(lo[:2], 0.0), np.maximum(hi[:2], 0.0)
        return lo, hi, -np.array([(lo[0] + hi[0]) / 2, (lo[1] + hi[1]) / 2, lo[2]])

    def _vertices(self) -> np.ndarray:
        """(N, 3) the loft's vertices from its rings alone, before the shift: every ring vertex (each the product
        :func:`_ring_xy` gives the mesh) and the poles on the axis. The loft's hull is theirs."""
        rings = [ring for sec in self.sections() for ring in sec]
        solid = [(z, r, sn) for z, r, sn, _ in rings if r > 0]
        x, y = _ring_xy([(r, sn) for _, r, sn in solid], self.segments)
        z = np.repeat([zz for zz, _, _ in solid], self.segments).reshape(x.shape)
        pts = np.stack([x.ravel(), y.ravel(), z.ravel()], axis=1)
        poles = [[0.0, 0.0, zz] for zz, r, _, _ in rings if r <= 0]
        return np.concatenate([pts, np.array(poles)]) if poles else pts

    def outline_m(self) -> np.ndarray:
        """(N, 3) the built mesh's vertices that its silhouette can reach (:meth:`_vertices`), after
        :func:`normalise_meshes`' shift; made without the mesh."""
        return self._vertices() + self._extent()[2]

    def triangles(self) -> np.ndarray:
        """(F, 3, 3) the built mesh's triangles (its faces in order; after :func:`normalise_meshes`' shift, the
        same sums), made without the mesh: what a shadow projected from the triangles reads. The mesh is never
        watertight (its sections and its UV seam do not share vertices), so a shadow reads every triangle."""
        tri = loft_triangles(self.sections(), self.segments)
        tri += self._extent()[2]  # the rings' vertices are the faces' (every vertex is in a face)
        return tri

    def _meshes(self) -> tuple:
        if self._built is None:
            mesh = _cone_mesh(self.params, self.height, self.texture(), self.segments)
            self._built = normalise_meshes([mesh], crease_deg=None)  # analytic normals (smooth within a section)
        return self._built

    def __len__(self) -> int:
        return 1

    def __getitem__(self, i):
        return self._meshes()[i]

    def __iter__(self):
        return iter(self._meshes())

    def __reduce__(self):
        return (ConeMeshes, (self.params, self.height, self.photo, self.segments))


GENERATORS = {
    "stone": make_stone,
    "concrete_block": make_concrete_block,
    "crumpled_sheet": make_crumpled_sheet,
    "traffic_cone": make_traffic_cone,
}

#: Generators that need no photo texture, per category: ``asset_source="procedural"`` draws a new one per object.
CATEGORY_SPECS: dict[str, ProceduralSpec] = {
    "traffic_cone": ProceduralSpec("traffic_cone", "traffic_cone", (0.3, 1.0)),
}


def generate(
    spec: ProceduralSpec,
    rng: np.random.Generator,
    texture: Image.Image | None = None,
    name: str | None = None,
    look: ConeLook | None = None,
) -> Asset:
    """One procedural asset in the canonical frame, its height drawn uniformly from the spec's range; ``look`` (cones
    only) sets its colours and sleeves."""
    if spec.generator not in GENERATORS:
        raise ValueError(f"unknown generator {spec.generator!r}; known: {sorted(GENERATORS)}")
    if look is not None and spec.generator != "traffic_cone":
        raise ValueError(f"a ConeLook applies to traffic cones only, not to {spec.generator!r}")
    lo, hi = spec.height_range_m
    height = float(rng.uniform(lo, hi))
    if spec.generator == "traffic_cone":  # its mesh made on first read (ConeMeshes), its draws recorded
        p = cone_params(rng, height, look)
        parts = ConeMeshes(p, height, texture)
        params = _cone_record(p, height, parts.segments)
    else:
        parts = normalise_meshes([GENERATORS[spec.generator](rng, height, texture)], crease_deg=None)
        params = {}
    return Asset(
        name or f"procedural {spec.generator}",
        spec.category,
        parts,
        f"procedural:{spec.generator}",
        licence="generated (textures: see meta)",
        procedural=True,
        meta={**params, "generator": spec.generator, "height_m": height, "textured": texture is not None},
    )


def procedural_asset(category: str, rng: np.random.Generator) -> Asset:
    """A new procedural asset of ``category`` (see :data:`CATEGORY_SPECS`) from its own generator, seeded by one draw
    of ``rng``; the seed is in ``meta['seed']``, so :func:`procedural_asset_from_seed` rebuilds it exactly."""
    return procedural_asset_from_seed(category, int(rng.integers(2**63 - 1)))


def procedural_asset_from_seed(category: str, seed: int, look: ConeLook | dict | None = None) -> Asset:
    """The procedural asset of ``category`` that the seed ``seed`` makes (the one a record's ``asset_meta['seed']``
    names), with ``look`` (a :class:`ConeLook` or its dict, the record's ``asset_meta['look']``) when it was drawn
    like a photo's own cones."""
    look = ConeLook.from_dict(look) if isinstance(look, dict) else look
    a = generate(CATEGORY_SPECS[category], np.random.default_rng(int(seed)), look=look)
    meta = {**a.meta, "seed": int(seed)}
    if look is not None:
        meta["look"] = look.to_dict()
    return Asset(a.name, a.category, a.meshes, a.source, a.licence, True, meta)


def procedural_asset_like(category: str, rng: np.random.Generator, looks) -> Asset:
    """A new procedural cone drawn like one of ``looks`` (a non-empty sequence of :class:`ConeLook`, a photo's own
    cones): one draw of ``rng`` (its seed, as :func:`procedural_asset`), the look chosen from that seed, so a record's
    ``asset_meta['seed']`` and ``['look']`` rebuild it."""
    if not looks:
        raise ValueError("procedural_asset_like needs at least one ConeLook")
    seed = int(rng.integers(2**63 - 1))
    look = looks[int(np.random.default_rng([seed, 53]).integers(len(looks)))]
    return procedural_asset_from_seed(category, seed, look)

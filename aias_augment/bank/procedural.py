"""Procedural generators for rare road debris that has no good mesh, labelled ``procedural=True``.

- ``stone``: a noise-displaced, flattened icosphere, box-projected UVs, textured with a real photo texture
  (the rock textures of the furniture catalogs when available).
- ``concrete_block``: a box with chipped (noise-displaced) corners, textured with a real concrete texture.
- ``crumpled_sheet``: a folded, crumpled thin sheet (plastic/cardboard/metal), double sided.
Each generator draws its size from the category's real range and all randomness from the passed generator.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import trimesh
from PIL import Image

from ..assets import Asset, normalise_meshes

__all__ = ["GENERATORS", "ProceduralSpec", "generate", "make_stone", "make_concrete_block", "make_crumpled_sheet"]


@dataclass(frozen=True)
class ProceduralSpec:
    generator: str                   # stone | concrete_block | crumpled_sheet
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
    m = trimesh.Trimesh(mesh.vertices[mesh.faces].reshape(-1, 3), np.arange(len(mesh.faces) * 3).reshape(-1, 3),
                        process=False)
    fn = np.repeat(mesh.face_normals, 3, axis=0)
    uv = _box_uv(m.vertices, fn, tile_m)
    mat = trimesh.visual.material.SimpleMaterial(image=texture, diffuse=np.array([255, 255, 255, 255], np.uint8))
    return trimesh.Trimesh(m.vertices, m.faces, vertex_normals=fn, visual=trimesh.visual.TextureVisuals(uv=uv, material=mat),
                           process=False)


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


def make_concrete_block(rng: np.random.Generator, height_m: float,
                        texture: Image.Image | None = None) -> trimesh.Trimesh:
    ext = np.array([rng.uniform(1.5, 2.5), rng.uniform(0.8, 1.3), 1.0]) * height_m
    box = trimesh.creation.box(extents=ext).subdivide().subdivide()
    v = box.vertices.copy()
    rel = np.abs(v) / (ext / 2)
    corner = np.clip((rel.min(1) - 0.5) * 2, 0, 1)  # 1 on edges/corners, 0 towards face centres
    v -= np.sign(v) * corner[:, None] * rng.uniform(0, 0.12, size=v.shape) * height_m  # chipped edges
    m = trimesh.Trimesh(v, box.faces, process=False)
    return _textured(m, texture, (150, 148, 142, 255), tile_m=0.4)


def make_crumpled_sheet(rng: np.random.Generator, height_m: float, texture: Image.Image | None = None,
                        colour_rgba=None) -> trimesh.Trimesh:
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
            int(rng.integers(4))]
    return _textured(both, texture, colour_rgba, tile_m=size)


GENERATORS = {"stone": make_stone, "concrete_block": make_concrete_block, "crumpled_sheet": make_crumpled_sheet}


def generate(spec: ProceduralSpec, rng: np.random.Generator, texture: Image.Image | None = None,
             name: str | None = None) -> Asset:
    """One procedural asset in the canonical frame, its height drawn uniformly from the spec's range."""
    if spec.generator not in GENERATORS:
        raise ValueError(f"unknown generator {spec.generator!r}; known: {sorted(GENERATORS)}")
    lo, hi = spec.height_range_m
    height = float(rng.uniform(lo, hi))
    mesh = GENERATORS[spec.generator](rng, height, texture)
    parts = normalise_meshes([mesh])
    return Asset(name or f"procedural {spec.generator}", spec.category, parts, f"procedural:{spec.generator}",
                 licence="generated (textures: see meta)", procedural=True,
                 meta={"generator": spec.generator, "height_m": height, "textured": texture is not None})

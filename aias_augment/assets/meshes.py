"""Mesh files read into the canonical object frame (metres, z up, centred in x/y on the bounding box, resting on
z = 0): the formats, the units and up axis a file declares (COLLADA ``<unit>``/``<up_axis>``, gazebo ``model.sdf``
``<scale>``), textures the renderer can upload, and vertex normals creased at sharp edges."""

from __future__ import annotations

import copy
import logging
import re
import xml.etree.ElementTree as ET
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from aias_augment.assets.errors import AssetError
from aias_augment.assets.texture import pad_mesh_textures

if TYPE_CHECKING:  # imported where used: trimesh (~0.16 s with networkx) only when meshes are read
    import trimesh

log = logging.getLogger(__name__)

__all__ = [
    "CREASE_ANGLE_DEG",
    "MESH_SUFFIXES",
    "axis_rotation_to_z_up",
    "crease_normals",
    "gazebo_visual_mesh",
    "load_mesh_file",
    "normalise_meshes",
    "read_collada_unit",
    "scene_parts",
]

MESH_SUFFIXES = {".obj", ".dae", ".glb", ".gltf", ".ply", ".stl", ".off"}


def axis_rotation_to_z_up(up_axis: str) -> np.ndarray:
    import trimesh

    up_axis = up_axis.upper().replace("_UP", "")
    if up_axis == "Z":
        return np.eye(4)
    if up_axis == "Y":  # y-up -> z-up: rotate +90 deg about x (y -> z, z -> -y)
        return trimesh.transformations.rotation_matrix(np.pi / 2, [1, 0, 0])
    if up_axis == "X":
        return trimesh.transformations.rotation_matrix(-np.pi / 2, [0, 1, 0])
    raise AssetError(f"unknown up axis {up_axis!r}")


def read_collada_unit(path: Path) -> tuple[float, str]:
    """(metres per unit, up axis) declared in a COLLADA file's <asset> block (defaults 1.0, 'Y' per the spec)."""
    try:
        root = ET.parse(path).getroot()
    except ET.ParseError as e:
        raise AssetError(f"{path}: not valid COLLADA XML ({e})") from e
    ns = re.match(r"\{.*\}", root.tag)
    ns = ns.group(0) if ns else ""
    meter, up = 1.0, "Y_UP"
    asset = root.find(f"{ns}asset")
    if asset is not None:
        unit = asset.find(f"{ns}unit")
        if unit is not None and unit.get("meter"):
            meter = float(unit.get("meter"))
        up_el = asset.find(f"{ns}up_axis")
        if up_el is not None and up_el.text:
            up = up_el.text.strip()
    return meter, up


def scene_parts(loaded, path: Path) -> list[trimesh.Trimesh]:
    """Every triangle mesh of a loaded file, its scene-graph transform applied, materials kept (no checks)."""
    import trimesh

    if isinstance(loaded, trimesh.Trimesh):
        return [loaded]
    if not isinstance(loaded, trimesh.Scene):
        raise AssetError(f"{path}: unsupported geometry type {type(loaded).__name__} (no triangles)")
    parts = []
    for node in loaded.graph.nodes_geometry:
        transform, geom_name = loaded.graph[node]
        g = loaded.geometry[geom_name]
        if isinstance(g, trimesh.Trimesh):
            g = g.copy()
            g.apply_transform(transform)
            parts.append(g)
    return parts


def _flatten(loaded, path: Path) -> list[trimesh.Trimesh]:
    meshes = [m for m in scene_parts(loaded, path) if len(m.faces) > 0]
    if not meshes:
        raise AssetError(f"{path}: contains no triangles")
    for m in meshes:
        if not np.all(np.isfinite(m.vertices)):
            raise AssetError(f"{path}: non-finite vertex coordinates")
    return meshes


def load_mesh_file(
    path: str | Path, *, scale: float | None = None, up_axis: str | None = None
) -> list[trimesh.Trimesh]:
    """Load a mesh file into z-up metres (not yet recentred). Units from the file unless ``scale`` is given."""
    import trimesh

    path = Path(path)
    if not path.is_file():
        raise AssetError(f"mesh file not found: {path}")
    if path.suffix.lower() not in MESH_SUFFIXES:
        raise AssetError(f"{path}: unsupported mesh format {path.suffix!r} (supported: {sorted(MESH_SUFFIXES)})")
    file_scale, file_up = 1.0, "Y_UP" if path.suffix.lower() in {".obj", ".gltf", ".glb"} else "Z_UP"
    if path.suffix.lower() == ".dae":
        file_scale, file_up = read_collada_unit(path)
    from aias_augment.assets.references import ConfinedResolver, check_gltf_references

    if path.suffix.lower() in (".gltf", ".glb"):
        check_gltf_references(path)  # external files only from the asset's own folder
    try:
        # no maintain_order: it drops OBJ UVs when vt != v counts
        loaded = trimesh.load(str(path), process=False, resolver=ConfinedResolver(path))
    except AssetError:
        raise
    except Exception as e:  # trimesh raises many types for broken files
        raise AssetError(f"{path}: failed to load ({type(e).__name__}: {e})") from e
    meshes = _flatten(loaded, path)
    for m in meshes:
        _renderable_textures(m.visual, path)
    pad_mesh_textures(meshes)  # no atlas background bleeding in at the UV islands' borders
    s = file_scale * (1.0 if scale is None else scale)
    R = axis_rotation_to_z_up(up_axis or file_up)
    for m in meshes:
        m.apply_transform(R)
        m.apply_scale(s)
    return meshes


#: The texture slots of trimesh's materials (SimpleMaterial, PBRMaterial) that the renderer uploads.
_TEXTURE_SLOTS = (
    "image",
    "baseColorTexture",
    "metallicRoughnessTexture",
    "normalTexture",
    "occlusionTexture",
    "emissiveTexture",
)


def _renderable_textures(visual, path: Path) -> None:
    """Convert the material's textures in place to 8-bit RGB or RGBA, the layouts the renderer takes for every
    slot: grey+alpha (``LA``, e.g. MetaDrive's ``vehicle/130``), palette, greyscale, CMYK and 16-bit/float images
    would otherwise be accepted here and fail at every render. An image that cannot be converted is an
    :class:`AssetError` naming the file."""
    material = getattr(visual, "material", None)
    if material is None:
        return
    from PIL import Image

    for slot in _TEXTURE_SLOTS:
        img = getattr(material, slot, None)
        if not isinstance(img, Image.Image) or img.mode in ("RGB", "RGBA"):
            continue
        try:
            if img.mode in ("I", "I;16", "I;16B", "I;16L", "F"):  # high bit depth: scaled to its own 8-bit range
                a = np.asarray(img, dtype=np.float64)
                lo, hi = (float(a.min()), float(a.max())) if a.size else (0.0, 1.0)
                a = np.round(255.0 * (a - lo) / (hi - lo)) if hi > lo else np.zeros_like(a)
                img = Image.fromarray(a.astype(np.uint8)).convert("RGB")
            else:
                alpha = img.mode in ("LA", "La", "PA", "RGBa") or "transparency" in img.info
                img = img.convert("RGBA" if alpha else "RGB")
        except (OSError, ValueError) as e:
            raise AssetError(
                f"{path}: texture {slot!r} of mode {img.mode!r} cannot be converted to RGB(A) ({e})"
            ) from e
        setattr(material, slot, img)


#: Crease angle (deg) of the vertex normals made at asset load (:func:`crease_normals`): faces meeting at a vertex
#: whose normals differ by less than this are shaded as one smooth surface, sharper edges stay sharp. A 24-sided cone's
#: neighbouring sides differ by 15 deg (smooth), its base rim by ~70-90 deg (sharp); a cube's faces by 90 deg (flat).
CREASE_ANGLE_DEG = 40.0


#: Above this many (corner, corner) pairs at shared positions (the sum over positions of corners^2) the crease pass
#: is skipped and the file's (or trimesh's) normals are kept, with a warning (a pathological file: thousands of faces
#: at one point).
_MAX_CREASE_PAIRS = 50_000_000


def crease_normals(mesh: trimesh.Trimesh, crease_deg: float = CREASE_ANGLE_DEG) -> trimesh.Trimesh:
    """A copy of ``mesh`` with angle-thresholded smooth vertex normals (same faces, in the same order).

    Each face corner gets the corner-angle-weighted mean of the normals of every face touching the same *position*
    (vertices split by UV or normal seams count as one) whose normal is within ``crease_deg`` of this face's normal;
    a vertex whose corners end up with different normals (a crease) is split into one vertex per normal, carrying
    its UV / colour. So a tessellated cone or cylinder is smooth along its side and sharp at its rims, a cube keeps
    flat faces. Angle weighting makes the normal independent of how a face fan is triangulated (Thuermer &
    Wuethrich 1998). trimesh's ``smooth_shade`` groups whole faces into patches through the face adjacency of merged
    vertices, which UV seams break (the cone's side would stay faceted at every texture seam), hence this per-corner
    version. Degenerate faces get their vertices' previous normals.
    """
    import trimesh

    v = np.asarray(mesh.vertices, dtype=np.float64)
    f = np.asarray(mesh.faces, dtype=np.int64)
    if len(f) == 0:
        return mesh.copy(include_cache=True)
    tri = v[f]
    cross = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    length = np.linalg.norm(cross, axis=1)
    diag = float(np.linalg.norm(np.ptp(v, axis=0)))
    valid = length > 1e-14 * max(diag, 1e-30) ** 2  # eps: zero-area faces have no normal
    fn = np.where(valid[:, None], cross / np.maximum(length, 1e-300)[:, None], 0.0)
    weight = np.nan_to_num(trimesh.triangles.angles(tri)) * valid[:, None]  # (F, 3) corner angles
    # one id per position (vertices within 1e-7 of the bounding-box diagonal are the same point)
    q = np.round(v / max(diag * 1e-7, 1e-30)).astype(np.int64)
    _, pos = np.unique(q, axis=0, return_inverse=True)
    corner_pos = pos.reshape(-1)[f].reshape(-1)  # (3F,)
    corner_face = np.repeat(np.arange(len(f)), 3)
    order = np.argsort(corner_pos, kind="stable")
    cp = corner_pos[order]
    starts = np.r_[0, np.flatnonzero(np.diff(cp)) + 1]
    counts = np.diff(np.r_[starts, len(cp)])
    if int(np.sum(counts.astype(np.int64) ** 2)) > _MAX_CREASE_PAIRS:
        log.warning("crease normals skipped: %d corners at one position (file normals kept)", int(counts.max()))
        return mesh.copy(include_cache=True)
    group = np.repeat(np.arange(len(starts)), counts)  # group of each sorted corner
    c = counts[group]
    i = np.repeat(np.arange(len(cp)), c)  # pairs (i, j) within a group
    j = starts[group][i] + (np.arange(len(i)) - np.repeat(np.cumsum(c) - c, c))
    fi, fj = corner_face[order][i], corner_face[order][j]
    keep = np.einsum("ij,ij->i", fn[fi], fn[fj]) >= np.cos(np.radians(crease_deg))
    contrib = fn[fj[keep]] * weight.reshape(-1)[order][j[keep]][:, None]
    target = order[i[keep]]
    n = np.stack([np.bincount(target, contrib[:, k], minlength=3 * len(f)) for k in range(3)], axis=1)
    n_len = np.linalg.norm(n, axis=1)
    old = np.asarray(mesh.vertex_normals, dtype=np.float64)[f.reshape(-1)]
    n = np.where(n_len[:, None] > 1e-12, n / np.maximum(n_len, 1e-300)[:, None], old)  # eps: degenerate faces
    # one vertex per (original vertex, normal): corners of one vertex with the same face set sum in the same order,
    # so their normals are bitwise equal; the rounding only merges what differs by float noise
    key = np.c_[f.reshape(-1), np.round(n * 1e6).astype(np.int64)]
    _, first, inverse = np.unique(key, axis=0, return_index=True, return_inverse=True)
    src = f.reshape(-1)[first]
    visual = None
    kind = getattr(mesh.visual, "kind", None)
    if isinstance(mesh.visual, trimesh.visual.TextureVisuals):
        uv = getattr(mesh.visual, "uv", None)
        uv = None if uv is None or len(uv) != len(v) else np.asarray(uv)[src]
        visual = trimesh.visual.TextureVisuals(uv=uv, material=mesh.visual.material)
    elif kind == "vertex":
        visual = trimesh.visual.ColorVisuals(vertex_colors=np.asarray(mesh.visual.vertex_colors)[src])
    elif kind == "face":
        visual = trimesh.visual.ColorVisuals(face_colors=np.asarray(mesh.visual.face_colors))
    out = trimesh.Trimesh(
        v[src],
        inverse.reshape(-1, 3),
        vertex_normals=n[first],
        visual=visual,
        process=False,
        metadata=copy.deepcopy(mesh.metadata),
    )
    return out


def normalise_meshes(
    meshes: list[trimesh.Trimesh], crease_deg: float | None = CREASE_ANGLE_DEG
) -> tuple[trimesh.Trimesh, ...]:
    """Centre x/y on the bounding box and put the lowest point on z = 0; vertex normals smoothed up to the crease
    angle ``crease_deg`` (:func:`crease_normals`; None: the meshes' normals are kept, e.g. analytic ones)."""
    b = np.array([m.bounds for m in meshes])
    lo, hi = b[:, 0].min(0), b[:, 1].max(0)
    ext = hi - lo
    if not np.all(np.isfinite(ext)) or ext.max() <= 0:
        raise AssetError("mesh has degenerate (zero-size) bounds")
    shift = -np.array([(lo[0] + hi[0]) / 2, (lo[1] + hi[1]) / 2, lo[2]])
    out = []
    for m in meshes:
        c = crease_normals(m, crease_deg) if crease_deg is not None else m.copy(include_cache=True)
        c.apply_translation(shift)  # keeps the vertex normals (a plain copy would recompute them)
        out.append(c)
    return tuple(out)


def gazebo_visual_mesh(model_dir: Path) -> tuple[Path, float]:
    sdf = model_dir / "model.sdf"
    root = ET.parse(sdf).getroot()
    mesh_el = root.find(".//visual//mesh") or root.find(".//mesh")
    if mesh_el is None or mesh_el.find("uri") is None:
        raise AssetError(f"{sdf}: no <mesh><uri> in a visual")
    uri = mesh_el.find("uri").text.strip()
    rel = uri.split("model://", 1)[-1].split("/", 1)[-1]
    scale_el = mesh_el.find("scale")
    scale = 1.0
    if scale_el is not None and scale_el.text:
        s = [float(v) for v in scale_el.text.split()]
        if len(set(s)) != 1:
            log.warning("%s: non-uniform scale %s, using the mean", sdf, s)
        scale = float(np.mean(s))
    return model_dir / rel, scale

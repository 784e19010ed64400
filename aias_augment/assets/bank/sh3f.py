"""Importer for Sweet Home 3D furniture catalogs (``*.sh3f``: zip of OBJ+MTL+textures and
``PluginFurnitureCatalog.properties``), e.g. Debian's ``sweethome3d-furniture`` in ``/usr/share/sweethome3d/furniture``.

Conventions of the format (as Sweet Home 3D applies them): the model is Y-up; the optional ``modelRotation`` (9 numbers,
row-major 3x3) is applied first; the rotated model's bounding box is then stretched to exactly ``width`` (x),
``height`` (y) and ``depth`` (z), given in centimetres. We do the same, then convert to the canonical frame
(metres, z up: (x, y, z)_sh3d -> (x, -z, y)), so an asset's extents equal the catalog's (width, depth, height).
"""

from __future__ import annotations

import logging
import re
import tempfile
import zipfile
from functools import lru_cache
from pathlib import Path, PurePosixPath

import numpy as np
import trimesh

from aias_augment.assets.asset import AssetError, normalise_meshes
from aias_augment.assets.bank.catalog import CatalogRecord
from aias_augment.assets.bank.meshio import load_raw_parts, missing_obj_textures
from aias_augment.assets.bank.taxonomy import Taxonomy
from aias_augment.assets.bank.validate import repair_parts

log = logging.getLogger(__name__)

__all__ = [
    "DEFAULT_SH3F_DIR",
    "parse_properties",
    "read_sh3f_catalog",
    "find_sh3f_files",
    "load_sh3f_parts",
    "IMPORTER_VERSION",
]

DEFAULT_SH3F_DIR = Path("/usr/share/sweethome3d/furniture")
IMPORTER_VERSION = 1
CM_TO_M = 0.01
_ESCAPES = {"t": "\t", "n": "\n", "r": "\r", "f": "\f"}


def _unescape(s: str) -> str:
    out, i = [], 0
    while i < len(s):
        c = s[i]
        if c == "\\" and i + 1 < len(s):
            n = s[i + 1]
            if n == "u" and re.fullmatch(r"[0-9a-fA-F]{4}", s[i + 2 : i + 6] or ""):
                out.append(chr(int(s[i + 2 : i + 6], 16)))
                i += 6
                continue
            out.append(_ESCAPES.get(n, n))
            i += 2
            continue
        out.append(c)
        i += 1
    return "".join(out)


def parse_properties(text: str) -> dict[str, str]:
    """Parse Java ``.properties`` text (comments, ``=``/``:``/space separators, continuations, ``\\uXXXX``)."""
    props: dict[str, str] = {}
    lines = text.splitlines()
    i = 0
    while i < len(lines):
        line = lines[i].lstrip()
        i += 1
        if not line or line[0] in "#!":
            continue
        # continuation: an odd number of trailing backslashes joins the next line (its leading blanks dropped)
        while (len(line) - len(line.rstrip("\\"))) % 2 == 1 and i <= len(lines):
            nxt = lines[i].lstrip() if i < len(lines) else ""
            line = line[:-1] + nxt
            i += 1
        m = re.match(r"((?:\\.|[^=:\s\\])*)\s*[=:\s]?\s*(.*)$", line, re.DOTALL)
        if m:
            props[_unescape(m.group(1))] = _unescape(m.group(2))
    return props


def find_sh3f_files(directory: str | Path = DEFAULT_SH3F_DIR) -> list[Path]:
    d = Path(directory)
    return sorted(d.glob("*.sh3f")) if d.is_dir() else []


@lru_cache(maxsize=8)
def _zip(path: str) -> zipfile.ZipFile:
    return zipfile.ZipFile(path)


def _floats(s: str | None, key: str, where: str) -> list[float] | None:
    if s is None:
        return None
    try:
        vals = [float(v) for v in s.replace(",", " ").split()]
    except ValueError as e:
        raise ValueError(f"{where}: bad number in {key}={s!r}") from e
    return vals


def read_sh3f_catalog(path: str | Path, taxonomy: Taxonomy) -> tuple[list[CatalogRecord], list[str]]:
    """Catalog records of one ``.sh3f`` from its properties alone (no mesh is loaded) and the skipped entries' reasons."""
    path = Path(path)
    try:
        zf = _zip(str(path))
        raw = zf.read("PluginFurnitureCatalog.properties")
    except (zipfile.BadZipFile, KeyError, OSError) as e:
        raise AssetError(f"{path}: not a furniture catalog ({type(e).__name__}: {e})") from e
    props = parse_properties(raw.decode("iso-8859-1"))  # Java properties files are ISO-8859-1 with \\u escapes
    licence = props.get("license", "").strip() or "see LICENSE.TXT in " + path.name
    members = set(zf.namelist())
    indices = sorted({int(m.group(1)) for k in props if (m := re.fullmatch(r"id#(\d+)", k))})
    records, skipped, seen = [], [], set()
    for n in indices:
        where = f"{path.name} entry #{n}"
        get = lambda key: props.get(f"{key}#{n}")  # noqa: E731
        model = get("model")
        try:
            if not model:
                raise ValueError("no model")
            member = model.lstrip("/")
            if member not in members:
                raise ValueError(f"model {model!r} not in the archive")
            dims_cm = [float(get(k)) for k in ("width", "depth", "height")]
            if not all(np.isfinite(dims_cm)) or min(dims_cm) <= 0:
                raise ValueError(f"non-positive size {dims_cm} cm")
            rot = _floats(get("modelRotation"), "modelRotation", where)
            if rot is not None and len(rot) != 9:
                raise ValueError(f"modelRotation needs 9 numbers, got {len(rot)}")
        except (TypeError, ValueError) as e:
            skipped.append(f"{where}: {e}")
            continue
        name = (get("name") or PurePosixPath(member).stem).strip()
        tags = tuple(t.strip() for t in (get("tags") or "").split(",") if t.strip())
        src_cat = (get("category") or "").strip()
        rid = f"sh3f:{get('id') or path.stem + '#' + str(n)}"
        if rid in seen:
            rid = f"{rid}~{n}"
        seen.add(rid)
        records.append(
            CatalogRecord(
                id=rid,
                name=name,
                category=taxonomy.classify(name, tags, src_cat),
                dimensions_m=tuple(d * CM_TO_M for d in dims_cm),
                importer="sh3f",
                source=f"{path}!{member}",
                licence=licence,
                creator=(get("creator") or "").strip(),
                source_category=src_cat,
                tags=tags,
                params={
                    "archive": str(path),
                    "member": member,
                    "model_rotation": rot,
                    "door_or_window": (get("doorOrWindow") or "false").lower() == "true",
                },
            )
        )
    return records, skipped


def _extract_model(zf: zipfile.ZipFile, member: str, dest: Path) -> Path:
    """Extract the model's folder (OBJ, MTL, textures) into ``dest``; returns the OBJ path."""
    folder = str(PurePosixPath(member).parent)
    prefix = "" if folder in ("", ".") else folder + "/"
    for info in zf.infolist():
        name = info.filename
        if info.is_dir() or not name.startswith(prefix) or (not prefix and "/" in name):
            continue
        target = (dest / name).resolve()
        if not str(target).startswith(str(dest.resolve())):  # zip-slip guard
            raise AssetError(f"unsafe path in archive: {name}")
        target.parent.mkdir(parents=True, exist_ok=True)
        target.write_bytes(zf.read(info))
    return dest / member


def sh3d_to_canonical(
    parts: list[trimesh.Trimesh], dims_m: tuple[float, float, float], model_rotation: list[float] | None, where: str
) -> tuple[tuple[trimesh.Trimesh, ...], list[str]]:
    """Apply Sweet Home 3D's rotation and stretch-to-size, then Y-up -> Z-up; result resting on z = 0."""
    notes = []
    R = np.eye(3) if model_rotation is None else np.asarray(model_rotation, np.float64).reshape(3, 3)
    if not np.all(np.isfinite(R)) or abs(abs(np.linalg.det(R)) - 1) > 1e-3:
        raise AssetError(f"{where}: modelRotation is not a rotation (det {np.linalg.det(R):.3g})")
    verts = [np.asarray(p.vertices, np.float64) @ R.T for p in parts]
    allv = np.concatenate(verts)
    lo, hi = allv.min(0), allv.max(0)
    ext = hi - lo
    width, depth, height = dims_m
    target = np.array([width, height, depth])  # sh3d axes: x = width, y = height (up), z = depth
    big = ext.max()
    if not np.isfinite(big) or big <= 0:
        raise AssetError(f"{where}: model has zero size")
    flat = ext < 1e-6 * big  # a flat axis (decals, road markings) cannot be stretched: keep its thickness
    scale = np.where(flat, 1.0, target / np.where(flat, 1.0, ext))
    if flat.any():
        scale[flat] = np.exp(np.mean(np.log(scale[~flat])))
    aniso = float(scale.max() / scale.min())
    if aniso > 1.25:
        notes.append(f"catalog size stretches the model anisotropically (x{aniso:.2f})")
    centre = (lo + hi) / 2
    yup_to_zup = np.array([[1.0, 0, 0], [0, 0, -1.0], [0, 1.0, 0]])  # (x, y, z) -> (x, -z, y)
    out = []
    for p, v in zip(parts, verts):
        v2 = ((v - centre) * scale) @ yup_to_zup.T
        # normals transform with the inverse transpose of the linear map (diag(1/scale), then the axis swap)
        n = np.asarray(p.vertex_normals, np.float64) @ R.T / scale
        n = n @ yup_to_zup.T
        n /= np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-12)  # eps: zero normals stay zero
        q = trimesh.Trimesh(v2, p.faces, vertex_normals=n, visual=p.visual.copy(), process=False)
        out.append(q)
    return normalise_meshes(out), notes


def load_sh3f_parts(record: CatalogRecord) -> tuple[tuple[trimesh.Trimesh, ...], list[str]]:
    """Load, repair and size one catalog model into the canonical frame; returns parts and repair notes."""
    archive, member = record.params["archive"], record.params["member"]
    try:
        zf = _zip(archive)
    except (zipfile.BadZipFile, OSError) as e:
        raise AssetError(f"{archive}: cannot open ({e})") from e
    with tempfile.TemporaryDirectory(prefix="aias_sh3f_") as tmp:
        obj = _extract_model(zf, member, Path(tmp))
        notes = [f"missing texture {t}: diffuse colour used" for t in missing_obj_textures(obj)]
        parts, rep = repair_parts(load_raw_parts(obj), where=record.source)
        notes += rep
        parts, more = sh3d_to_canonical(parts, record.dimensions_m, record.params.get("model_rotation"), record.source)
        # materialise lazily-read textures before the temp folder disappears
        for p in parts:
            img = getattr(getattr(p.visual, "material", None), "image", None)
            if img is not None:
                img.load()
    return parts, notes + more

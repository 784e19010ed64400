"""Texture atlases padded around their UV islands, so that sampling never reads what lies between them.

An atlas packs the parts of a mesh as islands on a background (the shared cone's side is a narrow strip on a dark
grey image). Bilinear filtering and mipmaps average texels across an island's border, so every edge of the strip
brings the background in: dark seams down every facet of the cone. The texels outside every island are never meant
to be seen; each takes the colour of the nearest texel inside an island (the usual "edge padding" of texture bakers),
so filtering at a border averages the island with itself. In an opaque material a texel whose alpha is 0 is
unpainted too (the renderer ignores alpha there and shows its colour: the cone's strip is cut out of a dark image
by alpha, and its UVs reach a few texels past the cut): it is filled the same way. Painted texels are unchanged.
"""

from __future__ import annotations

import cv2
import numpy as np

#: Material slots holding colour images (not normal or roughness maps, where a nearest-colour fill has no meaning).
COLOUR_SLOTS = ("image", "baseColorTexture", "emissiveTexture")


def island_mask(uv: np.ndarray, faces: np.ndarray, height: int, width: int) -> np.ndarray | None:
    """(H, W) bool: the texels that any triangle's UVs cover (conservatively, one texel grown), or None when the UVs
    leave [0, 1] (a tiling texture: no islands to speak of)."""
    uv = np.asarray(uv, np.float64)
    if uv.size == 0 or not np.all(np.isfinite(uv)) or uv.min() < -1e-6 or uv.max() > 1 + 1e-6:
        return None
    shift = 4  # fillPoly's fixed point: 1/16 texel
    xy = np.stack([uv[:, 0] * width - 0.5, (1.0 - uv[:, 1]) * height - 0.5], axis=1)
    tris = np.round(xy[np.asarray(faces)] * (1 << shift)).astype(np.int32)
    mask = np.zeros((height, width), np.uint8)
    cv2.fillPoly(mask, list(tris), 1, lineType=cv2.LINE_8, shift=shift)
    cv2.polylines(mask, list(tris), True, 1, lineType=cv2.LINE_8, shift=shift)  # thin triangles keep their texels
    return cv2.dilate(mask, np.ones((3, 3), np.uint8)).astype(bool)


def pad_islands(image: np.ndarray, inside: np.ndarray) -> np.ndarray:
    """``image`` (H, W[, C]) with every texel outside ``inside`` set to the nearest inside texel's value."""
    if inside.all() or not inside.any():
        return image
    _, labels = cv2.distanceTransformWithLabels(
        (~inside).astype(np.uint8), cv2.DIST_L2, 5, labelType=cv2.DIST_LABEL_PIXEL
    )
    # DIST_LABEL_PIXEL numbers the zero (inside) texels 1.. in row-major order
    flat_inside = np.flatnonzero(inside.ravel())
    src = flat_inside[labels.ravel() - 1]
    flat = image.reshape(inside.size, -1)
    return flat[src].reshape(image.shape)


def pad_mesh_textures(meshes) -> int:
    """Pad the colour textures of ``meshes`` (trimesh, in place) around the UV islands of every mesh that uses
    each image; returns how many images were padded. Images whose users' UVs tile are left as they are."""
    from PIL import Image

    users: dict[int, tuple] = {}
    for m in meshes:
        visual = getattr(m, "visual", None)
        material = getattr(visual, "material", None)
        uv = getattr(visual, "uv", None)
        if material is None or uv is None or len(uv) != len(m.vertices):
            continue
        for slot in COLOUR_SLOTS:
            img = getattr(material, slot, None)
            if isinstance(img, Image.Image):
                entry = users.setdefault(id(img), (img, []))
                entry[1].append((material, slot, np.asarray(uv), np.asarray(m.faces)))
    padded = 0
    for img, uses in users.values():
        w, h = img.size
        masks = [island_mask(uv, faces, h, w) for _, _, uv, faces in uses]
        if any(mk is None for mk in masks):
            continue
        inside = np.logical_or.reduce(masks)
        arr = np.asarray(img)
        if img.mode == "RGBA" and all(_opaque(material) for material, _, _, _ in uses):
            inside &= arr[..., 3] > 0
        new = Image.fromarray(pad_islands(arr, inside))
        for material, slot, _, _ in uses:
            setattr(material, slot, new)
        padded += 1
    return padded


def _opaque(material) -> bool:
    """Whether the renderer ignores the texture's alpha: a glTF/PBR material whose alpha mode is opaque (the default)."""
    mode = getattr(material, "alphaMode", None)
    return type(material).__name__ == "PBRMaterial" and mode in (None, "OPAQUE")

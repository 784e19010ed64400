"""Atlas padding. Truths: texels a mesh's UVs never reach, and unpainted (alpha 0) texels of an opaque material, are
never meant to be seen, so after padding no filtered sample of an island can take their colour; painted texels keep
their values; tiling UVs and alpha-blended materials are left alone."""

import numpy as np
import pytest
import trimesh
from PIL import Image
from trimesh.visual.material import PBRMaterial

from aias_augment.assets.texture import island_mask, pad_islands, pad_mesh_textures

ORANGE = (219, 68, 20, 255)


def _strip_quad(alpha_mode=None, uv_scale=1.0):
    """A quad whose UVs cover columns 24-40 of a 64x64 texture; only columns 26-37 are painted (alpha 255), the rest
    is dark and transparent, like the shared cone's atlas."""
    tex = np.zeros((64, 64, 4), np.uint8)
    tex[..., :3] = 25
    tex[:, 26:38] = ORANGE
    u0, u1 = 24 / 64, 40 / 64
    uv = np.array([[u0, 0.0], [u1, 0.0], [u1, 1.0], [u0, 1.0]]) * uv_scale
    mesh = trimesh.Trimesh(
        vertices=[[0, 0, 0], [1, 0, 0], [1, 0, 1], [0, 0, 1]], faces=[[0, 1, 2], [0, 2, 3]], process=False
    )
    material = PBRMaterial(baseColorTexture=Image.fromarray(tex, "RGBA"), alphaMode=alpha_mode)
    mesh.visual = trimesh.visual.TextureVisuals(uv=uv, material=material)
    return mesh, tex


def test_an_opaque_atlas_is_padded_from_its_painted_texels():
    mesh, before = _strip_quad()
    assert pad_mesh_textures([mesh]) == 1
    after = np.asarray(mesh.visual.material.baseColorTexture)
    assert np.array_equal(after[:, 26:38], before[:, 26:38])  # painted texels unchanged
    assert (after[..., :3] == ORANGE[:3]).all()  # nothing dark left anywhere a filter could reach


def test_tiling_uvs_and_blended_alpha_are_left_alone():
    tiled, before = _strip_quad(uv_scale=2.0)
    assert pad_mesh_textures([tiled]) == 0
    assert np.array_equal(np.asarray(tiled.visual.material.baseColorTexture), before)
    blended, before = _strip_quad(alpha_mode="BLEND")
    pad_mesh_textures([blended])
    after = np.asarray(blended.visual.material.baseColorTexture)
    assert np.array_equal(after[:, 24:40], before[:, 24:40])  # the cut-out inside the island is kept


def test_island_mask_and_nearest_fill_by_hand():
    uv = np.array([[0.25, 0.25], [0.75, 0.25], [0.5, 0.75]])
    mask = island_mask(uv, np.array([[0, 1, 2]]), 16, 16)
    assert mask[8, 8] and not mask[0, 0] and not mask[15, 15]
    img = np.zeros((4, 4), np.uint8)
    img[1, 1], img[2, 2] = 10, 20
    inside = img > 0
    out = pad_islands(img, inside)
    assert out[0, 0] == 10 and out[3, 3] == 20 and out[1, 1] == 10 and out[2, 2] == 20


def test_the_shared_cone_renders_without_dark_seams_on_its_side():
    """The cone's side is painted orange and white only (max channel >= 219 in every painted texel), so no rendered
    pixel of its side can be dark: unpadded, the atlas's dark background showed as lines down every facet."""
    from aias_augment.apply.render import linear_to_srgb, render_object
    from aias_augment.assets.asset import DEFAULT_ASSETS, load_asset
    from aias_augment.core.config import data_root
    from aias_augment.core.geometry import (
        Intrinsics,
        invert_rigid,
        make_rigid,
        rotation_about_axis,
        transform_points,
        unproject_points,
    )

    path = data_root() / DEFAULT_ASSETS["traffic_cone"][0]
    if not path.exists():
        pytest.skip("shared meshes not available")
    cone = load_asset(path, category="traffic_cone", name="cone")
    K = Intrinsics.from_fov(480, 640, 40.0)
    for yaw_deg in (0, 40, 80):
        T = make_rigid(
            rotation_about_axis([1, 0, 0], np.radians(100)) @ rotation_about_axis([0, 0, 1], np.radians(yaw_deg)),
            [0, 0.1, 2.2],
        )
        rl = render_object(cone, T, K, ssaa=2)
        ys, xs = np.nonzero(rl.alpha > 0.99)
        height = transform_points(invert_rigid(T), unproject_points(np.c_[xs, ys].astype(float), rl.depth[ys, xs], K.K))
        side = height[:, 2] > 0.15 * cone.height_m  # above the base
        brightest = np.clip(linear_to_srgb(rl.albedo_linear[ys, xs][side]), 0, 1).max(1) * 255
        assert side.sum() > 10000 and brightest.min() >= 120 and (brightest < 150).mean() < 1e-3

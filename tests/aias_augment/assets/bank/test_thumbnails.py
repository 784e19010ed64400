"""Rendering bank assets: road objects render at their catalog size; thumbnails and the contact sheet."""

import numpy as np
import pytest

from aias_augment.apply.render import render_object
from aias_augment.assets.bank import AssetBank
from aias_augment.assets.bank.cache import MeshCache
from aias_augment.assets.bank.thumbnails import contact_sheet, framing_camera, look_at_cam_from_object
from aias_augment.core.geometry import invert_rigid, transform_points, unproject_points

ROAD_IDS = ["sh3f:Scopia#cone", "sh3f:Scopia#stroller", "sh3f:Scopia#dog", "sh3f:Blend Swap CC-0#rock1"]


@pytest.fixture(scope="module")
def bank(sh3f_records, tmp_path_factory):
    recs = [sh3f_records[i] for i in ROAD_IDS]
    return AssetBank(recs, MeshCache(tmp_path_factory.mktemp("cache")))


def test_look_at_axes():
    T = look_at_cam_from_object(np.array([0.0, -5.0, 0.0]), np.zeros(3))
    # looking along +y: object +x is image right (cam +x), object +z is image up (cam -y), target 5 m ahead
    np.testing.assert_allclose(T[:3, :3] @ [1, 0, 0], [1, 0, 0], atol=1e-12)
    np.testing.assert_allclose(T[:3, :3] @ [0, 0, 1], [0, -1, 0], atol=1e-12)
    np.testing.assert_allclose(transform_points(T, np.zeros((1, 3)))[0], [0, 0, 5], atol=1e-12)


def _rendered_points_in_object(asset, azimuth, elevation):
    from aias_augment.apply.render import render_object

    cam_from_object, intr = framing_camera(asset, 320, azimuth_deg=azimuth, elevation_deg=elevation, fov_deg=8)
    layers = render_object(asset, cam_from_object, intr, with_normals=False, znear=0.1)
    v, u = np.nonzero(layers.mask)
    pts_cam = unproject_points(np.c_[u, v].astype(float), layers.depth[v, u], intr.K)
    return transform_points(invert_rigid(cam_from_object), pts_cam), layers


@pytest.mark.parametrize("record_id", ROAD_IDS)
def test_road_objects_render_at_catalog_size(bank, record_id):
    """Surface points seen by the renderer (depth unprojected from 4 sides and the top) span the catalog's
    width x depth x height: the import, the cache round trip and the render agree on the real size."""
    asset = bank.load(record_id)  # first load imports and caches
    bank._memo.clear()
    asset = bank.load(record_id)  # ... this one comes from the cache
    dims = np.array(bank.record(record_id).dimensions_m)
    pts = np.concatenate(
        [_rendered_points_in_object(asset, az, el)[0] for az, el in ((0, 0), (90, 0), (180, 0), (270, 0), (0, 89))]
    )
    measured = pts.max(0) - pts.min(0)
    np.testing.assert_allclose(measured, dims, rtol=0.04, atol=0.01)
    assert abs(pts[:, 2].min()) < 0.01  # rests on the ground plane z = 0


def test_contact_sheet(bank):
    sheet, ok = contact_sheet(bank, ROAD_IDS[:2] + ["sh3f:Scopia#cone"], tile_px=64, columns=2, render=render_object)
    assert ok == 3 and sheet.shape == (2 * (64 + 28), 128, 3) and sheet.dtype == np.uint8
    tile = sheet[:64, :64].astype(int)
    # the cone is red and white: its tile has strongly red pixels; the background is light grey
    assert ((tile[..., 0] - tile[..., 1]) > 80).sum() > 20
    assert np.all(sheet[92:, 64:] == 255)  # the unused 4th tile and its label stay white

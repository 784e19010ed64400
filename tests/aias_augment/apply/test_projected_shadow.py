import numpy as np
import pytest

from aias_augment.apply.projected_shadow import projected_ground_shadow
from aias_augment.apply.render import render_ground_shadow, render_object_window
from aias_augment.core.geometry import Intrinsics, make_rigid
from tests.aias_augment.fixtures import box_asset

K = Intrinsics.from_fov(640, 480, 60.0)
R_UP = np.array([[1.0, 0, 0], [0, 0, -1], [0, 1, 0]])


def _pose(x, z, yaw):
    c, s = np.cos(yaw), np.sin(yaw)
    return make_rigid(R_UP @ np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]]), [x, 1.6, z])


def _assets():
    out = [box_asset(extents=(0.5, 0.4, 0.9))]
    try:
        from aias_augment.assets.asset import default_asset

        out.append(default_asset("traffic_cone").scaled(1.0))
    except Exception:  # shared data not present: the box alone
        pass
    return out


def _ray_cast_shadow(asset, T, sun, layers, where):
    """(h, w) bool: ground pixels (``where``) whose ray toward the sun hits a triangle (Moller-Trumbore)."""
    vv, uu = np.nonzero(where)
    d = layers.ground_depth[vv, uu]
    x0, y0 = layers.roi[:2]
    pc = np.stack([(uu + x0 - K.cx) / K.fx * d, (vv + y0 - K.cy) / K.fy * d, d], -1)
    po = (pc - T[:3, 3]) @ T[:3, :3]
    po[:, 2] = 1e-4  # just above the ground
    tri = np.concatenate([np.asarray(m.triangles) for m in asset.meshes])
    v0, e1, e2 = tri[:, 0], tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]
    pvec = np.cross(sun, e2)
    det = (e1 * pvec).sum(-1)
    ok = np.abs(det) > 1e-12
    inv = np.where(ok, 1.0 / np.where(ok, det, 1.0), 0.0)
    hit = np.zeros(len(po), bool)
    for s0 in range(0, len(po), 2000):
        tv = po[s0 : s0 + 2000, None, :] - v0[None]
        u = (tv * pvec[None]).sum(-1) * inv
        q = np.cross(tv, e1[None])
        v = (q * sun).sum(-1) * inv
        t = (q * e2[None]).sum(-1) * inv
        hit[s0 : s0 + 2000] = (ok & (u >= 0) & (v >= 0) & (u + v <= 1) & (t > 1e-6)).any(1)
    out = np.zeros(where.shape, bool)
    out[vv[hit], uu[hit]] = True
    return out


# Suns in front of the camera (the shadow falls toward it, so that it is seen): low right, low left, high (near
# object only: from 9 m a high sun's shadow is a few dozen pixels, mostly hidden by the object).
@pytest.mark.parametrize(
    "pose, sun_cam",
    [
        ((-1.0, 6.0, 0.3), (0.5, -0.6, 0.3)),
        ((-1.0, 6.0, 0.3), (-0.7, -0.5, 0.4)),
        ((-1.0, 6.0, 0.3), (0.2, -0.9, 0.25)),
        ((1.2, 9.0, 1.1), (0.5, -0.6, 0.3)),
        ((1.2, 9.0, 1.1), (-0.7, -0.5, 0.4)),
    ],
)
def test_projected_shadow_matches_the_shadow_catcher(pose, sun_cam):
    """Same window and ground geometry as the GL catcher; shadow IoU >= 0.8 on the ground the camera sees
    (pixels the object covers excluded: the catcher has no ground there)."""
    for asset in _assets():
        T = _pose(*pose)
        sun = T[:3, :3].T @ (np.array(sun_cam) / np.linalg.norm(sun_cam))
        ref = render_ground_shadow(asset, T, K, sun, window=True)
        fast = projected_ground_shadow(asset, T, K, sun)
        assert fast.roi == ref.roi
        assert (fast.ground_mask == ref.ground_mask).mean() > 0.99  # differences: the patch's rasterised edge
        both = fast.ground_mask & ref.ground_mask
        assert np.abs(fast.ground_depth[both] - ref.ground_depth[both]).max() < 0.02 * ref.ground_depth[both].max()
        oroi, ol = render_object_window(asset, T, K, ssaa=1, with_normals=False)
        covered = np.zeros(ref.ground_mask.shape, bool)
        x0, y0 = oroi[0] - ref.roi[0], oroi[1] - ref.roi[1]
        covered[y0 : y0 + ol.alpha.shape[0], x0 : x0 + ol.alpha.shape[1]] = ol.alpha > 0
        m = both & ~covered
        a, b = (ref.visibility < 0.5) & m, (fast.visibility < 0.5) & m
        assert a.sum() > 50, "the reference shadow must be visible for the test to mean something"
        iou = (a & b).sum() / (a | b).sum()
        assert iou >= 0.8, (asset.name, iou)
        # And against the exact answer: a ray from each ground pixel toward the sun, tested against every triangle.
        exact = _ray_cast_shadow(asset, T, sun, fast, m)
        b_iou = ((exact & b).sum()) / (exact | b).sum()
        assert b_iou >= 0.95, (asset.name, b_iou)


def test_sun_below_horizon_casts_no_shadow():
    T = _pose(0.0, 6.0, 0.0)
    s = projected_ground_shadow(box_asset(), T, K, np.array([0.3, 0.2, -0.5]))
    assert s.ground_mask.any() and (s.visibility == 1).all()


def test_ground_points_are_the_pixels_rays_on_the_ground_plane():
    """projected_ground's object-frame x, y of each ground-patch pixel: the pixel's ray (from K) scaled by the
    patch's z-depth, taken into the object frame by the inverse pose, lies on z = 0 at that x, y."""
    from aias_augment.apply.projected_shadow import projected_ground

    T = _pose(0.4, 7.0, 0.6)
    layers, xy = projected_ground(box_asset(extents=(0.5, 0.4, 0.9)), T, K, np.array([0.3, -0.2, 0.8]))
    vv, uu = np.nonzero(layers.ground_mask)
    assert len(xy) == len(vv) > 100
    d = layers.ground_depth[vv, uu].astype(np.float64)
    x0, y0 = layers.roi[:2]
    pc = np.stack([(uu + x0 - K.cx) / K.fx * d, (vv + y0 - K.cy) / K.fy * d, d], -1)
    po = (pc - T[:3, 3]) @ T[:3, :3]
    np.testing.assert_allclose(po[:, 2], 0.0, atol=1e-5)  # float32 depth: ~1e-7 relative
    np.testing.assert_allclose(xy, po[:, :2], atol=1e-5)


def test_family_cone_shadow_reads_its_geometry_not_its_texture():
    """A family cone's projected shadow comes from its geometry alone: the same triangles as its built, textured
    mesh gives, bit for bit (all of them: trimesh finds that mesh open), and its full texture is never drawn."""
    from aias_augment.apply.projected_shadow import shadow_triangles
    from aias_augment.assets.bank.procedural import procedural_asset_from_seed

    sun = np.array([0.3, -0.5, 0.81])
    sun /= np.linalg.norm(sun)
    for seed in (3, 8):
        a = procedural_asset_from_seed("traffic_cone", seed)
        s = a.scaled(1.2)
        tri = shadow_triangles(s, sun)
        assert a.meshes._texture is None and a.meshes._built is None
        built = procedural_asset_from_seed("traffic_cone", seed).meshes[0]  # the textured mesh
        assert not built.is_watertight  # so a mesh's shadow reads every triangle, as the family cone's does
        ref = np.asarray(built.triangles) * 1.2
        ref = ref - np.minimum(np.clip(ref[..., 2:3], 0.0, None) / sun[2], 60.0) * sun
        np.testing.assert_array_equal(tri, ref)
        assert len(tri) > 100

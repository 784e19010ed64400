"""The ray-cast procedural cone (apply/cone_raycast.py): its depth against the analytic surface, its layers against
the GL render of the same mesh, scaled assets, the cases it leaves to the mesh, and the fast preset's calls."""

import numpy as np
import pytest

from aias_augment.apply.cone_raycast import cone_shape, raycast_cone, raycast_cone_window
from aias_augment.apply.render import render_object_window
from aias_augment.assets.bank.procedural import procedural_asset_from_seed
from aias_augment.core.geometry import Intrinsics, make_rigid
from tests.aias_augment.fixtures import box_asset

K = Intrinsics(700.0, 700.0, 320.0, 240.0, 640, 480)


def _look_at(centre, target=(0.0, 0.0, 0.35)):
    """cam_from_object of an upright OpenCV camera at ``centre`` (object frame) looking at ``target``."""
    c = np.asarray(centre, float)
    f = np.asarray(target, float) - c
    f /= np.linalg.norm(f)
    r = np.cross(f, [0.0, 0.0, 1.0])
    r /= np.linalg.norm(r)
    R = np.stack([r, np.cross(f, r), f])
    return make_rigid(R, -R @ c)


def _view(dist, elev_deg, az_deg):
    e, a = np.radians(elev_deg), np.radians(az_deg)
    return _look_at([dist * np.cos(e) * np.cos(a), dist * np.cos(e) * np.sin(a), dist * np.sin(e)])


def _random_views(seed, n, *, first, dist_m, max_elev_deg):
    """``n`` (family cone, cam_from_object) pairs: cones ``first``, ``first + 1``, ... at log-uniform distances in
    ``dist_m``, from 3 deg below the base up to ``max_elev_deg``, all round."""
    rng = np.random.default_rng(seed)
    for i in range(n):
        dist = float(np.exp(rng.uniform(np.log(dist_m[0]), np.log(dist_m[1]))))
        T = _view(dist, float(rng.uniform(-3.0, max_elev_deg)), float(rng.uniform(0.0, 360.0)))
        yield procedural_asset_from_seed("traffic_cone", first + i), T


def _radius_at(shape, z):
    return float(np.interp(z, shape.body_z, shape.body_r))


def test_depth_on_the_body_is_the_analytic_surface():
    """A level camera's central pixel column crosses the body where x = r(z) on the camera's side: the ray through
    the projection of that point gives its depth (independent of the renderer: the profile and a projection)."""
    a = procedural_asset_from_seed("traffic_cone", 3)
    shape = cone_shape(a)
    T = _look_at([4.0, 0.0, 0.35], target=(0.0, 0.0, 0.35))  # level, on the +x axis: the body's silhouette centre
    roi, layers = raycast_cone_window(a, T, K, ssaa=1)
    x0, y0 = roi[:2]
    checked = 0
    for z in np.linspace(shape.zb + 0.05, shape.body_z[-1] - 0.08, 6):
        p = np.array([_radius_at(shape, z), 0.0, z])
        pc = T[:3, :3] @ p + T[:3, 3]
        u, v = K.fx * pc[0] / pc[2] + K.cx, K.fy * pc[1] / pc[2] + K.cy
        iu, iv = int(round(u)), int(round(v))
        # the pixel centre's ray meets the surface within a pixel's height of z: depth within that slope's change
        got = layers.depth[iv - y0, iu - x0]
        assert got == pytest.approx(pc[2], abs=0.004), (z, got, pc[2])
        n = layers.normals_in_cam[iv - y0, iu - x0]
        assert n[2] < -0.9  # the body faces the camera there
        checked += 1
    assert checked == 6


def test_tip_and_base_project_where_the_geometry_says():
    """The topmost row the cone touches holds the tip's projection, the lowest the base's front corner's (within a pixel)."""
    a = procedural_asset_from_seed("traffic_cone", 11)
    shape = cone_shape(a)
    T = _view(5.0, 15.0, 30.0)
    roi, layers = raycast_cone_window(a, T, K, ssaa=2)
    rows = np.nonzero((layers.alpha > 0).any(1))[0] + roi[1]

    def v_of(p):
        pc = T[:3, :3] @ np.asarray(p, float) + T[:3, 3]
        return K.fy * pc[1] / pc[2] + K.cy

    assert rows.min() == pytest.approx(v_of([0.0, 0.0, shape.height]), abs=1.0)
    base = shape.polygon
    lowest = max(v_of([x, y, 0.0]) for x, y in base)
    assert rows.max() == pytest.approx(lowest, abs=1.0)


@pytest.mark.parametrize("seed", [0, 2, 5, 8])
def test_layers_match_the_gl_render_of_the_mesh(seed):
    """The same cone through the GL renderer (its mesh and texture): coverage IoU >= 0.95, albedo within 3 sRGB
    levels on average, normals within 1 deg (median) where both cover the pixel fully, depth within 1 cm (median)."""
    a = procedural_asset_from_seed("traffic_cone", seed)
    T = _view(3.0 + seed * 0.7, 6.0 + 4 * seed, 23.0 * seed)
    roi_g, g = render_object_window(a, T, K, ssaa=2)
    roi_c, c = raycast_cone_window(a, T, K, ssaa=2)
    assert roi_g == roi_c
    mg, mc = g.alpha > 0.5, c.alpha > 0.5
    assert (mg & mc).sum() / (mg | mc).sum() >= 0.95
    both = (g.alpha > 0.99) & (c.alpha > 0.99)

    def srgb(x):
        return np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.clip(x, 0, None) ** (1 / 2.4) - 0.055) * 255

    assert np.abs(srgb(g.albedo_linear[both]) - srgb(c.albedo_linear[both])).mean() <= 3.0
    cos = np.clip((g.normals_in_cam[both] * c.normals_in_cam[both]).sum(-1), -1, 1)
    assert np.median(np.degrees(np.arccos(cos))) <= 1.0
    assert np.median(np.abs(g.depth[both] - c.depth[both])) <= 0.01


def test_a_near_cone_over_many_ray_chunks_matches_the_gl_render():
    """A cone filling much of the frame (its rays in several chunks, some chunks hitting nothing): the coverage is
    the GL render's (IoU >= 0.98)."""
    from aias_augment.apply import cone_raycast

    a = procedural_asset_from_seed("traffic_cone", 6)
    T = _view(1.1, 10.0, 15.0)
    roi_g, g = render_object_window(a, T, K, ssaa=2)
    roi_c, c = raycast_cone_window(a, T, K, ssaa=2)
    assert (roi_c[2] - roi_c[0]) * (roi_c[3] - roi_c[1]) * 4 > 2 * cone_raycast.CHUNK_RAYS
    mg, mc = g.alpha > 0.5, c.alpha > 0.5
    assert (mg & mc).sum() / (mg | mc).sum() >= 0.98


def test_a_scaled_cone_is_the_root_scaled():
    """A scaled asset at a scaled pose is the same image: coverage identical, depth times the scale."""
    a = procedural_asset_from_seed("traffic_cone", 4)
    T = _view(4.0, 12.0, 40.0)
    T2 = T.copy()
    T2[:3, 3] *= 1.6
    roi1, l1 = raycast_cone_window(a, T, K)
    roi2, l2 = raycast_cone_window(a.scaled(1.6), T2, K)
    assert roi1 == roi2
    np.testing.assert_allclose(l2.alpha, l1.alpha)
    np.testing.assert_allclose(l2.depth, 1.6 * l1.depth, rtol=1e-5)


def test_left_to_the_mesh():
    """Not a procedural cone, a deformed one, or a cone reaching behind the camera: None (the mesh is rendered)."""
    assert raycast_cone(box_asset(extents=(0.5, 0.4, 0.9)), _view(4.0, 10.0, 0.0), K) is None
    a = procedural_asset_from_seed("traffic_cone", 1)
    from aias_augment.assets.asset import Asset

    bent = Asset(a.name, a.category, a.meshes, a.source, a.licence, True, {**a.meta, "deformation": {"p": 1}})
    assert raycast_cone(bent, _view(4.0, 10.0, 0.0), K) is None
    assert raycast_cone(a, _look_at([0.05, 0.0, 0.3], target=(1.0, 0.0, 0.3)), K) is None
    off = _view(4.0, 10.0, 0.0)
    off[0, 3] += 50.0  # far off to the side: an empty window
    got = raycast_cone(a, off, K)
    assert got is not None and got.alpha.size == 0


def test_fast_preset_ray_casts_its_cones_and_replays():
    """The fast preset's procedural cones are ray-cast (the record says so) and a replay of the record gives the same
    bytes."""
    from aias_augment.core.frame import Frame
    from aias_augment.pipeline.image import insert_into_image, load_preset
    from aias_augment.pipeline.replay import replay
    from tests.aias_augment.pipeline.test_image import road_frame

    img = road_frame()
    cfg = load_preset("fast", categories=("traffic_cone",), min_objects=2, max_objects=2)
    res = insert_into_image(img, np.zeros((0, 4)), [], np.random.default_rng(5), cfg)
    assert len(res.inserted_bboxes) >= 1
    render = res.record.modules["render"]
    assert render.startswith("ray cast: 2 of 2"), render
    again = replay(res.record.to_dict(), Frame(img, None), cfg)
    np.testing.assert_array_equal(again.image, res.image)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_the_body_solved_per_segment_span_equals_every_segment_for_every_ray(seed):
    """Solving a body segment only for the rays whose path inside the bounding cylinder reaches its heights gives
    the hits of solving every segment for every ray, bit for bit: from above, below the top, level with the body,
    inside its height range and looking straight down."""
    from aias_augment.apply.cone_raycast import _body_hits, _meets_cylinder, _Rays

    shape = cone_shape(procedural_asset_from_seed("traffic_cone", seed))
    rng = np.random.default_rng(seed)
    for origin in ([3.0, -1.0, 1.6], [0.5, 2.5, 0.3], [-4.0, 0.2, 0.5 * shape.height], [0.01, 0.0, 2.0]):
        o = np.asarray(origin, float)
        target = np.c_[rng.uniform(-0.3, 0.3, (20000, 2)), rng.uniform(-0.1, shape.height + 0.1, 20000)]
        d = target - o
        d[:50] = (0.0, 0.0, -1.0)  # vertical rays
        d[50:100, 2] = 0.0  # level rays
        rays = _Rays.of(o, d)
        meets, span = _meets_cylinder(rays, float(shape.body_r.max()), shape.zb, shape.height, with_span=True)
        sub = rays.subset(meets)
        full = _body_hits(sub, shape)
        culled = _body_hits(sub, shape, (span[0][meets], span[1][meets]))
        assert np.isfinite(full).sum() > 1000
        np.testing.assert_array_equal(culled, full)
        assert np.isinf(_body_hits(rays.subset(~meets), shape)).all()  # the cylinder test misses no body hit


@pytest.mark.parametrize("seed", [0, 1])
def test_outline_supersampling_keeps_the_coverage_of_supersampling_everywhere(seed, monkeypatch):
    """Supersampling only the outline (forced on every window, far small cones included) gives each pixel the
    coverage that ``ssaa`` x ``ssaa`` rays in every pixel give, exactly: near cones cut by the image's edge, far
    cones seen level (the base's rim a strip under a pixel tall), steep views. Where both cover a pixel fully, on
    the windows that take the outline pass by default, the centre sample reads what the four sub-samples average
    (the same texels): per cone within 3 sRGB levels on average (one bilinear sample of the grain against the mean
    of four), its mean within 2 levels (interpolating in sRGB before decoding darkens slightly), depth within 1 mm
    (median)."""
    from aias_augment.apply import cone_raycast

    default_min = cone_raycast.ADAPTIVE_MIN_PIXELS
    monkeypatch.setattr(cone_raycast, "ADAPTIVE_MIN_PIXELS", 0)

    def srgb(x):
        return np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.clip(x, 0, None) ** (1 / 2.4) - 0.055) * 255

    checked = 0
    for a, T in _random_views(seed, 40, first=200 + 40 * seed, dist_m=(1.2, 70.0), max_elev_deg=80.0):
        (roi, ref), (roi_got, got) = raycast_cone_window(a, T, K, everywhere=True), raycast_cone_window(a, T, K)
        assert roi == roi_got
        np.testing.assert_array_equal(got.alpha, ref.alpha)
        full = ref.alpha == 1
        if full.size < default_min or full.sum() < 20:
            continue
        diff = srgb(got.albedo_linear[full]) - srgb(ref.albedo_linear[full])
        assert np.abs(diff).mean() <= 3.0
        assert -2.0 <= diff.mean() <= 1.0
        assert np.median(np.abs(got.depth[full] - ref.depth[full])) <= 1e-3
        checked += 1
    assert checked >= 10


@pytest.mark.parametrize("seed", [0, 1])
def test_the_projected_hulls_hold_every_ray_that_meets_the_cone(seed, monkeypatch):
    """Only the grid points inside the cone's projected hulls are cast; casting the whole grid finds no hit outside
    them (near and far, below and far above the base, cut by the image's edge), and the layers are the same,
    bit for bit, as casting every point."""
    from aias_augment.apply import cone_raycast

    cast_in_mask = 0
    for a, T in _random_views(seed, 30, first=300 + 30 * seed, dist_m=(1.0, 40.0), max_elev_deg=85.0):
        shape, R, s = cone_shape(a), T[:3, :3], 1.0
        roi = raycast_cone_window(a, T, K)[0]
        Kw = cone_raycast.crop_intrinsics(K, roi)
        us, vs = np.arange(roi[2] - roi[0], dtype=float), np.arange(roi[3] - roi[1], dtype=float)
        mask = cone_raycast._hull_mask(shape, R, T[:3, 3] / s, Kw, us, vs)
        if mask is None:
            continue
        origin = -R.T @ T[:3, 3]
        tex = cone_raycast._texture_level(shape, 100.0)
        hits = cone_raycast._cast(shape, origin, cone_raycast._ray_dirs(Kw, R, us, vs, grid=True), tex, R, T[:3, 3], s)
        assert mask.ravel()[hits[0]].all()
        cast_in_mask += len(hits[0])
        monkeypatch.setattr(cone_raycast, "HULL_MIN_RAYS", 0)
        culled = raycast_cone_window(a, T, K)[1]
        monkeypatch.setattr(cone_raycast, "HULL_MIN_RAYS", 1 << 62)
        whole = raycast_cone_window(a, T, K)[1]
        for f in ("alpha", "albedo_linear", "normals_in_cam", "depth"):
            np.testing.assert_array_equal(getattr(culled, f), getattr(whole, f))
    assert cast_in_mask > 10000

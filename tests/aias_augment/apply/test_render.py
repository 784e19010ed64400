import numpy as np
import pytest

from aias_augment.apply.render import render_ground_shadow, render_object, render_object_window
from aias_augment.core.geometry import Intrinsics, make_rigid, project_points, transform_points
from tests.aias_augment.fixtures import box_asset

K = Intrinsics(600.0, 600.0, 319.5, 239.5, 640, 480)
# Object z-up -> camera -y (up), object y -> camera +z (away): a level camera looking at an upright object.
R_UPRIGHT = np.array([[1.0, 0, 0], [0, 0, -1], [0, 1, 0]])


def _box_of_corners(asset, T):
    uv, _ = project_points(transform_points(T, asset.corners_m()), K.K)
    # Analytic box of the silhouette in pixel-edge coordinates: pixel centres are integers, edges at +-0.5.
    return uv[:, 0].min() + 0.5, uv[:, 1].min() + 0.5, uv[:, 0].max() + 0.5, uv[:, 1].max() + 0.5


@pytest.mark.parametrize(
    "pose",
    [
        make_rigid(R_UPRIGHT, [0.3, 0.8, 5.0]),
        make_rigid(R_UPRIGHT, [-1.0, 0.2, 8.0]),
    ],
)
def test_mask_box_matches_analytic_projection_within_1px(pose):
    from aias_augment.apply.annotate import mask_box_xywh

    a = box_asset(extents=(0.5, 0.5, 1.2))
    layers = render_object(a, pose, K, ssaa=1)
    x, y, w, h = mask_box_xywh(layers.mask)
    ex0, ey0, ex1, ey1 = _box_of_corners(a, pose)
    assert np.allclose([x, y, x + w, y + h], [ex0, ey0, ex1, ey1], atol=1.0)


def test_depth_and_normals_are_metric_and_unit():
    a = box_asset(extents=(1.0, 1.0, 1.0))
    pose = make_rigid(R_UPRIGHT, [0.0, 0.5, 4.0])  # front face (object -y) at camera z = 4 - 0.5 = 3.5
    layers = render_object(a, pose, K, ssaa=1)
    c = layers.depth[240, 320]
    assert abs(c - 3.5) < 0.01
    n = layers.normals_in_cam[240, 320]
    assert np.allclose(n, [0, 0, -1], atol=0.05)  # the front face looks back at the camera
    assert layers.depth[~layers.mask].max() == 0


def test_albedo_is_linear_texture_colour():
    a = box_asset(color=(188, 188, 188))
    layers = render_object(a, make_rigid(R_UPRIGHT, [0, 0.5, 4.0]), K)
    # sRGB 188 -> linear ((188/255 + 0.055)/1.055)^2.4 = 0.5029
    assert np.allclose(layers.albedo_linear[layers.mask].mean(0), 0.5029, atol=0.01)


def test_supersampling_gives_fractional_edges_same_box():
    a = box_asset()
    pose = make_rigid(R_UPRIGHT, [0.1, 0.5, 5.0])
    l1, l3 = render_object(a, pose, K, ssaa=1), render_object(a, pose, K, ssaa=3)
    assert ((l3.alpha > 0) & (l3.alpha < 1)).sum() > 0
    assert abs(l1.alpha.sum() - l3.alpha.sum()) / l1.alpha.sum() < 0.03


def test_shadow_falls_where_planar_projection_says():
    """Independent check: a box's shadow on z=0 under a directional sun is the convex hull of its vertices
    projected along the sun direction onto the plane."""
    import cv2

    a = box_asset(extents=(0.4, 0.4, 1.0))
    cam_from_obj = make_rigid(np.array([[1.0, 0, 0], [0, -0.5, -0.866], [0, 0.866, -0.5]]) @ np.eye(3), [0, 0, 0])
    # Camera 3 m above the ground looking down 30 deg: build cam_from_obj from a look-at.
    eye = np.array([0.0, -6.0, 3.0])
    fwd = -eye / np.linalg.norm(eye)
    right = np.cross(fwd, [0, 0, 1.0])
    right /= np.linalg.norm(right)
    down = np.cross(fwd, right)
    R = np.stack([right, down, fwd])  # rows: camera axes in object coordinates
    cam_from_obj = make_rigid(R, -R @ eye)
    sun = np.array([0.6, 0.3, 0.74])
    sun /= np.linalg.norm(sun)
    s = render_ground_shadow(a, cam_from_obj, K, sun)
    verts = a.meshes[0].vertices
    flat = verts - (verts[:, 2:3] / sun[2]) * sun
    uv, _ = project_points(transform_points(cam_from_obj, flat), K.K)
    hull = cv2.convexHull((uv + 0.5).astype(np.float32)).astype(np.int32)
    expected = np.zeros((K.height, K.width), np.uint8)
    cv2.fillConvexPoly(expected, hull, 1)
    body = render_object(a, cam_from_obj, K, ssaa=1).mask
    got = (s.visibility < 0.5) & ~body
    exp = expected.astype(bool) & ~body
    iou = (got & exp).sum() / max((got | exp).sum(), 1)
    assert exp.sum() > 200 and iou > 0.8, iou


def test_sun_below_horizon_casts_no_shadow():
    a = box_asset()
    s = render_ground_shadow(a, make_rigid(R_UPRIGHT, [0, 1.5, 5.0]), K, np.array([1.0, 0.0, -0.1]))
    assert np.all(s.visibility == 1.0) and np.isfinite(s.visibility).all()


def test_nan_pose_is_a_clear_error():
    with pytest.raises(ValueError, match="NaN"):
        render_object(box_asset(), np.full((4, 4), np.nan), K)


def _cone_cases():
    """The shared-data traffic cone (textured) at three scales and poses, lit by a sun that casts their shadows."""
    from aias_augment.assets.asset import default_asset
    from aias_augment.core.geometry import Intrinsics

    k = Intrinsics.from_fov(837, 1024, 60.0)
    rup = np.array([[1.0, 0, 0], [0, 0, -1], [0, 1, 0]])

    def pose(x, z, yaw):
        c, s = np.cos(yaw), np.sin(yaw)
        return make_rigid(rup @ np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]]), [x, 1.6, z])

    sun_cam = np.array([0.5, -0.6, 0.3]) / np.linalg.norm([0.5, -0.6, 0.3])
    try:
        base = default_asset("traffic_cone")
    except Exception as e:  # shared data not present
        pytest.skip(f"traffic cone asset unavailable: {e}")
    cases = [
        (base.scaled(0.9), pose(-1.0, 6.0, 0.3)),
        (base.scaled(1.1), pose(1.5, 9.0, 1.0)),
        (base.scaled(1.0), pose(0.2, 4.0, 2.0)),
    ]
    return k, [(a, T, T[:3, :3].T @ sun_cam) for a, T in cases]


def test_shadow_catcher_does_not_depend_on_what_was_rendered_before():
    """Same inputs -> the same bytes, whatever the process rendered before (pyrender draws the nodes of a scene in
    the order of a set hashed by object address: ground and object must not tie in that order)."""
    k, cases = _cone_cases()
    ref = [render_ground_shadow(a, T, k, sun).visibility for a, T, sun in cases]
    assert all((v < 0.5).any() for v in ref)  # each object casts a shadow, so the test can fail
    for rep in range(6):
        for a, T, _ in cases[rep % 3 :]:
            render_object(a, T, k, ssaa=1 + rep % 2)
        order = [0, 1, 2] if rep % 2 == 0 else [2, 1, 0]
        for i in order:
            a, T, sun = cases[i]
            assert np.array_equal(render_ground_shadow(a, T, k, sun).visibility, ref[i]), (rep, i)


def test_scaled_asset_renders_as_if_its_mesh_were_scaled():
    """The renderer scales a cached mesh through the node pose: the result must equal a render of a mesh whose
    vertices were scaled (a fresh asset, not derived with Asset.scaled)."""
    import trimesh

    from aias_augment.assets.asset import Asset, normalise_meshes

    a = box_asset(extents=(0.4, 0.6, 1.0))
    pose = make_rigid(R_UPRIGHT, [0.2, 0.8, 5.0])
    m = trimesh.creation.box(extents=(0.8, 1.2, 2.0))
    m.visual.face_colors = np.array([200, 60, 20, 255], np.uint8)
    direct = render_object(Asset("box2", "box", normalise_meshes([m]), "tests"), pose, K, ssaa=2)
    render_object(a, pose, K, ssaa=2)  # the unscaled root is rendered (and cached) first
    via_pose = render_object(a.scaled(2.0), pose, K, ssaa=2)
    assert via_pose.alpha.sum() > 1000
    assert np.abs(via_pose.alpha - direct.alpha).max() < 1e-6
    assert np.abs(via_pose.depth - direct.depth).max() < 1e-4
    assert np.abs(via_pose.albedo_linear - direct.albedo_linear).max() < 1e-6
    assert np.abs(via_pose.normals_in_cam - direct.normals_in_cam).max() < 1e-3


def test_a_textured_asset_is_uploaded_once_across_its_two_passes(monkeypatch):
    """The albedo and normals passes keep each other's meshes resident: repeated renders of one asset upload its
    texture at most once (a counter on pyrender's real upload), and give the same bytes as the first."""
    import pyrender.texture

    try:
        from aias_augment.assets.asset import default_asset

        cone = default_asset("traffic_cone")
    except Exception:
        pytest.skip("shared data not present")
    if not any(getattr(m.visual, "kind", None) == "texture" for m in cone.meshes):
        pytest.skip("default cone has no texture")
    uploads = []
    real = pyrender.texture.Texture._add_to_context

    def counting(self, *a, **k):
        uploads.append(1)
        return real(self, *a, **k)

    monkeypatch.setattr(pyrender.texture.Texture, "_add_to_context", counting)
    K = Intrinsics.from_fov(320, 240, 60.0)
    T = make_rigid(np.array([[1.0, 0, 0], [0, 0, -1], [0, 1, 0]]), [0.0, 0.5, 4.0])
    first = render_object_window(cone, T, K, ssaa=2)
    n_first = len(uploads)
    for _ in range(3):
        again = render_object_window(cone, T, K, ssaa=2)
    assert n_first <= 1 and len(uploads) == n_first
    assert np.array_equal(first[1].albedo_linear, again[1].albedo_linear)
    assert np.array_equal(first[1].normals_in_cam, again[1].normals_in_cam)


def test_a_process_that_rendered_can_still_build_a_torch_optimizer():
    """Regression: on llvmpipe, importing Triton after the first render crashed the interpreter (two LLVMs; torch
    imports Triton from torch.optim.Adam through torch._dynamo). A fresh interpreter renders, then builds Adam and
    steps it: it must exit normally."""
    import subprocess
    import sys
    import textwrap

    pytest = __import__("pytest")
    pytest.importorskip("torch")
    code = textwrap.dedent("""
        import numpy as np
        from aias_augment.assets.asset import default_asset
        from aias_augment.core.geometry import Intrinsics
        from aias_augment.apply.render import render_object
        K = Intrinsics(300.0, 300.0, 63.5, 63.5, 128, 128)
        T = np.eye(4); T[:3, :3] = [[1, 0, 0], [0, 0, -1], [0, 1, 0]]; T[:3, 3] = [0, 0.3, 3]
        assert render_object(default_asset("traffic_cone"), T, K, ssaa=1).alpha.max() > 0.5
        import torch
        p = torch.nn.Parameter(torch.ones(3))
        opt = torch.optim.Adam([p], lr=0.1)
        (p ** 2).sum().backward()
        opt.step()
        assert float(p.detach().max()) < 1.0
        print("stepped")
    """)
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr[-2000:]
    assert "stepped" in r.stdout


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
@pytest.mark.parametrize("channels", [(), (1,), (3,), (4,)])
def test_the_block_mean_is_numpys_reduction_bit_for_bit(dtype, channels):
    """``_downsample`` gives the numbers of ``reshape(h, s, w, s, ...).mean(axis=(1, 3))`` exactly (the supersampled
    layers of every render read it), at s = 2 on odd and even, thin and wide grids, values over six decades, and at
    s = 3 and on a non-contiguous view."""
    from aias_augment.apply.render import _downsample

    rng = np.random.default_rng(len(channels) + (dtype is np.float64))
    for h, w in [(1, 1), (1, 2), (2, 1), (3, 5), (64, 1), (1, 300), (17, 255), (120, 64)]:
        for s in (2, 3):
            shape = (s * h, s * w, *channels)
            x = (rng.random(shape) * 10 ** rng.uniform(-3, 3, shape)).astype(dtype)
            want = x.reshape(h, s, w, s, *channels).mean(axis=(1, 3))
            got = _downsample(x, s)
            assert got.dtype == want.dtype
            np.testing.assert_array_equal(got, want)
            view = np.ascontiguousarray(x[::-1])[::-1]  # the same values through a reversed (non-contiguous) view
            np.testing.assert_array_equal(_downsample(view, s), want)

import numpy as np
import pytest
import trimesh

from aias_augment.assets.asset import Asset, AssetError, PathAssets, default_asset, load_asset, read_collada_unit
from aias_augment.assets.bank.procedural import procedural_asset_from_seed
from aias_augment.core.config import data_root
from aias_augment.core.geometry import project_points, transform_points

GAZEBO = data_root() / "meshes" / "gazebo_models"
needs_data = pytest.mark.skipif(not GAZEBO.exists(), reason="shared data not present")


@needs_data
def test_collada_units_are_read_from_the_file():
    assert read_collada_unit(GAZEBO / "construction_cone" / "meshes" / "construction_cone.dae") == (0.0254, "Z_UP")
    assert read_collada_unit(GAZEBO / "fire_hydrant" / "meshes" / "fire_hydrant.dae")[0] == 0.01


@needs_data
def test_gazebo_cone_in_metres_resting_on_ground():
    cone = default_asset("traffic_cone")
    lo, hi = cone.bounds_m
    # model.sdf scale 10 x inch (0.0254) -> about 1.09 m (SOURCE.txt), z up, base on z = 0, centred in x/y.
    assert 1.0 < cone.height_m < 1.2
    assert abs(lo[2]) < 1e-9 and np.allclose((lo[:2] + hi[:2]) / 2, 0, atol=1e-9)
    assert cone.extents_m[2] > cone.extents_m[0]  # a cone is taller than wide: the up axis is right


@needs_data
def test_obj_car_scale_from_sdf():
    car = load_asset(GAZEBO / "hatchback", category="car")
    assert 1.2 < car.height_m < 2.0 and 3.0 < car.extents_m.max() < 5.0


def test_bad_mesh_path_gives_clear_error(tmp_path):
    with pytest.raises(AssetError, match="not found"):
        load_asset(tmp_path / "missing.obj")
    bad = tmp_path / "broken.obj"
    bad.write_text("this is not an obj\n")
    with pytest.raises(AssetError):
        load_asset(bad)
    nan = tmp_path / "nan.obj"
    nan.write_text("v 0 0 0\nv 1 0 nan\nv 0 1 0\nf 1 2 3\n")
    with pytest.raises(AssetError, match="non-finite"):
        load_asset(nan)
    with pytest.raises(AssetError, match="unsupported"):
        load_asset(tmp_path / "x.txt") if (tmp_path / "x.txt").write_text("x") else None


def test_scaled_keeps_contact_plane():
    from tests.aias_augment.fixtures import box_asset

    b = box_asset().scaled(2.5)
    assert np.isclose(b.height_m, 2.5) and np.isclose(b.bounds_m[0, 2], 0)
    with pytest.raises(AssetError):
        box_asset().scaled(float("nan"))


def test_scaled_meshes_are_the_vertices_times_the_factor_and_pickle():
    """A scaled asset's meshes (made on first read): each vertex is the original's times the factor, faces shared,
    the bounds the mesh's own; a pickled copy has the same vertices."""
    import pickle

    from tests.aias_augment.fixtures import box_asset

    a = box_asset(extents=(0.5, 0.4, 0.9))
    b = a.scaled(1.7)
    assert len(b.meshes) == len(a.meshes)
    for mb, ma in zip(b.meshes, a.meshes):
        np.testing.assert_allclose(mb.vertices, np.asarray(ma.vertices) * 1.7, rtol=1e-15)
        assert np.array_equal(mb.faces, ma.faces)
    np.testing.assert_allclose(b.bounds_m, np.array([m.bounds for m in b.meshes]).reshape(-1, 2, 3)[0], rtol=1e-12)
    c = pickle.loads(pickle.dumps(b))
    assert np.array_equal(c.meshes[0].vertices, b.meshes[0].vertices)
    assert np.isclose(b.scaled(2.0).meshes[0].vertices.max(), np.asarray(a.meshes[0].vertices).max() * 3.4)


def test_path_assets_pickles_without_meshes(tmp_path):
    import pickle

    (tmp_path / "a.obj").write_text("v 0 0 0\nv 1 0 0\nv 0 1 1\nf 1 2 3\n")
    pa = PathAssets({"box": [str(tmp_path / "a.obj")]})
    assert pickle.loads(pickle.dumps(pa)).paths == pa.paths


def test_path_assets_missing_path_and_unit_guess(tmp_path):
    """Issue 16: a missing mesh is refused at construction; a pedestrian modelled in centimetres (187 units tall)
    is rescaled to 1.87 m with a warning naming the guess."""
    with pytest.raises(AssetError, match="do not exist"):
        PathAssets({"person": [str(tmp_path / "nope.glb")]})
    import trimesh

    trimesh.creation.box(extents=(50, 187, 30)).export(tmp_path / "ped.obj")  # OBJ: y up
    a = PathAssets({"person": [str(tmp_path / "ped.obj")]}).sample("person", np.random.default_rng(0))
    assert np.isclose(a.height_m, 1.87) and "centimetres" in a.meta["unit_guess"]


# --- crease-angle vertex normals (a smooth cone side, a sharp base rim) -------------------------------------------


def _faceted_frustum(n_seg: int, r0: float, r1: float, h: float):
    """A frustum (base radius r0 at z = 0, top r1 at z = h) with a base disk, stored as a file exporter stores a
    textured low-poly model: every side quad has its own 4 vertices (UV seams everywhere), so trimesh's per-vertex
    mean gives flat facets. UV u = azimuth / 2 pi, v = z / h. Returns the mesh and the analytic outward normal of each
    vertex's face group (side: (cos phi, sin phi, (r0 - r1) / h) normalised; base: (0, 0, -1))."""
    import trimesh

    verts, faces, uv, truth = [], [], [], []
    slope = (r0 - r1) / h
    for k in range(n_seg):
        a0, a1 = 2 * np.pi * k / n_seg, 2 * np.pi * (k + 1) / n_seg
        b = len(verts)
        for a, z, r in ((a0, 0, r0), (a1, 0, r0), (a1, h, r1), (a0, h, r1)):
            verts.append([r * np.cos(a), r * np.sin(a), z])
            uv.append([a / (2 * np.pi), z / h])
            nn = np.array([np.cos(a), np.sin(a), slope])
            truth.append(nn / np.linalg.norm(nn))
        faces += [[b, b + 1, b + 2], [b, b + 2, b + 3]]
    c = len(verts)  # base disk: centre + its own rim vertices, facing down
    verts.append([0, 0, 0])
    uv.append([0.5, 0.5])
    truth.append([0, 0, -1])
    for k in range(n_seg):
        a = 2 * np.pi * k / n_seg
        verts.append([r0 * np.cos(a), r0 * np.sin(a), 0])
        uv.append([0.5, 0.5])
        truth.append([0, 0, -1])
    for k in range(n_seg):
        faces.append([c, c + 1 + (k + 1) % n_seg, c + 1 + k])
    mesh = trimesh.Trimesh(
        np.array(verts, float), np.array(faces), process=False, visual=trimesh.visual.TextureVisuals(uv=np.array(uv))
    )
    return mesh, np.array(truth)


def _angle_deg(a, b):
    return np.degrees(np.arccos(np.clip(np.sum(a * b, axis=-1), -1, 1)))


def test_crease_normals_smooth_the_side_of_a_frustum_and_keep_the_rim_sharp():
    from aias_augment.assets.asset import crease_normals

    mesh, truth = _faceted_frustum(96, 0.2, 0.05, 0.7)
    before = _angle_deg(mesh.vertex_normals, truth)
    assert np.median(before[:-97]) > 1.0  # the input is faceted: flat face normals, 1.9 deg off at corners
    out = crease_normals(mesh, 40.0)
    assert len(out.faces) == len(mesh.faces)
    # map each output vertex back to an input vertex by position + UV (the split keeps each corner's UV)
    key_in = {tuple(np.round(np.r_[p, t], 9)): i for i, (p, t) in enumerate(zip(mesh.vertices, mesh.visual.uv))}
    src = np.array([key_in[tuple(np.round(np.r_[p, t], 9))] for p, t in zip(out.vertices, out.visual.uv)])
    n = np.asarray(out.vertex_normals)
    # every face corner: its normal against the analytic normal of the surface that face belongs to
    side = np.arange(len(out.faces)) < 2 * 96
    err_side = _angle_deg(n[out.faces[side]].reshape(-1, 3), truth[src[out.faces[side]]].reshape(-1, 3))
    assert err_side.max() < 0.05  # smooth: the analytic normal at each vertex (to float precision)
    base = n[out.faces[~side]].reshape(-1, 3)
    assert np.allclose(base, [0, 0, -1], atol=1e-12)  # the base stays flat, exactly down: the rim is a crease
    assert np.all(np.isfinite(n)) and np.allclose(np.linalg.norm(n, axis=1), 1)


def test_crease_normals_keep_a_cube_flat_and_a_smooth_mesh_unchanged():
    import trimesh

    from aias_augment.assets.asset import crease_normals

    cube = trimesh.creation.box((1, 2, 3))
    cube.merge_vertices()  # 8 shared corners: trimesh's mean would round every edge
    out = crease_normals(cube, 40.0)
    assert len(out.vertices) == 24  # each corner split into its 3 faces
    corner_n = np.asarray(out.vertex_normals)[out.faces]
    assert np.allclose(corner_n, out.face_normals[:, None, :], atol=1e-12)
    sphere = trimesh.creation.icosphere(subdivisions=3)
    out = crease_normals(sphere, 40.0)
    assert len(out.vertices) == len(sphere.vertices)  # nothing split on a smooth closed surface
    radial = sphere.vertices / np.linalg.norm(sphere.vertices, axis=1, keepdims=True)
    assert _angle_deg(np.asarray(out.vertex_normals), radial).max() < 1.0


@needs_data
def test_gazebo_cone_side_is_smooth_after_load():
    cone = default_asset("traffic_cone")
    m = cone.meshes[0]
    n, fn = np.asarray(m.vertex_normals), np.asarray(m.face_normals)
    side = np.abs(fn[:, 2]) < 0.9  # slanted side faces (not the base's flat top/bottom)
    corner = _angle_deg(n[m.faces[side]], fn[side][:, None, :])
    assert np.median(corner) > 3.0  # corners carry the smooth normal, not the face's (24 sides: 7.5)
    assert corner.max() < 30.0  # never averaged across the base rim
    assert np.allclose(cone.scaled(0.5).meshes[0].vertex_normals, n)  # scaling keeps them


def _grey_alpha_cone(path, mode="LA"):
    """A 0.7 m cone whose texture is a grey ramp (u) in a 2-channel grey+alpha image (MetaDrive's ``vehicle/130``
    ships one), or another non-RGB mode."""
    import trimesh
    from PIL import Image

    m = trimesh.creation.cone(radius=0.2, height=0.7, sections=24)
    uv = np.c_[(m.vertices[:, 0] + 0.2) / 0.4, m.vertices[:, 2] / 0.7]
    grey = np.tile(np.linspace(0, 255, 64).astype(np.uint8), (64, 1))
    tex = (
        Image.fromarray(np.dstack([grey, np.full_like(grey, 200)])).convert(mode)
        if mode == "LA"
        else Image.fromarray(grey).convert(mode)
    )
    m.visual = trimesh.visual.TextureVisuals(uv=uv, material=trimesh.visual.material.SimpleMaterial(image=tex))
    m.export(path)
    return grey


@pytest.mark.parametrize("mode", ["LA", "L", "P"])
def test_textures_the_renderer_cannot_take_are_converted_at_load(tmp_path, mode):
    """A grey+alpha, grey or palette texture loads as RGB(A) whose colour channels are the grey values (and alpha
    kept), and such a mesh is inserted; before, the renderer refused every call ('Cannot reformat 2-channel
    texture')."""
    from aias_augment.pipeline.config import load_preset
    from aias_augment.pipeline.image import insert_into_image

    path = tmp_path / f"cone_{mode}.glb"
    grey = _grey_alpha_cone(path, mode)
    a = load_asset(path, category="traffic_cone", scale=1.0)
    mat = a.meshes[0].visual.material  # a GLB loads as PBR: its base colour texture
    img = getattr(mat, "baseColorTexture", None) or mat.image
    rgba = np.asarray(img)
    assert img.mode == ("RGBA" if mode == "LA" else "RGB")
    assert rgba.shape[:2] == grey.shape
    assert np.array_equal(rgba[..., 0], rgba[..., 1]) and np.array_equal(rgba[..., 1], rgba[..., 2])
    # where the UVs reach (outside them the loader pads the atlas: tests/aias_augment/assets/test_texture.py)
    from aias_augment.assets.texture import island_mask

    seen = island_mask(a.meshes[0].visual.uv, a.meshes[0].faces, *grey.shape)
    assert seen.mean() > 0.3
    assert np.abs(rgba[..., 0].astype(int) - grey)[seen].max() <= (0 if mode != "P" else 8)
    if mode == "LA":
        assert np.all(rgba[..., 3] == 200)
    road = np.full((240, 320, 3), 170, np.uint8)
    road[120:] = 90
    res = insert_into_image(
        road,
        None,
        None,
        np.random.default_rng(0),
        load_preset("fast"),
        bank=PathAssets({"traffic_cone": [str(path)]}, scales={str(path): 1.0}),
        n_objects=1,
    )
    assert res.inserted_labels == ["traffic_cone"]


def test_path_assets_refuse_unreadable_or_unsizeable_files_at_construction(tmp_path):
    """What can be checked before the first image is: a file that does not parse as a mesh, and a mesh whose height
    no unit makes plausible for its category, are errors naming the file when PathAssets is built (before, each
    was a skip at every later call)."""
    import trimesh

    from aias_augment.adapters.boundary import InputError

    bad = tmp_path / "broken.glb"
    bad.write_bytes(b"glTF\x02\x00\x00\x00garbage")
    with pytest.raises(AssetError, match="broken.glb"):
        PathAssets({"traffic_cone": [str(bad)]})
    trimesh.creation.box(extents=(1, 1e7, 1)).export(tmp_path / "tower.obj")
    with pytest.raises(InputError, match="traffic_cone"):
        PathAssets({"traffic_cone": [str(tmp_path / "tower.obj")]})


def _views(rng, n):
    """``n`` camera-from-object poses looking at the object's middle from 1.5-20 m, 0-80 deg above its base."""
    out = []
    for _ in range(n):
        d, elev, az = rng.uniform(1.5, 20.0), np.radians(rng.uniform(0.0, 80.0)), rng.uniform(0.0, 2 * np.pi)
        eye = d * np.array([np.cos(elev) * np.cos(az), np.cos(elev) * np.sin(az), np.sin(elev)]) + [0, 0, 0.3]
        fwd = np.array([0.0, 0.0, 0.3]) - eye
        fwd /= np.linalg.norm(fwd)
        right = np.cross(fwd, [0.0, 0.0, 1.0])
        right = right / np.linalg.norm(right) if np.linalg.norm(right) > 1e-9 else np.array([1.0, 0.0, 0.0])
        down = np.cross(fwd, right)
        R = np.stack([right, down, fwd])  # rows: the camera's x (right), y (down), z (forward) in the object frame
        T = np.eye(4)
        T[:3, :3], T[:3, 3] = R, -R @ eye
        out.append(T)
    return out


def _projected_box(points, cam_from_object):
    K = np.array([[700.0, 0, 320], [0, 700.0, 240], [0, 0, 1]])
    uv, _ = project_points(transform_points(cam_from_object, points), K)
    return np.r_[uv.min(0), uv.max(0)]


@pytest.mark.parametrize("seed", [0, 1, 7, 42])
def test_the_outline_gives_the_mask_tight_box_of_the_built_mesh(seed):
    """A procedural cone's outline (made from its rings, without the mesh) projects to the box of every vertex of its
    built mesh, in views from 1.5-20 m and 0-80 deg up; its bounding box's corners give a larger box."""
    cone = procedural_asset_from_seed("traffic_cone", seed)
    built = np.concatenate([np.asarray(m.vertices) for m in cone.meshes])
    views = _views(np.random.default_rng(seed), 40)
    for T in views:
        np.testing.assert_allclose(_projected_box(cone.outline_m(), T), _projected_box(built, T), atol=1e-6)
    taller = [np.ptp(_projected_box(cone.corners_m(), T)[1::2]) / np.ptp(_projected_box(built, T)[1::2]) for T in views]
    assert np.median(taller) > 1.02, np.median(taller)
    half = cone.scaled(0.5)
    np.testing.assert_allclose(half.outline_m(), cone.outline_m() * 0.5)


def test_the_outline_of_a_loaded_mesh_is_its_hull():
    """A mesh asset's outline is its convex hull's vertices: the same projected box as all its vertices."""
    rng = np.random.default_rng(3)
    pts = rng.normal(size=(500, 3)) * [0.3, 0.2, 0.4] + [0, 0, 0.5]
    mesh = trimesh.convex.convex_hull(pts)
    asset = Asset("blob", "other", (trimesh.Trimesh(pts, np.zeros((0, 3), int), process=False), mesh), "test")
    assert len(asset.outline_m()) < len(pts)
    everything = np.concatenate([pts, mesh.vertices])
    for T in _views(rng, 20):
        np.testing.assert_allclose(_projected_box(asset.outline_m(), T), _projected_box(everything, T), atol=1e-9)

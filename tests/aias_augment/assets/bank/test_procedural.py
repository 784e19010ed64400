import numpy as np
import pytest
import trimesh
from PIL import Image

from aias_augment.assets.bank.procedural import CATEGORY_SPECS, GENERATORS, ProceduralSpec, generate


@pytest.mark.parametrize("gen", sorted(GENERATORS))
def test_generators_are_labelled_sized_and_deterministic(gen):
    spec = ProceduralSpec(gen, "debris", (0.05, 0.3))
    tex = Image.fromarray(np.random.default_rng(0).integers(0, 255, (32, 32, 3)).astype(np.uint8))
    a = generate(spec, np.random.default_rng(7), tex)
    b = generate(spec, np.random.default_rng(7), tex)
    c = generate(spec, np.random.default_rng(8), tex)
    assert a.procedural and a.source == f"procedural:{gen}" and a.meta["textured"]
    assert a.height_m == pytest.approx(a.meta["height_m"], rel=1e-6)
    assert 0.05 <= a.height_m <= 0.3
    assert abs(a.bounds_m[0, 2]) < 1e-9
    np.testing.assert_array_equal(a.meshes[0].vertices, b.meshes[0].vertices)
    assert a.meshes[0].vertices.shape != c.meshes[0].vertices.shape or not np.allclose(
        a.meshes[0].vertices, c.meshes[0].vertices
    )
    m = a.meshes[0]
    assert np.all(np.isfinite(m.vertices)) and m.visual.uv is not None and len(m.visual.uv) == len(m.vertices)
    assert np.all(m.area_faces > 0)


def test_untextured_fallback_and_unknown_generator():
    a = generate(ProceduralSpec("stone", "rock", (0.1, 0.2)), np.random.default_rng(0), None)
    assert a.meshes[0].visual.uv is None and not a.meta["textured"]
    with pytest.raises(ValueError, match="unknown generator"):
        generate(ProceduralSpec("blob", "rock", (0.1, 0.2)), np.random.default_rng(0))


# --- the traffic-cone family --------------------------------------------------------------------------------------

CONE = CATEGORY_SPECS["traffic_cone"]


def _cone(seed):
    return generate(CONE, np.random.default_rng(seed))


def _hsv(rgb_uint8):
    rgb = np.asarray(rgb_uint8, float)[..., :3] / 255.0
    mx, mn = rgb.max(-1), rgb.min(-1)
    return mx, (mx - mn) / np.maximum(mx, 1e-9)  # value, saturation


def test_cone_same_seed_same_mesh_texture_and_meta():
    a, b = _cone(3), _cone(3)
    ma, mb = a.meshes[0], b.meshes[0]
    np.testing.assert_array_equal(ma.vertices, mb.vertices)
    np.testing.assert_array_equal(ma.faces, mb.faces)
    np.testing.assert_array_equal(ma.visual.uv, mb.visual.uv)
    np.testing.assert_array_equal(np.asarray(ma.visual.material.image), np.asarray(mb.visual.material.image))
    assert a.meta == b.meta and a.meta["generator"] == "traffic_cone"
    c = _cone(4)
    assert c.meta != a.meta
    assert not np.array_equal(np.asarray(c.meshes[0].visual.material.image), np.asarray(ma.visual.material.image))


def test_cone_seeds_vary_within_the_real_ranges():
    metas = [_cone(s).meta for s in range(60)]
    heights = np.array([m["height_m"] for m in metas])
    assert heights.min() >= 0.3 and heights.max() <= 1.0 and heights.std() > 0.1
    n_bands = [len(m["bands_z_m"]) for m in metas]
    assert set(n_bands) <= {0, 1, 2, 3} and {1, 2, 3} <= set(n_bands)
    colours = [m["colour"] for m in metas]
    assert colours.count("orange") == max(colours.count(c) for c in set(colours))  # orange dominates
    assert len(set(colours)) >= 3
    assert {m["base_shape"] for m in metas} == {"square", "round"}
    assert len({m["base_colour"] for m in metas}) >= 2
    for m in metas:  # bands lie on the body, in order, without overlap
        z = np.array(m["bands_z_m"]).ravel()
        assert np.all(np.diff(z) > 0) and (len(z) == 0 or (z[0] > m["base_height_m"] and z[-1] < m["height_m"]))


@pytest.mark.parametrize("seed", [0, 1, 2, 5])
def test_cone_is_closed_outward_and_smooth(seed):
    a = _cone(seed)
    m = a.meshes[0]
    merged = trimesh.Trimesh(m.vertices, m.faces, process=True)  # creases/UV seam share positions, not vertices
    assert merged.is_watertight and merged.is_winding_consistent
    assert merged.volume > 0  # faces wound outward
    assert np.all(m.area_faces > 0)
    # stored vertex normals agree with the faces' outward normals
    vn = m.vertex_normals
    assert np.all(np.einsum("fkj,fj->fk", vn[m.faces], m.face_normals) > 0)
    # smooth (not faceted) on the body, seam included: each normal's horizontal part points radially outward at
    # its own vertex (a flat 64-gon facet's normal is off by up to 2.8 deg, cos = 0.9988)
    p = a.meta
    z = m.vertices[:, 2]
    body = (z > p["base_height_m"] + 0.01) & (z < p["height_m"] - 2 * p["top_radius_m"])
    xy, nxy = m.vertices[body, :2], vn[body, :2]
    cos = np.sum(xy * nxy, 1) / np.linalg.norm(xy, axis=1) / np.linalg.norm(nxy, axis=1)
    assert body.sum() > 200 and cos.min() > 0.9995


@pytest.mark.parametrize("seed", range(6))
def test_cone_size_matches_its_draws(seed):
    a = _cone(seed)
    v = a.meshes[0].vertices
    p = a.meta
    assert np.ptp(v[:, 2]) == pytest.approx(p["height_m"], abs=1e-9) and v[:, 2].min() == pytest.approx(0, abs=1e-12)
    foot = v[v[:, 2] < 1e-9]  # the contact face: the base outline
    assert np.abs(foot[:, 0]).max() == pytest.approx(p["base_half_width_m"], rel=1e-6)
    r_diag = np.linalg.norm(foot[:, :2], axis=1).max()
    if p["base_shape"] == "square":  # rounded square: corners reach out past the side
        assert r_diag > 1.15 * p["base_half_width_m"]
    else:
        assert r_diag == pytest.approx(p["base_half_width_m"], rel=1e-6)


@pytest.mark.parametrize("seed", [0, 3, 7, 11])
def test_cone_bands_are_where_the_meta_says_in_the_texture(seed):
    a = _cone(seed)
    m, p = a.meshes[0], a.meta
    col = trimesh.visual.color.uv_to_color(m.visual.uv, m.visual.material.image)
    z = m.vertices[:, 2]
    on_body = (z > p["base_height_m"] + 1e-6) & (z < p["height_m"] - 1e-6)
    inside = np.zeros(len(z), bool)
    near = np.zeros(len(z), bool)
    for z0, z1 in p["bands_z_m"]:
        inside |= (z > z0 + 0.005) & (z < z1 - 0.005)
        near |= (z > z0 - 0.01) & (z < z1 + 0.01)
    val, sat = _hsv(col)
    if p["bands_z_m"]:
        assert inside.any() and np.all(sat[inside] < 0.15) and np.all(val[inside] > 0.6)
    body = on_body & ~near
    dirty = p["dirt"] > 0
    assert np.mean(sat[body] > 0.6) > (0.8 if dirty else 0.99)  # the body colour is saturated


def test_cone_bands_render_where_the_meta_says():
    """End to end through pyrender's UV convention: a far, long-lens side view; the pixel column through the axis
    is white at each band's middle height and saturated between bands."""
    from aias_augment.apply.render import render_object
    from aias_augment.core.geometry import Intrinsics, make_rigid

    seed = next(s for s in range(50) if len(_cone(s).meta["bands_z_m"]) >= 2 and _cone(s).meta["dirt"] == 0)
    a = _cone(seed)
    p, h, d = a.meta, a.height_m, 30.0
    f = 300.0 * d / h  # the cone is ~300 px tall
    K = Intrinsics(f, f, 80.0, 200.0, 161, 400)
    R_up = np.array([[1, 0, 0], [0, 0, -1], [0, 1, 0]], float)  # object z -> camera -y
    pose = make_rigid(R_up, np.array([0.0, h / 2, d]))
    L = render_object(a, pose, K, ssaa=1, with_normals=False)
    row = lambda zz: int(round(K.cy - f * (zz - h / 2) / d))  # noqa: E731  (the axis point at height zz)
    px = lambda zz: L.albedo_linear[row(zz), 80]  # noqa: E731
    bands = p["bands_z_m"]
    for z0, z1 in bands:
        c = px((z0 + z1) / 2)
        assert c.min() > 0.5 and c.max() - c.min() < 0.15, c
    for (_, z1), (z0, _) in zip(bands[:-1], bands[1:]):  # between two bands: the body colour
        c = px((z1 + z0) / 2)
        assert c.max() > 0.4 and c.min() < 0.25 * c.max(), c


def test_choose_asset_procedural_draws_a_new_seeded_cone_per_object():
    from aias_augment.pipeline.config import InsertionConfig
    from aias_augment.plan.insertion import choose_asset

    cfg = InsertionConfig(asset_source="procedural")
    rng = np.random.default_rng(9)
    a, b = choose_asset("traffic_cone", rng, cfg), choose_asset("traffic_cone", rng, cfg)
    a2 = choose_asset("traffic_cone", np.random.default_rng(9), cfg)
    assert a.procedural and a.source == "procedural:traffic_cone" and a.meta["seed"] != b.meta["seed"]
    np.testing.assert_array_equal(a.meshes[0].vertices, a2.meshes[0].vertices)
    rebuilt = generate(CONE, np.random.default_rng(a.meta["seed"]))  # the recorded seed rebuilds it
    np.testing.assert_array_equal(a.meshes[0].vertices, rebuilt.meshes[0].vertices)
    with pytest.raises(ValueError, match="asset_source"):
        InsertionConfig(asset_source="procedurally")


def test_cone_mesh_made_on_first_read_with_the_bounds_it_gets():
    """A cone's mesh is made only when read; the bounds known before (from its rings) are the built mesh's, bit
    for bit, over many draws; it pickles as its recipe and rebuilds the same mesh."""
    import pickle

    from aias_augment.assets.bank.procedural import ConeMeshes, procedural_asset_from_seed

    for seed in range(0, 400, 7):
        a = procedural_asset_from_seed("traffic_cone", seed)
        assert isinstance(a.meshes, ConeMeshes) and a.meshes._built is None
        before = a.bounds_m
        assert a.meshes._built is None  # the bounds did not build it
        np.testing.assert_array_equal(before, a.meshes[0].bounds)
    back = pickle.loads(pickle.dumps(a))
    assert back.meshes._built is None
    np.testing.assert_array_equal(back.meshes[0].vertices, a.meshes[0].vertices)
    np.testing.assert_array_equal(
        np.asarray(back.meshes[0].visual.material.image), np.asarray(a.meshes[0].visual.material.image)
    )


def test_raycast_cone_does_not_build_the_mesh():
    from aias_augment.apply.cone_raycast import raycast_cone
    from aias_augment.assets.bank.procedural import procedural_asset_from_seed
    from aias_augment.core.geometry import Intrinsics

    a = procedural_asset_from_seed("traffic_cone", 11)
    s = a.scaled(1.3)
    T = np.eye(4)
    T[:3, :3] = [[1, 0, 0], [0, 0, -1], [0, 1, 0]]  # object z up -> camera -y (image up)
    T[:3, 3] = [0.0, 0.5, 6.0]
    assert raycast_cone(s, T, Intrinsics(500.0, 500.0, 320.0, 240.0, 640, 480)) is not None
    assert a.meshes._built is None


@pytest.mark.parametrize("seed", [1, 2, 5, 8])
def test_cone_texture_level_is_the_full_textures_mipmap(seed):
    """A level drawn directly is the full texture area-averaged (what a mipmap holds): the same cone (rows' colours,
    bands, blotches, scuffs), texel by texel close to the average, its grain with the average's spread; a
    different cone is far from it."""
    import cv2

    from aias_augment.assets.bank.procedural import CONE_TEXTURE_SIZE, cone_texture, procedural_asset_from_seed

    tw, th = CONE_TEXTURE_SIZE
    m = procedural_asset_from_seed("traffic_cone", seed).meshes
    other = procedural_asset_from_seed("traffic_cone", seed + 100).meshes
    full = cone_texture(m.params, m.height)
    for k in (1, 2, 3, 5):
        size = (tw >> k, th >> k)
        level = cone_texture(m.params, m.height, None, size)
        mip = cv2.resize(full, size, interpolation=cv2.INTER_AREA)
        assert level.shape == (th >> k, tw >> k, 3) and level.min() >= 0 and level.max() <= 1
        diff = level - mip
        assert np.abs(diff).mean() < 0.01
        assert np.abs(level.mean(1) - mip.mean(1)).max() < 0.03  # every row's colour (bands, base, dirt)
        # what is left is grain (about the average's spread: 0.015 / 2^k of the colour, two draws) and, at the
        # coarsest levels, band edges averaged before the clip to [0, 1] instead of after
        assert diff.std() < 0.015 * 2.0 / 2**k + 0.01
        far = cv2.resize(cone_texture(other.params, other.height), size, interpolation=cv2.INTER_AREA)
        assert np.abs(level - far).mean() > 3 * np.abs(diff).mean()
    with pytest.raises(ValueError, match="texture size"):
        cone_texture(m.params, m.height, None, (tw * 2, th))


def test_raycast_cone_texture_levels_are_powers_of_two_made_once():
    """The ray cast reads the smallest power-of-two level with a texel per sample; a cone seen again at a nearby
    size reads the same level (no new grain: a clip does not flicker)."""
    from aias_augment.apply.cone_raycast import _texture_level, cone_shape
    from aias_augment.assets.bank.procedural import CONE_TEXTURE_SIZE, procedural_asset_from_seed

    tw, th = CONE_TEXTURE_SIZE
    shape = cone_shape(procedural_asset_from_seed("traffic_cone", 4))
    rows = th * (shape.body_v[-1] - shape.body_v[0])
    for body_px, k in [
        (2 * rows, 0),
        (rows, 0),
        (0.99 * rows, 0),
        (rows / 2, 1),
        (rows / 2.1, 1),
        (rows / 4.5, 2),
        (0.5, 6),
    ]:
        tex = _texture_level(shape, body_px)
        assert tex.shape[:2] == (th >> k, tw >> k), body_px
        assert tex.dtype == np.float32
    a = _texture_level(shape, rows / 3.0)
    assert _texture_level(shape, rows / 3.5) is a


def test_weighted_index_is_generator_choice_draw_for_draw():
    """The cone's weighted draws take numpy's ``Generator.choice(n, p=...)`` index and consume the same draw of the
    generator, whatever the weights (normalised or not, zeros among them)."""
    from aias_augment.assets.bank.procedural import _weighted_index

    for weights in ([0.15, 0.37, 0.38, 0.10], [0.2, 0.5, 0.3], [0.55, 0.27, 0.06, 0.07, 0.05], [3.0, 0.0, 1.0]):
        p = np.asarray(weights, float)
        for seed in range(300):
            a, b = np.random.default_rng(seed), np.random.default_rng(seed)
            assert _weighted_index(a, weights) == int(b.choice(len(p), p=p / p.sum()))
            assert a.random() == b.random()  # the same state after

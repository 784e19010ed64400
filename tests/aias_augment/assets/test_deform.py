"""Deformed variants: closed where the source was, UVs and faces kept, sizes as the physics says, replay exact."""

import json
import os
from pathlib import Path

import cv2
import numpy as np
import pytest
import trimesh
from PIL import Image

from aias_augment.assets.asset import Asset, PathAssets, normalise_meshes
from aias_augment.assets.bank.lift import bank_paths
from aias_augment.assets.bank.taxonomy import load_taxonomy
from aias_augment.assets.bank.validate import check_size
from aias_augment.assets.deform import (
    CATEGORY_KINDS,
    KINDS,
    DeformConfig,
    DeformParams,
    apply_deformation,
    fall_segments,
    geometry_is_watertight,
    sample_deformation,
    tipped,
    topple_rest_angle,
    write_variants,
)

DATA = Path(os.environ.get("AIAS_DATA", "../shared/data"))


def textured_cylinder(radius=0.2, height=0.8, sections=24) -> Asset:
    """A closed cylinder with a cylindrical UV map; its texture seam splits vertices, so its raw mesh is open
    (vertex-wise) while its geometry is closed."""
    base = trimesh.creation.cylinder(radius=radius, height=height, sections=sections)
    base.apply_translation([0, 0, height / 2])
    tri = base.vertices[base.faces]  # unshared corners: every face keeps its own UVs (seams everywhere)
    v = tri.reshape(-1, 3)
    f = np.arange(len(v)).reshape(-1, 3)
    uv = np.c_[(np.arctan2(v[:, 1], v[:, 0]) + np.pi) / (2 * np.pi), v[:, 2] / height]
    tex = Image.fromarray(np.random.default_rng(0).integers(0, 255, (16, 16, 3), dtype=np.uint8))
    m = trimesh.Trimesh(v, f, visual=trimesh.visual.TextureVisuals(uv=uv, image=tex), process=False)
    return Asset("cylinder", "barrel", normalise_meshes([m]), "test")


def corner_uvs(asset: Asset) -> list[np.ndarray]:
    return [np.asarray(m.visual.uv)[np.asarray(m.faces)] for m in asset.meshes]


@pytest.fixture(scope="module")
def cylinder():
    a = textured_cylinder()
    assert not all(m.is_watertight for m in a.meshes)  # as loaded: the seams are open vertex-wise ...
    assert geometry_is_watertight(a)  # ... the surface is closed
    return a


@pytest.mark.parametrize("kind", [k for k in KINDS if k != "fracture"])  # a fracture cuts faces: its own test
def test_variant_stays_closed_and_keeps_faces_and_uvs(cylinder, kind):
    p = sample_deformation(cylinder, np.random.default_rng(3), kind=kind)
    v = apply_deformation(cylinder, p)
    assert geometry_is_watertight(v)
    for a, b in zip(corner_uvs(cylinder), corner_uvs(v)):
        assert np.array_equal(a, b)  # each face corner keeps its texture coordinate
    assert sum(len(m.faces) for m in v.meshes) == sum(len(m.faces) for m in cylinder.meshes)
    lo, hi = v.bounds_m
    assert lo[2] == pytest.approx(0.0, abs=1e-9)  # rests on the ground
    assert (lo[:2] + hi[:2]) == pytest.approx([0.0, 0.0], abs=1e-9)  # centred in x/y
    assert v.reference_height_m == pytest.approx(cylinder.height_m)  # what the size range refers to


def test_crush_lowers_the_top_by_its_amount(cylinder):
    p = DeformParams("crush", crush_amount=0.3, crush_bulge=0.2, source_height_m=cylinder.height_m)
    v = apply_deformation(cylinder, p)
    assert v.height_m == pytest.approx(0.7 * cylinder.height_m, rel=1e-9)  # z' = z (1 - a z / H) at z = H
    # the bulge: at mid-height the radius grows by 1 + bulge * amount * sin(pi / 2)
    assert v.extents_m[0] <= cylinder.extents_m[0] * (1 + 0.2 * 0.3) + 1e-9


def test_a_dent_moves_nothing_further_than_its_depth_nor_beyond_its_radius(cylinder):
    c = np.array([0.2, 0.0, 0.4])  # on the side, mid-height
    p = DeformParams("dent", dents=((*c, -1.0, 0.0, 0.0, 0.1, 0.03),), source_height_m=cylinder.height_m)
    src = np.concatenate([m.vertices for m in cylinder.meshes])
    out = np.concatenate([m.vertices for m in apply_deformation(cylinder, p).meshes])
    # compare positions as sets (normals re-creased may reorder nothing, but vertices can be split): nearest match
    from scipy.spatial import cKDTree

    moved = cKDTree(src).query(out)[0]
    assert moved.max() <= 0.03 + 1e-9
    far = np.linalg.norm(out - c, axis=1) > 0.1 + 0.03
    assert moved[far].max() < 1e-9


def test_knocked_over_is_rigid_and_lies_on_a_face(cylinder):
    p = sample_deformation(cylinder, np.random.default_rng(0), kind="knocked_over")
    R = np.asarray(p.rotation).reshape(3, 3)
    assert R @ R.T == pytest.approx(np.eye(3), abs=1e-9) and np.linalg.det(R) == pytest.approx(1.0)
    v = apply_deformation(cylinder, p)
    pts = np.concatenate([m.vertices for m in v.meshes])
    # a 24-gon cylinder of radius 0.2 and height 0.8 on its flank: it lies on a side facet, so it stands
    # 2 r cos(pi / 24) high, and its axis (R z) is horizontal and 0.8 long
    axis = R[:, 2]
    assert axis[2] == pytest.approx(0.0, abs=1e-9)
    assert v.height_m == pytest.approx(0.4 * np.cos(np.pi / 24), abs=1e-6)
    assert np.ptp(pts @ axis) == pytest.approx(0.8, abs=1e-6)
    assert np.sum(np.abs(pts[:, 2]) < 1e-9) >= 3  # a face, not a point, on the ground


def test_bend_keeps_the_axis_length(cylinder):
    p = DeformParams("bend", bend_azimuth=0.3, bend_angle=np.radians(30), source_height_m=cylinder.height_m)
    axis = np.c_[np.zeros(50), np.zeros(50), np.linspace(0, cylinder.height_m, 50)]
    from aias_augment.assets.deform import _displace

    bent = _displace(axis, p)
    assert np.sum(np.linalg.norm(np.diff(bent, axis=0), axis=1)) == pytest.approx(cylinder.height_m, rel=1e-3)
    tilt = np.degrees(np.arccos((bent[-1] - bent[-2])[2] / np.linalg.norm(bent[-1] - bent[-2])))
    assert tilt == pytest.approx(30, abs=1.0)  # the top's tangent is turned by the bend angle


def test_variant_replays_byte_for_byte_from_its_json_record(cylinder):
    rng = np.random.default_rng(7)
    for kind in KINDS:
        p = sample_deformation(cylinder, rng, kind=kind)
        again = DeformParams.from_dict(json.loads(json.dumps(p.to_dict())))
        a, b = apply_deformation(cylinder, p), apply_deformation(cylinder, again)
        for m, n in zip(a.meshes, b.meshes):
            assert np.asarray(m.vertices).tobytes() == np.asarray(n.vertices).tobytes()


def test_same_seed_same_draws_and_bad_config_refused(cylinder):
    a = sample_deformation(cylinder, np.random.default_rng(5))
    b = sample_deformation(cylinder, np.random.default_rng(5))
    assert a.to_dict() == b.to_dict()
    with pytest.raises(ValueError, match="must be one of"):
        DeformConfig(kinds=("melt",))
    with pytest.raises(ValueError):
        DeformConfig(crush_amount=(0.5, 0.2))
    with pytest.raises(ValueError, match="kind"):
        DeformParams("melt")


def test_bank_round_trip_keeps_the_record_and_the_reference_height(cylinder, tmp_path):
    rng = np.random.default_rng(1)
    params = [sample_deformation(cylinder, rng, kind=k) for k in ("knocked_over", "crush")]
    entries = write_variants(cylinder, params[:1], tmp_path)
    entries += write_variants(cylinder, params, tmp_path)  # the first again: listed once; the second appended
    paths = bank_paths(tmp_path)["barrel"]
    assert [Path(p).name for p in paths] == ["0000.glb", "0001.glb"]
    assert entries[0] == entries[1]
    bank = PathAssets({"barrel": paths})
    lying = bank._load("barrel", paths[0])
    assert lying.meta["deformation"] == entries[0]["deformation"]
    assert lying.reference_height_m == pytest.approx(cylinder.height_m, rel=1e-5)
    assert lying.height_m == pytest.approx(apply_deformation(cylinder, params[0]).height_m, rel=1e-5)
    # the placement's size range refers to the source's height: scaled to a 1 m barrel, the lying one is 1 m long
    axis = np.asarray(params[0].rotation).reshape(3, 3)[:, 2]
    pts = np.concatenate([m.vertices for m in lying.scaled(1.0 / lying.reference_height_m).meshes])
    assert np.ptp(pts @ axis) == pytest.approx(1.0, rel=1e-4)


@pytest.mark.skipif(not (DATA / "meshes").is_dir(), reason="AIAS_DATA missing")
def test_deformed_insertion_replays_exactly():
    from aias_augment import load_preset
    from aias_augment.core.frame import Frame
    from aias_augment.pipeline.bounded import insert_bounded
    from aias_augment.pipeline.replay import replay

    img = cv2.imread(str(DATA / "kitti06_color_snippet" / "kitti06-12-color.png"))
    if img is None:
        pytest.skip("KITTI frame missing")
    img = np.ascontiguousarray(img[:, :, ::-1])
    cfg = load_preset("fast", deform_probability=1.0, min_objects=2, max_objects=2)
    res = insert_bounded(img, None, None, np.random.default_rng(2), cfg)
    record = json.loads(json.dumps(res.record.to_dict()))
    kinds = [p["asset_meta"]["deformation"]["kind"] for p in record["placements"]]
    assert kinds and all(k in KINDS for k in kinds)
    assert np.array_equal(replay(record, Frame(img, None), cfg).image, res.image)


def test_a_cone_tipping_over_lands_on_its_side_line_with_its_texture():
    """Truth by hand: a cone of height H on a 48-gon base of circumradius R turns about a base edge (the apothem
    a = R cos(pi / 48) from the axis) and rests when its apex reaches the ground, at pi - atan(H / a) (beyond
    90 deg: it lies on a side line); the turn is rigid (edge lengths kept),
    keeps the UVs, the pivot stays put, and nothing dips below the ground on the way."""
    R, H = 0.2, 0.7
    m = trimesh.creation.cone(R, H, sections=48)
    uv = np.c_[np.arctan2(m.vertices[:, 1], m.vertices[:, 0]), m.vertices[:, 2]]
    m.visual = trimesh.visual.TextureVisuals(uv=uv)
    cone = Asset("cone", "traffic_cone", normalise_meshes([m]), "test")
    rest = topple_rest_angle(cone, 0.0)
    assert rest == pytest.approx(np.pi - np.arctan(H / (R * np.cos(np.pi / 48))), abs=1e-9)
    src = np.asarray(cone.meshes[0].vertices)
    for t in (0.0, 0.3, 0.8, 1.0):
        out, origin = tipped(cone, 0.0, rest * t)
        v = np.asarray(out.meshes[0].vertices) + origin  # back in the upright cone's frame
        assert v[:, 2].min() == pytest.approx(0.0, abs=1e-12)
        edges = np.asarray(cone.meshes[0].edges_unique)
        assert np.allclose(
            np.linalg.norm(v[edges[:, 0]] - v[edges[:, 1]], axis=1),
            np.linalg.norm(src[edges[:, 0]] - src[edges[:, 1]], axis=1),
            atol=1e-12,
        )
        assert np.array_equal(np.asarray(out.meshes[0].visual.uv), np.asarray(cone.meshes[0].visual.uv))
        edge = src[:, 0] > R * np.cos(np.pi / 48) - 1e-9  # the base rim's points on the pivot edge
        assert np.allclose(v[edge & (src[:, 2] < 1e-9)], src[edge & (src[:, 2] < 1e-9)], atol=1e-12)
    apex = v[np.argmax(src[:, 2])]
    assert apex[2] == pytest.approx(0.0, abs=1e-9)  # landed: the apex touches the ground
    assert out.meta["tipped"]["azimuth"] == pytest.approx(np.pi / 48, abs=1e-9)  # the facet edge nearest to 0


def test_a_cone_on_a_square_plate_rolls_over_the_plate_rim_onto_its_side():
    """Truth by hand: a cone (0.7 m, base radius 0.15 m) on a 0.4 m square plate 4 cm thick, knocked towards +x,
    first turns 90 deg about the plate's bottom edge, until the plate's top edge touches (0.04 m past it). Its
    centre of mass then lies far beyond that strip, so it turns on about the top edge; the apex, 0.2 m up and
    0.70 m along from it, lands after atan2(0.2, 0.70) more. At rest the apex and the plate's top edge are on the
    ground."""
    plate = trimesh.creation.box(extents=(0.4, 0.4, 0.04))
    plate.apply_translation([0, 0, 0.02])
    body = trimesh.creation.cone(0.15, 0.7, sections=32)
    body.apply_translation([0, 0, 0.04])
    cone = Asset("plated", "traffic_cone", normalise_meshes([plate, body]), "test")
    f, azimuth, segments = fall_segments(cone, 0.0)
    assert azimuth == pytest.approx(0.0) and len(segments) == 2
    assert segments[0][1] == pytest.approx(np.pi / 2, abs=1e-9)  # onto the plate's rim
    assert np.allclose(segments[1][0], [0.24, 0.0, 0.0], atol=1e-9)  # then about its top edge
    rest = topple_rest_angle(cone, 0.0)
    assert rest == pytest.approx(np.pi / 2 + np.arctan2(0.2, 0.70), abs=1e-9)
    out, origin = tipped(cone, 0.0, rest)
    v = np.concatenate([np.asarray(m.vertices) for m in out.meshes]) + origin
    src = np.concatenate([np.asarray(m.vertices) for m in cone.meshes])
    assert v[:, 2].min() == pytest.approx(0.0, abs=1e-12)
    assert v[np.argmax(src[:, 2]), 2] == pytest.approx(0.0, abs=1e-9)  # the apex is down
    top_edge = (np.abs(src[:, 0] - 0.2) < 1e-9) & (np.abs(src[:, 2] - 0.04) < 1e-9)
    assert top_edge.sum() >= 2 and np.allclose(v[top_edge, 2], 0.0, atol=1e-9)  # and the plate's top edge


def test_a_fracture_makes_two_closed_pieces_of_the_same_volume_apart_with_the_uvs_kept(cylinder):
    """Truth by hand: a plane through the axis of a cylinder (r 0.2 m, H 0.8 m; a 24-gon prism of area A) at height c,
    tilted less than atan(min(c, H - c) / r), leaves A c below it and A (H - c) above; each piece is closed (two
    watertight components); the fallen top lies beyond the standing base along its fall direction by the drawn
    gap; every face of the source wholly below the cut is still there with its texture coordinates."""
    from aias_augment.assets.deform import _merged_geometry

    p = sample_deformation(cylinder, np.random.default_rng(4), DeformConfig(fracture_debris=(0, 0)), kind="fracture")
    v = apply_deformation(cylinder, p)
    pieces = _merged_geometry(v).split(only_watertight=False)
    assert len(pieces) == 2 and all(piece.is_watertight for piece in pieces)
    area, c = 0.5 * 24 * 0.2**2 * np.sin(2 * np.pi / 24), p.cut[2]
    base, top = sorted(pieces, key=lambda piece: abs(piece.volume - area * c))
    assert base.volume == pytest.approx(area * c, rel=1e-6) and top.volume == pytest.approx(area * (0.8 - c), rel=1e-6)
    f = np.array([np.cos(p.fall_azimuth), np.sin(p.fall_azimuth), 0.0])
    gap = float(np.min(top.vertices @ f) - np.max(base.vertices @ f))
    assert gap >= p.gap * float(cylinder.extents_m.max()) - 1e-6
    assert v.height_m < cylinder.height_m and v.reference_height_m == pytest.approx(cylinder.height_m)
    point, normal = np.asarray(p.cut[:3]), np.asarray(p.cut[3:])
    src = cylinder.meshes[0]
    below = np.all((np.asarray(src.vertices)[np.asarray(src.faces)] - point) @ normal < -1e-6, axis=1)
    kept = {tuple(np.round(t, 12).ravel()) for m in v.meshes if hasattr(m.visual, "uv") for t in corner_uvs_of(m)}
    assert below.sum() > 10
    assert all(tuple(np.round(t, 12).ravel()) in kept for t in corner_uvs_of(src)[below])


def corner_uvs_of(m) -> np.ndarray:
    return np.asarray(m.visual.uv)[np.asarray(m.faces)]


def test_fracture_debris_are_closed_chips_on_the_ground_around_it(cylinder):
    """Three chips drawn: five closed components (base, top, chips), each chip resting on the ground (its lowest
    point at the pieces' ground), no larger than the drawn length, and the record replays them."""
    from aias_augment.assets.deform import _merged_geometry

    p = sample_deformation(cylinder, np.random.default_rng(4), DeformConfig(fracture_debris=(3, 3)), kind="fracture")
    assert len(p.debris) == 3
    v = apply_deformation(cylinder, p)
    pieces = _merged_geometry(v).split(only_watertight=False)
    assert len(pieces) == 5 and all(piece.is_watertight for piece in pieces)
    chips = sorted(pieces, key=lambda piece: piece.volume)[:3]
    for chip in chips:
        assert chip.bounds[0, 2] == pytest.approx(0.0, abs=1e-9)
        assert np.max(chip.extents) <= max(c[2] for c in p.debris) * 1.2 + 1e-9
    again = apply_deformation(cylinder, DeformParams.from_dict(json.loads(json.dumps(p.to_dict()))))
    for m, n in zip(v.meshes, again.meshes):
        assert np.asarray(m.vertices).tobytes() == np.asarray(n.vertices).tobytes()


def _source_for(category: str, height: float) -> Asset:
    """The test cylinder with the category's name, its height set to ``height`` (width in the usual ratio)."""
    a = textured_cylinder(radius=0.25 * height, height=height)
    return Asset(f"{category}_proxy", category, a.meshes, "test")


@pytest.mark.parametrize("category", sorted(CATEGORY_KINDS))
def test_every_variant_placed_at_its_category_sizes_stays_within_the_range_the_bank_accepts(category):
    """Placed the way the planner places it (source height drawn from the taxonomy's range), no variant of any kind
    rises or spreads beyond what its deformation's geometry allows, and the bank's size check accepts it.

    The source is ``h`` tall and ``w = h / 2`` wide. Height: only a bend can raise a point, the outer rim of the top
    rising to (h / theta + w / 2) sin(theta) <= h + (w / 2) sin(theta_max). Along the ground: a dent moves inward, a
    crush bulges by at most bulge x amount and leans by ``crush_max_lean`` h, a fall or a bend turns the section
    (at most its diagonal). A fracture's top lies along its fall direction at most the widest gap beyond the base,
    at most the source's diagonal long and w / 2 to each side, so every point lies within R = hypot(w / 2 + gap h +
    diag, w / 2) of the axis; chips lie within 0.8 h; the footprint then spans at most 0.8 h + R."""
    lo, hi = load_taxonomy().height_range_m(category)
    cfg = DeformConfig()
    rng = np.random.default_rng(7)
    for kind in CATEGORY_KINDS[category]:
        for h in (lo, hi):
            source = _source_for(category, h)
            w, diag = 0.5 * h, np.hypot(h, 0.5 * h)
            rise = h + 0.5 * w * np.sin(np.radians(cfg.bend_angle_deg[1])) if kind == "bend" else h
            spread = {
                "dent": w,
                "crush": w * (1 + cfg.crush_bulge[1] * cfg.crush_amount[1]) + cfg.crush_max_lean * h,
                "fracture": 0.8 * h + np.hypot(0.5 * w + cfg.fracture_gap[1] * h + diag, 0.5 * w),
            }.get(kind, diag)
            for _ in range(3):
                v = apply_deformation(source, sample_deformation(source, rng, kind=kind))
                assert v.reference_height_m == pytest.approx(h, rel=1e-6)
                ext = np.ptp(np.concatenate([m.vertices for m in v.meshes]), axis=0)
                assert ext[2] <= rise * (1 + 1e-6), (kind, ext, rise)
                assert max(ext[0], ext[1]) <= spread * (1 + 1e-6), (kind, ext, spread)
                check_size(ext, category, (lo, hi), where=f"{category}/{kind}")

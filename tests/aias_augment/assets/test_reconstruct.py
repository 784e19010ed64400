"""Reconstruction of analytic shapes from views the project's renderer draws at known poses.

The bounds: a visual hull contains its object (every silhouette does), so its volume is at least the object's and
its error is the hull's excess (largest at a box's corners, which no silhouette pins down between views) plus the
sampling of the distance field (marching cubes interpolates a field that changes by at most 1 m per m, so the
surface is off by less than one voxel: 0.6 m / 64 = 9.4 mm = 1.6 % of the sphere's size at the coarsest). Measured
at 24 views: sphere 0.67 %, box 0.82 %; the bounds below leave room for neither more than 1 % (sphere) and 1.5 %
(box), against 1.6 % that discretisation alone could reach.
"""

import json

import cv2
import numpy as np
import pytest
import trimesh

from aias_augment.apply.render import render_object
from aias_augment.assets.asset import Asset, normalise_meshes
from aias_augment.assets.reconstruct import (
    ReconstructConfig,
    View,
    load_views,
    read_views,
    reconstruct,
    reconstruct_unposed,
    search_box,
    visual_hull,
)
from aias_augment.assets.view_masks import grabcut_mask
from studies.assets.reconstruction.run import align_yaw, cameras, compare, floor_texture, on_floor, shoot, write_views
from studies.assets.reconstruction.run import psnr as eval_psnr


def coloured(mesh: trimesh.Trimesh, name: str) -> Asset:
    mesh.visual = trimesh.visual.ColorVisuals(
        mesh, vertex_colors=np.tile([200, 120, 40, 255], (len(mesh.vertices), 1)).astype(np.uint8)
    )
    return Asset(name, "object", normalise_meshes([mesh], crease_deg=None), "analytic")


@pytest.mark.parametrize(
    "name,mesh,bound",
    [("sphere", trimesh.creation.icosphere(4, 0.3), 0.010), ("box", trimesh.creation.box((0.5, 0.3, 0.2)), 0.015)],
)
def test_analytic_shapes_from_24_posed_views(name, mesh, bound):
    truth = coloured(mesh, name)
    views = shoot(truth, cameras(truth, 24))
    lo, hi = search_box(views)
    assert np.all(lo <= truth.bounds_m[0]) and np.all(hi >= truth.bounds_m[1])  # the search box holds it
    rec = reconstruct(views, lo, hi, category="object", cfg=ReconstructConfig(resolution=64), render=render_object)
    m = compare(truth, rec, np.random.default_rng(0))
    assert m["chamfer_rel"] <= bound
    assert m["normal_consistency"] >= 0.95
    hull = rec.meshes[0]
    assert hull.is_watertight
    voxel = float(truth.extents_m.max()) / 64
    assert hull.volume >= mesh.volume - hull.area * voxel  # contains the object, up to one voxel of its surface
    assert rec.height_m == pytest.approx(truth.height_m, abs=voxel)  # metric: the poses' metres are kept


def test_height_scales_and_colour_comes_from_the_views():
    truth = coloured(trimesh.creation.box((0.4, 0.4, 0.4)), "cube")
    views = shoot(truth, cameras(truth, 12))
    lo, hi = search_box(views)
    rec = reconstruct(
        views, lo, hi, category="object", height_m=1.0, cfg=ReconstructConfig(resolution=48), render=render_object
    )
    assert rec.height_m == pytest.approx(1.0)
    # the rendered albedo of (200, 120, 40), as the views show it, is what the vertices got (sRGB round trip)
    col = np.asarray(rec.meshes[0].visual.vertex_colors)[:, :3].astype(float)
    assert np.median(col, axis=0) == pytest.approx([200, 120, 40], abs=3)


def test_views_file_round_trip_and_grabcut_masks(tmp_path):
    truth = coloured(trimesh.creation.cylinder(radius=0.2, height=0.6), "drum")
    views = shoot(truth, cameras(truth, 8))
    write_views(views, tmp_path)
    back, ground_z = load_views(tmp_path / "views.json")
    assert ground_z == 0.0 and len(back) == 8
    for a, b in zip(views, back):
        assert np.array_equal(a.mask, b.mask) and np.array_equal(a.image_rgb, b.image_rgb)
        assert np.allclose(a.cam_from_object, b.cam_from_object) and np.allclose(a.intrinsics.K, b.intrinsics.K)
    # GrabCut from the object's box on a plain background finds the rendered silhouette
    v = views[0]
    img = np.where(v.mask[..., None], v.image_rgb, np.uint8(235))
    ys, xs = np.nonzero(v.mask)
    got = grabcut_mask(img, (xs.min() - 6, ys.min() - 6, xs.max() + 6, ys.max() + 6))
    iou = (got & v.mask).sum() / (got | v.mask).sum()
    assert iou >= 0.95


def test_bad_views_are_refused(tmp_path):
    img = np.zeros((32, 32, 3), np.uint8)
    from aias_augment.core.geometry import Intrinsics

    with pytest.raises(ValueError, match="empty mask"):
        View(img, np.zeros((32, 32), bool), Intrinsics(30, 30, 16, 16, 32, 32), np.eye(4))
    with pytest.raises(ValueError, match="intrinsics"):
        View(img, np.ones((32, 32), bool), Intrinsics(30, 30, 16, 16, 64, 32), np.eye(4))
    (tmp_path / "views.json").write_text(json.dumps({"views": [{"image": "missing.png", "K": np.eye(3).tolist()}]}))
    with pytest.raises(ValueError, match="view 0"):
        load_views(tmp_path / "views.json")
    cv2.imwrite(str(tmp_path / "a.png"), img)
    (tmp_path / "views.json").write_text(
        json.dumps({"views": [{"image": "a.png", "K": np.eye(3).tolist(), "cam_from_object": np.eye(4).tolist()}]})
    )
    with pytest.raises(ValueError, match="mask or a box"):
        load_views(tmp_path / "views.json")


def test_a_textured_sphere_from_24_unposed_views_on_a_textured_floor():
    """Without poses: SfM (COLMAP) registers the views, the floor plane gives the vertical and the height the scale.
    The error bound adds the poses' error to the posed one (0.67 % measured, 1 % bound): SfM's reprojection error is
    under a pixel, a few millimetres at these 1.3 m distances; 1.5 % leaves the same room again."""
    mesh = trimesh.creation.icosphere(4, 0.3)
    rng = np.random.default_rng(3)
    colours = np.c_[rng.integers(30, 230, (len(mesh.vertices), 3)), np.full(len(mesh.vertices), 255)]
    mesh.visual = trimesh.visual.ColorVisuals(mesh, vertex_colors=colours.astype(np.uint8))
    truth = Asset("sphere", "object", normalise_meshes([mesh], crease_deg=None), "analytic")
    views = shoot(truth, cameras(truth, 24))
    tex = floor_texture(np.random.default_rng(0))
    rec = reconstruct_unposed(
        [on_floor(v, tex) for v in views],
        [v.mask for v in views],
        views[0].intrinsics,
        category="object",
        height_m=truth.height_m,
        seed=0,
        cfg=ReconstructConfig(resolution=64),
        render=render_object,
    )
    assert rec.meta["registered_views"] >= 20
    assert rec.height_m == pytest.approx(truth.height_m)
    rec, _ = align_yaw(truth, rec, np.random.default_rng(0))
    m = compare(truth, rec, np.random.default_rng(0))
    assert m["chamfer_rel"] <= 0.015
    assert m["normal_consistency"] >= 0.95


def test_unposed_views_files_need_all_or_no_poses_and_a_height(tmp_path, capsys):
    from aias_augment.cli.assets import main

    truth = coloured(trimesh.creation.cylinder(radius=0.2, height=0.6), "drum")
    write_views(shoot(truth, cameras(truth, 4)), tmp_path)
    spec = json.loads((tmp_path / "views.json").read_text())
    for e in spec["views"]:
        e.pop("cam_from_object")
    (tmp_path / "views.json").write_text(json.dumps(spec))
    photos, _ = read_views(tmp_path / "views.json")
    assert len(photos) == 4 and all(p[3] is None for p in photos)
    with pytest.raises(ValueError, match="no cam_from_object"):
        load_views(tmp_path / "views.json")
    assert (
        main(["reconstruct", "--views", str(tmp_path / "views.json"), "--category", "x", "--out", str(tmp_path / "b")])
        == 2
    )
    assert "--height-m" in capsys.readouterr().err
    spec["views"][0]["cam_from_object"] = np.eye(4).tolist()
    (tmp_path / "views.json").write_text(json.dumps(spec))
    with pytest.raises(ValueError, match="all or none"):
        read_views(tmp_path / "views.json")


def test_a_decimated_hull_keeps_its_shape_its_closure_and_its_budget(tmp_path, capsys):
    """Quadric decimation to 800 faces: each face of a 0.3 m sphere then spans about 1.4e-3 m^2 (edge ~57 mm,
    circumradius ~33 mm), and a flat triangle leaves the sphere by at most R_c^2 / (2 r) = 1.8 mm = 0.3 % of the
    size. The hull's own 1 % bound (above) plus that is the bound; the hull must stay closed and within budget."""
    from aias_augment.cli.assets import main

    truth = coloured(trimesh.creation.icosphere(4, 0.3), "sphere")
    views = shoot(truth, cameras(truth, 24))
    lo, hi = search_box(views)
    cfg = ReconstructConfig(resolution=64, max_faces=800)
    rec = reconstruct(views, lo, hi, category="object", cfg=cfg, render=render_object)
    assert rec.meta["faces"] <= 800 < len(visual_hull(views, lo, hi, ReconstructConfig(resolution=64)).faces)
    assert len(rec.meshes[0].faces) == rec.meta["faces"] and rec.meshes[0].is_watertight
    m = compare(truth, rec, np.random.default_rng(0))
    assert m["chamfer_rel"] <= 0.013
    assert m["normal_consistency"] >= 0.95
    col = np.asarray(rec.meshes[0].visual.vertex_colors)[:, :3].astype(float)  # coloured after decimation
    assert np.median(col, axis=0) == pytest.approx([200, 120, 40], abs=3)
    write_views(views[:4], tmp_path)
    args = ["reconstruct", "--views", str(tmp_path / "views.json"), "--category", "x", "--out", str(tmp_path / "b")]
    assert main([*args, "--max-faces", "10"]) == 2  # refused at construction, before any work
    assert "max_faces" in capsys.readouterr().err


def test_a_texture_atlas_keeps_colour_detail_that_vertex_colours_lose_on_a_decimated_hull():
    """A sphere painted in two halves (a sharp boundary at z = 0.3, its centre), decimated to 400 faces: vertex
    colours can only interpolate across each ~80 mm face, an atlas baked from the views keeps the boundary to about a
    texel. Truth: the halves' colours, and the boundary's sharpness measured on held-out renders."""
    mesh = trimesh.creation.icosphere(5, 0.3)
    mesh.apply_translation([0, 0, 0.3])
    top = mesh.vertices[:, 2] > 0.3
    colours = np.where(top[:, None], [230, 40, 40, 255], [40, 40, 230, 255]).astype(np.uint8)
    mesh.visual = trimesh.visual.ColorVisuals(mesh, vertex_colors=colours)
    truth = Asset("halves", "object", normalise_meshes([mesh], crease_deg=None), "analytic")
    views = shoot(truth, cameras(truth, 16))
    lo, hi = search_box(views)
    psnr = {}
    for tex in (None, 256):
        rec = reconstruct(
            views,
            lo,
            hi,
            category="object",
            cfg=ReconstructConfig(resolution=48, max_faces=400, texture_px=tex),
            render=render_object,
        )
        assert rec.meta["faces"] <= 400
        assert trimesh.Trimesh(rec.meshes[0].vertices, rec.meshes[0].faces).is_watertight  # seams merged: closed
        psnr[tex] = eval_psnr(truth, rec)[0]
    assert psnr[256] >= psnr[None] + 2.0
    assert psnr[256] >= 20.0


def _pit_block(textured: bool) -> Asset:
    """A 0.4 m square block, 0.25 m tall, with a 0.2 m square pit 0.1 m deep in its top: a concavity that no
    silhouette shows. Two closed parts (the base and the rim around the pit), subdivided to 1 cm edges and given a
    random grey per vertex (texture to match) or one flat colour."""
    from shapely.geometry import Polygon

    base = trimesh.creation.box((0.4, 0.4, 0.15))
    base.apply_translation((0, 0, 0.075))
    ring = Polygon(
        [(-0.2, -0.2), (0.2, -0.2), (0.2, 0.2), (-0.2, 0.2)], [[(-0.1, -0.1), (0.1, -0.1), (0.1, 0.1), (-0.1, 0.1)]]
    )
    rim = trimesh.creation.extrude_polygon(ring, 0.1)
    rim.apply_translation((0, 0, 0.15))
    rng = np.random.default_rng(5)
    parts = []
    for m in (base, rim):
        v, f = trimesh.remesh.subdivide_to_size(m.vertices, m.faces, 0.01)
        m = trimesh.Trimesh(v, f)
        grey = rng.integers(30, 230, len(m.vertices)) if textured else np.full(len(m.vertices), 150)
        m.visual = trimesh.visual.ColorVisuals(
            m, vertex_colors=np.c_[grey, grey, grey, np.full(len(grey), 255)].astype(np.uint8)
        )
        parts.append(m)
    return Asset("pit_block", "object", normalise_meshes(parts, crease_deg=None), "analytic")


def _top_height(mesh, xy) -> np.ndarray:
    """Height of the highest surface above each (x, y): the faces whose top-view projection holds the point,
    interpolated barycentrically (a vertical ray from above meets that one first)."""
    tri = np.asarray(mesh.vertices)[np.asarray(mesh.faces)]  # (F, 3, 3)
    a, b, c = tri[:, 0, :2], tri[:, 1, :2], tri[:, 2, :2]
    det = (b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (c[:, 0] - a[:, 0]) * (b[:, 1] - a[:, 1])
    out = np.full(len(xy), -np.inf)
    ok = np.abs(det) > 1e-12
    for i, p in enumerate(np.asarray(xy, float)):
        l1 = ((p[0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (c[:, 0] - a[:, 0]) * (p[1] - a[:, 1])) / np.where(ok, det, 1)
        l2 = ((b[:, 0] - a[:, 0]) * (p[1] - a[:, 1]) - (p[0] - a[:, 0]) * (b[:, 1] - a[:, 1])) / np.where(ok, det, 1)
        inside = ok & (l1 >= 0) & (l2 >= 0) & (l1 + l2 <= 1)
        if inside.any():
            z = (1 - l1 - l2) * tri[:, 0, 2] + l1 * tri[:, 1, 2] + l2 * tri[:, 2, 2]
            out[i] = z[inside].max()
    return out


def test_photo_consistency_digs_the_pit_the_hull_fills_and_leaves_flat_surfaces_alone():
    """The hull closes the pit at the rim's height (0.25 m), 0.1 m above its floor. Refined, the pit's middle must
    come down to within 3 cm of the floor (0.15 m: the plane sweep's step is half a voxel, 3 mm, and the median
    smoothing over a ring of 2 cm vertices), the rim must stay within 1 cm of its height, the surface stay closed,
    and a flat-coloured block (no texture: nothing to match) must not move at all."""
    cfg = ReconstructConfig(resolution=64, refine=True, refine_depth=0.35)
    xy_pit = np.stack(np.meshgrid(np.linspace(-0.04, 0.04, 5), np.linspace(-0.04, 0.04, 5)), -1).reshape(-1, 2)
    xy_rim = np.array([[0.15, 0.0], [-0.15, 0.0], [0.0, 0.15], [0.0, -0.15], [0.15, 0.15], [-0.15, -0.15]])
    truth = _pit_block(True)
    views = shoot(truth, cameras(truth, 24, elevations=(10.0, 80.0)))
    lo, hi = search_box(views)
    hull = visual_hull(views, lo, hi, cfg)
    assert np.median(_top_height(hull, xy_pit)) > 0.24  # the hull fills the pit
    rec = reconstruct(views, lo, hi, category="object", cfg=cfg, render=render_object)
    mesh = rec.meshes[0]
    assert mesh.is_watertight
    assert rec.meta["refinement"]["moved_share"] > 0
    assert np.median(np.abs(_top_height(mesh, xy_pit) - 0.15)) < 0.03
    assert np.all(np.abs(_top_height(mesh, xy_rim) - 0.25) < 0.01)
    flat = _pit_block(False)
    views = shoot(flat, cameras(flat, 24, elevations=(10.0, 80.0)))
    lo, hi = search_box(views)
    rec = reconstruct(views, lo, hi, category="object", cfg=cfg, render=render_object)
    assert rec.meta["refinement"]["moved_share"] == 0.0


def test_refinement_settings_are_checked():
    with pytest.raises(ValueError, match="refine_patch_radius"):
        ReconstructConfig(refine_patch_radius=0)
    with pytest.raises(ValueError, match="refine_depth"):
        ReconstructConfig(refine_depth=0.0)

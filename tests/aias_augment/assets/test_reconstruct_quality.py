"""A posed reconstruction measures its own quality and refuses views that disagree (issue 54, item 2).

Truth: an analytic 0.7 m cone (a traffic cone's size) drawn by the project's renderer into 12 posed views; the
broken inputs are made from the same views, so each refusal is caused by the one thing changed.
"""

import json

import numpy as np
import pytest
import trimesh

from aias_augment.apply.render import render_object
from aias_augment.assets.asset import Asset, normalise_meshes
from aias_augment.assets.reconstruct import ReconstructConfig, View, reconstruct, search_box
from aias_augment.assets.reconstruct_quality import ReconstructionRefused, check_reprojection
from studies.assets.reconstruction.run import cameras, shoot, write_views

CFG = ReconstructConfig(resolution=48)
HEIGHT = 0.7


@pytest.fixture(scope="module")
def cone_views():
    mesh = trimesh.creation.cone(0.2, HEIGHT, sections=48)
    mesh.visual = trimesh.visual.ColorVisuals(
        mesh, vertex_colors=np.tile([230, 120, 30, 255], (len(mesh.vertices), 1)).astype(np.uint8)
    )
    truth = Asset("cone", "traffic_cone", normalise_meshes([mesh], crease_deg=None), "analytic")
    return shoot(truth, cameras(truth, 12))


def _rebuilt(views):
    lo, hi = search_box(views)
    return reconstruct(views, lo, hi, category="traffic_cone", cfg=CFG, render=render_object)


def test_clean_views_are_accepted_at_their_size(cone_views):
    asset = _rebuilt(cone_views)
    assert asset.height_m == pytest.approx(HEIGHT, rel=0.10)
    q = asset.meta["quality"]
    assert q["min_view_iou"] >= CFG.min_view_iou and q["view_spread_deg"] >= CFG.min_view_spread_deg
    assert q["height_range_m"] == [0.25, 1.1]


def test_one_pose_moved_0_3_m_is_refused_naming_it(cone_views):
    T = np.array(cone_views[5].cam_from_object, float)
    T[0, 3] += 0.3
    views = list(cone_views)
    views[5] = View(views[5].image_rgb, views[5].mask, views[5].intrinsics, T)
    with pytest.raises(ReconstructionRefused, match="contradict view 5 most") as e:
        _rebuilt(views)
    assert 5 in e.value.bad_views


def test_poses_shifted_by_one_photo_are_refused(cone_views):
    views = [
        View(v.image_rgb, v.mask, v.intrinsics, cone_views[(i + 1) % 12].cam_from_object)
        for i, v in enumerate(cone_views)
    ]
    with pytest.raises(ReconstructionRefused, match="views disagree") as e:
        _rebuilt(views)
    assert e.value.bad_views and e.value.measures["min_view_iou"] < CFG.min_view_iou


def test_twelve_identical_views_are_refused(cone_views):
    with pytest.raises(ReconstructionRefused, match="within 0.0 degrees") as e:
        _rebuilt([cone_views[0]] * 12)
    assert e.value.bad_views == tuple(range(12))


def test_blank_white_photos_with_full_masks_are_refused(cone_views):
    white = np.full_like(cone_views[0].image_rgb, 255)
    full = np.ones_like(cone_views[0].mask)
    with pytest.raises(ReconstructionRefused, match="views disagree"):
        _rebuilt([View(white, full, v.intrinsics, v.cam_from_object) for v in cone_views])


def test_a_height_outside_the_category_is_refused(cone_views):
    lo, hi = search_box(cone_views)
    with pytest.raises(ReconstructionRefused, match="outside traffic_cone's 0.25-1.1 m"):
        reconstruct(cone_views, lo, hi, category="traffic_cone", height_m=2.7, cfg=CFG, render=render_object)


def test_a_bad_sfm_reprojection_error_is_refused():
    check_reprojection(0.7, 2.0)
    with pytest.raises(ReconstructionRefused, match="reprojection error is 3.10 px"):
        check_reprojection(3.1, 2.0)
    with pytest.raises(ReconstructionRefused):
        check_reprojection(float("nan"), 2.0)


def test_the_cli_refuses_with_one_line_and_files_nothing(cone_views, tmp_path, capsys):
    from aias_augment.cli.assets import main

    views = list(cone_views)
    T = np.array(views[3].cam_from_object, float)
    T[1, 3] += 0.3
    views[3] = View(views[3].image_rgb, views[3].mask, views[3].intrinsics, T)
    write_views(views, tmp_path / "v")
    bank = tmp_path / "bank"
    rc = main(
        [
            "reconstruct",
            "--views",
            str(tmp_path / "v" / "views.json"),
            "--category",
            "traffic_cone",
            "--out",
            str(bank),
            "--resolution",
            "48",
        ]
    )
    err = capsys.readouterr().err
    assert rc == 2 and err.count("\n") == 1 and "view 3" in err and "Traceback" not in err
    assert not (bank / "bank.json").exists()
    write_views(cone_views, tmp_path / "ok")
    rc = main(
        [
            "reconstruct",
            "--views",
            str(tmp_path / "ok" / "views.json"),
            "--category",
            "traffic_cone",
            "--out",
            str(bank),
            "--resolution",
            "48",
        ]
    )
    assert rc == 0
    entry = json.loads((bank / "bank.json").read_text())["report"]["assets"][0]
    assert entry["height_m"] == pytest.approx(HEIGHT, rel=0.10)

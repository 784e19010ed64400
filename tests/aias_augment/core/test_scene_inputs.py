"""scene_inputs.SceneInputs: typed, checked scene facts; the meta dict split into facts and provenance."""

import numpy as np
import pytest

from aias_augment import SceneInputs
from aias_augment.core.scene_inputs import scene_meta
from aias_augment.pipeline.image import insert_into_image
from tests.aias_augment.fixtures import box_asset
from tests.aias_augment.pipeline.test_image import CFG, K, OneAsset, road_frame

HW = (K.height, K.width)


def test_meta_splits_into_facts_and_provenance_and_round_trips():
    mask = np.zeros(HW, bool)
    mask[300:, 100:200] = True
    facts, prov = SceneInputs.from_meta({"placeable_mask": mask, "source": "kitti", "frame_id": 7, "indoor": None})
    assert prov == {"source": "kitti", "frame_id": 7}
    assert facts.placeable_mask is mask and facts.indoor is None
    assert set(facts.as_meta()) == {"placeable_mask"}
    again, prov2 = SceneInputs.from_meta(facts.as_meta())
    assert prov2 == {} and again.placeable_mask is mask


@pytest.mark.parametrize(
    "key, meant",
    [
        ("placable_mask", "placeable_mask"),
        ("lidar_point_in_cam", "lidar_points_in_cam"),
        ("heading_degs", "heading_deg"),
    ],
)
def test_a_misspelt_fact_is_refused_with_the_name_it_meant(key, meant):
    with pytest.raises(ValueError, match=f"did you mean '{meant}'"):
        SceneInputs.from_meta({key: 1})


@pytest.mark.parametrize(
    "facts, message",
    [
        (dict(placeable_mask=np.ones((10, 10), bool)), r"must be \(480, 640\)"),
        (dict(placeable_mask=np.full(HW, 0.5, np.float32)), "bool"),
        (dict(ground_mask=np.full(HW, 2, np.uint8)), "bool"),
        (dict(semantic=np.zeros(HW, np.float32)), "integer label map"),
        (dict(lidar_points_in_cam=np.array([[0.0, 1.0, np.nan]])), "non-finite"),
        (dict(lidar_points_in_cam=np.zeros((5, 2))), r"\(N, 3\)"),
        (dict(boxes_in_cam=("car",)), "OrientedBox"),
        (dict(lat=48.1, lon=11.6), "go together"),
        (dict(lat=123.0, lon=0.0, utc="2020-06-01T12:00:00Z"), r"\[-90, 90\]"),
        (dict(heading_deg=float("inf")), "finite"),
        (dict(enu_from_cam=np.diag([1.0, 1.0, 2.0])), "not a rotation"),
        (dict(enu_from_cam=np.diag([1.0, 1.0, -1.0])), "not a rotation"),
        (dict(up_in_world=np.zeros(3)), "non-zero"),
        (dict(indoor="yes"), "bool"),
    ],
)
def test_bad_facts_are_refused_before_anything_runs(facts, message):
    with pytest.raises(ValueError, match=message):
        SceneInputs(**facts).checked(HW)


def test_good_facts_pass_and_masks_become_bool():
    c, s = np.cos(0.3), np.sin(0.3)
    ok = SceneInputs(
        placeable_mask=np.ones(HW, np.uint8),
        lat=48.1,
        lon=11.6,
        utc="2020-06-01T12:00:00Z",
        enu_from_cam=[[c, -s, 0], [s, c, 0], [0, 0, 1]],
        up_in_world=[0, 0, 1],
    ).checked(HW)
    assert ok.placeable_mask.dtype == bool and ok.placeable_mask.all()


def test_facts_given_twice_are_refused():
    with pytest.raises(ValueError, match="given twice"):
        scene_meta({"indoor": True}, SceneInputs(indoor=False), HW)


def test_typed_placeable_mask_restricts_contact_points_like_meta():
    """The typed input reaches the planner: every contact pixel lies in the given mask, and the result is the one
    the same facts give as a meta dict (same seed)."""
    mask = np.zeros(HW, bool)
    mask[:, 400:] = True
    kw = dict(rng=None, cfg=CFG, intrinsics=K, bank=OneAsset(box_asset()), n_objects=2)
    typed = insert_into_image(
        road_frame(), **{**kw, "rng": np.random.default_rng(4)}, scene=SceneInputs(placeable_mask=mask)
    )
    plain = insert_into_image(road_frame(), **{**kw, "rng": np.random.default_rng(4)}, meta={"placeable_mask": mask})
    assert typed.record.placements and all(p.contact_pixel[0] >= 399.5 for p in typed.record.placements)
    assert np.array_equal(typed.image, plain.image)
    with pytest.raises(ValueError, match="did you mean 'placeable_mask'"):
        insert_into_image(road_frame(), **{**kw, "rng": np.random.default_rng(4)}, meta={"placable_mask": mask})

"""Layer stages through the whole door: drawn in the plan from their own generators (every other draw unchanged),
recorded, replayed byte for byte, applied in clips along the object's motion, and found by their module alone."""

import json

import numpy as np
import pytest

from aias_augment.core.frame import Frame
from aias_augment.core.stages import ObjectLayer, apply_layer_stages, draw_layer_params, stages_in_order
from aias_augment.pipeline.config import load_preset
from aias_augment.pipeline.image import insert_into_image
from aias_augment.pipeline.replay import replay
from tests.aias_augment.fixtures import tracon_train_photo


def test_the_motion_blur_module_is_found_as_a_stage():
    assert "motion_blur_px" in [s.name for s in stages_in_order("layer")]


def test_an_unknown_stage_in_a_record_is_refused():
    layer = ObjectLayer((0, 0, 2, 2), np.ones((2, 2), np.float32), np.ones((2, 2), np.float32), np.ones((2, 2, 3)))
    with pytest.raises(ValueError, match="not in the stage list"):
        apply_layer_stages(layer, {"lens_flare": {}}, (2, 2))


def test_params_come_from_their_own_generators():
    cfg = load_preset("fast", motion_blur_px=(1.0, 4.0))
    a, b = draw_layer_params(cfg, 123, 3), draw_layer_params(cfg, 123, 3)
    assert a == b and len({json.dumps(p) for p in a}) == 3  # repeatable, and one draw per object
    assert draw_layer_params(load_preset("fast"), 123, 3) == ({}, {}, {})


@pytest.fixture(scope="module")
def photo():
    return tracon_train_photo("imh_179_00000000.jpg", 480)


def test_blur_changes_only_the_objects_and_replays_byte_for_byte(photo):
    plain_cfg = load_preset("fast")
    blur_cfg = load_preset("fast", motion_blur_px=(4.0, 6.0))
    plain = insert_into_image(photo, rng=np.random.default_rng(5), cfg=plain_cfg)
    blurred = insert_into_image(photo, rng=np.random.default_rng(5), cfg=blur_cfg)
    assert plain.inserted_labels
    # The plan's own stream is untouched: the same objects stand in the same places.
    assert [p.cam_from_object for p in plain.record.placements] == [
        p.cam_from_object for p in blurred.record.placements
    ]
    params = blurred.record.layer_params
    assert len(params) == len(blurred.record.placements)
    assert all(4.0 <= p["motion_blur_px"]["length_px"] <= 6.0 for p in params)
    assert not np.array_equal(plain.image, blurred.image)
    record = json.loads(json.dumps(blurred.record.to_dict()))
    assert np.array_equal(replay(record, Frame(photo, None), blur_cfg).image, blurred.image)
    # Without its layer parameters the same record replays the plain insertion.
    record["layer_params"] = []
    assert np.array_equal(replay(record, Frame(photo, None), plain_cfg).image, plain.image)

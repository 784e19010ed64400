"""A stage that lives outside the package (registered from this test module) is read wherever the stage list is: the
plan draws it, the record keeps it, a replay applies the recorded values, and :func:`apply_plan` applies it, a frame
stage also to a frame that got no object. Nothing else of the insertion changes."""

import json

import numpy as np
import pytest

from aias_augment.core.frame import Frame
from aias_augment.core.stages import ObjectLayer, register_stage, stages_in_order
from aias_augment.pipeline.config import load_preset
from aias_augment.pipeline.image import InsertionRecord, insert_into_image
from aias_augment.pipeline.replay import replay
from tests.aias_augment.fixtures import tracon_train_photo


class RedLift:
    """A frame stage: the red channel lifted by a drawn amount, saturating at 255."""

    name = "test_red_lift"
    kind = "frame"
    order = 0

    def enabled(self, cfg) -> bool:
        return True

    def draw(self, cfg, rng: np.random.Generator) -> dict:
        return {"lift": int(rng.integers(10, 40))}

    def apply(self, image: np.ndarray, params: dict) -> np.ndarray:
        out = image.copy()
        out[..., 0] = np.minimum(image[..., 0].astype(np.int32) + params["lift"], 255)
        return out


class Darken:
    """A layer stage: the object's linear RGB scaled by a drawn factor."""

    name = "test_darken"
    kind = "layer"
    order = 5

    def enabled(self, cfg) -> bool:
        return True

    def draw(self, cfg, rng: np.random.Generator) -> dict:
        return {"factor": round(float(rng.uniform(0.2, 0.5)), 4)}

    def apply(self, layer: ObjectLayer, params: dict, motion_px) -> ObjectLayer:
        return ObjectLayer(layer.roi, layer.alpha, layer.depth, layer.rgb * np.float32(params["factor"]))


def _lifted(image: np.ndarray, lift: int) -> np.ndarray:
    out = image.astype(np.int64)
    out[..., 0] = np.clip(out[..., 0] + lift, 0, 255)
    return out.astype(np.uint8)


@pytest.fixture(scope="module")
def photo():
    return tracon_train_photo("imh_179_00000000.jpg", 480)


def _json(record) -> dict:
    return json.loads(json.dumps(record.to_dict()))


def _inserted(photo, cfg, stage):
    """The insertion of seed 5 with ``stage`` in the stage list."""
    remove = register_stage(stage)
    try:
        assert stage in stages_in_order(stage.kind)
        return insert_into_image(photo, rng=np.random.default_rng(5), cfg=cfg)
    finally:
        remove()


def test_a_registered_frame_stage_is_drawn_recorded_replayed_and_applied(photo):
    cfg = load_preset("fast")
    plain = insert_into_image(photo, rng=np.random.default_rng(5), cfg=cfg)
    lifted = _inserted(photo, cfg, RedLift())
    lift = lifted.record.frame_params["test_red_lift"]["lift"]
    assert 10 <= lift < 40
    # the plan's own stream and everything composited before the stage are untouched: the plain run, lifted
    assert plain.inserted_labels and "frame_params" not in plain.record.to_dict()
    assert np.array_equal(lifted.image, _lifted(plain.image, lift))
    assert np.array_equal(lifted.bboxes, plain.bboxes) and lifted.labels == plain.labels
    record = _json(lifted.record)
    assert record["frame_params"] == {"test_red_lift": {"lift": lift}}
    assert _json(InsertionRecord.from_dict(record)) == record
    remove = register_stage(RedLift())
    try:
        assert np.array_equal(replay(record, Frame(photo, None), cfg).image, lifted.image)
        record["frame_params"] = {"test_red_lift": {"lift": 3}}  # the recorded value is applied, not a new draw
        assert np.array_equal(replay(record, Frame(photo, None), cfg).image, _lifted(plain.image, 3))
    finally:
        remove()
    # outside the stage list the record is refused, not replayed without the stage
    with pytest.raises(ValueError, match="not in the stage list"):
        replay(record, Frame(photo, None), cfg)
    # a frame without objects goes through the stage too (the stage alone never marks the frames with objects)
    empty = _inserted(photo, load_preset("fast", min_objects=0, max_objects=0), RedLift())
    assert not empty.inserted_labels
    assert np.array_equal(empty.image, _lifted(photo, empty.record.frame_params["test_red_lift"]["lift"]))


def test_a_registered_layer_stage_is_drawn_per_object_recorded_and_replayed(photo):
    cfg = load_preset("fast", harmonize=False)
    dark = _inserted(photo, cfg, Darken())
    params = dark.record.layer_params
    assert len(params) == len(dark.record.placements) >= 1
    assert all(0.2 <= p["test_darken"]["factor"] <= 0.5 for p in params)
    record = _json(dark.record)
    remove = register_stage(Darken())
    try:
        assert np.array_equal(replay(record, Frame(photo, None), cfg).image, dark.image)
    finally:
        remove()
    record["layer_params"] = [{} for _ in params]
    plain = replay(record, Frame(photo, None), cfg)
    # the same objects in the same places, each darker where it covers the frame alone
    assert [p.cam_from_object for p in dark.record.placements] == [p.cam_from_object for p in plain.placements]
    cover = plain.cover > 0.99
    assert cover.any()
    assert dark.image[cover].astype(float).mean() < plain.image[cover].astype(float).mean() - 5


def test_a_stage_is_registered_once_and_with_a_known_kind():
    with pytest.raises(ValueError, match="in the stage list already"):
        register_stage(type("Clash", (), {"name": "edge_blend", "kind": "layer", "order": 0})())
    with pytest.raises(ValueError, match="kind must be one of"):
        register_stage(type("NoKind", (), {"name": "x", "order": 0})())


class Brighten:
    """A frame stage: every channel lifted by a drawn amount, saturating at 255 (a grey frame stays grey)."""

    name = "test_brighten"
    kind = "frame"
    order = 0

    def enabled(self, cfg) -> bool:
        return True

    def draw(self, cfg, rng: np.random.Generator) -> dict:
        return {"lift": int(rng.integers(10, 40))}

    def apply(self, image: np.ndarray, params: dict) -> np.ndarray:
        return np.minimum(image.astype(np.int32) + params["lift"], 255).astype(np.uint8)


def test_the_clip_door_applies_a_registered_frame_stage_to_every_frame():
    from aias_augment.analyse.ground import prior_ground_plane
    from aias_augment.core.config import data_root
    from aias_augment.pipeline.clip_objects import ClipRequest, insert_objects_into_clip

    seq_dir = data_root() / "kitti06_seq"
    if not seq_dir.exists():
        pytest.skip("shared KITTI data not available")
    from aias_augment.scenes.kitti import open_kitti_sequence

    seq = open_kitti_sequence(seq_dir)
    frames = [seq.frame(i).image for i in range(4)]
    poses = np.stack([seq.cam_from_world(i) for i in range(4)])
    req = ClipRequest(lighting="ambient", harmonize="none", lookahead_frames=0, ahead_m=10.0, seed=2)
    plain = insert_objects_into_clip(frames, seq.intrinsics, poses, prior_ground_plane(1.65), req)
    remove = register_stage(Brighten())
    try:
        bright = insert_objects_into_clip(frames, seq.intrinsics, poses, prior_ground_plane(1.65), req)
    finally:
        remove()
    lift = bright.frame_params["test_brighten"]["lift"]
    assert plain.frame_params == {} and 10 <= lift < 40
    expected = [np.minimum(f.astype(np.int64) + lift, 255).astype(np.uint8) for f in plain.frames]
    assert all(np.array_equal(a, b) for a, b in zip(bright.frames, expected))
    assert [r.boxes_xywh for r in bright.results] == [r.boxes_xywh for r in plain.results]

"""Replay and audit logs hold the insertion's JSON record: ``ReplayCompose`` and ``save_applied_params`` output goes
through ``json`` and ``pickle``, and replaying it (after a JSON round trip) on the same sample gives the same bytes;
``A.to_dict`` / ``from_dict`` / ``save`` / ``load`` keep every constructor argument."""

import json
import pickle

import albumentations as A
import numpy as np
import pytest

from aias_augment import InsertObjects
from tests.aias_augment.pipeline.test_image import road_frame

K = [[500.0, 0, 319.5], [0, 500.0, 239.5], [0, 0, 1]]
BOXES = [[40.0, 250.0, 60.0, 50.0], [0.0, 300.0, 640.0, 180.0]]


def _insert(**kw):
    args = {"categories": ["traffic_cone"], "max_objects": 2, "p": 1.0, "preset": "fast"}
    return InsertObjects(**{**args, **kw})


def _replay_compose(**kw):
    c = A.ReplayCompose(
        [_insert(**kw), A.HorizontalFlip(p=0.5)],
        bbox_params=A.BboxParams(format="coco", label_fields=["labels"], min_visibility=0.2),
    )
    c.set_random_seed(7)
    return c


@pytest.mark.parametrize("variants", [None, 2])
def test_replay_compose_record_is_json_and_replays_to_the_same_bytes(variants):
    sample = {"image": road_frame(), "bboxes": BOXES, "labels": ["car", "road"], "camera_k": K}
    out = _replay_compose(variants_per_image=variants)(**sample)
    assert len(out["bboxes"]) > 2
    saved = json.loads(json.dumps(out["replay"]))
    assert pickle.loads(pickle.dumps(out["replay"])) == out["replay"]
    record = saved["transforms"][0]["params"]["insertion"]
    assert record["placements"] and record["harmonize_seed"] is not None
    assert not any(isinstance(v, dict) and "image" in v for v in saved["transforms"][0]["params"].values())
    again = A.ReplayCompose.replay(saved, **sample)
    assert again["image"].tobytes() == out["image"].tobytes()
    assert np.array_equal(np.asarray(again["bboxes"]), np.asarray(out["bboxes"]))
    assert again["labels"] == out["labels"]


def test_save_applied_params_holds_the_record_and_it_replays():
    tf = A.Compose([_insert(category_ids={"traffic_cone": 3})], save_applied_params=True, seed=2)
    out = tf(image=road_frame(), camera_k=K)
    log = json.loads(json.dumps(out["applied_transforms"]))
    ((name, params),) = log
    assert name == "InsertObjects" and params["insertion"]["placements"]
    fresh = _insert(category_ids={"traffic_cone": 3})
    again = fresh.apply_with_params(params, image=road_frame(), camera_k=K)
    assert again["image"].tobytes() == out["image"].tobytes()
    with pytest.raises(ValueError, match="insertion record"):
        fresh.apply_with_params({"shape": [480, 640, 3]}, image=road_frame())


def test_the_insertion_argument_replays_the_logged_record_instead_of_drawing():
    """``InsertObjects(insertion=record)`` from a ``save_applied_params`` log (through JSON), in a Compose of another
    seed, gives the logged call's bytes, boxes and labels; the same Compose without it draws another insertion."""
    sample = {"image": road_frame(), "bboxes": BOXES, "labels": [1, 2], "camera_k": K}
    bbox = {"format": "coco", "label_fields": ["labels"], "min_visibility": 0.2}
    ids = {"category_ids": {"traffic_cone": 3}}
    out = A.Compose([_insert(**ids)], A.BboxParams(**bbox), save_applied_params=True, seed=2)(**sample)
    ((_, params),) = json.loads(json.dumps(out["applied_transforms"]))
    assert len(out["bboxes"]) > len(BOXES)
    drawn = A.Compose([_insert(**ids)], A.BboxParams(**bbox), seed=9)(**sample)
    assert drawn["image"].tobytes() != out["image"].tobytes()
    again = A.Compose([_insert(insertion=params["insertion"], **ids)], A.BboxParams(**bbox), seed=9)(**sample)
    assert again["image"].tobytes() == out["image"].tobytes()
    assert np.array_equal(np.asarray(again["bboxes"]), np.asarray(out["bboxes"]))
    assert list(again["labels"]) == list(out["labels"])
    unchanged = A.Compose([_insert(insertion={}, **ids)], A.BboxParams(**bbox), seed=9)(**sample)
    assert unchanged["image"].tobytes() == sample["image"].tobytes() and len(unchanged["bboxes"]) == len(BOXES)


@pytest.mark.parametrize("bad", [[1, 2], {"placements": []}, {"x": object()}])
def test_an_insertion_that_is_not_a_record_is_refused_at_construction(bad):
    with pytest.raises(ValueError, match="insertion"):
        _insert(insertion=bad)


def test_a_plain_compose_keeps_no_record_in_its_params():
    tf = A.Compose([_insert()], seed=2)
    tf(image=road_frame(), camera_k=K)
    assert "insertion" not in tf.transforms[0].params


def _args(tmp_path) -> dict:
    """A value other than the default for every argument; a pedestrian-sized box of the user's own; the record of
    an insertion."""
    import trimesh

    tf = A.Compose([_insert()], save_applied_params=True, seed=2)
    ((_, params),) = tf(image=road_frame(), camera_k=K)["applied_transforms"]

    mesh = tmp_path / "pedestrian.obj"
    trimesh.creation.box(extents=(0.45, 1.8, 0.3)).export(mesh)
    return {
        "categories": ["traffic_cone", "person"],
        "max_objects": 4,
        "min_objects": 2,
        "preset": "fast",
        "category_ids": {"traffic_cone": 5, "person": 6},
        "assets": {"person": [str(mesh)]},
        "config_overrides": {"shadow": False, "placement_cfg": {"max_tries": 30}},
        "scene_cache": str(tmp_path / "cache"),
        "scene_cache_items": 7,
        "variants_per_image": 3,
        "variants_seed": 11,
        "mask_values": {"traffic_cone": 2, "person": 1},
        "insertion": json.loads(json.dumps(params["insertion"])),  # as read from a log
        "p": 0.25,
    }


@pytest.mark.parametrize("data_format", ["json", "yaml"])
def test_to_dict_from_dict_save_load_keep_every_argument(tmp_path, data_format):
    import inspect

    args = _args(tmp_path)
    t = InsertObjects(**args)
    assert set(inspect.signature(InsertObjects.__init__).parameters) - {"self"} == set(args)
    d = A.to_dict(t)
    assert {k: v for k, v in d["transform"].items() if k != "__class_fullname__"} == {
        k: tuple(v) if k == "categories" else v for k, v in args.items()
    }
    back = A.from_dict(json.loads(json.dumps(d)))
    path = tmp_path / f"t.{data_format}"
    A.save(t, str(path), data_format=data_format)
    loaded = A.load(str(path), data_format=data_format)
    for other in (back, loaded):
        assert isinstance(other, InsertObjects)
        assert A.to_dict(other) == d
        assert other.config == t.config

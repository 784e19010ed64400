"""Each step reads its own config record (analyse/config.py, plan/config.py, apply/config.py), which the door's flat
``InsertionConfig`` builds from its effective values: the records carry exactly the user's values (a naive paste's
switches off), are checked at construction, and a step given its record makes what it makes given the door's config."""

import dataclasses

import numpy as np
import pytest

from aias_augment.analyse.analysis import analyse_scene, scene_key
from aias_augment.analyse.config import AnalyseConfig, analyse_config
from aias_augment.apply.config import ApplyConfig
from aias_augment.apply.stages import apply_plan
from aias_augment.core.config import ConfigValueError
from aias_augment.core.frame import Frame
from aias_augment.pipeline.config import PRESETS, InsertionConfig, load_preset
from aias_augment.plan.config import PlanConfig
from aias_augment.plan.insertion import plan_insertion
from tests.aias_augment.analyse.test_analysis import CFG, K, road_image
from tests.aias_augment.analyse.test_cache import OneAsset
from tests.aias_augment.fixtures import box_asset

RECORDS = {"analyse": AnalyseConfig, "plan": PlanConfig, "apply": ApplyConfig}
SWITCHES_OFF_IN_A_NAIVE_PASTE = {"placement", "shadow", "lighting", "harmonize"}


def _door_configs():
    for name in PRESETS:
        yield name, load_preset(name)
        yield f"{name}+naive_paste", load_preset(name, naive_paste=True)
    yield "ablation", InsertionConfig(shadow=False, lighting=False, motion_blur_px=(1.0, 4.0), edge_blend=("hard",))


@pytest.mark.parametrize("name, cfg", list(_door_configs()), ids=[n for n, _ in _door_configs()])
def test_each_record_holds_the_door_configs_values(name, cfg):
    """Every field of a record is the door's field of the same name as the user set it, except the stage switches a
    naive paste turns off; and every door field but the per-image share of naive pastes reaches a step."""
    door = dataclasses.asdict(cfg)
    reached = set()
    for attr, cls in RECORDS.items():
        record = getattr(cfg, attr)
        assert type(record) is cls and getattr(cfg, attr) is record  # built once per config
        for key, value in dataclasses.asdict(record).items():
            off = cfg.naive_paste and key in SWITCHES_OFF_IN_A_NAIVE_PASTE
            assert value == (False if off else door[key]), (attr, key)
            reached.add(key)
    assert set(door) - reached == {"naive_share"}


def test_the_records_are_frozen_and_checked_at_construction():
    with pytest.raises(dataclasses.FrozenInstanceError):
        CFG.plan.max_objects = 9
    with pytest.raises(ConfigValueError, match=r"AnalyseConfig\.analysis_max_width"):
        AnalyseConfig(analysis_max_width=10)
    with pytest.raises(ConfigValueError, match=r"PlanConfig\.min_objects.*max_objects"):
        PlanConfig(min_objects=3, max_objects=1)
    with pytest.raises(ConfigValueError, match=r"PlanConfig\.decoy_categories"):
        PlanConfig(decoys=(1, 2))
    with pytest.raises(ConfigValueError, match=r"ApplyConfig\.ssaa"):
        ApplyConfig(ssaa=5)
    with pytest.raises(TypeError, match="AnalyseConfig or a config with one"):
        analyse_config(PlanConfig())


def test_the_scene_key_reads_the_same_fields_as_before():
    """The analysis cache's key hashes the repr of the sorted analysis fields of the effective config: the same
    bytes as the door's config gave (so analyses cached on disk stay valid), and a naive paste's key is the one of
    placement and lighting off."""
    frame = Frame(road_image(), K)
    cfg = load_preset("fast")
    assert scene_key(frame, cfg) == scene_key(frame, cfg.analyse)
    expected = {
        k: getattr(cfg, k)
        for k in (
            "placement",
            "lighting",
            "estimate_camera",
            "camera_height_m",
            "max_camera_pitch_deg",
            "max_camera_roll_deg",
            "default_hfov_deg",
            "lighting_cfg",
            "analysis_max_width",
            "camera_analysis_width",
        )
    }
    assert cfg.analysis_max_width and cfg.analyse.key_fields() == expected
    naive = dataclasses.replace(cfg, naive_paste=True)
    assert scene_key(frame, naive) == scene_key(frame, dataclasses.replace(cfg, placement=False, lighting=False))


def test_each_step_given_its_record_makes_the_same_bytes():
    frame = Frame(road_image(), K)
    bank = OneAsset(box_asset())
    door = analyse_scene(frame, CFG)
    own = analyse_scene(frame, CFG.analyse)
    assert door.key == own.key and door.modules == own.modules
    assert np.array_equal(door.region.mask, own.region.mask) and np.array_equal(door.ground.normal, own.ground.normal)
    a = plan_insertion(door, CFG, np.random.default_rng(3), bank=bank, n_objects=2)
    b = plan_insertion(own, CFG.plan, np.random.default_rng(3), bank=bank, n_objects=2)
    assert a.to_dict() == b.to_dict()
    out_door = apply_plan(frame, door, a, CFG)
    out_own = apply_plan(frame, own, b, CFG.apply)
    assert np.array_equal(out_door.image, out_own.image) and out_door.modules.keys() == out_own.modules.keys()

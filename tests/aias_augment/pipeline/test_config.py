"""InsertionConfig: every value is checked at construction and a bad one names its field.

Before, ``shadow: "false"`` kept the shadow on, ``ssaa: "2"`` failed later with a TypeError naming no field, and the
other cases below passed construction and then every call of the transform was a counted skip.
"""

from __future__ import annotations

import pickle
from dataclasses import replace

import pytest

from aias_augment.analyse.lighting.estimate import LightingConfig
from aias_augment.core.config import CONFIG_DIR, ConfigError, UnknownConfigKeys, load_config
from aias_augment.pipeline.config import PRESETS, HarmonizeMethod, InsertionConfig, load_preset
from aias_augment.plan.placement import PlacementConfig

# (overrides, error type, text the message must hold: the field's dotted path, and what it accepts)
ISSUE_CASES = [
    ({"shadow": "false"}, TypeError, ["InsertionConfig.shadow", "bool", "'false'"]),
    ({"shadow": 0}, TypeError, ["InsertionConfig.shadow", "bool"]),
    ({"ssaa": "2"}, TypeError, ["InsertionConfig.ssaa", "int", "'2'"]),
    ({"ssaa": 2.5}, TypeError, ["InsertionConfig.ssaa", "int", "2.5"]),
    ({"ssaa": 2.0}, TypeError, ["InsertionConfig.ssaa", "int"]),
    ({"ssaa": 0}, ValueError, ["InsertionConfig.ssaa", "[1, 4]"]),
    ({"camera_height_m": "1.6"}, TypeError, ["InsertionConfig.camera_height_m", "number", "'1.6'"]),
    ({"camera_height_m": -1.6}, ValueError, ["InsertionConfig.camera_height_m", "(0, inf)"]),
    (
        {"harmonize_method": "fastt"},
        ValueError,
        ["InsertionConfig.harmonize_method", "'fastt'", "'camera'", "'fast'", "'network'"],
    ),
    ({"shadow_method": "raytraced"}, ValueError, ["InsertionConfig.shadow_method", "'catcher'", "'projected'"]),
    ({"render_method": "cache"}, ValueError, ["InsertionConfig.render_method", "'full'", "'view_cache'"]),
    ({"asset_source": "procedurally"}, ValueError, ["InsertionConfig.asset_source", "'procedural'"]),
    ({"placement_cfg": {"x": 1}}, UnknownConfigKeys, ["InsertionConfig.placement_cfg", "unknown", "'x'", "max_tries"]),
    ({"placement_cfg": 1}, TypeError, ["InsertionConfig.placement_cfg", "PlacementConfig"]),
    (
        {"placement_cfg": {"box_height_tolerance": 0}},
        ValueError,
        ["InsertionConfig.placement_cfg.box_height_tolerance", "(0, inf)"],
    ),
    ({"placement_cfg": {"max_tries": "60"}}, TypeError, ["InsertionConfig.placement_cfg.max_tries", "int"]),
    (
        {"placement_cfg": {"camera_height_range_m": (2.0, 1.0)}},
        ValueError,
        ["InsertionConfig.placement_cfg.camera_height_range_m", "lo<=hi"],
    ),
    (
        {"placement_cfg": {"min_distance_m": 80.0}},
        ValueError,
        ["InsertionConfig.placement_cfg.min_distance_m", "max_distance_m"],
    ),
    ({"lighting_cfg": {"turbidity": 0.5}}, ValueError, ["InsertionConfig.lighting_cfg.turbidity", "[1, 20]"]),
    ({"naive_height_frac_range": (0.4, 0.05)}, ValueError, ["InsertionConfig.naive_height_frac_range", "lo<=hi"]),
    ({"naive_height_frac_range": (0.05,)}, TypeError, ["InsertionConfig.naive_height_frac_range", "2 items"]),
    ({"naive_height_frac_range": (0.05, 1.5)}, ValueError, ["InsertionConfig.naive_height_frac_range", "(0, 1]"]),
    ({"naive_height_frac_samples": (0.1, "0.2")}, TypeError, ["InsertionConfig.naive_height_frac_samples", "item 1"]),
    ({"default_hfov_deg": 0}, ValueError, ["InsertionConfig.default_hfov_deg", "(0, 180)"]),
    ({"default_hfov_deg": 200}, ValueError, ["InsertionConfig.default_hfov_deg", "(0, 180)"]),
    ({"default_hfov_deg": float("nan")}, ValueError, ["InsertionConfig.default_hfov_deg", "(0, 180)"]),
    ({"categories": "traffic_cone"}, TypeError, ["InsertionConfig.categories", "tuple"]),
    ({"categories": ()}, ValueError, ["InsertionConfig.categories", "empty"]),
    ({"min_objects": 4, "max_objects": 3}, ValueError, ["InsertionConfig.min_objects", "max_objects"]),
    ({"analysis_max_width": 32}, ValueError, ["InsertionConfig.analysis_max_width", "64"]),
    # ranges whose extreme makes every image a MemoryError or an endless render: refused at construction
    ({"max_objects": 10000}, ValueError, ["InsertionConfig.max_objects", "[0, 64]", "10000"]),
    ({"max_objects": 65}, ValueError, ["InsertionConfig.max_objects", "[0, 64]"]),
    ({"min_objects": 65, "max_objects": 64}, ValueError, ["InsertionConfig.min_objects", "[0, 64]"]),
    ({"motion_blur_px": (1e6, 1e6)}, ValueError, ["InsertionConfig.motion_blur_px", "[0, 200]", "1000000.0"]),
    ({"motion_blur_px": (0.0, 200.5)}, ValueError, ["InsertionConfig.motion_blur_px", "item 1", "[0, 200]"]),
    ({"edge_feather_px": (1.0, 1e6)}, ValueError, ["InsertionConfig.edge_feather_px", "[0, 50]"]),
    ({"decoys": (0, 1000)}, ValueError, ["InsertionConfig.decoys", "[0, 64]"]),
    ({"ssaa": 64}, ValueError, ["InsertionConfig.ssaa", "[1, 4]"]),
    (
        {"lighting_cfg": {"ambient_map_height": 100000}},
        ValueError,
        ["InsertionConfig.lighting_cfg.ambient_map_height", "[4, 1024]"],
    ),
]


@pytest.mark.parametrize("overrides, error, texts", ISSUE_CASES, ids=[str(c[0]) for c in ISSUE_CASES])
def test_bad_value_raises_at_construction_naming_the_field(overrides, error, texts):
    with pytest.raises(error) as e:
        InsertionConfig(**overrides)
    assert all(t in str(e.value) for t in texts), str(e.value)
    # ... the same through a preset's keyword overrides (the transform's config_overrides) ...
    with pytest.raises(error) as e:
        load_preset("balanced", **overrides)
    assert all(t in str(e.value) for t in texts), str(e.value)
    # ... and through replace() on a valid config
    with pytest.raises(error):
        replace(InsertionConfig(), **overrides)


YAML_CASES = [
    ('shadow: "false"\n', TypeError, "InsertionConfig.shadow"),
    ("ssaa: 2.5\n", TypeError, "InsertionConfig.ssaa"),
    ("camera_height_m: '1.6'\n", TypeError, "InsertionConfig.camera_height_m"),
    ("harmonize_method: fastt\n", ValueError, "InsertionConfig.harmonize_method"),
    ("placement_cfg:\n  x: 1\n", KeyError, "InsertionConfig.placement_cfg"),
    ("placement_cfg:\n  max_tries: 0\n", ValueError, "InsertionConfig.placement_cfg.max_tries"),
    (
        "lighting_cfg:\n  fallback_ground_boxes_m: [[[1, 0], [4, 20]]]\n",
        ValueError,
        "InsertionConfig.lighting_cfg.fallback_ground_boxes_m",
    ),
    ("default_hfov_deg: 200\n", ValueError, "InsertionConfig.default_hfov_deg"),
]


@pytest.mark.parametrize("text, error, field", YAML_CASES, ids=[c[0].split(":")[0] for c in YAML_CASES])
def test_yaml_values_are_checked_and_the_error_names_the_file(tmp_path, text, error, field):
    path = tmp_path / "cfg.yaml"
    path.write_text(text)
    with pytest.raises(error) as e:
        load_config(InsertionConfig, path)
    assert str(path) in str(e.value) and field in str(e.value), str(e.value)


def test_cost_bounds_are_inclusive():
    cfg = InsertionConfig(
        min_objects=64, max_objects=64, motion_blur_px=(200.0, 200.0), edge_feather_px=(50.0, 50.0), ssaa=4
    )
    assert (cfg.max_objects, cfg.motion_blur_px[1], cfg.edge_feather_px[1], cfg.ssaa) == (64, 200.0, 50.0, 4)
    assert InsertionConfig(decoys=(64, 64), decoy_categories=("person",)).decoys == (64, 64)
    assert LightingConfig(ambient_map_height=1024).ambient_map_height == 1024


def test_billion_laughs_under_one_field_is_refused_naming_the_file(tmp_path):
    from aias_augment.core.config_files import ConfigFileError

    refs = ["&a [" + ",".join(["lol"] * 9) + "]"] + [
        f"&{n} [" + ",".join([f"*{p}"] * 9) + "]" for p, n in zip("abcdefgh", "bcdefghi")
    ]
    path = tmp_path / "cfg.yaml"
    path.write_text("motion_blur_px: [" + ", ".join(refs) + "]\n")
    with pytest.raises(ConfigFileError, match="cfg.yaml: expands to more than"):
        load_config(InsertionConfig, path)


def test_valid_yaml_values_load(tmp_path):  # shadow: false is a YAML bool; lists become tuples
    path = tmp_path / "cfg.yaml"
    path.write_text(
        "shadow: false\nnaive_height_frac_range: [0.1, 0.2]\nplacement_cfg:\n  camera_height_range_m: [1, 2]\n"
    )
    cfg = load_config(InsertionConfig, path)
    assert cfg.shadow is False and cfg.naive_height_frac_range == (0.1, 0.2)
    assert cfg.placement_cfg.camera_height_range_m == (1, 2) and hash(cfg)


def test_transform_config_overrides_are_checked_at_construction():
    from aias_augment import InsertObjects

    with pytest.raises(TypeError, match=r"InsertionConfig\.shadow"):
        InsertObjects(config_overrides={"shadow": "false"})
    with pytest.raises(ValueError, match=r"InsertionConfig\.placement_cfg\.max_tries"):
        InsertObjects(config_overrides={"placement_cfg": {"max_tries": 0}})
    with pytest.raises(TypeError, match="not_a_field"):
        InsertObjects(config_overrides={"not_a_field": 1})


def test_every_preset_loads():
    names = sorted(p.stem for p in (CONFIG_DIR / "presets").glob("*.yaml"))
    assert names == sorted(PRESETS)
    for name in names:
        cfg = load_preset(name)
        assert isinstance(cfg, InsertionConfig) and load_preset(name) == cfg


def test_valid_values_are_kept_as_given():
    # ints for floats stay ints (the scene-cache key is made of these values); lists and NumPy scalars become the
    # tuples and Python numbers a frozen, hashable, JSON-able config holds
    import numpy as np

    cfg = InsertionConfig(
        camera_height_m=2,
        min_objects=np.int64(2),
        naive_height_frac_range=[0.1, 0.3],
        placement_cfg={"max_tries": 5, "box_height_frac_samples": np.array([0.1, 0.2])},
        lighting_cfg=LightingConfig(analysis_width=200),
    )
    assert cfg.camera_height_m == 2 and type(cfg.camera_height_m) is int
    assert type(cfg.min_objects) is int and cfg.naive_height_frac_range == (0.1, 0.3)
    assert cfg.placement_cfg == PlacementConfig(max_tries=5, box_height_frac_samples=(0.1, 0.2))
    assert hash(cfg) == hash(replace(cfg))
    assert InsertionConfig() == InsertionConfig(
        **{k: getattr(InsertionConfig(), k) for k in InsertionConfig.__dataclass_fields__}
    )


def test_nested_mapping_override_updates_the_presets_nested_config():
    accurate = load_preset("accurate")
    assert accurate.placement_cfg.max_tries == 120
    cfg = load_preset("accurate", placement_cfg={"sizes_from_existing": True})
    assert cfg.placement_cfg == replace(accurate.placement_cfg, sizes_from_existing=True)
    # a mapping given to the constructor is a whole config (fields it does not name take the defaults)
    assert InsertionConfig(placement_cfg={"max_tries": 7}).placement_cfg == PlacementConfig(max_tries=7)


def test_harmonize_methods_agree_with_the_harmonizer():
    from typing import get_args

    from aias_augment.apply.harmonize.api import METHODS

    assert set(get_args(HarmonizeMethod)) == set(METHODS)
    from aias_augment.core.stages.edge_blend import MODES
    from aias_augment.pipeline.config import EdgeBlendMode

    assert set(get_args(EdgeBlendMode)) == set(MODES)


def test_config_errors_pickle():  # offline workers send errors between processes
    with pytest.raises(ConfigError) as e:
        InsertionConfig(placement_cfg={"max_tries": 0})
    back = pickle.loads(pickle.dumps(e.value))
    assert type(back) is type(e.value) and str(back) == str(e.value)
    assert e.value.field == "placement_cfg.max_tries"

"""Config inheritance (``_base_``): the merge rules, the one-line errors, and the shipped configs' effective values
against a fixture captured from the flat configs they were before inheriting."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import pytest

from aias_augment.core.config_files import ConfigFileError
from detection_eval.config import load_detector_config
from detection_eval.inherit import load_inherited, merge_configs
from detection_eval.study.config import load_study_config

REPO = Path(__file__).resolve().parents[2]
FIXTURE = Path(__file__).with_name("effective_configs.json")


def test_merge_dicts_recursively_child_wins_lists_replaced():
    base = {"a": 1, "m": {"x": 1, "y": [1, 2], "n": {"p": 1}}, "keep": "b"}
    child = {"a": 2, "m": {"y": [3], "n": {"q": 2}}}
    assert merge_configs(base, child) == {"a": 2, "m": {"x": 1, "y": [3], "n": {"p": 1, "q": 2}}, "keep": "b"}
    assert base == {"a": 1, "m": {"x": 1, "y": [1, 2], "n": {"p": 1}}, "keep": "b"}  # inputs untouched


def test_delete_replaces_instead_of_merging():
    base = {"m": {"x": 1, "y": 2}, "z": 0}
    assert merge_configs(base, {"m": {"_delete_": True, "y": 5}}) == {"m": {"y": 5}, "z": 0}
    assert merge_configs(base, {"m": {"_delete_": False, "y": 5}}) == {"m": {"x": 1, "y": 5}, "z": 0}


def test_bases_relative_to_the_file_in_order(tmp_path):
    (tmp_path / "sub").mkdir()
    (tmp_path / "a.yaml").write_text("v: a\nonly_a: 1\nm: {x: 1}\n")
    (tmp_path / "sub" / "b.yaml").write_text("_base_: ../a.yaml\nv: b\nm: {y: 2}\n")
    (tmp_path / "c.yaml").write_text("v: c\nm: {_delete_: true, z: 3}\n")
    (tmp_path / "child.yaml").write_text("_base_: [sub/b.yaml, c.yaml]\nonly_child: true\n")
    assert load_inherited(tmp_path / "child.yaml") == {"v": "c", "only_a": 1, "m": {"z": 3}, "only_child": True}
    assert load_inherited(tmp_path / "sub" / "b.yaml") == {"v": "b", "only_a": 1, "m": {"x": 1, "y": 2}}


def test_cycle_and_missing_base_are_one_line_errors(tmp_path):
    (tmp_path / "a.yaml").write_text("_base_: b.yaml\n")
    (tmp_path / "b.yaml").write_text("_base_: a.yaml\n")
    with pytest.raises(ConfigFileError, match=r"cycle: a.yaml -> b.yaml -> a.yaml") as e:
        load_inherited(tmp_path / "a.yaml")
    assert "\n" not in str(e.value)
    (tmp_path / "c.yaml").write_text("_base_: nowhere.yaml\n")
    with pytest.raises(ConfigFileError, match=r"_base_ 'nowhere.yaml' not found") as e:
        load_study_config(tmp_path / "c.yaml")
    assert "\n" not in str(e.value)
    (tmp_path / "d.yaml").write_text("_base_: {x: 1}\n")
    with pytest.raises(ConfigFileError, match="_base_ must be a path or a list"):
        load_detector_config(tmp_path / "d.yaml")
    (tmp_path / "e.yaml").write_text("_base_: e.yaml\n")
    with pytest.raises(ConfigFileError, match="cycle"):
        load_inherited(tmp_path / "e.yaml")


def test_safe_loading_only(tmp_path):
    (tmp_path / "a.yaml").write_text("x: !!python/object/apply:os.getcwd []\n")
    (tmp_path / "b.yaml").write_text("_base_: a.yaml\n")
    with pytest.raises(ConfigFileError):
        load_inherited(tmp_path / "b.yaml")


def _effective(cfg) -> dict:
    return json.loads(json.dumps(dataclasses.asdict(cfg)))


STUDY_CONFIGS = {
    "tracon_cones": "studies/detection/lite0_320/config.yaml",
    "tracon_cones_ablations": "studies/detection/lite0_320/ablations.yaml",
    "tracon_cones_amounts": "studies/detection/lite0_320/amounts.yaml",
    "tracon_cones_closeup": "studies/detection/lite0_320/closeup.yaml",
    "tracon_cones_online": "studies/detection/lite0_320/online.yaml",
    "tracon_cones_procedural": "studies/detection/lite0_320/procedural.yaml",
    "tracon_cones_core": "studies/detection/core/config.yaml",
    "tracon_cones_probe": "studies/detection/probe/config.yaml",
    "tracon_cones_probe_n200": "studies/detection/probe_n200/config.yaml",
}


def _study_folder(path: str) -> str:
    return path.rsplit("/", 1)[0] + "/result"


def test_shipped_configs_inherit_and_keep_their_effective_values():
    """Every shipped study and detector config loads to the values the flat file had, key by key (the fixture was
    written from the configs before they named a ``_base_``); only ``results_dir`` points to the study's folder."""
    before = json.loads(FIXTURE.read_text())
    assert set(before["study"]) == set(STUDY_CONFIGS)
    for name, path in STUDY_CONFIGS.items():
        text = (REPO / path).read_text()
        assert "_base_" in text, path
        now = _effective(load_study_config(REPO / path))
        want = dict(before["study"][name], results_dir=_study_folder(path))
        assert now == want, path
    for name, want in before["detector"].items():
        assert _effective(load_detector_config(REPO / "configs" / "detector" / f"{name}.yaml")) == want, name
    inheriting = [n for n in before["detector"] if "_base_" in (REPO / f"configs/detector/{n}.yaml").read_text()]
    assert set(inheriting) >= {"lite0_320_b", "lite0_320_c", "cspdarknet_tiny", "cspdarknet_s"}

"""Config files read at a bounded cost: alias expansion, nesting, size, encoding, strict JSON."""

from __future__ import annotations

import math

import pytest
import yaml
from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st

from aias_augment.core.config import CONFIG_DIR, load_config
from aias_augment.core.config_files import (
    MAX_CONFIG_BYTES,
    MAX_NESTING,
    MAX_YAML_NODES,
    ConfigFileError,
    check_yaml_graph,
    load_json_file,
    load_yaml_file,
    parse_json,
    parse_yaml,
)
from aias_augment.core.errors import InputError
from aias_augment.pipeline.config import InsertionConfig


def laughs(levels: int, width: int = 9, field: str = "motion_blur_px") -> str:
    """A "billion laughs" under one field: ``width ** levels`` leaves once every alias is expanded."""
    names = "abcdefghijklmnop"
    parts = ["&a [" + ",".join(["lol"] * width) + "]"]
    for i in range(1, levels):
        parts.append(f"&{names[i]} [" + ",".join([f"*{names[i - 1]}"] * width) + "]")
    return f"{field}: [" + ", ".join(parts) + "]\n"


def expanded_nodes(levels: int, width: int = 9) -> int:
    """Independent count of the nodes of :func:`laughs` with every alias expanded: the mapping, its key, the outer
    list, and level k (k = 1..levels) as a list of width copies of level k - 1 (level 0: one scalar)."""
    size = [1]
    for _ in range(levels):
        size.append(1 + width * size[-1])
    return 3 + sum(size[1:])


def test_billion_laughs_refused_before_construction(tmp_path):
    p = tmp_path / "bomb.yaml"
    p.write_text(laughs(9))
    assert len(p.read_bytes()) < 400
    with pytest.raises(ConfigFileError, match=r"bomb.yaml: expands to more than 100000 nodes"):
        load_config(InsertionConfig, p)


def test_six_level_laughs_refused_by_load_config(tmp_path):
    # 9**6 = 531441 leaves: the plain safe_load + type check reads it (as a type error); the bounded loader refuses
    p = tmp_path / "bomb6.yaml"
    p.write_text(laughs(6))
    with pytest.raises(ConfigFileError, match="expands to more than"):
        load_config(InsertionConfig, p)


@pytest.mark.parametrize("levels", [1, 2, 3, 4])
def test_expanded_count_matches_an_independent_count(levels):
    node = yaml.compose(laughs(levels), Loader=yaml.SafeLoader)
    assert check_yaml_graph(node) == expanded_nodes(levels)


def test_bound_is_exact():
    node = yaml.compose(laughs(4), Loader=yaml.SafeLoader)
    n = expanded_nodes(4)
    assert check_yaml_graph(node, max_nodes=n) == n
    with pytest.raises(Exception, match="expands to more than"):
        check_yaml_graph(node, max_nodes=n - 1)


def test_small_aliases_and_merge_keys_still_load():
    data = parse_yaml("base: &b {x: 1, y: 2}\nother:\n  <<: *b\n  y: 3\nlist: [*b, *b]\n", "t.yaml")
    assert data == {"base": {"x": 1, "y": 2}, "other": {"x": 1, "y": 3}, "list": [{"x": 1, "y": 2}] * 2}


def test_recursive_alias_refused():
    with pytest.raises(ConfigFileError, match=r"^t.yaml: a recursive alias"):
        parse_yaml("a: &a [1, *a]\n", "t.yaml")


@pytest.mark.parametrize("depth", [MAX_NESTING + 1, 5000])
def test_deep_nesting_refused_in_one_line(depth):
    with pytest.raises(ConfigFileError, match="nested deeper than") as e:
        parse_yaml("[" * depth + "]" * depth, "t.yaml")
    assert "\n" not in str(e.value)
    with pytest.raises(ConfigFileError, match="nested deeper than"):
        parse_json("[" * depth + "]" * depth, "t.json")


def test_nesting_at_the_bound_loads():
    assert parse_json("[" * MAX_NESTING + "]" * MAX_NESTING, "t") is not None
    assert parse_yaml("[" * (MAX_NESTING - 1) + "]" * (MAX_NESTING - 1), "t") is not None


def test_non_utf8_config_one_line(tmp_path):
    p = tmp_path / "latin1.yaml"
    text = "motion_blur_px: [0.0, 2.0]  # d\xe9j\xe0\n"
    p.write_bytes(text.encode("latin-1"))
    where = f"byte 0xe9 at offset {text.index(chr(0xE9))}"
    with pytest.raises(ConfigFileError, match=rf"latin1.yaml: not UTF-8 \({where}\); save it as UTF-8$"):
        load_config(InsertionConfig, p)


def test_utf8_bom_accepted(tmp_path):
    p = tmp_path / "bom.yaml"
    p.write_bytes(b"\xef\xbb\xbfmotion_blur_px: [0.0, 2.0]\n")
    assert load_config(InsertionConfig, p).motion_blur_px == (0.0, 2.0)


def test_oversized_file_refused_without_reading_it_all(tmp_path):
    p = tmp_path / "big.yaml"
    p.write_bytes(b"# " + b"x" * MAX_CONFIG_BYTES + b"\n")
    with pytest.raises(ConfigFileError, match=f"larger than {MAX_CONFIG_BYTES} bytes"):
        load_yaml_file(p)


def test_unreadable_file_one_line(tmp_path):
    with pytest.raises(ConfigFileError, match="cannot read it"):
        load_yaml_file(tmp_path)  # a folder
    with pytest.raises(ConfigFileError, match=r"^--flag x: cannot read it"):
        load_json_file(tmp_path / "missing.json", "--flag x")


@pytest.mark.parametrize("text", ["NaN", "[Infinity]", '{"a": -Infinity}'])
def test_json_non_finite_constants_refused(text):
    with pytest.raises(ConfigFileError, match="is not a JSON number"):
        parse_json(text, "t.json")


def test_json_finite_numbers_kept():
    assert parse_json('{"a": [1, 2.5e3, -0.0]}', "t") == {"a": [1, 2500.0, -0.0]}


def test_every_shipped_config_loads_far_below_the_bound():
    files = sorted(CONFIG_DIR.rglob("*.yaml"))
    assert len(files) >= 10
    for f in files:
        node = yaml.compose(f.read_text(), Loader=yaml.SafeLoader)
        assert check_yaml_graph(node) < MAX_YAML_NODES / 10, f
        load_yaml_file(f)


@settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(
    st.lists(st.sampled_from([*"[]{}&*ab:,- \n\t'\"!<>|0.9", "\x00", "\ud7ff", "NaN", "<<"]), max_size=60).map("".join)
)
def test_fuzz_yaml_gives_a_value_or_one_line_error(text):
    try:
        parse_yaml(text, "f.yaml")
    except ConfigFileError as e:
        assert "\n" not in str(e) and str(e).startswith("f.yaml: ")


@settings(max_examples=300, deadline=None)
@given(st.lists(st.sampled_from([*'[]{}",:0123456789.eE-+ ', "NaN", "Infinity", "true", "null"])).map("".join))
@example("1e310")  # past the float range: json reads it as inf
@example("[-1.5e999]")
def test_fuzz_json_gives_a_finite_value_or_one_line_error(text):
    try:
        v = parse_json(text, "f.json")
    except ConfigFileError as e:
        assert "\n" not in str(e) and str(e).startswith("f.json: ")
        return
    stack = [v]
    while stack:
        x = stack.pop()
        if isinstance(x, float):
            assert math.isfinite(x)
        elif isinstance(x, dict):
            stack.extend(x.values())
        elif isinstance(x, list):
            stack.extend(x)


# ------------------------------------------------------------------- every config reader goes through the loader
def _read_with(reader: str, path):
    if reader == "aias-augment --config":
        from aias_augment.cli.augment import insertion_config

        return insertion_config("fast", str(path), None, None)
    if reader == "aias-augment --box-convention":
        from aias_augment.cli.augment import read_box_convention

        return read_box_convention(str(path))
    if reader == "--yolo data.yaml":
        from aias_augment.cli.yolo_io import read_yolo_dataset

        return read_yolo_dataset(path)
    if reader == "clip --camera":
        from aias_augment.cli.clip_inputs import read_camera

        return read_camera(path, 640, 480)
    if reader == "asset sidecar":
        from aias_augment.assets.bank.sidecar import read_sidecar

        return read_sidecar(path)
    if reader == "taxonomy":
        from aias_augment.assets.bank.taxonomy import load_taxonomy

        return load_taxonomy(path)
    if reader == "detector config":
        from detection_eval.config import load_detector_config

        return load_detector_config(path)
    if reader == "study config":
        from detection_eval.study.config import load_study_config

        return load_study_config(path)
    raise AssertionError(reader)


READERS = [
    "aias-augment --config",
    "--yolo data.yaml",
    "clip --camera",
    "asset sidecar",
    "taxonomy",
    "detector config",
    "study config",
]


@pytest.mark.parametrize("reader", READERS)
@pytest.mark.parametrize("bad", ["laughs", "latin1"])
def test_every_yaml_reader_is_bounded(tmp_path, reader, bad):
    p = tmp_path / f"{bad}.yaml"
    p.write_bytes(laughs(9, field="fx").encode() if bad == "laughs" else "fx: 1  # caf\xe9\n".encode("latin-1"))
    # an InputError (ConfigFileError, or the clip reader's own UTF-8 check): one line naming the file
    with pytest.raises(InputError, match="expands to more than" if bad == "laughs" else "not UTF-8") as e:
        _read_with(reader, p)
    assert f"{bad}.yaml" in str(e.value) and "\n" not in str(e.value)


def test_box_convention_json_is_strict(tmp_path):
    p = tmp_path / "bc.json"
    p.write_text('{"box_convention": [NaN, 0, 0, 0]}')
    with pytest.raises(ConfigFileError, match=r"^--box-convention .*bc.json: not valid JSON \(NaN is not"):
        _read_with("aias-augment --box-convention", p)

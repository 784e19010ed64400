"""config.checked_config: every field of every checked config is checked at construction.

Property tests walk the fields of every checked class from its own type hints and bounds (``config_spec``), so a
field added later is covered without touching this file: a value of the wrong type raises a TypeError, a value out of
its bounds (or not one of its Literal strings, or an inverted (lo, hi) pair) a ValueError, and either names the field
(``Class.field``; ``InsertionConfig.placement_cfg.field`` when the nested config comes as a mapping).
"""

from __future__ import annotations

import math
import types
import typing
from dataclasses import dataclass

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from aias_augment.analyse.config import AnalyseConfig
from aias_augment.analyse.lighting.estimate import LightingConfig
from aias_augment.analyse.region import RegionConfig
from aias_augment.core.config import (
    CHECKED_CONFIGS,
    ConfigTypeError,
    ConfigValueError,
    Interval,
    UnknownConfigKeys,
    checked_config,
    config_spec,
    from_dict,
)
from aias_augment.pipeline.config import InsertionConfig
from aias_augment.plan.collision import CollisionConfig
from aias_augment.plan.config import PlanConfig
from aias_augment.plan.placement import PlacementConfig

# Every checked config of the package (the imports above load them all; classes checked later join by themselves).
CLASSES = [c for c in CHECKED_CONFIGS if c.__module__.startswith("aias_augment.")]
NESTED = {PlacementConfig: "placement_cfg", LightingConfig: "lighting_cfg"}  # fields of InsertionConfig
SETTINGS = settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.too_slow])


def _fields(pred=lambda spec: True):
    return [
        pytest.param(cls, spec, id=f"{cls.__name__}.{name}")
        for cls in CLASSES
        for name, spec in config_spec(cls).items()
        if pred(spec)
    ]


def _split(tp):
    return typing.get_origin(tp), typing.get_args(tp)


def _is_optional(tp) -> bool:
    origin, args = _split(tp)
    return origin in (typing.Union, types.UnionType) and type(None) in args


def _inner(tp):
    return next(a for a in typing.get_args(tp) if a is not type(None))


def _per_position(bounds, n):
    return bounds if isinstance(bounds, tuple) else (bounds,) * n


# ------------------------------------------------------------------------------------------------------ strategies
def valid(tp, bounds=None) -> st.SearchStrategy:
    """Values a field of hint ``tp`` accepts (numbers inside ``bounds``, (lo, hi) pairs in order)."""
    origin, args = _split(tp)
    if tp is bool:
        return st.booleans()
    if tp in (int, float):
        b = bounds or Interval(-math.inf, math.inf, True, True)
        lo, hi = max(b.lo, -1e6), min(b.hi, 1e6)
        if tp is int:
            return st.integers(
                math.ceil(lo) + (b.lo_open and lo == math.ceil(lo)),
                math.floor(hi) - (b.hi_open and hi == math.floor(hi)),
            )
        return st.floats(lo, hi, exclude_min=b.lo_open and lo == b.lo, exclude_max=b.hi_open and hi == b.hi)
    if tp is str:
        return st.text(max_size=8)
    if origin is typing.Literal:
        return st.sampled_from(args)
    if _is_optional(tp):
        return st.none() | valid(_inner(tp), bounds)
    if origin is tuple:
        if args[-1] is Ellipsis:
            return st.lists(valid(args[0], bounds), max_size=3).map(tuple)
        parts = st.tuples(*(valid(a, b) for a, b in zip(args, _per_position(bounds, len(args)))))
        order = bounds.order if isinstance(bounds, Interval) else ""
        if order and len(args) == 2 and all(a in (int, float) for a in args):
            parts = parts.map(lambda t: tuple(sorted(t)))
            if order == "lo<hi":
                parts = parts.filter(lambda t: t[0] < t[1])
        return parts
    if isinstance(tp, type) and hasattr(tp, "__dataclass_fields__"):
        return st.sampled_from([tp(), {}])  # a nested config, or a mapping of its fields
    raise AssertionError(f"no strategy for {tp}")


WRONG_SCALARS = {
    bool: st.one_of(
        st.text(max_size=5),
        st.sampled_from(["false", "true", "no"]),
        st.integers(),
        st.floats(allow_nan=False),
        st.none(),
        st.lists(st.booleans(), max_size=2),
    ),
    int: st.one_of(st.floats(), st.text(max_size=5), st.sampled_from(["2", "1e3"]), st.booleans(), st.none()),
    float: st.one_of(
        st.text(max_size=5),
        st.sampled_from(["1.6", "1e-3"]),
        st.booleans(),
        st.none(),
        st.lists(st.floats(), max_size=2),
        st.complex_numbers(min_magnitude=1),
    ),
    str: st.one_of(st.integers(), st.floats(), st.booleans(), st.none(), st.lists(st.text(), max_size=2)),
}


def wrong_type(tp, bounds=None) -> st.SearchStrategy:
    """Values of the wrong type for hint ``tp`` (for a tuple: not a sequence, the wrong length, or one bad item)."""
    origin, args = _split(tp)
    if tp in WRONG_SCALARS:
        return WRONG_SCALARS[tp]
    if origin is typing.Literal:
        return WRONG_SCALARS[str]
    if _is_optional(tp):
        return wrong_type(_inner(tp), bounds).filter(lambda v: v is not None)
    if origin is tuple:
        not_a_sequence = st.one_of(
            st.integers(),
            st.floats(),
            st.text(max_size=5),
            st.booleans(),
            st.dictionaries(st.text(max_size=2), st.integers(), max_size=2),
        )
        if args[-1] is Ellipsis:
            bad_item = st.tuples(
                st.lists(valid(args[0], bounds), max_size=2), wrong_type(args[0], bounds), st.integers(0, 2)
            ).map(lambda t: tuple(t[0][: t[2]] + [t[1]] + t[0][t[2] :]))
            return not_a_sequence | bad_item
        per = _per_position(bounds, len(args))
        wrong_length = st.lists(valid(args[0], per[0]), max_size=len(args) + 2).filter(lambda v: len(v) != len(args))

        @st.composite
        def bad_item(draw):
            i = draw(st.integers(0, len(args) - 1))
            items = [draw(valid(a, b)) for a, b in zip(args, per)]
            items[i] = draw(wrong_type(args[i], per[i]))
            return tuple(items)

        return not_a_sequence | wrong_length | bad_item()
    if isinstance(tp, type) and hasattr(tp, "__dataclass_fields__"):
        return st.one_of(st.integers(), st.text(max_size=5), st.none(), st.lists(st.integers(), max_size=2))
    raise AssertionError(f"no strategy for {tp}")


def _outside(tp, b: Interval) -> st.SearchStrategy:
    below, above = [], []
    if b.lo > -math.inf:
        below.append(
            st.floats(max_value=b.lo, exclude_max=not b.lo_open, allow_nan=False)
            if tp is float
            else st.integers(max_value=math.ceil(b.lo) - (not b.lo_open or b.lo != math.ceil(b.lo)))
        )
    elif tp is float and b.lo_open:
        below.append(st.just(-math.inf))
    if b.hi < math.inf:
        above.append(
            st.floats(min_value=b.hi, exclude_min=not b.hi_open, allow_nan=False)
            if tp is float
            else st.integers(min_value=math.floor(b.hi) + (not b.hi_open or b.hi != math.floor(b.hi)))
        )
    elif tp is float and b.hi_open:
        above.append(st.just(math.inf))
    if tp is float:
        below.append(st.just(math.nan))
    return st.one_of(*below, *above)


def out_of_range(tp, bounds) -> st.SearchStrategy | None:
    """Values of the right type that break the field's bounds: a number (one item of a tuple) outside its interval,
    a string not among a Literal's, an inverted (lo, hi) pair; None when the field has no bounds."""
    origin, args = _split(tp)
    if origin is typing.Literal:
        return st.text(max_size=10).filter(lambda s: s not in args)
    if bounds is None:
        return None
    if tp in (int, float):
        return _outside(tp, bounds)
    if _is_optional(tp):
        return out_of_range(_inner(tp), bounds)
    if origin is tuple:
        if args[-1] is Ellipsis:
            bad = out_of_range(args[0], bounds)
            options = (
                []
                if bad is None
                else [
                    st.tuples(st.lists(valid(args[0], bounds), max_size=2), bad, st.integers(0, 2)).map(
                        lambda t: tuple(t[0][: t[2]] + [t[1]] + t[0][t[2] :])
                    )
                ]
            )
        else:
            per = _per_position(bounds, len(args))
            options = []
            for i in range(len(args)):
                bad = out_of_range(args[i], per[i])
                if bad is not None:
                    options.append(
                        st.tuples(*(bad if j == i else valid(a, b) for j, (a, b) in enumerate(zip(args, per))))
                    )
            order = bounds.order if isinstance(bounds, Interval) else ""
            if order and len(args) == 2 and all(a in (int, float) for a in args):
                pairs = st.tuples(valid(args[0], bounds), valid(args[1], bounds))
                options.append(pairs.filter(lambda t: t[0] > t[1] or (order == "lo<hi" and t[0] == t[1])))
        return st.one_of(*options) if options else None
    raise AssertionError(f"no strategy for {tp}")


def _assert_names(error, cls, name, value):
    text = str(error)
    assert f"{cls.__name__}.{name}" in text, (value, text)
    if cls in NESTED:  # ... and the dotted path when it comes as a mapping inside InsertionConfig
        with pytest.raises(type(error)) as nested:
            InsertionConfig(**{NESTED[cls]: {name: value}})
        assert f"InsertionConfig.{NESTED[cls]}.{name}" in str(nested.value), (value, str(nested.value))


# ------------------------------------------------------------------------------------------------- property tests
def test_every_checked_config_is_covered():
    assert {InsertionConfig, PlacementConfig, LightingConfig, CollisionConfig, RegionConfig} <= set(CLASSES)
    for cls in CLASSES:
        for name, spec in config_spec(cls).items():  # every hint is one the checker and these strategies know
            wrong_type(spec.hint, spec.bounds)
            cls(**{name: getattr(cls(), name)})


@pytest.mark.parametrize("cls, spec", _fields())
@SETTINGS
@given(data=st.data())
def test_wrong_type_raises_naming_the_field(cls, spec, data):
    value = data.draw(wrong_type(spec.hint, spec.bounds), label=spec.name)
    with pytest.raises(TypeError) as e:
        cls(**{spec.name: value})
    assert isinstance(e.value, ConfigTypeError)
    _assert_names(e.value, cls, spec.name, value)


@pytest.mark.parametrize("cls, spec", _fields(lambda s: out_of_range(s.hint, s.bounds) is not None))
@SETTINGS
@given(data=st.data())
def test_out_of_range_raises_naming_the_field(cls, spec, data):
    value = data.draw(out_of_range(spec.hint, spec.bounds), label=spec.name)
    with pytest.raises(ValueError) as e:
        cls(**{spec.name: value})
    assert isinstance(e.value, ConfigValueError)
    _assert_names(e.value, cls, spec.name, value)


@pytest.mark.parametrize("cls, spec", _fields())
@SETTINGS
@given(data=st.data())
def test_valid_values_construct(cls, spec, data):
    value = data.draw(valid(spec.hint, spec.bounds), label=spec.name)
    if spec.name in {lo for c in CLASSES for lo, _, _ in c.__config_orders__} | {
        hi for c in CLASSES for _, hi, _ in c.__config_orders__
    }:
        return  # bounded against another field: tested below
    cross = {
        "analysis_max_width",
        "camera_analysis_width",
        "categories",
        "decoys",
        "decoy_categories",
        "family_members",
    }
    if cls in (InsertionConfig, AnalyseConfig, PlanConfig) and spec.name in cross:
        return  # cross-value rules of their own __post_init__ (test_insertion config tests, test_decoys, test_family_cache)
    cfg = cls(**{spec.name: value})
    expected = spec.hint(**value) if isinstance(value, dict) else value
    assert getattr(cfg, spec.name) == expected and hash(cfg) == hash(cls(**{spec.name: value}))


@SETTINGS
@given(lo=st.integers(0, 50), hi=st.integers(0, 50))
def test_field_orders(lo, hi):
    if lo <= hi:
        assert InsertionConfig(min_objects=lo, max_objects=hi).max_objects == hi
    else:
        with pytest.raises(ValueError, match=r"InsertionConfig\.min_objects.*max_objects"):
            InsertionConfig(min_objects=lo, max_objects=hi)
    lo_m, hi_m = float(lo), float(hi) + 0.5
    if lo_m <= hi_m:
        PlacementConfig(min_distance_m=lo_m, max_distance_m=hi_m)
    else:
        with pytest.raises(ValueError, match=r"PlacementConfig\.min_distance_m.*max_distance_m"):
            PlacementConfig(min_distance_m=lo_m, max_distance_m=hi_m)


@pytest.mark.parametrize("cls", list(NESTED))
def test_unknown_nested_keys_raise_naming_the_path(cls):
    with pytest.raises(UnknownConfigKeys) as e:
        InsertionConfig(**{NESTED[cls]: {"no_such_field": 1}})
    assert f"InsertionConfig.{NESTED[cls]}" in str(e.value) and "no_such_field" in str(e.value)
    assert isinstance(e.value, KeyError) and isinstance(e.value, ValueError) and isinstance(e.value, TypeError)


# ------------------------------------------------------------------------------------------------- the checker
def test_interval_notation():
    i = Interval.parse("(0, 180)")
    assert 1 in i and 0 not in i and 180 not in i and math.nan not in i and str(i) == "(0, 180)"
    j = Interval.parse("[1, inf) lo<=hi")
    assert 1 in j and math.inf not in j and j.order == "lo<=hi" and str(j) == "[1, inf)"
    for bad in ["0, 1", "(1, 0)", "[a, 1]", "(0, 1] lo>hi"]:
        with pytest.raises(ValueError):
            Interval.parse(bad)


def test_a_bad_specification_fails_when_the_class_is_made_or_first_built():
    with pytest.raises(TypeError, match="name no field"):

        @checked_config({"nope": "[0, 1]"})
        @dataclass(frozen=True)
        class A:
            x: float = 0.5

    with pytest.raises(TypeError, match="default fails"):

        @checked_config({"x": "[0, 1]"})
        @dataclass(frozen=True)
        class B:
            x: float = 2.0

        B()
    with pytest.raises(TypeError, match="no config check"):

        @checked_config()
        @dataclass(frozen=True)
        class C:
            x: dict = None

        C()


def test_a_class_without_post_init_is_checked_and_its_own_post_init_runs_after():
    calls = []

    @checked_config({"x": "[0, 1]"})
    @dataclass(frozen=True)
    class D:
        x: float = 0.5
        flag: bool = False

    @checked_config({"x": "[0, 1]"})
    @dataclass(frozen=True)
    class E:
        x: float = 0.5

        def __post_init__(self):
            calls.append(self.x)  # sees a checked value only

    assert D(x=1).x == 1
    with pytest.raises(ValueError, match=r"D\.x"):
        D(x=2)
    with pytest.raises(TypeError, match=r"D\.flag"):
        D(flag="yes")
    E(x=0.25)
    with pytest.raises(TypeError, match=r"E\.x"):
        E(x="0.5")
    assert calls == [0.25]


def test_from_dict_names_the_source():
    with pytest.raises(TypeError, match=r"^somewhere\.yaml: PlacementConfig\.max_tries: expected an int"):
        from_dict(PlacementConfig, {"max_tries": 2.5}, where="somewhere.yaml")
    with pytest.raises(KeyError, match="unknown config keys"):
        from_dict(PlacementConfig, {"max_trie": 2})

"""Strict dataclass configs loaded from YAML: an unknown key is an error, never a silent no-op, and a value of the
wrong type or out of range is an error at construction (:func:`checked_config`), naming the field."""

from __future__ import annotations

import dataclasses
import functools
import math
import operator
import os
import re
import types
import typing
from collections.abc import Callable, Iterable, Mapping
from pathlib import Path
from typing import Any, TypeVar

import numpy as np

from aias_augment.core.config_files import load_yaml_file
from aias_augment.core.errors import AiasError

T = TypeVar("T")

REPO_ROOT = Path(__file__).resolve().parents[2]
# The shipped configs (presets, taxonomy, detector and study configs) and checkpoints. In a checkout
# ``aias_augment/_data/{configs,checkpoints}`` are symlinks to the repository's top-level folders; a built wheel holds
# copies (``[tool.setuptools.package-data]``), so an installed package loads ``preset="balanced"`` from anywhere.
PACKAGE_DATA = Path(__file__).resolve().parents[1] / "_data"
CONFIG_DIR = PACKAGE_DATA / "configs"
CHECKPOINT_DIR = PACKAGE_DATA / "checkpoints"


def data_root() -> Path:
    """Root of the real data: ``$AIAS_DATA`` or ``../shared/data`` beside the repository."""
    env = os.environ.get("AIAS_DATA")
    return Path(env) if env else (REPO_ROOT.parent / "shared" / "data")


def from_dict(cls: type[T], data: dict[str, Any] | None, where: str = "") -> T:
    """Build dataclass ``cls`` from a mapping, recursing into nested dataclass fields.

    Raises :class:`UnknownConfigKeys` (a ``KeyError``) naming the unknown keys (with the path inside the config),
    :class:`ConfigTypeError` (a ``TypeError``) for non-mappings, and for a :func:`checked_config` class its
    construction errors (a value of the wrong type or out of range), prefixed with ``where`` (e.g. the YAML file).
    """
    data = {} if data is None else data
    source = where
    where = where or cls.__name__
    if not isinstance(data, dict):
        raise ConfigTypeError((cls.__name__,), f"expected a mapping, got {type(data).__name__}", source or "")
    fields = {f.name: f for f in dataclasses.fields(cls)}
    unknown = sorted(set(data) - set(fields), key=str)
    if unknown:
        raise UnknownConfigKeys((), f"{where}: unknown config keys {unknown}; allowed: {sorted(fields)}")
    if is_checked_config(cls):
        kwargs = data  # its construction converts lists and nested mappings, naming a bad field by its dotted path
    else:
        hints = _hints(cls)
        kwargs = {}
        for name, value in data.items():
            tp = hints[name]
            if dataclasses.is_dataclass(tp) and isinstance(value, dict):
                value = from_dict(tp, value, f"{where}.{name}")
            elif isinstance(value, list) and (
                typing.get_origin(tp) is tuple or any(typing.get_origin(a) is tuple for a in typing.get_args(tp))
            ):  # tuple or Optional[tuple]
                value = tuple(value)
            kwargs[name] = value
    try:
        return cls(**kwargs)
    except ConfigError as e:
        raise (e.from_source(source) if source else e) from None


def load_config(cls: type[T], path: str | Path) -> T:
    """Load ``cls`` from a YAML file (a bare name is looked up in ``configs/``) through the bounded loader
    (:func:`~aias_augment.core.config_files.load_yaml_file`: size, UTF-8 and alias expansion checked)."""
    p = Path(path)
    if not p.exists() and not p.suffix:
        p = CONFIG_DIR / f"{path}.yaml"
    if not p.exists():
        raise FileNotFoundError(f"config not found: {path}")
    data = load_yaml_file(p) or {}
    return from_dict(cls, data, where=str(p))


def to_dict(obj) -> dict:
    return dataclasses.asdict(obj)


_HINTS: dict[type, dict[str, Any]] = {}


def _hints(cls: type) -> dict[str, Any]:
    """``typing.get_type_hints(cls)``, resolved once per class."""
    h = _HINTS.get(cls)
    if h is None:
        h = _HINTS[cls] = typing.get_type_hints(cls)
    return h


# ------------------------------------------------------------------------------- typed configs checked at construction
class ConfigError(AiasError):
    """A config value of the wrong type, out of its range, or an unknown key; ``path`` names the field from the class
    down (``("InsertionConfig", "placement_cfg", "max_tries")``), ``source`` the file it came from, if any."""

    def __init__(self, path: tuple[str, ...], reason: str, source: str = ""):
        super().__init__(path, reason, source)
        self.path, self.reason, self.source = tuple(path), reason, source

    @property
    def field(self) -> str:
        """The dotted field path below the class (``"placement_cfg.max_tries"``)."""
        return ".".join(self.path[1:])

    def __str__(self) -> str:
        where = ".".join(self.path)
        text = f"{where}: {self.reason}" if where else self.reason
        return f"{self.source}: {text}" if self.source else text

    def under(self, owner: str, name: str) -> "ConfigError":
        """The same error seen from ``owner``, whose field ``name`` holds the config that raised it."""
        return type(self)((owner, name) + self.path[1:], self.reason, self.source)

    def from_source(self, source: str) -> "ConfigError":
        return self if self.source else type(self)(self.path, self.reason, source)


class ConfigTypeError(ConfigError, TypeError):
    """A config value of the wrong type (a string for a bool, a float for an int, a tuple of the wrong length...)."""


class ConfigValueError(ConfigError, ValueError):
    """A config value of the right type outside its allowed range or set."""


class UnknownConfigKeys(ConfigError, KeyError, TypeError, ValueError):
    """Keys that are no field of the config: a KeyError (what :func:`from_dict` raised before), a TypeError (what an
    unknown keyword argument raises) and a ValueError (like the other config errors), so any of them catches it."""


_INTERVAL = re.compile(r"^\s*([\[(])\s*([^,\s]+)\s*,\s*([^\]\)\s]+)\s*([\])])\s*(lo<=hi|lo<hi)?\s*$")


@dataclasses.dataclass(frozen=True)
class Interval:
    """Allowed values of a number (every number of a tuple field), in interval notation: ``"(0, 180)"``,
    ``"[1, inf)"``, ``"(0, 1] lo<=hi"`` (the suffix: each (lo, hi) pair of the value must be ordered so)."""

    lo: float
    hi: float
    lo_open: bool
    hi_open: bool
    order: str = ""  # "", "lo<=hi" or "lo<hi"

    @classmethod
    def parse(cls, spec: str) -> "Interval":
        m = _INTERVAL.match(spec)
        if not m:
            raise ValueError(f"bad interval {spec!r}; write e.g. '(0, 180)', '[1, inf)', '(0, 1] lo<=hi'")
        lo, hi = float(m[2]), float(m[3])
        if not lo <= hi:
            raise ValueError(f"bad interval {spec!r}: lo > hi")
        return cls(lo, hi, m[1] == "(", m[4] == ")", m[5] or "")

    def __contains__(self, v) -> bool:  # NaN is in no interval
        return ((self.lo < v) if self.lo_open else (self.lo <= v)) and (
            (v < self.hi) if self.hi_open else (v <= self.hi)
        )

    def __str__(self) -> str:
        def num(x):
            return "inf" if x == math.inf else "-inf" if x == -math.inf else f"{x:g}"

        return f"{'(' if self.lo_open else '['}{num(self.lo)}, {num(self.hi)}{')' if self.hi_open else ']'}"


@dataclasses.dataclass(frozen=True)
class FieldSpec:
    """What a config field accepts: its type hint and, for numbers, the interval(s) (one per tuple position, or one
    for every number of the value)."""

    name: str
    hint: Any
    bounds: Interval | tuple[Interval, ...] | None = None


Check = Callable[[Any], Any]  # value -> the value to store (a list becomes a tuple...), or raises ConfigError


def _desc(tp) -> str:
    origin, args = typing.get_origin(tp), typing.get_args(tp)
    if tp is bool:
        return "a bool (true or false)"
    if tp is int:
        return "an int"
    if tp is float:
        return "a number"
    if tp is str:
        return "a str"
    if origin is typing.Literal:
        return "one of " + ", ".join(repr(a) for a in args)
    if origin in (typing.Union, types.UnionType):
        return " or ".join("None" if a is type(None) else _desc(a) for a in args)
    if origin is tuple:
        if len(args) == 2 and args[1] is Ellipsis:
            plural = {bool: "bools", int: "ints", float: "numbers", str: "strs"}
            return f"a tuple of {plural.get(args[0]) or '(' + _desc(args[0]) + ')s'}"
        return f"a tuple ({', '.join(_desc(a) for a in args)})"
    if dataclasses.is_dataclass(tp):
        return f"a {tp.__name__} or a mapping of its fields"
    return repr(tp)


def _got(v) -> str:
    text = repr(v)
    return f"{type(v).__name__} {text if len(text) <= 80 else text[:77] + '...'}"


def _wrong_type(tp, v) -> ConfigTypeError:
    hint = ""
    if isinstance(v, str) and tp is bool:
        hint = " (write true or false unquoted: a quoted 'false' is a non-empty string)"
    elif isinstance(v, str) and tp in (int, float):
        try:
            float(v)
            hint = " (write the number unquoted; YAML reads 1e-3 as a string: write 1.0e-3)"
        except ValueError:
            pass
    return ConfigTypeError((), f"expected {_desc(tp)}, got {_got(v)}{hint}")


def _compile(tp, bounds, where: str) -> Check:
    """The check of values of hint ``tp`` (numbers in ``bounds``); ``where`` names the class and field for errors in
    the specification itself (raised when the class is first built)."""
    origin, args = typing.get_origin(tp), typing.get_args(tp)
    if isinstance(bounds, tuple) and not (origin is tuple and args[-1:] != (Ellipsis,) and len(args) == len(bounds)):
        raise TypeError(f"{where}: per-position bounds need a fixed-length tuple hint of as many items, got {tp}")
    if bounds is not None and not _numeric(tp):
        raise TypeError(f"{where}: bounds on a field without numbers ({tp})")
    if tp is bool:

        def check(v):
            if type(v) is bool:
                return v
            if isinstance(v, np.bool_):
                return bool(v)
            raise _wrong_type(bool, v)

        return check
    if tp is int or tp is float:
        return _number_check(tp, bounds)
    if tp is str:

        def check(v):
            if type(v) is str or isinstance(v, str):
                return v
            raise _wrong_type(str, v)

        return check
    if origin is typing.Literal:
        if not all(isinstance(a, str) for a in args):
            raise TypeError(f"{where}: only Literal strings are supported, got {tp}")
        allowed = frozenset(args)

        def check(v):
            if type(v) is str and v in allowed:
                return v
            if not isinstance(v, str):
                raise _wrong_type(tp, v)
            if v not in allowed:
                raise ConfigValueError((), f"must be one of {', '.join(repr(a) for a in args)}; got {v!r}")
            return v

        return check
    if origin in (typing.Union, types.UnionType):
        if len(args) != 2 or type(None) not in args:
            raise TypeError(f"{where}: only 'X | None' unions are supported, got {tp}")
        inner = _compile(next(a for a in args if a is not type(None)), bounds, where)

        def check(v):
            if v is None:
                return v
            try:
                return inner(v)
            except ConfigTypeError as e:
                if e.reason.startswith("expected"):  # the value itself, not one of its items: say None is allowed
                    raise _wrong_type(tp, v) from None
                raise

        return check
    if origin is tuple:
        return _tuple_check(tp, bounds, where)
    if dataclasses.is_dataclass(tp):
        names = frozenset(f.name for f in dataclasses.fields(tp) if f.init)

        def check(v):
            if isinstance(v, tp):
                return v
            if not isinstance(v, Mapping):
                raise _wrong_type(tp, v)
            unknown = sorted(set(v) - names, key=str)
            if unknown:
                raise UnknownConfigKeys((tp.__name__,), f"unknown config keys {unknown}; allowed: {sorted(names)}")
            try:
                return tp(**v)
            except ConfigError:
                raise
            except (TypeError, ValueError) as e:  # a class's own cross-field checks
                raise (ConfigTypeError if isinstance(e, TypeError) else ConfigValueError)((tp.__name__,), str(e))

        return check
    raise TypeError(
        f"{where}: no config check for the type hint {tp!r}; use bool, int, float, str, Literal[...], "
        "tuple[...], X | None or a config dataclass"
    )


def _number_check(tp, bounds: Interval | None) -> Check:
    """int: an integer (not a bool, not 2.0); float: any real number. NumPy scalars become Python numbers."""
    np_kinds = (np.integer,) if tp is int else (np.integer, np.floating)
    is_float = tp is float
    lo, hi = (bounds.lo, bounds.hi) if bounds is not None else (-math.inf, math.inf)
    lo_open, hi_open = (bounds.lo_open, bounds.hi_open) if bounds is not None else (False, False)

    def check(v):
        t = type(v)
        if not (t is int or (is_float and t is float)):
            if isinstance(v, np_kinds):
                v = v.item()
            elif isinstance(v, bool) or not isinstance(v, (int, float) if is_float else int):
                raise _wrong_type(tp, v)
        if bounds is not None and not ((v > lo if lo_open else v >= lo) and (v < hi if hi_open else v <= hi)):
            raise ConfigValueError((), f"must be in {bounds}, got {v!r}")  # NaN is in no interval
        return v

    return check


def _tuple_check(tp, bounds, where: str) -> Check:
    """tuple[X, ...] or tuple[X, Y, ...] (a list or a 1-D array is taken as one); an ``order`` in ``bounds`` checks
    every (lo, hi) pair of numbers inside."""
    args = typing.get_args(tp)
    variadic = len(args) == 2 and args[1] is Ellipsis
    if not args or (Ellipsis in args and not variadic):
        raise TypeError(f"{where}: write the tuple's item types (tuple[float, float], tuple[int, ...]), got {tp}")
    if variadic:
        item, items, n = _compile(args[0], bounds, where), None, None
    else:
        per = bounds if isinstance(bounds, tuple) else (bounds,) * len(args)
        items, n = tuple(_compile(a, b, where) for a, b in zip(args, per)), len(args)
    order = bounds.order if isinstance(bounds, Interval) else ""
    pair = order and n == 2 and all(a in (int, float) for a in args)
    strict = order == "lo<hi"

    def check(v):
        if type(v) is not tuple:
            if isinstance(v, np.ndarray):
                v = v.tolist()
            if not isinstance(v, (tuple, list)):
                raise _wrong_type(tp, v)
        if n is not None and len(v) != n:
            raise ConfigTypeError((), f"expected {_desc(tp)}: {n} items, got {len(v)}: {v!r}")
        try:
            out = tuple([item(x) for x in v] if items is None else [f(x) for f, x in zip(items, v)])
        except ConfigError:
            for i, x in enumerate(v):  # say which item
                try:
                    item(x) if items is None else items[i](x)
                except ConfigError as e:
                    raise type(e)((), f"item {i} of {_got(v)}: {e.reason}") from None
            raise
        if pair and not (out[0] < out[1] if strict else out[0] <= out[1]):
            raise ConfigValueError((), f"needs {order} in each (lo, hi), got {_got(v)}")
        return v if type(v) is tuple and all(map(operator.is_, out, v)) else out

    return check


def _numeric(tp) -> bool:
    if tp is int or tp is float:
        return True
    return any(_numeric(a) for a in typing.get_args(tp) if a is not Ellipsis)


@dataclasses.dataclass(frozen=True)
class _ClassCheck:
    checks: tuple[tuple[str, Check, Any], ...]  # (field, check, its default object, skipped when found)
    orders: tuple[tuple[str, str, bool], ...]  # (lo field, hi field, strict)


_CHECKS: dict[type, _ClassCheck] = {}
_NO_DEFAULT = object()
CHECKED_CONFIGS: list[type] = []  # every class decorated with checked_config, in definition order


def config_spec(cls: type) -> dict[str, FieldSpec]:
    """The fields of a :func:`checked_config` class: type hint and bounds (what its construction checks)."""
    hints = _hints(cls)
    bounds = cls.__config_bounds__
    return {f.name: FieldSpec(f.name, hints[f.name], bounds.get(f.name)) for f in dataclasses.fields(cls) if f.init}


def _class_check(cls: type) -> _ClassCheck:
    cc = _CHECKS.get(cls)
    if cc is None:
        defaults = {f.name: f.default for f in dataclasses.fields(cls)}
        checks = []
        for name, spec in config_spec(cls).items():
            check = _compile(spec.hint, spec.bounds, f"{cls.__name__}.{name}")
            default = defaults[name]
            if default is not dataclasses.MISSING:
                try:
                    if check(default) is not default:
                        default = _NO_DEFAULT  # stored converted: checked each time
                except ConfigError as e:
                    raise TypeError(f"{cls.__name__}.{name}: the default fails its own check: {e}") from None
            checks.append((name, check, default))
        cc = _CHECKS[cls] = _ClassCheck(tuple(checks), cls.__config_orders__)
    return cc


def _check_fields(self) -> None:
    cls = type(self)
    cc = _CHECKS.get(cls) or _class_check(cls)
    values = self.__dict__
    for name, check, default in cc.checks:
        v = values[name]
        if v is default:  # the class's own default object (immutable, checked once): nothing to check
            continue
        try:
            new = check(v)
        except ConfigError as e:
            raise e.under(cls.__name__, name) from None
        if new is not v:
            object.__setattr__(self, name, new)
    for lo_name, hi_name, strict in cc.orders:
        lo, hi = values[lo_name], values[hi_name]
        if not (lo < hi if strict else lo <= hi):
            raise ConfigValueError(
                (cls.__name__, lo_name), f"must be {'<' if strict else '<='} {hi_name} ({hi!r}), got {lo!r}"
            )


def checked_config(
    bounds: Mapping[str, str | tuple[str, ...]] | None = None, *, orders: Iterable[str] = ()
) -> Callable[[type[T]], type[T]]:
    """Class decorator (above ``@dataclass``): every construction (``cls(...)``, ``dataclasses.replace``,
    :func:`from_dict`) checks every field against its type hint before the class's own ``__post_init__``.

    - ``bool`` takes only True/False (not "false", not 0); ``int`` only integers (not 2.5, not 2.0); ``float`` any
      real number; ``str``; ``Literal["a", "b"]`` one of its strings; ``X | None``; ``tuple[float, float]`` and
      ``tuple[int, ...]`` (a list is stored as a tuple); a nested config dataclass, or a mapping of its fields (built
      into it; unknown keys raise). NumPy scalars are stored as Python ones.
    - ``bounds``: field -> interval of its numbers (:class:`Interval` notation, e.g. ``"(0, 180)"``, ``"[1, inf)"``,
      ``"(0, 1] lo<=hi"``), or a tuple of intervals, one per position of a fixed-length tuple.
    - ``orders``: ``"min_x <= max_x"`` or ``"a < b"`` between two fields.

    Errors are :class:`ConfigTypeError` (a TypeError) or :class:`ConfigValueError` (a ValueError) naming the field
    by its dotted path (``InsertionConfig.placement_cfg.max_tries``) and what it accepts. The type hints are
    resolved once per class, on its first construction.
    """
    parsed_orders = []
    for o in orders:
        m = re.fullmatch(r"\s*(\w+)\s*(<=|<)\s*(\w+)\s*", o)
        if not m:
            raise ValueError(f"bad order {o!r}; write 'min_x <= max_x'")
        parsed_orders.append((m[1], m[3], m[2] == "<"))

    def wrap(cls):
        if not dataclasses.is_dataclass(cls):
            raise TypeError("checked_config goes above @dataclass")
        names = {f.name for f in dataclasses.fields(cls)}
        parsed = {}
        for name, spec in (bounds or {}).items():
            parsed[name] = tuple(Interval.parse(s) for s in spec) if isinstance(spec, tuple) else Interval.parse(spec)
        bad = sorted((set(parsed) | {n for o in parsed_orders for n in o[:2]}) - names)
        if bad:
            raise TypeError(f"{cls.__name__}: bounds/orders name no field: {bad}")
        cls.__config_bounds__ = parsed
        cls.__config_orders__ = tuple(parsed_orders)
        own = cls.__dict__.get("__post_init__")
        if own is not None:  # the dataclass __init__ calls it: check the fields first

            def __post_init__(self):
                _check_fields(self)
                own(self)

            __post_init__.__doc__ = own.__doc__
            cls.__post_init__ = __post_init__
        else:  # an __init__ made without a __post_init__ never calls one: check after it
            init = cls.__init__

            def __init__(self, *args, **kwargs):
                init(self, *args, **kwargs)
                _check_fields(self)

            functools.update_wrapper(__init__, init)
            cls.__init__ = __init__
        CHECKED_CONFIGS.append(cls)
        return cls

    return wrap


def is_checked_config(cls) -> bool:
    return isinstance(cls, type) and "__config_bounds__" in cls.__dict__

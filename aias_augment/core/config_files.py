"""Reading YAML and JSON config files at a bounded cost: every config reader of the package goes through here.

- A file is read only up to :data:`MAX_CONFIG_BYTES` (the shipped configs are a few KB) and must be UTF-8.
- YAML: the safe loader (no Python objects), with alias expansion capped. Aliases are shared in the composed graph,
  so a 363-byte "billion laughs" composes to a few dozen nodes; what explodes is every later walk over the data
  (type checks, ``repr`` in an error message). The node count the document would have with every alias expanded is
  computed on the composed graph (each distinct node once) and refused above :data:`MAX_YAML_NODES` before a single
  Python object is built; a recursive alias (``&a [*a]``) and nesting deeper than :data:`MAX_NESTING` are refused too.
- JSON: ``NaN``, ``Infinity`` and ``-Infinity`` (not JSON, but Python's reader takes them) are refused; nesting
  deeper than :data:`MAX_NESTING` too.

Every problem raises :class:`ConfigFileError` (an :class:`~aias_augment.core.errors.InputError`), one line:
``"<source>: <reason>"``.
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import yaml

from aias_augment.core.errors import AiasError, InputError

MAX_CONFIG_BYTES = 1 << 20
# The largest shipped config (configs/taxonomy.yaml) has ~1500 nodes: 100k leaves room for any hand-written file and
# bounds the cost of everything that walks the data (~100 bytes a node: ~10 MB).
MAX_YAML_NODES = 100_000
MAX_NESTING = 64


class ConfigFileError(InputError):
    """A config file that cannot be read as a bounded YAML/JSON document; ``source`` names the file (or flag)."""

    def __init__(self, source: str, reason: str):
        super().__init__(f"{source}: {reason}")
        self.source, self.reason = source, reason

    def __reduce__(self):
        return (type(self), (self.source, self.reason))


def read_config_text(path: str | Path, source: str | None = None, *, max_bytes: int = MAX_CONFIG_BYTES) -> str:
    """The text of a config file: at most ``max_bytes`` read, UTF-8 (a BOM is dropped); :class:`ConfigFileError`
    otherwise (``source`` names it in the message, default the path)."""
    p = Path(path)
    source = str(p) if source is None else source
    try:
        with open(p, "rb") as f:
            data = f.read(max_bytes + 1)
    except OSError as e:
        raise ConfigFileError(source, f"cannot read it ({e.strerror or e})") from None
    if len(data) > max_bytes:
        raise ConfigFileError(source, f"larger than {max_bytes} bytes: not a config file")
    try:
        return data.decode("utf-8-sig")
    except UnicodeDecodeError as e:
        raise ConfigFileError(
            source, f"not UTF-8 (byte 0x{data[e.start]:02x} at offset {e.start}); save it as UTF-8"
        ) from None


class _Refused(AiasError):
    """Raised inside the loader; :func:`parse_yaml` adds the source."""


def _children(node: yaml.Node) -> list:
    if isinstance(node, yaml.SequenceNode):
        return node.value
    if isinstance(node, yaml.MappingNode):
        return [n for kv in node.value for n in kv]
    return []


def check_yaml_graph(root: yaml.Node, max_nodes: int = MAX_YAML_NODES, max_nesting: int = MAX_NESTING) -> int:
    """The number of nodes ``root`` has with every alias expanded (each distinct node visited once, iteratively);
    raises ``_Refused`` above ``max_nodes``, deeper than ``max_nesting`` or on a recursive alias."""
    size: dict[int, int] = {}
    entered: set[int] = set()
    stack: list[tuple[yaml.Node, int, bool]] = [(root, 1, False)]
    while stack:
        node, depth, done = stack.pop()
        key = id(node)
        if done:
            entered.discard(key)
            n = 1 + sum(size[id(c)] for c in _children(node))
            if n > max_nodes:
                raise _Refused(f"expands to more than {max_nodes} nodes (aliases of aliases): refused")
            size[key] = n
            continue
        if key in size:
            continue
        if key in entered:
            raise _Refused(f"a recursive alias (line {node.start_mark.line + 1}): refused")
        if depth > max_nesting:
            raise _Refused(f"nested deeper than {max_nesting} levels (line {node.start_mark.line + 1})")
        entered.add(key)
        stack.append((node, depth, True))
        stack.extend((c, depth + 1, False) for c in _children(node))
    return size[id(root)]


class BoundedSafeLoader(yaml.SafeLoader):
    """``yaml.SafeLoader`` that checks the composed document with :func:`check_yaml_graph` before constructing it."""

    def compose_document(self):
        node = super().compose_document()
        if node is not None:
            check_yaml_graph(node)
        return node


def parse_yaml(text: str, source: str) -> Any:
    """``text`` as YAML (one document) with :class:`BoundedSafeLoader`; :class:`ConfigFileError` naming ``source``."""
    try:
        return yaml.load(text, Loader=BoundedSafeLoader)  # noqa: S506 (a SafeLoader subclass)
    except _Refused as e:
        raise ConfigFileError(source, str(e)) from None
    except yaml.YAMLError as e:
        raise ConfigFileError(source, f"not valid YAML ({' '.join(str(e).split())})") from None
    except RecursionError:
        raise ConfigFileError(source, f"nested deeper than {MAX_NESTING} levels") from None


def _no_constant(name: str):
    raise ValueError(f"{name} is not a JSON number")


def _finite_float(text: str) -> float:
    value = float(text)
    if not math.isfinite(value):  # a literal past the float range (1e310) reads as inf
        raise ValueError(f"{text} is out of the float range")
    return value


def _json_depth(value: Any) -> int:
    depth, level = 0, [value]
    while level:
        depth += 1
        nxt = []
        for v in level:
            if isinstance(v, dict):
                nxt.extend(v.values())
            elif isinstance(v, list):
                nxt.extend(v)
        level = nxt
    return depth


def parse_json(text: str, source: str) -> Any:
    """``text`` as strict JSON (no NaN/Infinity nor a number past the float range, nesting <= :data:`MAX_NESTING`);
    :class:`ConfigFileError`."""
    try:
        value = json.loads(text, parse_constant=_no_constant, parse_float=_finite_float)
    except ValueError as e:  # json.JSONDecodeError, and a NaN/Infinity refused by _no_constant
        raise ConfigFileError(source, f"not valid JSON ({e})") from None
    except RecursionError:
        raise ConfigFileError(source, f"nested deeper than {MAX_NESTING} levels") from None
    if _json_depth(value) > MAX_NESTING:
        raise ConfigFileError(source, f"nested deeper than {MAX_NESTING} levels")
    return value


def load_yaml_file(path: str | Path, source: str | None = None) -> Any:
    """A YAML config file (see the module docstring); ``source`` names it in errors (default the path)."""
    source = str(path) if source is None else source
    return parse_yaml(read_config_text(path, source), source)


def load_json_file(path: str | Path, source: str | None = None) -> Any:
    """A JSON config file (see the module docstring); ``source`` names it in errors (default the path)."""
    source = str(path) if source is None else source
    return parse_json(read_config_text(path, source), source)

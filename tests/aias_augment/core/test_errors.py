"""One error base: every exception class that aias_augment and detection_eval define is an ``AiasError`` and keeps
its builtin base, so ``except AiasError`` catches any project error and ``except ValueError`` still works."""

from __future__ import annotations

import ast
import json
import subprocess
import sys
from pathlib import Path

import pytest

import aias_augment
from aias_augment.core import errors
from aias_augment.core.config import ConfigValueError
from aias_augment.core.config_files import ConfigFileError, parse_json
from aias_augment.core.errors import AiasError, InputError
from aias_augment.pipeline.config import InsertionConfig

# Imports every module of both packages in a fresh interpreter (a ``__main__`` module would run its program) and
# prints each exception class defined there: whether it is an AiasError and its builtin exception bases.
_ENUMERATE = """
import importlib, inspect, json, pkgutil
from aias_augment.core.errors import AiasError
found, broken = {}, []
for root in ("aias_augment", "detection_eval"):
    pkg = importlib.import_module(root)
    names = [root] + [m.name for m in pkgutil.walk_packages(pkg.__path__, root + ".", onerror=broken.append)]
    for name in names:
        if name.rsplit(".", 1)[-1] == "__main__":
            continue
        try:
            module = importlib.import_module(name)
        except Exception as e:
            broken.append(f"{name}: {e!r}")
            continue
        for obj in vars(module).values():
            if inspect.isclass(obj) and issubclass(obj, BaseException) and obj.__module__.split(".")[0] == root:
                builtin = sorted(c.__name__ for c in obj.__mro__ if c.__module__ == "builtins" and c is not object)
                found[f"{obj.__module__}.{obj.__qualname__}"] = [issubclass(obj, AiasError), builtin]
print(json.dumps({"found": found, "broken": broken}))
"""


@pytest.fixture(scope="module")
def project_exceptions() -> dict[str, list]:
    out = subprocess.run([sys.executable, "-c", _ENUMERATE], capture_output=True, text=True, check=True).stdout
    result = json.loads(out.strip().splitlines()[-1])
    assert result["broken"] == [], "modules that do not import: " + "; ".join(result["broken"])
    return result["found"]


def test_every_exception_class_of_the_project_is_an_aias_error(project_exceptions):
    # The walk reaches every layer (core, analyse, plan, assets, adapters, cli, evaluation), not only core.
    for name in (
        "aias_augment.core.config.ConfigValueError",
        "aias_augment.core.plane_fit.GroundFitError",
        "aias_augment.plan.local_ground.UnevenGroundError",
        "aias_augment.assets.bank.db.BankError",
        "aias_augment.adapters.boundary.ImageSkip",
        "aias_augment.cli.manifest.OutputBusy",
        "aias_augment.evaluation.abstudy.store.DuplicateVote",
    ):
        assert name in project_exceptions, name
    outside = sorted(name for name, (is_aias, _) in project_exceptions.items() if not is_aias)
    assert outside == [], f"exception classes without AiasError as a base: {outside}"


@pytest.mark.parametrize(
    ("name", "builtin"),
    [
        ("aias_augment.core.errors.InputError", "ValueError"),
        ("aias_augment.core.config.ConfigValueError", "ValueError"),
        ("aias_augment.core.config.ConfigTypeError", "TypeError"),
        ("aias_augment.core.config.UnknownConfigKeys", "KeyError"),
        ("aias_augment.core.image_io.CorruptImage", "ValueError"),
        ("aias_augment.assets.errors.AssetError", "ValueError"),
        ("aias_augment.cli.manifest.ManifestMismatch", "RuntimeError"),
        ("aias_augment.cli.clip.ClipNotVisible", "RuntimeError"),
        ("aias_augment.adapters.boundary.SampleSkip", "ValueError"),
    ],
)
def test_each_class_keeps_its_builtin_base(project_exceptions, name, builtin):
    assert builtin in project_exceptions[name][1]


def test_a_raised_config_error_is_caught_both_as_aias_error_and_as_value_error():
    for call, cls in (
        (lambda: InsertionConfig(analysis_max_width=10), ConfigValueError),
        (lambda: parse_json("{", "cfg.json"), ConfigFileError),
    ):
        with pytest.raises(AiasError) as caught:
            call()
        assert type(caught.value) is cls
        with pytest.raises(ValueError):
            call()
    assert issubclass(InputError, ValueError) and issubclass(ConfigValueError, ValueError)


def test_the_base_is_exported_and_its_module_imports_nothing():
    assert aias_augment.AiasError is AiasError and "AiasError" in aias_augment.__all__
    assert AiasError.__bases__ == (Exception,)
    tree = ast.parse(Path(errors.__file__).read_text())
    assert [n for n in ast.walk(tree) if isinstance(n, (ast.Import, ast.ImportFrom))] == []

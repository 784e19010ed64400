"""Every command line the package installs takes ``--log-level`` and ``--quiet`` (and each of its subcommands does);
``detection-eval --help`` lists all its subcommands; a real ``aias-augment`` run prints no INFO line by default, this
project's INFO with ``--log-level INFO``, other libraries' INFO only with ``--log-level DEBUG``, and with ``--quiet``
nothing but errors."""

from __future__ import annotations

import importlib
import os
import re
import subprocess
import sys

import cv2
import pytest
import tomllib

from aias_augment.assets.asset import DEFAULT_ASSETS
from aias_augment.core.config import REPO_ROOT, data_root

#: The installed commands, read from the package's own declaration (a new command is checked without editing here).
SCRIPTS = tomllib.loads((REPO_ROOT / "pyproject.toml").read_text())["project"]["scripts"]


def _help(entry: str, argv: list[str], capsys) -> str:
    module, func = entry.split(":")
    with pytest.raises(SystemExit) as e:
        getattr(importlib.import_module(module), func)([*argv, "--help"])
    assert e.value.code == 0
    return capsys.readouterr().out


def _subcommands(usage: str) -> list[str]:
    """The ``{a,b,c}`` choice of subcommands in an argparse help text, or none."""
    groups = re.findall(r"\{([\w,-]+)\}", usage.split("\n\n")[0])
    subs = [g.split(",") for g in groups if g != "DEBUG,INFO,WARNING,ERROR"]
    return subs[0] if subs else []


@pytest.mark.parametrize("name", sorted(SCRIPTS))
def test_every_command_and_subcommand_has_the_logging_flags(name, capsys):
    top = _help(SCRIPTS[name], [], capsys)
    for argv in ([], *([s] for s in _subcommands(top))):
        text = top if not argv else _help(SCRIPTS[name], argv, capsys)
        assert "--log-level {DEBUG,INFO,WARNING,ERROR}" in text and "--quiet" in text, (name, argv)


def test_detection_eval_help_lists_all_subcommands(capsys):
    assert set(_subcommands(_help(SCRIPTS["detection-eval"], [], capsys))) == {"eval", "train", "predict"}


def test_aias_augment_help_holds_the_clip_options(capsys):
    text = _help(SCRIPTS["aias-augment"], [], capsys)
    assert all(f in text for f in ("--camera", "--poses", "--log-level", "--quiet"))


def _tiny_tracon(tmp_path):
    """A real TraCon road photo at half size."""
    src = data_root() / "tracon" / "images" / "train" / "cone (101).jpg"
    img = cv2.imread(str(src))
    (tmp_path / "in").mkdir()
    cv2.imwrite(str(tmp_path / "in" / "road.jpg"), cv2.resize(img, (img.shape[1] // 2, img.shape[0] // 2)))
    return tmp_path / "in"


def _augment(images, out, *flags, preset="fast"):
    env = {**os.environ, "PYOPENGL_PLATFORM": "egl", "NO_ALBUMENTATIONS_UPDATE": "1"}
    cmd = [sys.executable, "-m", "aias_augment.cli.augment", "--images", str(images), "--preset", preset]
    return subprocess.run(
        [*cmd, "--out", str(out), *flags], capture_output=True, text=True, env=env, cwd=REPO_ROOT, timeout=300
    )


def _records(stderr: str) -> set[tuple[str, str]]:
    """(level, logger) of each log line; progress bars share stderr and are split off at their carriage returns."""
    out = set()
    for line in re.split(r"[\r\n]", stderr):
        m = re.search(r"\b(DEBUG|INFO|WARNING|ERROR) ([\w.]+):", line)
        if m:
            out.add((m.group(1), m.group(2)))
    return out


@pytest.mark.skipif(
    not (data_root() / DEFAULT_ASSETS["traffic_cone"][0]).exists()
    or not (data_root() / "tracon" / "images" / "train" / "cone (101).jpg").exists(),
    reason="shared data not present",
)
def test_real_run_prints_no_library_info_by_default(tmp_path):
    images = _tiny_tracon(tmp_path)
    runs = {}
    for key, flags in {"default": (), "info": ("--log-level", "INFO"), "debug": ("--log-level", "DEBUG")}.items():
        r = _augment(images, tmp_path / key, *flags, preset="balanced")  # balanced: the GL renderer runs
        assert r.returncode == 0, r.stderr[-2000:]
        assert "'inserted': 0," not in r.stdout  # the renderer ran: an object was drawn
        runs[key] = _records(r.stderr)
    assert not {rec for rec in runs["default"] if rec[0] in ("DEBUG", "INFO")}, runs["default"]
    info = {name for level, name in runs["info"] if level == "INFO"}
    assert info and all(n.split(".")[0] == "aias_augment" for n in info), runs["info"]
    # The libraries' INFO (PyOpenGL's OpenGL_accelerate line) is there, only asked for with DEBUG.
    assert any(level == "INFO" and name.split(".")[0] == "OpenGL" for level, name in runs["debug"]), runs["debug"]

    quiet = _augment(images, tmp_path / "quiet", "--quiet")
    assert quiet.returncode == 0 and quiet.stderr == ""  # no progress bar, no log line
    assert (tmp_path / "quiet" / "annotations.json").exists()
    bad = _augment(tmp_path / "missing", tmp_path / "bad", "--quiet")
    assert bad.returncode == 2 and bad.stderr.strip().splitlines() == [
        f"aias-augment: error: {tmp_path / 'missing'} is not a folder"
    ]

"""An installed wheel carries the presets, taxonomy, detector configs and checkpoints: built here, unpacked outside the
checkout, and imported from there in a fresh process (the checkout must not be what answers)."""

from __future__ import annotations

import json
import shutil
import subprocess
import sys
import zipfile
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]

PROBE = r"""
import json, sys
import aias_augment
from aias_augment.pipeline.config import load_preset
from aias_augment.assets.bank.taxonomy import load_taxonomy
from aias_augment.apply.harmonize.api import DEFAULT_CHECKPOINTS
from detection_eval.config import load_detector_config
out = {"module": aias_augment.__file__,
       "presets": {n: load_preset(n).ssaa for n in ("fast", "balanced", "accurate")},
       "taxonomy": sorted(load_taxonomy().categories),
       "checkpoints": {k: (str(v), v.is_file()) for k, v in DEFAULT_CHECKPOINTS.items()},
       "fast_npz": __import__("aias_augment.apply.harmonize.fast_infer", fromlist=["x"]).load_fast_np(
           DEFAULT_CHECKPOINTS["fast"]).cfg.thumbnail_px,
       "detector": load_detector_config("lite0_320").train.img_size}
print(json.dumps(out))
"""


@pytest.mark.slow
def test_wheel_ships_configs_and_checkpoints(tmp_path):
    # build from a copy: an in-tree build leaves build/ in the checkout (and stale files there can leak into wheels)
    src = tmp_path / "src"
    shutil.copytree(
        REPO,
        src,
        symlinks=True,
        ignore=shutil.ignore_patterns(
            ".git",
            ".venv",
            "out",
            "runs",
            "logs",
            "cache",
            "build",
            "results",
            "*.egg-info",
            "__pycache__",
            ".hypothesis",
        ),
    )
    wheel_dir = tmp_path / "wheel"
    # with build isolation, as `make setup`'s `pip install -e .` builds: the venv's own setuptools may predate the
    # build requirements in pyproject.toml
    r = subprocess.run(
        [sys.executable, "-m", "pip", "wheel", "--no-deps", "-q", "-w", str(wheel_dir), str(src)],
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert r.returncode == 0, r.stderr[-2000:]
    (wheel,) = wheel_dir.glob("aias_augment-*.whl")
    names = set(zipfile.ZipFile(wheel).namelist())
    for rel in (
        "configs/presets/fast.yaml",
        "configs/presets/balanced.yaml",
        "configs/presets/accurate.yaml",
        "configs/taxonomy.yaml",
        "configs/detector/lite0_320.yaml",
        "checkpoints/harmonizer_fast.pt",
        "checkpoints/harmonizer_fast.npz",
        "checkpoints/harmonizer_small.pt",
    ):
        assert f"aias_augment/_data/{rel}" in names, rel
    site = tmp_path / "site"
    zipfile.ZipFile(wheel).extractall(site)
    # a symlink would point back into the checkout: the wheel must hold real files
    assert not (site / "aias_augment" / "_data" / "configs").is_symlink()
    r = subprocess.run(
        [sys.executable, "-c", PROBE],
        cwd=tmp_path,
        capture_output=True,
        text=True,
        timeout=300,
        env={"PYTHONPATH": str(site), "PATH": "/usr/bin:/bin", "NO_ALBUMENTATIONS_UPDATE": "1"},
    )
    assert r.returncode == 0, r.stderr[-3000:]
    out = json.loads(r.stdout.strip().splitlines()[-1])
    assert Path(out["module"]).resolve().is_relative_to(site.resolve())
    assert set(out["presets"]) == {"fast", "balanced", "accurate"}
    for path, exists in out["checkpoints"].values():
        assert exists and Path(path).resolve().is_relative_to(site.resolve())
    assert out["detector"] == 320
    assert out["fast_npz"] == 64  # the fast harmonizer's NumPy weights load from the wheel (checked against the .pt)
    assert "traffic_cone" in out["taxonomy"]

"""A bank folder is a database: unique names, appends that never overwrite, an atomic index under a lock,
idempotent appends, one-line errors for an index that is not one (issue 54, item 4)."""

import hashlib
import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import trimesh

from aias_augment.assets.asset import Asset, normalise_meshes
from aias_augment.assets.bank.db import BankError, append_entry, read_index
from aias_augment.assets.bank.folder import glb_bytes
from aias_augment.assets.bank.lift import bank_paths
from aias_augment.assets.deform import sample_deformation, write_variants

ROOT = Path(__file__).resolve().parents[4]


def cylinder_asset() -> Asset:
    mesh = trimesh.creation.cylinder(radius=0.15, height=0.6, sections=24)
    mesh.apply_translation((0, 0, 0.3))
    return Asset("drum", "barrel", normalise_meshes([mesh], crease_deg=None), "analytic cylinder")


def write_cylinder(path: Path) -> Path:
    path.write_bytes(glb_bytes(cylinder_asset().meshes))
    return path


def files_of(folder: Path) -> dict[str, str]:
    return {p.name: hashlib.sha256(p.read_bytes()).hexdigest() for p in sorted(folder.iterdir()) if p.is_file()}


def test_appends_never_overwrite_and_keep_other_writers_entries(tmp_path):
    from aias_augment.assets.bank.lift import lift_instances
    from tests.aias_augment.assets.bank.test_lift import draw_cone, noise_background

    source = cylinder_asset()
    rng = np.random.default_rng(0)
    params = [sample_deformation(source, rng) for _ in range(2)]
    write_variants(source, params, tmp_path)
    user_file = tmp_path / "0002.glb"
    user_file.write_bytes(b"the user's own file, not listed")
    before = files_of(tmp_path)
    img = noise_background(240, 320)
    box = draw_cone(img, 160, 200, 130, 35)
    _, report = lift_instances([("x.png", img, np.array([box], float))], "traffic_cone", tmp_path)
    assert report.lifted == 1
    index = read_index(tmp_path)
    assert [e["file"] for e in index["report"]["assets"]] == ["0000.glb", "0001.glb", "0003.glb"]
    assert [e["category"] for e in index["report"]["assets"]] == ["barrel", "barrel", "traffic_cone"]
    after = files_of(tmp_path)
    assert all(after[name] == digest for name, digest in before.items() if name != "bank.json")
    for e in index["report"]["assets"]:
        assert hashlib.sha256((tmp_path / e["file"]).read_bytes()).hexdigest() == e["sha256"]


def test_the_same_deform_twice_adds_nothing(tmp_path):
    source = cylinder_asset()
    rng = np.random.default_rng(3)
    params = [sample_deformation(source, rng) for _ in range(3)]
    write_variants(source, params, tmp_path)
    first = files_of(tmp_path)
    write_variants(source, params, tmp_path)
    assert files_of(tmp_path) == first
    assert len(read_index(tmp_path)["report"]["assets"]) == 3


def test_a_bank_index_that_is_not_one_is_a_one_line_error(tmp_path):
    glb = glb_bytes(cylinder_asset().meshes)
    for text, match in [
        ("{not json", "not a readable bank index"),
        ("[]", "not a bank index"),
        (
            '{"report": {"assets": [{"file": "0000.glb", "category": "x"}, {"file": "0000.glb", "category": "x"}]}}',
            "listed twice",
        ),
        (
            '{"report": {"assets": [{"file": "../../etc/passwd", "category": "x"}]}}',
            "relative paths inside the bank folder",
        ),
    ]:
        (tmp_path / "bank.json").write_text(text)
        with pytest.raises(BankError, match=match) as e:
            append_entry(tmp_path, glb, {"category": "x"})
        assert "\n" not in str(e.value) and str(tmp_path / "bank.json") in str(e.value)
        assert (tmp_path / "bank.json").read_text() == text  # never repaired or overwritten
    with pytest.raises(BankError, match="is a file"):
        append_entry(tmp_path / "bank.json", glb, {"category": "x"})


def test_two_concurrent_deform_runs_both_land_all_their_entries(tmp_path):
    asset = write_cylinder(tmp_path / "drum.glb")
    bank = tmp_path / "bank"
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    runs = [
        subprocess.Popen(
            [
                sys.executable,
                "-m",
                "aias_augment.cli.assets",
                "deform",
                "--category",
                "barrel",
                "--asset",
                str(asset),
                "--count",
                "4",
                "--seed",
                str(seed),
                "--out",
                str(bank),
            ],
            env=env,
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
        )
        for seed in (1, 2)
    ]
    for r in runs:
        _, err = r.communicate(timeout=300)
        assert r.returncode == 0, err.decode()
    entries = read_index(bank)["report"]["assets"]
    assert len(entries) == 8 and len({e["file"] for e in entries}) == 8
    assert sorted(json.dumps(e["deformation"], sort_keys=True) for e in entries) == sorted(
        {json.dumps(e["deformation"], sort_keys=True) for e in entries}
    )
    for e in entries:
        assert hashlib.sha256((bank / e["file"]).read_bytes()).hexdigest() == e["sha256"]
    assert sorted(Path(p).name for p in bank_paths(bank)["barrel"]) == sorted(e["file"] for e in entries)

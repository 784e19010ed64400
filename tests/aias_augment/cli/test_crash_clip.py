"""Crash consistency of the clip writer: killed (SIGKILL) at every write point, a rerun leaves the folder byte for
byte as a clean run does, and a folder never claims to be complete when it is not."""

import hashlib
import json
import os
import signal
import subprocess
import sys

import cv2
import numpy as np
import pytest

from aias_augment.cli.augment import main
from aias_augment.cli.manifest import LOCK_NAME
from aias_augment.core.config import data_root

SEQ = data_root() / "kitti06_seq"
KEEP = (0, 4, 8)  # three KITTI frames a car length apart, at half size: the cone is in view in two
# A run's write points: the manifest, 3 frames, annotations, mot, video, contact sheet, record, the complete
# manifest; each a temporary file on disk, then its rename.
WRITE_POINTS = 2 * (1 + len(KEEP) + 5 + 1)

pytestmark = pytest.mark.skipif(not SEQ.exists(), reason="shared KITTI data not available")


@pytest.fixture(scope="module")
def small_clip(tmp_path_factory):
    root = tmp_path_factory.mktemp("small_clip")
    (root / "frames").mkdir()
    files = sorted((SEQ / "image_l").iterdir())
    for i, k in enumerate(KEEP):
        im = cv2.imread(str(files[k]))
        small = cv2.resize(im, (im.shape[1] // 2, im.shape[0] // 2), interpolation=cv2.INTER_AREA)
        cv2.imwrite(str(root / "frames" / f"{i:06d}.png"), small)
    np.savetxt(root / "poses.txt", np.loadtxt(SEQ / "poses.txt")[list(KEEP)])
    f, cx, cy = 707.0912 / 2, 601.8873 / 2, 183.1104 / 2
    (root / "cam.yaml").write_text(f"fx: {f}\nfy: {f}\ncx: {cx}\ncy: {cy}\n")
    return root


def clip_args(root, out, *extra):
    return [
        "--input",
        str(root / "frames"),
        "--camera",
        str(root / "cam.yaml"),
        "--poses",
        str(root / "poses.txt"),
        "--lighting",
        "ambient",
        "--out",
        str(out),
        *extra,
    ]


def folder_bytes(out) -> dict:
    """Every file under ``out`` but the run lock (it holds its holder's pid): its sha256."""
    return {
        str(p.relative_to(out)): hashlib.sha256(p.read_bytes()).hexdigest()
        for p in sorted(out.rglob("*"))
        if p.is_file() and p.name != LOCK_NAME
    }


def killed_run(args, kill_at: int) -> int:
    env = {**os.environ, "AIAS_TEST_KILL_AFTER_WRITES": str(kill_at)}
    cmd = [sys.executable, "-m", "aias_augment.cli.augment", *args, "--quiet"]
    return subprocess.run(cmd, env=env, capture_output=True, timeout=300).returncode


def claims_complete(out) -> bool:
    try:
        return json.loads((out / "manifest.json").read_text()).get("complete") is True
    except (OSError, ValueError):
        return False


@pytest.fixture(scope="module")
def clean(small_clip, tmp_path_factory):
    out = tmp_path_factory.mktemp("clean") / "out"
    assert main(clip_args(small_clip, out)) == 0
    return folder_bytes(out)


def test_the_clean_run_has_the_write_points_counted(small_clip, clean, tmp_path):
    assert {n for n in clean if n.startswith("frames/")} == {f"frames/{i:06d}.jpg" for i in range(len(KEEP))}
    assert killed_run(clip_args(small_clip, tmp_path / "out"), WRITE_POINTS + 1) == 0  # past the last: no kill
    assert folder_bytes(tmp_path / "out") == clean


@pytest.mark.parametrize("kill_at", range(1, WRITE_POINTS + 1))
def test_a_clip_killed_at_any_write_point_reruns_to_the_clean_bytes(small_clip, clean, tmp_path, kill_at):
    out = tmp_path / "out"
    assert killed_run(clip_args(small_clip, out), kill_at) == -signal.SIGKILL
    after_kill = folder_bytes(out)
    if claims_complete(out):  # only once every file is in place: the kill after the last rename
        assert after_kill == clean and kill_at == WRITE_POINTS
    else:
        assert after_kill != clean
    assert main(clip_args(small_clip, out, "--quiet")) == 0
    assert claims_complete(out) and folder_bytes(out) == clean


def test_a_killed_other_run_is_never_taken_for_the_finished_one(small_clip, clean, tmp_path, capsys):
    """Run A finishes; run B (another seed, --overwrite) is killed after rewriting frames; A again is refused (its
    folder holds B's unfinished run), not "already done"; A with --overwrite is A's bytes again."""
    out = tmp_path / "out"
    args = clip_args(small_clip, out, "--quiet")
    assert main(args) == 0 and folder_bytes(out) == clean
    assert killed_run(clip_args(small_clip, out, "--seed", "7", "--overwrite"), 8) == -signal.SIGKILL
    assert not claims_complete(out)
    capsys.readouterr()
    assert main(args) == 2
    err = capsys.readouterr().err
    assert "seed: 7 -> 0" in err and len(err.strip().splitlines()) == 1
    assert main([*args, "--overwrite"]) == 0 and folder_bytes(out) == clean


def test_a_finished_clip_missing_a_file_is_not_done_and_is_redone(small_clip, clean, tmp_path):
    out = tmp_path / "out"
    assert main(clip_args(small_clip, out, "--quiet")) == 0
    (out / "frames" / "000001.jpg").unlink()  # a listed file gone: not done, redone
    assert main(clip_args(small_clip, out, "--quiet")) == 0
    assert folder_bytes(out) == clean

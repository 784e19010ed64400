"""Crash consistency of the bank writers (issue 54, "Done when"): ``aias-assets deform`` and ``from-labels`` are
killed (SIGKILL, through the ``AIAS_TEST_KILL_AFTER_WRITES`` hook) after each of their durable write steps in turn.
After every kill the index lists only files that are there with the bytes it records; a rerun then leaves the bank
byte for byte as a clean run does.

The runs are forked from the test process (the imports are done once); each child counts its writes from zero.
"""

import hashlib
import multiprocessing
import os
import sys
from pathlib import Path

import cv2
import pytest

from aias_augment.assets.bank import db
from aias_augment.cli.assets import main
from tests.aias_augment.assets.bank.test_bank_db import write_cylinder
from tests.aias_augment.assets.bank.test_lift import draw_cone, noise_background


def _run(argv: list[str], kill_after: int | None) -> int:
    def child():
        db._writes_done = 0
        os.environ.pop(db.KILL_ENV, None)
        if kill_after is not None:
            os.environ[db.KILL_ENV] = str(kill_after)
        sys.stdout = open(os.devnull, "w")
        os._exit(main(argv))

    p = multiprocessing.get_context("fork").Process(target=child)
    p.start()
    p.join(300)
    return p.exitcode


def _files(folder: Path) -> dict[str, str]:
    return {p.name: hashlib.sha256(p.read_bytes()).hexdigest() for p in sorted(folder.iterdir()) if p.is_file()}


def _index_never_lies(folder: Path) -> None:
    if not (folder / "bank.json").exists():
        return
    for e in db.read_index(folder)["report"]["assets"]:
        assert (folder / e["file"]).is_file(), f"bank.json lists {e['file']}, which is missing"
        assert hashlib.sha256((folder / e["file"]).read_bytes()).hexdigest() == e["sha256"]


def _kill_everywhere(tmp_path: Path, argv_for, min_points: int) -> int:
    clean = tmp_path / "clean"
    assert _run(argv_for(clean), None) == 0
    expected = _files(clean)
    k = 0
    while True:
        k += 1
        out = tmp_path / f"killed_{k}"
        code = _run(argv_for(out), k)
        if code == 0:  # fewer writes than k: the run finished
            break
        assert code == -9
        _index_never_lies(out)
        assert _run(argv_for(out), None) == 0
        assert _files(out) == expected, f"killed after write {k}: the rerun differs from a clean run"
    assert k - 1 >= min_points
    return k - 1


def test_deform_killed_at_each_write_reruns_to_the_clean_bank(tmp_path):
    asset = write_cylinder(tmp_path / "drum.glb")

    def argv(out):
        return [
            "deform",
            "--category",
            "barrel",
            "--asset",
            str(asset),
            "--count",
            "6",
            "--seed",
            "4",
            "--out",
            str(out),
        ]

    assert _kill_everywhere(tmp_path, argv, 20) == 24  # 6 entries x (mesh temp, rename, index temp, rename)


@pytest.fixture
def yolo_cones(tmp_path):
    img_dir, lab_dir = tmp_path / "images", tmp_path / "labels"
    img_dir.mkdir()
    lab_dir.mkdir()
    for k in range(5):
        img = noise_background(240, 320, k)
        b = draw_cone(img, 120 + 20 * k, 200, 110 + 10 * k, 30 + 2 * k)
        cv2.imwrite(str(img_dir / f"{k}.png"), img[..., ::-1])
        rows = f"0 {(b[0] + b[2]) / 640} {(b[1] + b[3]) / 480} {(b[2] - b[0]) / 320} {(b[3] - b[1]) / 240}\n"
        if k == 0:
            rows += "0 0.9 0.1 0.03 0.03\n"  # a 10 px cone: rejected as too small, a count in the index
        (lab_dir / f"{k}.txt").write_text(rows)
    return img_dir


def test_from_labels_killed_at_each_write_reruns_to_the_clean_bank(tmp_path, yolo_cones):
    def argv(out):
        return [
            "from-labels",
            "--yolo",
            str(yolo_cones),
            "--class-names",
            "cone",
            "--category",
            "traffic_cone",
            "--out",
            str(out),
        ]

    assert _kill_everywhere(tmp_path, argv, 20) >= 20

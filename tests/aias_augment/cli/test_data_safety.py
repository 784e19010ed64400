"""Issue 54: the offline image CLI never writes over or removes the user's data.

``--out`` may neither be, hold, nor lie inside an input (refused at start, exit 2, both paths named); only files a
run's manifest lists are ever removed; temporary files carry the run's own recorded prefix. Each data-loss case
hashes every file of the test's folder before and after: every input byte is unchanged and nothing is created
outside ``--out``. Also: a run that inserts no object fails (exit 1), one that misses some images says how many, and
``--sun-from ...,now,...`` is one time for the whole run, kept by a resume.
"""

import hashlib
import json
import os
import subprocess
import sys
import time
from datetime import datetime, timezone

import cv2
import numpy as np
import pytest

from aias_augment.assets.asset import DEFAULT_ASSETS
from aias_augment.cli.augment import main
from aias_augment.cli.manifest import KILL_HOOK
from aias_augment.core.config import data_root
from tests.aias_augment.pipeline.test_image import road_frame

needs_data = pytest.mark.skipif(
    not (data_root() / DEFAULT_ASSETS["traffic_cone"][0]).exists(), reason="shared data not present"
)
FAST = ["--preset", "fast", "--per-image", "1"]


def snapshot(root) -> dict[str, str | None]:
    """Every path under ``root``: a file's sha256, None for a folder or link."""
    return {
        p.relative_to(root).as_posix(): hashlib.sha256(p.read_bytes()).hexdigest() if p.is_file() else None
        for p in sorted(root.rglob("*"))
    }


def picture(path, small=False, seed=0):
    img = road_frame()[::4, ::4].copy() if not small else np.full((12, 16, 3), 110, np.uint8)
    img[seed : seed + 3] = 30 * seed
    path.parent.mkdir(parents=True, exist_ok=True)
    cv2.imwrite(str(path), img[..., ::-1])


def truncated(path):
    """An image the run skips without rendering anything (a run whose manifest and records are cheap to make)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    ok, buf = cv2.imencode(".jpg", road_frame())
    path.write_bytes(buf.tobytes()[: len(buf) // 3])


def dataset(root):
    """``root/annotations.json`` (COCO) over ``root/images/{a,b}.png``, a ``holiday.tmp.jpg`` among them."""
    for i, name in enumerate(("a.png", "b.png", "holiday.tmp.jpg")):
        picture(root / "images" / name, seed=i)
    h, w = road_frame()[::4, ::4].shape[:2]
    coco = {
        "images": [{"id": i + 1, "file_name": n, "width": w, "height": h} for i, n in enumerate(("a.png", "b.png"))],
        "annotations": [{"id": 1, "image_id": 1, "category_id": 1, "bbox": [5, 5, 10, 10]}],
        "categories": [{"id": 1, "name": "sign"}],
    }
    (root / "annotations.json").write_text(json.dumps(coco))
    (root / "labels").mkdir()
    (root / "labels" / "a.txt").write_text("0 0.5 0.5 0.1 0.1\n")
    (root / "run.yaml").write_text("max_objects: 1\n")


def refused_line(err: str, *paths) -> str:
    lines = [line for line in err.splitlines() if line.strip()]
    assert len(lines) == 1, err
    assert lines[0].startswith("aias-augment: error: --out") and "Traceback" not in err, err
    for p in paths:
        assert str(p) in lines[0], (p, lines[0])
    return lines[0]


# ------------------------------------------------------------------------ --out apart from every input (no run)
@pytest.mark.parametrize(
    "case",
    [
        "out is the dataset root",
        "out is the images folder",
        "out inside the images folder",
        "images folder inside out (YOLO)",
        "out is the config's folder",
        "out through a symlink to the dataset",
        "out is the annotation file",
    ],
)
def test_an_out_that_is_holds_or_lies_inside_an_input_is_refused(tmp_path, capsys, case):
    ds = tmp_path / "ds"
    dataset(ds)
    coco = ["--input", str(ds / "annotations.json"), "--images", str(ds / "images")]
    argv, named = {
        "out is the dataset root": ([*coco, "--out", str(ds)], [ds, ds / "annotations.json"]),
        "out is the images folder": (["--images", str(ds / "images"), "--out", str(ds / "images")], [ds / "images"]),
        "out inside the images folder": (
            ["--images", str(ds / "images"), "--out", str(ds / "images" / "aug")],
            [ds / "images" / "aug", ds / "images"],
        ),
        "images folder inside out (YOLO)": (["--yolo", str(ds / "images"), "--out", str(ds)], [ds, ds / "images"]),
        "out is the config's folder": (
            [*coco, "--config", str(ds / "run.yaml"), "--out", str(ds)],
            [ds],
        ),
        "out through a symlink to the dataset": (
            [*coco, "--out", str(tmp_path / "link")],
            [tmp_path / "link", ds],
        ),
        "out is the annotation file": ([*coco, "--out", str(ds / "annotations.json")], [ds / "annotations.json"]),
    }[case]
    (tmp_path / "link").symlink_to(ds)
    before = snapshot(tmp_path)
    assert main([*argv, *FAST]) == 2
    refused_line(capsys.readouterr().err, *named)
    assert snapshot(tmp_path) == before  # every input byte, and nothing created anywhere


@needs_data
def test_an_input_image_named_into_out_is_refused(tmp_path, capsys):
    """A COCO ``file_name`` that leads into ``--out`` (``../out/a.png``): the run refuses before writing."""
    dataset(tmp_path / "ds")
    picture(tmp_path / "out" / "a.png")
    coco = json.loads((tmp_path / "ds" / "annotations.json").read_text())
    coco["images"][0]["file_name"] = "../../out/a.png"
    (tmp_path / "ds" / "annotations.json").write_text(json.dumps(coco))
    before = snapshot(tmp_path)
    argv = ["--input", str(tmp_path / "ds" / "annotations.json"), "--images", str(tmp_path / "ds" / "images")]
    assert main([*argv, "--out", str(tmp_path / "out"), *FAST]) == 2
    refused_line(capsys.readouterr().err, tmp_path / "out")
    assert snapshot(tmp_path) == before


# ------------------------------------------------------------------ only what the manifest lists is ever removed
@needs_data
def test_overwrite_with_the_inputs_in_out_deletes_nothing(tmp_path, capsys):
    """A finished run in ``out``; the user then keeps photos in ``out/images`` and augments them with
    ``--overwrite``: refused (the images folder lies inside --out), every photo intact."""
    truncated(tmp_path / "src" / "t.jpg")
    out = tmp_path / "out"
    assert main(["--images", str(tmp_path / "src"), "--out", str(out), "--seed", "1", *FAST]) == 1  # a run, no image
    picture(out / "images" / "holiday.png")
    picture(out / "images" / "holiday.tmp.jpg", seed=1)
    capsys.readouterr()
    before = snapshot(tmp_path)
    assert main(["--images", str(out / "images"), "--out", str(out), "--seed", "2", "--overwrite", *FAST]) == 2
    refused_line(capsys.readouterr().err, out, out / "images")
    assert snapshot(tmp_path) == before


@needs_data
def test_cleanup_and_overwrite_remove_only_files_the_manifest_lists(tmp_path, capsys):
    """The user's files in ``out`` (``images/holiday.tmp.jpg``, ``x.check``, ``notes.tmp``, a record-like name)
    survive a run's start-up cleanup and an ``--overwrite``; the previous run's listed outputs go."""
    for name in ("t0.jpg", "t1.jpg"):
        truncated(tmp_path / "src" / name)
    out = tmp_path / "out"
    mine = ["images/holiday.tmp.jpg", "x.check", "notes.tmp", "records/mine.json.tmp", "records/999999.json"]

    def keep(rels):
        for rel in rels:
            (out / rel).parent.mkdir(parents=True, exist_ok=True)
            if rel.endswith(".jpg"):
                picture(out / rel)
            else:
                (out / rel).write_text(f"the user's {rel}")
        return {rel: h for rel, h in snapshot(out).items() if rel in mine}

    user = keep(mine[:3])
    outside = {k: v for k, v in snapshot(tmp_path).items() if not k.startswith("out")}
    argv = ["--images", str(tmp_path / "src"), "--out", str(out), *FAST]
    assert main([*argv, "--seed", "1"]) == 1  # runs (both inputs truncated: a skip each)
    assert {rel: h for rel, h in snapshot(out).items() if rel in mine} == user
    assert (out / "records" / "000001.json").exists()
    user = keep(mine[3:])  # beside the run's records
    manifest = json.loads((out / "manifest.json").read_text())
    assert "records/000001.json" in manifest["outputs"] and manifest["temp_prefix"].startswith(".aias-tmp-")
    assert main([*argv, "--seed", "2"]) == 2  # another run: refused
    assert main([*argv, "--seed", "2", "--overwrite", "--limit", "1"]) == 1
    assert {rel: h for rel, h in snapshot(out).items() if rel in mine} == user
    assert not (out / "records" / "000001.json").exists()  # the previous run's, listed: removed
    assert json.loads((out / "manifest.json").read_text())["seed"] == 2
    assert {k: v for k, v in snapshot(tmp_path).items() if not k.startswith("out")} == outside


@needs_data
def test_a_user_file_where_the_run_would_write_is_refused(tmp_path, capsys):
    """``out`` holds the user's own ``annotations.json`` (no manifest): a new run refuses, never writes over it."""
    truncated(tmp_path / "src" / "t.jpg")
    out = tmp_path / "out"
    out.mkdir()
    (out / "annotations.json").write_text('{"my": "labels"}')
    before = snapshot(tmp_path)
    assert main(["--images", str(tmp_path / "src"), "--out", str(out), *FAST]) == 2
    err = capsys.readouterr().err
    assert "already holds annotations.json" in err and "never written over" in err
    after = snapshot(tmp_path)
    assert after["out/annotations.json"] == before["out/annotations.json"]
    assert {k: v for k, v in after.items() if not k.startswith("out/")} == {
        k: v for k, v in before.items() if not k.startswith("out/")
    }


@needs_data
def test_a_link_in_out_leading_elsewhere_is_refused(tmp_path, capsys):
    """``out/records`` a link to the user's folder: the run would write through it; refused, that folder intact."""
    truncated(tmp_path / "src" / "t.jpg")
    picture(tmp_path / "photos" / "holiday.png")
    out = tmp_path / "out"
    out.mkdir()
    (out / "records").symlink_to(tmp_path / "photos")
    before = snapshot(tmp_path / "photos")
    assert main(["--images", str(tmp_path / "src"), "--out", str(out), *FAST]) == 2
    assert "leads outside --out" in capsys.readouterr().err
    assert snapshot(tmp_path / "photos") == before


# ------------------------------------------------------------------------------------ runs that insert nothing
@needs_data
def test_a_run_that_inserts_no_object_fails_and_a_partial_one_warns(tmp_path, capsys):
    """16x12 images have no ground to stand on: nothing inserted in any -> exit 1 with one line; one such image
    beside a road -> exit 0, a WARNING with the count, the count in report.json."""
    for i in range(2):
        picture(tmp_path / "tiny" / f"t{i}.png", small=True, seed=i)
    assert main(["--images", str(tmp_path / "tiny"), "--out", str(tmp_path / "o1"), *FAST]) == 1
    err = capsys.readouterr().err
    assert "error: no object inserted in any of the 2 images written" in err
    assert json.loads((tmp_path / "o1" / "report.json").read_text())["nothing_inserted_count"] == 2
    picture(tmp_path / "mixed" / "road.png")
    picture(tmp_path / "mixed" / "tiny.png", small=True)
    assert main(["--images", str(tmp_path / "mixed"), "--out", str(tmp_path / "o2"), *FAST]) == 0
    assert "WARNING: no object inserted in 1 of 2 images written" in capsys.readouterr().err
    assert json.loads((tmp_path / "o2" / "report.json").read_text())["nothing_inserted_count"] == 1


# ------------------------------------------------------------------------------------------ --sun-from ...,now
@needs_data
def test_sun_now_is_one_time_recorded_and_kept_by_a_resume(tmp_path):
    """A run with ``now`` killed after its first image (SIGKILL through the writer's test hook), resumed a second
    later: the manifest holds one concrete UTC from the run's start, the resume keeps it (and is a resume, not a
    refused other run), and the images equal those of a run given that UTC explicitly."""
    for i in range(2):
        picture(tmp_path / "src" / f"im{i}.png", seed=i)
    out = tmp_path / "out"
    argv = ["--images", str(tmp_path / "src"), "--seed", "3", *FAST]
    sun = ["--sun-from", "48.1,11.6,now,90"]
    t0 = datetime.now(timezone.utc).replace(microsecond=0)
    killed = subprocess.run(  # steps: manifest (2), image (2), record (2): killed once the first record is in
        [sys.executable, "-m", "aias_augment.cli.augment", *argv, *sun, "--out", str(out)],
        env={**os.environ, KILL_HOOK: "6"},
        capture_output=True,
    )
    assert killed.returncode == -9, killed.stderr[-2000:]
    assert sorted(p.name for p in (out / "records").iterdir()) == ["000000.json"]
    recorded = json.loads((out / "manifest.json").read_text())["options"]["sun_from"]
    assert recorded["utc_given"] == "now"
    utc = datetime.strptime(recorded["utc"], "%Y-%m-%dT%H:%M:%SZ").replace(tzinfo=timezone.utc)
    assert t0 <= utc <= datetime.now(timezone.utc)
    first = (out / "records" / "000000.json").stat().st_mtime_ns
    time.sleep(1.1)  # a `now` taken again would be another second
    assert main([*argv, *sun, "--out", str(out)]) == 0
    assert json.loads((out / "manifest.json").read_text())["options"]["sun_from"] == recorded
    assert (out / "records" / "000000.json").stat().st_mtime_ns == first  # resumed, not redone
    fixed = ["--sun-from", f"48.1,11.6,{recorded['utc']},90", "--out", str(tmp_path / "fixed")]
    assert main([*argv, *fixed]) == 0
    images = {p.name: p.read_bytes() for p in (out / "images").rglob("*.png")}
    assert len(images) == 2 and images == {
        p.name: p.read_bytes() for p in (tmp_path / "fixed" / "images").rglob("*.png")
    }


def test_an_assets_folder_that_is_a_disk_is_named_as_itself_before_any_scan_or_write(tmp_path, capsys):
    """``--assets traffic_cone=/`` is an --assets error (the folder is not a folder of meshes), not an --out one,
    and the scan stops at a bounded number of entries."""
    dataset(tmp_path / "ds")
    before = snapshot(tmp_path)
    images, out = str(tmp_path / "ds" / "images"), str(tmp_path / "out")
    argv = ["--images", images, "--out", out, "--assets", "traffic_cone=/", *FAST]
    assert main(argv) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and err.startswith("aias-augment: error: --assets traffic_cone=/:"), err
    assert "--out" not in err
    assert snapshot(tmp_path) == before

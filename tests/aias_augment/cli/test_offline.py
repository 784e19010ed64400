import json
from dataclasses import replace
from pathlib import Path

import cv2
import numpy as np
import pytest

from aias_augment.assets.asset import DEFAULT_ASSETS
from aias_augment.cli.offline import Item, items_from_yolo, run
from aias_augment.core.config import data_root
from aias_augment.pipeline.image import load_preset
from tests.aias_augment.pipeline.test_image import road_frame

pytestmark = pytest.mark.skipif(
    not (data_root() / DEFAULT_ASSETS["traffic_cone"][0]).exists(), reason="shared data not present"
)
CFG = replace(load_preset("fast"), categories=("traffic_cone",), max_objects=2, harmonize=False)


def _items(tmp_path, n=3):
    items = []
    for i in range(n):
        p = tmp_path / "in" / f"im{i}.png"
        p.parent.mkdir(exist_ok=True)
        cv2.imwrite(str(p), road_frame()[..., ::-1])
        items.append(Item(str(p), [[5.0, 5.0, 20.0, 20.0]], ["sign"]))
    items.append(Item(str(tmp_path / "in" / "missing.png")))  # a bad input: counted skip, not a crash
    return items


def test_same_output_for_one_or_two_workers_and_resume(tmp_path):
    s1 = run(_items(tmp_path), CFG, seed=4, out_dir=str(tmp_path / "w1"), workers=1)
    # Two workers sharing a scene-cache folder: the cache changes when the analysis runs, never the pixels.
    s2 = run(
        _items(tmp_path), CFG, seed=4, out_dir=str(tmp_path / "w2"), workers=2, scene_cache=str(tmp_path / "scenes")
    )
    assert list((tmp_path / "scenes").rglob("*.npz"))
    assert s1["skipped"] == s2["skipped"] == 1 and s1["inserted"] == s2["inserted"] >= 3
    for name in sorted(p.name for p in (tmp_path / "w1" / "images").iterdir()):
        a = cv2.imread(str(tmp_path / "w1" / "images" / name))
        b = cv2.imread(str(tmp_path / "w2" / "images" / name))
        assert np.array_equal(a, b)
    coco = json.loads((tmp_path / "w1" / "annotations.json").read_text())
    assert {c["name"] for c in coco["categories"]} == {"sign", "traffic_cone"}
    assert sum(a["inserted"] for a in coco["annotations"]) == s1["inserted"]
    # Resume: records exist, nothing is recomputed or overwritten.
    rec = tmp_path / "w1" / "records" / "000000.json"
    before = rec.stat().st_mtime_ns
    run(_items(tmp_path), CFG, seed=4, out_dir=str(tmp_path / "w1"), workers=1)
    assert rec.stat().st_mtime_ns == before


def test_yolo_items(tmp_path):
    (tmp_path / "images").mkdir()
    (tmp_path / "labels").mkdir()
    cv2.imwrite(str(tmp_path / "images" / "a.png"), road_frame()[..., ::-1])
    (tmp_path / "labels" / "a.txt").write_text("0 0.5 0.5 0.1 0.2\n")
    items = items_from_yolo(str(tmp_path / "images"))
    assert len(items) == 1 and items[0].meta["yolo_rows"] == [["0", "0.5", "0.5", "0.1", "0.2"]]


def test_kill_9_mid_run_then_rerun_gives_byte_identical_outputs(tmp_path):
    """A run killed with SIGKILL while it writes, then rerun with the same arguments: annotations.json, report.json
    and every image byte-identical to an uninterrupted run, no duplicate ids, no stale temporary file."""
    import os
    import signal
    import subprocess
    import sys
    import time

    from aias_augment.cli.augment import main

    images = tmp_path / "images"
    (tmp_path / "labels").mkdir(parents=True)
    images.mkdir()
    for i in range(10):
        img = road_frame()[::4, ::4].copy()
        img[i : i + 5, :] = 25 * i  # ten different scenes
        cv2.imwrite(str(images / f"im{i}.png"), img[..., ::-1])
        (tmp_path / "labels" / f"im{i}.txt").write_text("0 0.5 0.8 0.1 0.1\n")
    args = ["--yolo", str(images), "--class-names", "sign", "--preset", "fast", "--per-image", "1", "--seed", "7"]
    args += ["--format", "coco"]  # images/ flat, as this test reads them
    assert main(args + ["--out", str(tmp_path / "whole")]) == 0

    killed = tmp_path / "killed"
    proc = subprocess.Popen(
        [sys.executable, "-m", "aias_augment.cli.augment", *args, "--out", str(killed)],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
        env=os.environ.copy(),
    )
    deadline = time.time() + 300
    while time.time() < deadline and proc.poll() is None:
        if len(list((killed / "records").glob("*.json"))) >= 3:
            break
        time.sleep(0.02)
    assert proc.poll() is None, "the run ended before it could be killed"
    os.kill(proc.pid, signal.SIGKILL)
    proc.wait()
    done = len(list((killed / "records").glob("*.json")))
    assert 3 <= done < 10 and not (killed / "annotations.json").exists()
    # What a kill in the middle of a write leaves (temporary files named with the run's recorded prefix, in the
    # folder of the file written): removed on resume.
    manifest = json.loads((killed / "manifest.json").read_text())
    prefix = manifest["temp_prefix"]
    image = next(Path(o) for o in manifest["outputs"] if Path(o).name.startswith("000009_"))
    (killed / "records" / f"{prefix}000009.json").write_text('{"index": 9, "sou')
    (killed / image.parent / f"{prefix}{image.name}").write_bytes(b"\x89PNG half")

    assert main(args + ["--out", str(killed)]) == 0
    for name in ("annotations.json", "report.json"):
        assert (killed / name).read_bytes() == (tmp_path / "whole" / name).read_bytes(), name
    whole_images = {p.name: p.read_bytes() for p in (tmp_path / "whole" / "images").iterdir()}
    assert {p.name: p.read_bytes() for p in (killed / "images").iterdir()} == whole_images
    coco = json.loads((killed / "annotations.json").read_text())
    for key in ("images", "annotations", "categories"):
        ids = [x["id"] for x in coco[key]]
        assert len(ids) == len(set(ids))
    assert len(coco["images"]) == 10
    assert not [p for p in killed.rglob("*") if p.name.startswith(".aias-tmp-")]


def test_cli_exits_1_when_every_image_is_skipped(tmp_path, capsys):
    """A YOLO folder whose only label row names a class outside --class-names: 0 images written is an error."""
    from aias_augment.cli.augment import main

    (tmp_path / "images").mkdir()
    (tmp_path / "labels").mkdir()
    cv2.imwrite(str(tmp_path / "images" / "a.png"), road_frame()[..., ::-1])
    (tmp_path / "labels" / "a.txt").write_text("3 0.5 0.5 0.1 0.2\n")
    rc = main(
        [
            "--yolo",
            str(tmp_path / "images"),
            "--class-names",
            "cone",
            "--preset",
            "fast",
            "--out",
            str(tmp_path / "out"),
        ]
    )
    assert rc == 1 and "no image written" in capsys.readouterr().err
    report = json.loads((tmp_path / "out" / "report.json").read_text())
    assert report["skipped"] == 1


def test_coco_category_ids_come_out_as_they_went_in(tmp_path):
    """Input ``pole`` has id 7 and ``sign`` id 3; the first image has no input boxes (only inserted objects):
    the output keeps 7 and 3 and gives the inserted category the next id, whichever image comes first."""
    from aias_augment.cli.augment import main

    (tmp_path / "im").mkdir()
    for i in range(2):
        cv2.imwrite(str(tmp_path / "im" / f"{i}.png"), road_frame()[..., ::-1])
    h, w = road_frame().shape[:2]
    coco_in = {
        "images": [
            {"id": 1, "file_name": "0.png", "width": w, "height": h},
            {"id": 2, "file_name": "1.png", "width": w, "height": h},
        ],
        "annotations": [
            {"id": 1, "image_id": 2, "category_id": 7, "bbox": [5, 5, 20, 20]},
            {"id": 2, "image_id": 2, "category_id": 3, "bbox": [50, 5, 20, 20]},
        ],
        "categories": [{"id": 3, "name": "sign"}, {"id": 7, "name": "pole"}],
    }
    (tmp_path / "in.json").write_text(json.dumps(coco_in))
    rc = main(
        [
            "--input",
            str(tmp_path / "in.json"),
            "--images",
            str(tmp_path / "im"),
            "--preset",
            "fast",
            "--categories",
            "traffic_cone",
            "--out",
            str(tmp_path / "out"),
        ]
    )
    assert rc == 0
    out = json.loads((tmp_path / "out" / "annotations.json").read_text())
    ids = {c["name"]: c["id"] for c in out["categories"]}
    assert ids == {"sign": 3, "pole": 7, "traffic_cone": 8}
    names = {c["id"]: c["name"] for c in out["categories"]}
    inserted = [names[a["category_id"]] for a in out["annotations"] if a["inserted"]]
    real = sorted(names[a["category_id"]] for a in out["annotations"] if not a["inserted"])
    assert inserted and set(inserted) == {"traffic_cone"} and real == ["pole", "sign"]

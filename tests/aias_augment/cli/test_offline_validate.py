"""Issue 16: a corpus of bad inputs, each a counted, named skip or a clear error; outputs checked; exact resume.

The run tests use the real renderer on small images (fast preset, one object) to stay fast."""

import json
import math
from dataclasses import replace

import cv2
import numpy as np
import pytest

from aias_augment.adapters.boundary import InputError, check_float_image, parse_yolo_labels, read_image_checked
from aias_augment.assets.asset import DEFAULT_ASSETS, plausible_scale
from aias_augment.cli.augment import main
from aias_augment.cli.manifest import ManifestMismatch
from aias_augment.cli.offline import items_from_coco, items_from_yolo, run
from aias_augment.core.config import data_root
from aias_augment.pipeline.image import load_preset

needs_data = pytest.mark.skipif(
    not (data_root() / DEFAULT_ASSETS["traffic_cone"][0]).exists(), reason="shared data not present"
)
CFG = replace(load_preset("fast"), categories=("traffic_cone",), min_objects=1, max_objects=1, harmonize=False)


def road_picture(h=120, w=160, seed=0):
    rng = np.random.default_rng(seed)
    img = np.full((h, w, 3), 110, np.uint8)
    img[: h // 2] = (220, 180, 150)  # BGR sky
    return np.clip(img + rng.integers(-8, 8, img.shape), 0, 255).astype(np.uint8)


def _yolo(tmp_path, files: dict):
    """files: stem -> (image writer kind, label text or None)."""
    (tmp_path / "images").mkdir(exist_ok=True)
    (tmp_path / "labels").mkdir(exist_ok=True)
    for stem, (kind, label) in files.items():
        if kind == "png":
            cv2.imwrite(str(tmp_path / "images" / f"{stem}.png"), road_picture())
        elif kind == "jpg":
            cv2.imwrite(str(tmp_path / "images" / f"{stem}.jpg"), road_picture())
        elif kind == "truncated":
            ok, buf = cv2.imencode(".jpg", road_picture())
            (tmp_path / "images" / f"{stem}.jpg").write_bytes(buf.tobytes()[: len(buf) // 3])
        elif kind == "png16":
            cv2.imwrite(str(tmp_path / "images" / f"{stem}.png"), road_picture().astype(np.uint16) * 257)
        if label is not None:
            (tmp_path / "labels" / f"{stem}.txt").write_text(label)
    return tmp_path / "images"


# ------------------------------------------------------------------------------- input checks (no rendering)
def test_truncated_and_16bit_images(tmp_path):
    _yolo(tmp_path, {"t": ("truncated", None), "d": ("png16", None)})
    with pytest.raises(ValueError, match="^corrupt image"):
        read_image_checked(tmp_path / "images" / "t.jpg")
    img, notes = read_image_checked(tmp_path / "images" / "d.png")
    assert img.dtype == np.uint8 and np.array_equal(img, road_picture()[..., ::-1])
    assert notes[0]["kind"] == "converted" and "16-bit" in notes[0]["reason"]
    (tmp_path / "empty.png").write_bytes(b"")
    with pytest.raises(ValueError, match="^unreadable image: empty file"):
        read_image_checked(tmp_path / "empty.png")


def test_float_images_explicit():
    assert check_float_image(np.full((2, 2, 3), 0.5, np.float32)).max() == 128
    assert check_float_image(np.full((2, 2, 3), 200.0)).max() == 200
    with pytest.raises(ValueError, match="NaN"):
        check_float_image(np.full((2, 2, 3), np.nan, np.float32))
    with pytest.raises(ValueError, match="neither"):
        check_float_image(np.full((2, 2, 3), 300.0))


def test_yolo_boxes_clipped_or_dropped_with_counts(tmp_path):
    lab = tmp_path / "a.txt"
    lab.write_text("0 0.5 0.5 0.2 0.2\n0 0.95 0.5 0.2 0.2\n0 1.5 0.5 0.2 0.2\n0 0.5 0.5 0 0.1\n0 0.5 0.5 -0.1 0.1\n")
    rows, notes = parse_yolo_labels(lab, ["cone"], "clip")
    kinds = [n["kind"] for n in notes]
    assert len(rows) == 2 and kinds.count("box clipped to the image") == 1
    assert kinds.count("box dropped: outside the image") == 1
    assert kinds.count("box dropped: zero or negative size") == 2
    assert all(0 <= float(r[1]) - float(r[3]) / 2 and float(r[1]) + float(r[3]) / 2 <= 1 + 1e-12 for r in rows)
    assert [n["line"] for n in notes] == [2, 3, 4, 5]
    rows, notes = parse_yolo_labels(lab, ["cone"], "drop")
    assert len(rows) == 1 and sum(n["kind"] == "box dropped: outside the image" for n in notes) == 2


@pytest.mark.parametrize(
    "text,match",
    [
        ("0 0.5 0.5 0.1 0.1\n7 0.5 0.5 0.1 0.1\n", r"^class id out of range: .*a\.txt:2: class 7 \(1 class names\)"),
        ("-1 0.5 0.5 0.1 0.1\n", r"^class id out of range: .*a\.txt:1: class -1"),
        ("0 0.5 0.5 0.1 0.1\n0 0.5 banana 0.1\n", r"^garbage label line: .*a\.txt:2: expected"),
        ("0 0.5 0.5 0.1\n", r"^garbage label line: .*a\.txt:1:"),
        ("0 nan 0.5 0.1 0.1\n", r"^non-finite box: .* at .*a\.txt:1"),
    ],
)
def test_yolo_bad_lines_name_file_and_line(tmp_path, text, match):
    (tmp_path / "a.txt").write_text(text)
    with pytest.raises(ValueError, match=match):
        parse_yolo_labels(tmp_path / "a.txt", ["cone"])


def test_coco_duplicate_ids_refused_and_nan_named(tmp_path):
    ims = [
        {"id": 1, "file_name": "a.png", "width": 160, "height": 120},
        {"id": 1, "file_name": "b.png", "width": 160, "height": 120},
    ]
    cats = [{"id": 1, "name": "cone"}]
    (tmp_path / "d.json").write_text(json.dumps({"images": ims, "annotations": [], "categories": cats}))
    with pytest.raises(InputError, match=r"duplicate image ids \[1\]"):
        items_from_coco(str(tmp_path / "d.json"), str(tmp_path))
    ims[1]["id"] = 2
    ims.append({"id": 3, "file_name": "c.png", "width": 160, "height": 120})
    anns = [
        {"id": 1, "image_id": 1, "category_id": 1, "bbox": [float("nan"), 1, 5, 5]},
        {"id": 2, "image_id": 2, "category_id": 1, "bbox": [150, 100, 20, 30]},  # crosses the border
        {"id": 3, "image_id": 2, "category_id": 1, "bbox": [10, 10, 0, 5]},  # zero width
        {"id": 4, "image_id": 3, "category_id": 9, "bbox": [10, 10, 5, 5]},
    ]  # unknown category
    (tmp_path / "d.json").write_text(json.dumps({"images": ims, "annotations": anns, "categories": cats}))
    a, b, c = items_from_coco(str(tmp_path / "d.json"), str(tmp_path))
    assert a.invalid.kind == "non-finite box" and "annotation 1" in str(a.invalid)
    assert b.invalid is None and b.bboxes_xywh == [[150.0, 100.0, 10.0, 20.0]]
    assert sorted(p["kind"] for p in b.problems) == ["box clipped to the image", "box dropped: zero or negative size"]
    assert c.invalid.kind == "unknown category id" and c.invalid.file == "annotation 4"


def test_empty_input_unknown_category_are_errors(tmp_path, capsys):
    (tmp_path / "images" / "train").mkdir(parents=True)
    cv2.imwrite(str(tmp_path / "images" / "train" / "a.png"), road_picture())
    assert main(["--yolo", str(tmp_path / "images"), "--out", str(tmp_path / "o")]) == 2  # the parent folder
    assert "no images" in capsys.readouterr().err
    assert (
        main(["--yolo", str(tmp_path / "images" / "train"), "--categories", "unicorn", "--out", str(tmp_path / "o")])
        == 2
    )
    assert "unknown categories ['unicorn']" in capsys.readouterr().err
    with pytest.raises(InputError, match="no input images"):
        run([], CFG, 0, str(tmp_path / "o"))


def test_clip_options_on_images_are_refused(tmp_path, capsys):
    """--objects and --object-speed shape a clip; on an image dataset they would be silently ignored."""
    (tmp_path / "images").mkdir()
    cv2.imwrite(str(tmp_path / "images" / "a.png"), road_picture())
    for flag in (["--objects", "3"], ["--object-speed", "2"]):
        with pytest.raises(SystemExit) as e:
            main(["--images", str(tmp_path / "images"), "--out", str(tmp_path / "o"), *flag])
        assert e.value.code == 2
        assert f"{flag[0]}: for clips" in capsys.readouterr().err
    assert not (tmp_path / "o").exists()


def test_mesh_scale_guess():
    assert plausible_scale(1.8, "person") == (1.0, None)
    s, warning = plausible_scale(187.0, "person")
    assert s == 0.01 and "centimetres" in warning and "1.87 m" in warning
    with pytest.raises(InputError, match="no unit"):
        plausible_scale(1e9, "person")


# ------------------------------------------------------------------------------------- runs (real renderer)
@needs_data
def test_bad_corpus_report_resume_refuse_retry(tmp_path):
    images = _yolo(
        tmp_path,
        {
            "good": ("png", "0 0.5 0.75 0.1 0.1\n0 0.98 0.5 0.1 0.1\n0 0.5 0.5 0 0.1\n"),
            "trunc": ("truncated", None),
            "garbage": ("png", "0 0.5 0.5 0.1 0.1\nhello\n"),
            "class7": ("png", "7 0.5 0.5 0.1 0.1\n"),
            "deep": ("png16", None),
        },
    )
    out = tmp_path / "out"
    args = ["--yolo", str(images), "--class-names", "cone", "--preset", "fast", "--per-image", "1", "--out", str(out)]
    args += ["--format", "coco"]  # images/ flat, as this test reads them
    assert main(args + ["--seed", "3"]) == 0
    report = json.loads((out / "report.json").read_text())
    assert report["skipped_by_kind"] == {"class id out of range": 1, "corrupt image": 1, "garbage label line": 1}
    garbage = report["skips"]["garbage label line"][0]
    assert garbage["file"].endswith("garbage.png") and garbage["line"] == 2 and "garbage.txt:2" in garbage["reason"]
    assert report["notes"] == {"box clipped to the image": 1, "box dropped: zero or negative size": 1, "converted": 1}
    coco = json.loads((out / "annotations.json").read_text())
    assert len(coco["images"]) == 2 and len({a["id"] for a in coco["annotations"]}) == len(coco["annotations"])
    for a in coco["annotations"]:
        im = next(i for i in coco["images"] if i["id"] == a["image_id"])
        x, y, w, h = a["bbox"]
        assert w > 0 and h > 0 and x >= 0 and y >= 0 and x + w <= im["width"] and y + h <= im["height"]
    assert {c["name"] for c in coco["categories"]} <= {"cone", "traffic_cone"}
    manifest = json.loads((out / "manifest.json").read_text())
    assert manifest["seed"] == 3 and len(manifest["inputs"]) == 5 and manifest["preset"] == "fast"

    # Same run: resumes byte-identically, nothing rendered again.
    snap = {p.name: p.read_bytes() for p in (out / "images").iterdir()}
    ann = (out / "annotations.json").read_bytes()
    recs = {p.name: p.stat().st_mtime_ns for p in (out / "records").iterdir()}
    assert main(args + ["--seed", "3"]) == 0
    assert (out / "annotations.json").read_bytes() == ann
    assert {p.name: p.read_bytes() for p in (out / "images").iterdir()} == snap
    assert all(
        (out / "records" / n).stat().st_mtime_ns == t
        for n, t in recs.items()
        if not json.loads((out / "records" / n).read_text()).get("skipped")
    )

    # Another seed: refused with a clear message, the folder untouched.
    with pytest.raises(ManifestMismatch, match=r"seed: 3 -> 4.*--overwrite"):
        run(items_from_yolo(str(images), class_names=["cone"]), CFG, 4, str(out), preset="fast")
    assert main(args + ["--seed", "4"]) == 2 and (out / "annotations.json").read_bytes() == ann

    # A fixed input is retried on resume; the rest is kept.
    (tmp_path / "labels" / "garbage.txt").write_text("0 0.5 0.5 0.1 0.1\n")
    assert main(args + ["--seed", "3"]) == 0
    report = json.loads((out / "report.json").read_text())
    assert "garbage label line" not in report["skipped_by_kind"]
    assert len(json.loads((out / "annotations.json").read_text())["images"]) == 3
    assert {p.name: p.read_bytes() for p in (out / "images").iterdir() if p.name in snap} == snap


@needs_data
def test_overwrite_replaces_a_different_run(tmp_path):
    images = _yolo(tmp_path, {"t": ("truncated", None)})  # nothing rendered: the manifest logic alone
    out = tmp_path / "out"
    assert main(["--yolo", str(images), "--out", str(out), "--seed", "1"]) == 1  # ran; nothing written: exit 1
    (out / "records" / "000000.json").write_text('{"stale": 1}')  # the previous run's output, listed
    (out / "records" / "999999.json").write_text("{}")  # not in its manifest: someone else's, kept
    assert main(["--yolo", str(images), "--out", str(out), "--seed", "2"]) == 2
    assert main(["--yolo", str(images), "--out", str(out), "--seed", "2", "--overwrite"]) == 1
    assert json.loads((out / "records" / "000000.json").read_text())["skip_kind"] == "corrupt image"  # rewritten
    assert (out / "records" / "999999.json").read_text() == "{}"
    assert json.loads((out / "manifest.json").read_text())["seed"] == 2


@needs_data
def test_huge_image_is_bounded(tmp_path):
    (tmp_path / "images").mkdir()
    cv2.imwrite(str(tmp_path / "images" / "big.png"), cv2.resize(road_picture(), (1600, 1200)))
    out = tmp_path / "out"
    assert (
        main(
            [
                "--yolo",
                str(tmp_path / "images"),
                "--preset",
                "fast",
                "--per-image",
                "1",
                "--out",
                str(out),
                "--max-megapixels",
                "0.1",
            ]
        )
        == 0
    )
    rec = json.loads((out / "records" / "000000.json").read_text())
    assert rec["width"] * rec["height"] <= 100_000 and rec["source_size"] == [1600, 1200]
    assert math.isclose(rec["scale"], math.sqrt(0.1e6 / (1600 * 1200)), rel_tol=0.01)
    assert json.loads((out / "report.json").read_text())["notes"] == {"downscaled": 1}


def test_a_second_run_into_a_busy_out_is_refused_and_a_killed_holder_frees_it(tmp_path, capsys):
    """A run holds --out (another process, here one that only takes the lock): a second run is refused at start
    with exit 2 and a message, touching nothing; once the holder is killed (SIGKILL, no cleanup) the folder is free."""
    import signal
    import subprocess
    import sys

    images = _yolo(tmp_path, {"t": ("truncated", None)})
    out = tmp_path / "out"
    holder = subprocess.Popen(
        [
            sys.executable,
            "-c",
            (
                "import sys, time; from pathlib import Path; from aias_augment.cli.manifest import output_lock\n"
                f"with output_lock(Path({str(out)!r})):\n    print('held', flush=True); time.sleep(60)"
            ),
        ],
        stdout=subprocess.PIPE,
        text=True,
    )
    try:
        assert holder.stdout.readline().strip() == "held"
        assert main(["--yolo", str(images), "--out", str(out)]) == 2
        err = capsys.readouterr().err
        assert "being written by another aias-augment run (pid" in err and not (out / "manifest.json").exists()
    finally:
        holder.send_signal(signal.SIGKILL)
        holder.wait()
    assert main(["--yolo", str(images), "--out", str(out)]) == 1  # runs (its one image is truncated: exit 1)
    assert (out / "manifest.json").exists()


def test_an_out_that_cannot_be_a_folder_is_one_line(tmp_path, capsys):
    images = _yolo(tmp_path, {"t": ("truncated", None)})
    (tmp_path / "file").write_text("x")
    assert main(["--yolo", str(images), "--out", str(tmp_path / "file" / "out")]) == 2
    err = capsys.readouterr().err
    assert err.startswith("aias-augment: error:") and "writable folder" in err and "Traceback" not in err


def test_a_bounded_image_keeps_its_camera_where_the_resize_puts_the_pixels():
    """The camera of an image augmented at a bounded size is the one that sees the resized pixels: a point of the
    scene that projects onto a bright 8x8 block of the original projects, through the rescaled K, onto that block's
    centroid in the resized image (K scaled without the half-pixel shift misses it by ~(1 - s) / 2 px)."""
    from aias_augment.cli.offline_job import Item, _bound_size

    K = np.array([[900.0, 0, 611.3], [0, 880.0, 355.7], [0, 0, 1]])
    img = np.zeros((720, 1280, 3), np.uint8)
    img[400:408, 900:908] = 255  # pixel centres 900..907: the block's centre is 903.5, 403.5
    point = np.linalg.inv(K) @ np.array([903.5, 403.5, 1.0]) * 7.0  # the scene point seen there, 7 m away
    item = Item(path="x.png", K=K.tolist())
    small, _ = _bound_size(img, item, max_pixels=160 * 90)
    w = small[..., 0].astype(float)
    ys, xs = np.mgrid[: w.shape[0], : w.shape[1]]
    centroid = np.array([(w * xs).sum(), (w * ys).sum()]) / w.sum()
    uvw = np.asarray(item.K) @ point
    assert np.abs(uvw[:2] / uvw[2] - centroid).max() < 0.05, (uvw[:2] / uvw[2], centroid)

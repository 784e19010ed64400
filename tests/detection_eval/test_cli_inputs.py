"""``detection-eval`` and ``aias-study`` on bad inputs: a bad weights file or config is one line and exit 2; an
unreadable image in ``eval`` or ``predict`` is a named, counted skip and the run goes on."""

from __future__ import annotations

import json
import shutil

import pytest
import torch

from detection_eval.cli import main
from detection_eval.study.cli import main as study_main

LAUGHS = (
    "model: ["
    + ", ".join(
        ["&a [" + ",".join(["lol"] * 9) + "]"]
        + [f"&{n} [" + ",".join([f"*{p}"] * 9) + "]" for p, n in zip("abcdefgh", "bcdefghi")]
    )
    + "]\n"
)


def _exit_2_one_line(capsys, run, *texts):
    with pytest.raises(SystemExit) as e:
        run()
    out, err = capsys.readouterr()
    assert e.value.code == 2, (out, err)
    lines = [ln for ln in err.strip().splitlines() if not ln.startswith("WARNING ")]  # named skips are logged
    assert len(lines) == 1 and "Traceback" not in out + err, err
    assert all(t in lines[0] for t in texts), lines[0]
    return lines[0]


def _bad_weights(tmp_path, kind):
    p = tmp_path / f"{kind}.pt"
    if kind == "text":
        p.write_text("not a checkpoint\n")
    elif kind == "empty":
        p.write_bytes(b"")
    elif kind == "foreign_torch":
        torch.save({"state_dict": {}}, p)
    elif kind == "tensor":
        torch.save(torch.zeros(3), p)
    elif kind == "truncated":
        torch.save({"format": "detection_eval/1", "x": torch.zeros(1000)}, p)
        p.write_bytes(p.read_bytes()[:300])
    return p


@pytest.mark.parametrize("kind", ["text", "empty", "foreign_torch", "tensor", "truncated", "missing"])
@pytest.mark.parametrize("command", ["eval", "predict"])
def test_bad_weights_one_line_exit_2(tmp_path, capsys, tiny_yolo_dir, kind, command):
    w = str(_bad_weights(tmp_path, kind))
    if command == "eval":
        argv = ["eval", "--weights", w, "--data", str(tiny_yolo_dir)]
    else:
        argv = ["predict", "--weights", w, "--images", str(tiny_yolo_dir / "images"), "--out", str(tmp_path / "p")]
    _exit_2_one_line(capsys, lambda: main(argv), f"detection-eval {command}: error:", kind)


CONFIGS = {
    "unknown_key": ("train:\n  max_iterz: 3\n".encode(), "max_iterz"),
    "not_utf8": ("# d\xe9j\xe0 vu\ntrain:\n  max_iters: 3\n".encode("latin-1"), "not UTF-8"),
    "billion_laughs": (LAUGHS.encode(), "expands to more than"),
    "bad_yaml": (b"train: [\n", "not valid YAML"),
    "bad_value": (b"train:\n  max_iters: -3\n", "max_iters"),
}


@pytest.mark.parametrize("case", sorted(CONFIGS))
def test_bad_detector_config_one_line_exit_2(tmp_path, capsys, tiny_yolo_dir, case):
    text, expected = CONFIGS[case]
    cfg = tmp_path / "det.yaml"
    cfg.write_bytes(text)
    argv = ["train", "--config", str(cfg), "--data", str(tiny_yolo_dir), "--out", str(tmp_path / "run")]
    _exit_2_one_line(capsys, lambda: main(argv), "detection-eval train: error:", expected)
    assert not (tmp_path / "run").exists()


STUDY_CONFIGS = {
    "unknown_key": (b"armz: [original]\n", "armz"),
    "not_utf8": ("name: caf\xe9\n".encode("latin-1"), "not UTF-8"),
    "billion_laughs": (LAUGHS.replace("model:", "arms:").encode(), "expands to more than"),
    "missing": (None, "config not found"),
}


@pytest.mark.parametrize("case", sorted(STUDY_CONFIGS))
def test_bad_study_config_one_line_exit_2(tmp_path, capsys, case):
    text, expected = STUDY_CONFIGS[case]
    cfg = tmp_path / "study.yaml"
    if text is not None:
        cfg.write_bytes(text)
    _exit_2_one_line(capsys, lambda: study_main(["--config", str(cfg)]), "aias-study: error:", expected)


@pytest.fixture()
def yolo_with_a_broken_image(tiny_yolo_dir, tmp_path):
    """The tiny YOLO set plus an image that is no image (its label file is there)."""
    root = tmp_path / "yolo"
    shutil.copytree(tiny_yolo_dir, root)
    (root / "images" / "broken.jpg").write_bytes(b"\xff\xd8\xff\xe0 not really a jpeg")
    (root / "labels" / "broken.txt").write_text("0 0.5 0.5 0.2 0.3\n")
    return root


def test_eval_skips_an_unreadable_image_and_counts_it(weights, yolo_with_a_broken_image, tmp_path, capsys):
    out = tmp_path / "m.json"
    main(["eval", "--weights", str(weights), "--data", str(yolo_with_a_broken_image), "--out", str(out)])
    m = json.loads(out.read_text())
    assert m["num_images"] == 4 and m["num_gt"] == 6  # the four good images, as without the broken one
    _, err = capsys.readouterr()
    assert "broken.jpg" in err and "Traceback" not in err


def test_eval_skips_an_unreadable_coco_image(weights, tiny_yolo_dir, tmp_path, capsys):
    from detection_eval.data import coco_gt_dict, load_yolo_dir

    ds = load_yolo_dir(tiny_yolo_dir)
    gt = coco_gt_dict(ds)
    for im, r in zip(gt["images"], ds.records):
        im["file_name"] = r.image_path
    gt["images"][1]["file_name"] = str(tmp_path / "gone.jpg")  # listed, not on disk
    (tmp_path / "gt.json").write_text(json.dumps(gt))
    out = tmp_path / "m.json"
    main(["eval", "--weights", str(weights), "--data", str(tmp_path / "gt.json"), "--out", str(out)])
    m = json.loads(out.read_text())
    assert m["num_images"] == 3 and list(m["skipped_images"]) == [str(tmp_path / "gone.jpg")]
    assert m["num_gt"] == ds.num_boxes - len(ds.records[1].labels)
    stdout, err = capsys.readouterr()
    assert "1 unreadable images skipped" in stdout and "gone.jpg" in err


def test_eval_with_no_readable_image_is_one_line_exit_2(weights, tiny_yolo_dir, tmp_path, capsys):
    from detection_eval.data import coco_gt_dict, load_yolo_dir

    gt = coco_gt_dict(load_yolo_dir(tiny_yolo_dir))
    for im in gt["images"]:
        im["file_name"] = str(tmp_path / "gone.jpg")
    (tmp_path / "gt.json").write_text(json.dumps(gt))
    argv = ["eval", "--weights", str(weights), "--data", str(tmp_path / "gt.json")]
    _exit_2_one_line(capsys, lambda: main(argv), "none of the 4 images could be read")


def test_predict_skips_an_unreadable_image_and_counts_it(weights, yolo_with_a_broken_image, tmp_path, capsys):
    out = tmp_path / "pred"
    main(
        ["predict", "--weights", str(weights), "--images", str(yolo_with_a_broken_image / "images"), "--out", str(out)]
    )
    assert sorted(p.name for p in out.glob("*.jpg")) == [f"img_{i}.jpg" for i in range(4)]
    assert "broken.jpg" not in {d["file_name"] for d in json.loads((out / "detections.json").read_text())}
    stdout, err = capsys.readouterr()
    assert "1 unreadable images skipped" in stdout and "broken.jpg" in err and "Traceback" not in err

"""Datasets in the user's format, read back by a reader this project does not write with (``supervision``): a YOLO
dataset in the Ultralytics layout stays one (class names and order, the other split copied, JPEG kept), a COCO input
can come out as YOLO, and the KITTI-3D labels agree with a projection of their own 3D boxes."""

import hashlib
import json
import math
from pathlib import Path

import cv2
import numpy as np
import pytest
import yaml

from aias_augment.assets.asset import DEFAULT_ASSETS
from aias_augment.cli.augment import main
from aias_augment.core.config import data_root
from tests.aias_augment.pipeline.test_image import road_frame

sv = pytest.importorskip("supervision")
pytestmark = pytest.mark.skipif(
    not (data_root() / DEFAULT_ASSETS["traffic_cone"][0]).exists(), reason="shared data not present"
)


def _tree_digest(root: Path) -> dict:
    return {
        str(p.relative_to(root)): hashlib.sha256(p.read_bytes()).hexdigest() for p in root.rglob("*") if p.is_file()
    }


def _jpeg(path: Path, seed: int = 0) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    img = road_frame()
    img[:40, 40 * seed : 40 * seed + 40] = (200, 60, 20)  # the images differ
    cv2.imwrite(str(path), img[..., ::-1], [cv2.IMWRITE_JPEG_QUALITY, 90])


def make_yolo_dataset(root: Path) -> Path:
    """Ultralytics layout: train (2 JPEGs) and val (1 JPEG), classes [cone, person], each image one person box."""
    for split, n in (("train", 2), ("val", 1)):
        for i in range(n):
            _jpeg(root / "images" / split / f"{split}{i}.jpg", i)
            lab = root / "labels" / split / f"{split}{i}.txt"
            lab.parent.mkdir(parents=True, exist_ok=True)
            lab.write_text("1 0.100000 0.100000 0.050000 0.080000\n")
    (root / "data.yaml").write_text("path: .\ntrain: images/train\nval: images/val\nnames:\n  0: cone\n  1: person\n")
    return root / "data.yaml"


@pytest.fixture(scope="module")
def yolo_run(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("yolo")
    data = make_yolo_dataset(tmp / "ds")
    before = _tree_digest(tmp / "ds")
    out = tmp / "out"
    rc = main(["--yolo", str(data), "--preset", "fast", "--export-3d", "kitti", "--out", str(out)])
    assert rc == 0
    return tmp / "ds", out, before


def _records(out: Path) -> list[dict]:
    return [json.loads(p.read_text()) for p in sorted((out / "records").glob("*.json"))]


def _xyxy(b):
    return [b[0], b[1], b[0] + b[2], b[1] + b[3]]


def _check_dataset(ds, records, images_dir: Path, names_of_record):
    """Every record's image is in ``ds`` with the record's boxes (1 px) and class names; nothing else is."""
    by_name = {Path(p).resolve(): det for p, _, det in ds}
    assert set(by_name) == {(images_dir / r["file_name"]).resolve() for r in records}
    for r in records:
        det = by_name[(images_dir / r["file_name"]).resolve()]
        got = sorted((ds.classes[c], *np.round(b, 1).tolist()) for b, c in zip(det.xyxy, det.class_id))
        want = sorted(zip(names_of_record(r), *np.array([_xyxy(b) for b in r["boxes"]]).T))
        assert [g[0] for g in got] == [w[0] for w in want]
        assert np.allclose([g[1:] for g in got], [w[1:] for w in want], atol=1.0)


def test_yolo_in_yolo_out_same_classes_read_by_supervision(yolo_run):
    ds_in, out, _ = yolo_run
    records = _records(out)
    assert all("skipped" not in r for r in records) and sum(sum(r["inserted"]) for r in records) >= 2
    data = yaml.safe_load((out / "data.yaml").read_text())
    assert data["names"] == {0: "cone", 1: "person"}  # the user's names, in their order; no traffic_cone class
    assert (data["train"], data["val"]) == ("images/train", "images/val")
    ds = sv.DetectionDataset.from_yolo(
        str(out / "images" / "train"), str(out / "labels" / "train"), str(out / "data.yaml")
    )
    assert ds.classes == ["cone", "person"]

    def names(r):  # inserted cones as the user's "cone" (a taxonomy synonym), the user's boxes as they were
        return ["cone" if ins else lab for lab, ins in zip(r["labels"], r["inserted"])]

    _check_dataset(ds, records, out / "images", names)
    report = json.loads((out / "report.json").read_text())["output"]
    assert report["labels"] == {"traffic_cone": {"as": "cone", "why": "taxonomy synonym"}}
    assert report["yolo"]["augmented_split"] == "train"
    # annotations.json (COCO) of the same run, read by supervision too: the same boxes and names
    coco = sv.DetectionDataset.from_coco(str(out / "images"), str(out / "annotations.json"))
    assert sorted(coco.classes) == ["cone", "person"]
    _check_dataset(coco, records, out / "images", names)


def test_other_split_copied_unchanged_and_inputs_untouched(yolo_run):
    ds_in, out, before = yolo_run
    assert _tree_digest(ds_in) == before  # every input byte unchanged
    for sub in ("images/val/val0.jpg", "labels/val/val0.txt"):
        assert not (out / sub).is_symlink()
        assert (out / sub).read_bytes() == (ds_in / sub).read_bytes()
    ds = sv.DetectionDataset.from_yolo(str(out / "images" / "val"), str(out / "labels" / "val"), str(out / "data.yaml"))
    assert len(ds) == 1
    (_, _, det) = next(iter(ds))
    assert [ds.classes[c] for c in det.class_id] == ["person"]


def test_jpeg_in_jpeg_out(yolo_run):
    ds_in, out, _ = yolo_run
    for r in _records(out):
        p = out / "images" / r["file_name"]
        assert p.suffix == ".jpg" and p.read_bytes()[:2] == b"\xff\xd8"


def test_kitti_labels_match_the_projection_of_their_3d_box(yolo_run):
    """Each label line's devkit box (corners from h, w, l, x, y, z, ry as the KITTI devkit builds them), projected
    with the calib file's P2, is the object's projected box (the placement's, from the asset's own corners) within
    rounding, and holds the object's rendered mask box; alpha = ry - atan2(x, z)."""
    _, out, _ = yolo_run
    checked = 0
    for r in _records(out):
        stem = Path(r["file_name"]).stem
        calib = dict(line.split(": ", 1) for line in (out / "kitti" / "calib" / f"{stem}.txt").read_text().splitlines())
        P2 = np.array(calib["P2"].split(), float).reshape(3, 4)
        lines = [ln.split() for ln in (out / "kitti" / "label_2" / f"{stem}.txt").read_text().splitlines()]
        objects = [ln for ln in lines if ln[0] != "DontCare"]
        shown = [(p, a) for p, a in zip(r["placements"], r["annotations"]) if a["visible_box_xywh"] and not p["decoy"]]
        assert len(objects) == len(shown) and sum(ln[0] == "DontCare" for ln in lines) == r["inserted"].count(False)
        for f, (p, a) in zip(objects, shown):
            assert f[0] == "cone"
            trunc, alpha, box2d = float(f[1]), float(f[3]), np.array(f[4:8], float)
            h, w, length, x, y, z, ry = (float(v) for v in f[8:15])
            assert abs((alpha - (ry - math.atan2(x, z)) + math.pi) % (2 * math.pi) - math.pi) < 0.011
            c, s = math.cos(ry), math.sin(ry)
            R = np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])
            corners = R @ np.array(
                [
                    [length / 2, length / 2, -length / 2, -length / 2] * 2,
                    [0, 0, 0, 0, -h, -h, -h, -h],
                    [w / 2, -w / 2, -w / 2, w / 2] * 2,
                ]
            ) + np.array([[x], [y], [z]])
            uvw = P2 @ np.vstack([corners, np.ones(8)])
            uv = uvw[:2] / uvw[2]
            projected = np.array([uv[0].min(), uv[1].min(), uv[0].max(), uv[1].max()])
            assert np.allclose(projected, p["amodal_box_xyxy"], atol=2.5)
            assert np.allclose(box2d, _xyxy(a["visible_box_xywh"]), atol=0.01)
            if trunc == 0 and a["visibility"] > 0.99:  # the whole object is drawn: its mask lies in its 3D box
                assert np.all(projected[:2] <= box2d[:2] + 1) and np.all(projected[2:] >= box2d[2:] - 1)
            checked += 1
    assert checked >= 2


def test_coco_in_yolo_out_with_a_synonym_category(tmp_path):
    """A COCO input with classes sign (id 3) and cone (id 7), ``--categories cone`` (the taxonomy's traffic_cone),
    ``--format yolo --image-format png``: YOLO classes [sign, cone] (id order), inserted objects as ``cone``, and
    lossless PNGs: rows far above every inserted object are the input's decoded pixels exactly."""
    for i in range(2):
        _jpeg(tmp_path / "im" / f"{i}.jpg", i)
    h, w = road_frame().shape[:2]
    coco_in = {
        "images": [{"id": i + 1, "file_name": f"{i}.jpg", "width": w, "height": h} for i in range(2)],
        "annotations": [{"id": 1, "image_id": 2, "category_id": 3, "bbox": [50, 5, 20, 20]}],
        "categories": [{"id": 3, "name": "sign"}, {"id": 7, "name": "cone"}],
    }
    (tmp_path / "in.json").write_text(json.dumps(coco_in))
    out = tmp_path / "out"
    args = ["--input", str(tmp_path / "in.json"), "--images", str(tmp_path / "im"), "--preset", "fast"]
    rc = main([*args, "--categories", "cone", "--format", "yolo", "--image-format", "png", "--out", str(out)])
    assert rc == 0
    records = _records(out)
    ds = sv.DetectionDataset.from_yolo(
        str(out / "images" / "train"), str(out / "labels" / "train"), str(out / "data.yaml")
    )
    assert ds.classes == ["sign", "cone"]
    _check_dataset(
        ds, records, out / "images", lambda r: ["cone" if i else x for x, i in zip(r["labels"], r["inserted"])]
    )
    assert json.loads((out / "report.json").read_text())["output"]["labels"] == {
        "traffic_cone": {"as": "cone", "why": "--categories"}
    }
    # the contact sheet names boxes as they are written: the inserted ones under the user's class
    from aias_augment.core.viz import contact_sheet, draw_boxes

    def sheet(names_of):
        tiles = []
        for r in records:
            img = cv2.cvtColor(cv2.imread(str(out / "images" / r["file_name"])), cv2.COLOR_BGR2RGB)
            tiles.append(draw_boxes(img, r["boxes"], names_of(r), r["inserted"]))
        return contact_sheet(tiles)

    written = cv2.cvtColor(cv2.imread(str(out / "contact_sheet.png")), cv2.COLOR_BGR2RGB)
    assert np.array_equal(written, sheet(lambda r: ["cone" if i else x for x, i in zip(r["labels"], r["inserted"])]))
    assert not np.array_equal(written, sheet(lambda r: r["labels"]))
    for r in records:
        assert r["file_name"].endswith(".png")
        got = cv2.imread(str(out / "images" / r["file_name"]))
        src = cv2.imread(r["source"])
        top = int(min(p["amodal_box_xyxy"][1] for p in r["placements"])) - 60
        assert top > 20 and np.array_equal(got[:top], src[:top])


def test_bad_split_and_quality_are_one_line_errors(tmp_path, capsys):
    data = make_yolo_dataset(tmp_path / "ds")
    assert main(["--yolo", str(data), "--split", "nope", "--out", str(tmp_path / "o")]) == 2
    assert "--split 'nope'" in capsys.readouterr().err
    assert main(["--yolo", str(data), "--jpeg-quality", "0", "--out", str(tmp_path / "o")]) == 2
    assert "--jpeg-quality 0" in capsys.readouterr().err
    assert main(["--yolo", str(data), "--label-as", "barrel=cone", "--out", str(tmp_path / "o")]) == 2
    assert "not an inserted category" in capsys.readouterr().err
    assert not (tmp_path / "o").exists()
    inside_val = tmp_path / "ds" / "images" / "val" / "aug"  # a split that would be copied into --out
    assert main(["--yolo", str(data), "--out", str(inside_val)]) == 2
    assert "--yolo val images" in capsys.readouterr().err and not inside_val.exists()


def readme_block(marker: str) -> list[str]:
    """The command lines of the fenced block that follows ``<!-- readme-test: marker -->`` in README.md."""
    text = (Path(__file__).resolve().parents[3] / "README.md").read_text()
    after = text.split(f"<!-- readme-test: {marker} -->", 1)[1]
    block = after.split("```bash\n", 1)[1].split("```", 1)[0]
    return [line for line in block.splitlines() if line.strip() and not line.startswith("#")]


def test_readme_yolo_to_yolo_runs_as_written(tmp_path, monkeypatch):
    """The README's block, run as written in a folder holding ``my_dataset``: a YOLO dataset with the input's class
    names comes out, read back by supervision."""
    import shlex

    make_yolo_dataset(tmp_path / "my_dataset")
    monkeypatch.chdir(tmp_path)
    lines = readme_block("yolo-to-yolo")
    assert lines and all(line.startswith("aias-augment ") for line in lines)
    for line in lines:
        assert main(shlex.split(line)[1:]) == 0
    out = tmp_path / "my_dataset_aug"
    ds = sv.DetectionDataset.from_yolo(
        str(out / "images" / "train"), str(out / "labels" / "train"), str(out / "data.yaml")
    )
    assert ds.classes == ["cone", "person"] and len(ds) == 2
    labels = [ds.classes[c] for _, _, det in ds for c in det.class_id]
    assert labels.count("person") == 2 and labels.count("cone") >= 1

"""The labels inserted objects get (``--label-as``, taxonomy synonyms, ``--categories cone``) and the YOLO input's
splits and names, without running an insertion."""

import pytest

from aias_augment.adapters.boundary import InputError
from aias_augment.cli.dataset_out import ImageOut, canonical_categories, resolve_label_as
from aias_augment.cli.yolo_io import labels_dir_for, read_yolo_dataset, yolo_label_text

KNOWN = {"traffic_cone", "barrel", "person"}


def _map(label_as):
    return {m.category: (m.label, m.why) for m in label_as}


def test_an_input_class_the_taxonomy_reads_as_the_category_is_used():
    got = resolve_label_as(None, ("traffic_cone", "barrel"), ("person", "Traffic-Cone"), KNOWN)
    assert _map(got) == {"traffic_cone": ("Traffic-Cone", "taxonomy synonym")}
    assert _map(resolve_label_as(None, ("traffic_cone",), ("cone",), KNOWN)) == {
        "traffic_cone": ("cone", "taxonomy synonym")
    }
    # the input has the category's own name: nothing to map; no synonym at all: nothing either
    assert resolve_label_as(None, ("traffic_cone",), ("cone", "traffic_cone"), KNOWN) == ()
    assert resolve_label_as(None, ("traffic_cone",), ("sign",), KNOWN) == ()


def test_label_as_wins_and_is_checked():
    got = resolve_label_as(["traffic_cone=person"], ("traffic_cone",), ("cone", "person"), KNOWN)
    assert _map(got) == {"traffic_cone": ("person", "--label-as")}
    # the category by a synonym of it
    assert _map(resolve_label_as(["cone=obstacle"], ("traffic_cone",), (), KNOWN)) == {
        "traffic_cone": ("obstacle", "--label-as")
    }
    with pytest.raises(InputError, match="not an inserted category"):
        resolve_label_as(["barrel=cone"], ("traffic_cone",), ("cone",), KNOWN)
    with pytest.raises(InputError, match="CATEGORY=CLASS"):
        resolve_label_as(["traffic_cone"], ("traffic_cone",), ("cone",), KNOWN)


def test_categories_by_a_synonym():
    cats, label_as = canonical_categories(["cone", "barrel"], KNOWN)
    assert cats == ("traffic_cone", "barrel")
    assert _map(label_as) == {"traffic_cone": ("cone", "--categories")}
    assert canonical_categories(["crate"], KNOWN) == (("crate",), ())  # unknown names are left to the caller's check


def test_image_names_keep_the_input_format():
    assert ImageOut("keep").file_name(3, "/a/b/x.JPG") == "000003_x.jpg"
    assert ImageOut("keep", subdir="train").file_name(3, "x.bmp") == "train/000003_x.png"
    assert ImageOut("jpg").file_name(0, "x.png") == "000000_x.jpg"
    assert ImageOut("png").file_name(0, "x.jpeg") == "000000_x.png"
    with pytest.raises(InputError, match="--jpeg-quality"):
        ImageOut("keep", 101)


def test_yolo_layouts(tmp_path):
    for split in ("train", "val"):
        (tmp_path / "ds" / "images" / split).mkdir(parents=True)
    ds = read_yolo_dataset(tmp_path / "ds")  # images/<split> folders, no data.yaml
    assert [s.name for s in ds.splits] == ["train", "val"] and ds.names is None
    assert ds.split(None).labels == tmp_path / "ds" / "labels" / "train"
    (tmp_path / "ds" / "data.yaml").write_text("train: images/train\nval: images/val\nnames: [a, b]\n")
    ds = read_yolo_dataset(tmp_path / "ds")
    assert ds.names == ("a", "b") and ds.split("val").images == tmp_path / "ds" / "images" / "val"
    with pytest.raises(InputError, match="--split 'test'"):
        ds.split("test")
    (tmp_path / "ds" / "data.yaml").write_text("train: images/train\nnames: {0: a, 2: c}\n")
    with pytest.raises(InputError, match="every class index"):
        read_yolo_dataset(tmp_path / "ds" / "data.yaml")
    (tmp_path / "ds" / "data.yaml").write_text("train: ../images/train\nnames: [a]\n")  # Roboflow's export
    assert (
        read_yolo_dataset(tmp_path / "ds" / "data.yaml").split("train").images == tmp_path / "ds" / "images" / "train"
    )
    (tmp_path / "ds" / "list.txt").write_text("images/train/a.jpg\n")
    (tmp_path / "ds" / "data.yaml").write_text("train: list.txt\nnames: [a]\n")
    with pytest.raises(InputError, match="list file"):
        read_yolo_dataset(tmp_path / "ds" / "data.yaml")
    # Ultralytics' rule: the last "images" component becomes "labels"
    assert (
        labels_dir_for(tmp_path / "images" / "x" / "images" / "train") == tmp_path / "images" / "x" / "labels" / "train"
    )
    assert labels_dir_for(tmp_path / "pics") == tmp_path / "pics"


def test_yolo_label_text_normalises_pixel_boxes():
    assert yolo_label_text([[10, 20, 30, 40]], [2], 100, 200) == "2 0.250000 0.200000 0.300000 0.200000\n"

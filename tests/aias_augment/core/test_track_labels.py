"""MOTChallenge and COCO-video track labels: round trips through independent readers (motmetrics for MOT,
pycocotools for COCO-video) and the MOTChallenge columns read literally."""

import json

import numpy as np
import pytest
from pycocotools.coco import COCO

from aias_augment.core.errors import InputError
from aias_augment.core.track_labels import (
    TrackBox,
    detect_format,
    format_number,
    mot_line,
    read_coco_video,
    read_mot,
)

BOXES = [  # frame (0-based), track, COCO box
    (0, 1, (10.0, 20.5, 30.25, 40.0)),
    (0, 4, (0.0, 0.0, 5.0, 7.0)),
    (1, 1, (11.37, 21.0, 30.0, 40.125)),
    (3, 9, (-2.5, 100.0, 12.0, 8.0)),  # partly left of the frame, as MOT ground truth often is
]


def _write_mot(path):
    path.write_text("".join(mot_line(f, t, b, 0.5 if t == 4 else 1.0) + "\n" for f, t, b in BOXES))


def test_mot_lines_are_motchallenge_columns_literally(tmp_path):
    """frame (from 1), id, bb_left, bb_top (pixels from 1), bb_width, bb_height, conf, x, y, z (-1: no world)."""
    p = tmp_path / "gt.txt"
    _write_mot(p)
    for line, (f, t, (x, y, w, h)) in zip(p.read_text().splitlines(), BOXES):
        cols = line.split(",")
        assert len(cols) == 10 and cols[7:] == ["-1", "-1", "-1"]
        assert int(cols[0]) == f + 1 and int(cols[1]) == t
        assert [float(c) for c in cols[2:6]] == [x + 1, y + 1, w, h]
        assert float(cols[6]) == (0.5 if t == 4 else 1.0)


def test_mot_round_trip_and_motmetrics_reads_the_same_boxes(tmp_path):
    import motmetrics as mm

    p = tmp_path / "gt.txt"
    _write_mot(p)
    back = read_mot(p, "pedestrian")
    assert [(b.frame, b.track_id, b.box_xywh, b.category) for b in back] == [
        (f, t, b, "pedestrian") for f, t, b in BOXES
    ]
    df = mm.io.loadtxt(str(p), fmt="mot15-2D")  # motmetrics undoes MOTChallenge's 1-based pixels
    for f, t, (x, y, w, h) in BOXES:
        r = df.loc[(f + 1, t)]
        assert np.allclose([r["X"], r["Y"], r["Width"], r["Height"]], [x, y, w, h])
    # written again from what was read: the same bytes
    again = tmp_path / "again.txt"
    again.write_text("".join(mot_line(b.frame, b.track_id, b.box_xywh, b.conf) + "\n" for b in back))
    assert again.read_bytes() == p.read_bytes()


def test_mot_reads_space_separated_and_six_column_rows(tmp_path):
    p = tmp_path / "gt.txt"
    p.write_text("1 2 11 21 30 40\n\n2 2 12 21 30 40\n")
    assert [b.box_xywh for b in read_mot(p)] == [(10.0, 20.0, 30.0, 40.0), (11.0, 20.0, 30.0, 40.0)]
    assert detect_format(p) == "mot"


def test_coco_video_read_by_pycocotools_and_by_the_reader_agree(tmp_path):
    """A TAO-style file (instance_id for track_id, frame_index for frame_id) and a plain COCO-video one."""
    images = [
        {"id": 7 + i, "file_name": f"seq/{i:06d}.jpg", "width": 64, "height": 48, "video_id": 3} for i in range(4)
    ]
    for im, fid in zip(images, (0, 1, 2, 3)):
        im["frame_id"] = fid
    anns = [
        {"id": k + 1, "image_id": 7 + f, "category_id": 2, "bbox": list(b), "track_id": t, "area": b[2] * b[3]}
        for k, (f, t, b) in enumerate(BOXES)
    ]
    d = {"videos": [{"id": 3}], "images": images, "annotations": anns, "categories": [{"id": 2, "name": "car"}]}
    p = tmp_path / "labels.json"
    p.write_text(json.dumps(d))
    assert detect_format(p) == "coco-video"
    coco = COCO(str(p))
    read = read_coco_video(p)
    assert len(read) == len(coco.getAnnIds())
    for b, a in zip(read, coco.loadAnns(coco.getAnnIds())):
        im = coco.loadImgs(a["image_id"])[0]
        assert b == TrackBox(im["frame_id"], a["track_id"], "car", tuple(a["bbox"]), 1.0, im["file_name"][4:10])
    for a in d["annotations"]:
        a["instance_id"] = a.pop("track_id")
    for im in d["images"]:
        im["frame_index"] = im.pop("frame_id")
    p.write_text(json.dumps(d))
    assert read_coco_video(p) == read


@pytest.mark.parametrize(
    ("edit", "needle"),
    [
        (lambda d: d["images"].append({**d["images"][0], "id": 99, "video_id": 4}), "2 videos"),
        (lambda d: d["annotations"][0].pop("track_id"), "track_id None"),
        (lambda d: d["annotations"][0].update(category_id=5), "category_id 5 is not in categories"),
        (lambda d: d["annotations"][0].update(bbox=[1, 2, 0, 3]), "w, h > 0"),
        (lambda d: d["annotations"][0].update(image_id=1234), "no image_id"),
        (lambda d: d["annotations"].append({**d["annotations"][0], "id": 50}), "track 1 twice"),
        (lambda d: d["images"][0].update(frame_id=-1), "frame ids are whole numbers"),
    ],
)
def test_bad_coco_video_is_a_one_line_input_error(tmp_path, edit, needle):
    d = {
        "images": [{"id": 1, "file_name": "a.jpg", "frame_id": 0, "video_id": 1}],
        "annotations": [{"id": 1, "image_id": 1, "category_id": 1, "bbox": [1, 2, 3, 4], "track_id": 1}],
        "categories": [{"id": 1, "name": "car"}],
    }
    edit(d)
    p = tmp_path / "l.json"
    p.write_text(json.dumps(d))
    with pytest.raises(InputError, match=needle) as e:
        read_coco_video(p)
    assert "\n" not in str(e.value)


def test_numbers_keep_a_ten_thousandth_of_a_pixel():
    assert [format_number(v) for v in (100.0, 10.37, -2.5, 1 / 3, 1e-9, -1e-9)] == [
        "100",
        "10.37",
        "-2.5",
        "0.3333",
        "0",
        "0",
    ]

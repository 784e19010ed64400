"""A clip's own track labels (MOT or COCO-video in): carried into its COCO-video and MOT output with their track ids,
occluding the inserted objects behind them, and both visibilities updated.

The clip is 8 KITTI 06 frames (GT poses, seed 3: the cone stands to the right and is visible in frames 0-4) into
which two dark "real objects" are painted at known pixels: one whose base is lower in the image than the cone's (nearer,
frames 0 and 1) and one whose base is higher (farther, frame 2); a third labelled object (frame 6) meets nothing.
What the test knows independently is the painted pixels, not GrabCut's mask."""

import json

import cv2
import numpy as np
import pytest
from pycocotools.coco import COCO

from aias_augment.cli.augment import main
from aias_augment.cli.clip import ClipJob, read_clip_inputs, render_clip
from aias_augment.core.config import data_root

SEQ = data_root() / "kitti06_seq"
N = 8
# Painted objects (x0, y0, x1, y1), pixel-edge coordinates, and their labels: frame (0-based), track id.
NEAR = {0: (760, 250, 812, 340), 1: (790, 262, 846, 360)}  # bases below the cone's (y 310, 335): nearer
FAR = {2: (870, 230, 950, 330)}  # base above the cone's (y 368): farther, the cone stands in front of it
APART = {6: (100, 200, 160, 300)}  # meets no inserted object
TRACKS = {"near": 7, "far": 12, "apart": 3}
MARGIN_PX = 4  # the label box around the painted object (GrabCut needs background inside the box's context)


def _labels():
    rows = []
    for name, shapes in (("near", NEAR), ("far", FAR), ("apart", APART)):
        for f, (x0, y0, x1, y1) in shapes.items():
            box = (x0 - MARGIN_PX, y0 - MARGIN_PX, x1 - x0 + 2 * MARGIN_PX, y1 - y0 + 2 * MARGIN_PX)
            rows.append((f, TRACKS[name], box))
    return sorted(rows)


def _write_mot(path, rows):
    # MOTChallenge: frame from 1, id, bb_left, bb_top (pixels from 1), width, height, conf, x, y, z
    path.write_text("".join(f"{f + 1},{t},{b[0] + 1},{b[1] + 1},{b[2]},{b[3]},1,-1,-1,-1\n" for f, t, b in rows))


def _write_coco_video(path, rows):
    images = [
        {"id": 10 + f, "file_name": f"{f:06d}.png", "width": 1226, "height": 370, "video_id": 5} for f in range(N)
    ]
    anns = [
        {"id": k + 1, "image_id": 10 + f, "category_id": 4, "bbox": list(map(float, b)), "track_id": t}
        for k, (f, t, b) in enumerate(rows)
    ]
    d = {"videos": [{"id": 5}], "images": images, "annotations": anns, "categories": [{"id": 4, "name": "pedestrian"}]}
    path.write_text(json.dumps(d))


@pytest.fixture(scope="module")
def painted(tmp_path_factory):
    """A frame folder of the first N KITTI frames with the objects painted (ellipses of intensity 12, dark objects
    on the road), its MOT and COCO-video label files and the painted masks per frame."""
    if not SEQ.exists():
        pytest.skip("shared KITTI data not available")
    root = tmp_path_factory.mktemp("painted")
    frames = root / "frames"
    frames.mkdir()
    masks = {}
    for f in range(N):
        img = cv2.imread(str(SEQ / "image_l" / f"{f:06d}.png"), cv2.IMREAD_COLOR)
        m = np.zeros(img.shape[:2], np.uint8)
        for shapes in (NEAR, FAR, APART):
            if f in shapes:  # an ellipse filling the box (no corners for GrabCut's smoothing to round)
                x0, y0, x1, y1 = shapes[f]
                centre, axes = ((x0 + x1 - 1) // 2, (y0 + y1 - 1) // 2), ((x1 - x0 - 1) // 2, (y1 - y0 - 1) // 2)
                cv2.ellipse(m, centre, axes, 0, 0, 360, 1, thickness=-1)
        m = m.astype(bool)
        img[m] = 12
        masks[f] = m
        cv2.imwrite(str(frames / f"{f:06d}.png"), img)
    _write_mot(root / "gt.txt", _labels())
    _write_coco_video(root / "labels.json", _labels())
    return root, masks


def _job(root, out, labels=None, **kw):
    return ClipJob(
        str(root / "frames"),
        str(SEQ / "calib.txt"),
        str(SEQ / "poses.txt"),
        str(out),
        seed=3,
        lighting="ambient",
        labels=labels,
        **kw,
    )


@pytest.fixture(scope="module")
def rendered(painted):
    root, _ = painted
    plain = _job(root, root / "plain")
    labelled = _job(root, root / "labelled", str(root / "gt.txt"))
    inputs = read_clip_inputs(labelled)
    return render_clip(plain, read_clip_inputs(plain)), render_clip(labelled, inputs), inputs


def test_a_nearer_labelled_object_hides_the_inserted_one_inside_its_mask(painted, rendered):
    """Frames 0 and 1: inside the painted (nearer) object the composite is the input frame, byte for byte; the cone's
    visible mask is the unlabelled run's minus the painted pixels; its visibility drops by that share."""
    _, masks = painted
    plain, labelled, inputs = rendered
    for f in NEAR:
        painted_px = masks[f]
        inner = cv2.erode(painted_px.astype(np.uint8), np.ones((5, 5), np.uint8)).astype(bool)  # 2 px in
        before = plain.results[0].masks[f] > 0.5
        after = labelled.results[0].masks[f] > 0.5
        assert (before & inner).sum() > 300, f  # the cone is drawn there without labels
        assert np.array_equal(labelled.frames[f][inner], inputs.frames[f][inner]), f
        assert not (after & inner).any(), f
        expected = before & ~painted_px
        x0, y0, x1, y1 = NEAR[f]
        assert (after ^ expected).sum() <= 2 * (x1 - x0 + y1 - y0), f  # GrabCut's edge: within a pixel of the paint
        v_before, v_after = plain.results[0].visibilities[f], labelled.results[0].visibilities[f]
        share = (before & painted_px).sum() / (before.sum() / v_before)  # hidden pixels / amodal pixels
        assert v_after == pytest.approx(v_before - share, abs=0.03), (f, v_before, v_after, share)
        # the labelled object in front of the cone stays fully visible
        near = [k for k, b in enumerate(inputs.labels[f]) if b.track_id == TRACKS["near"]][0]
        assert labelled.labels_visibility[f][near] == 1.0


def test_a_farther_labelled_object_is_covered_and_loses_visibility(painted, rendered):
    """Frame 2: the cone stands in front of the farther painted object: its visible mask is the unlabelled run's (it
    is drawn over the object's pixels), and the object's visibility is the share of its box the cone's visible mask
    leaves uncovered."""
    _, masks = painted
    plain, labelled, inputs = rendered
    f = 2
    cone = labelled.results[0].masks[f]
    assert np.array_equal(cone, plain.results[0].masks[f])
    over = (cone > 0.5) & masks[f]
    assert over.sum() > 300 and (labelled.frames[f][over] != inputs.frames[f][over]).any(axis=1).mean() > 0.9
    k = [k for k, b in enumerate(inputs.labels[f]) if b.track_id == TRACKS["far"]][0]
    x, y, w, h = (int(v) for v in inputs.labels[f][k].box_xywh)
    expected = 1 - cone[y : y + h, x : x + w].sum() / (w * h)
    assert expected < 0.9  # the cone covers a good part of it
    assert labelled.labels_visibility[f][k] == pytest.approx(expected, abs=1e-6)
    assert labelled.results[0].visibilities[f] == plain.results[0].visibilities[f]


def _mot_rows(path):
    import motmetrics as mm  # an independent MOTChallenge reader (it undoes the 1-based pixels)

    df = mm.io.loadtxt(str(path), fmt="mot15-2D")
    return {(int(f), int(i)): tuple(r) for (f, i), r in zip(df.index, df[["X", "Y", "Width", "Height"]].values)}


@pytest.fixture(scope="module")
def cli_runs(painted):
    root, _ = painted
    base = ["--input", str(root / "frames"), "--camera", str(SEQ / "calib.txt"), "--poses", str(SEQ / "poses.txt")]
    base += ["--max-frames", str(N), "--lighting", "ambient", "--seed", "3"]
    assert (
        main([*base, "--labels", str(root / "gt.txt"), "--labels-category", "pedestrian", "--out", str(root / "m")])
        == 0
    )
    assert main([*base, "--labels", str(root / "labels.json"), "--out", str(root / "c")]) == 0
    return root


def test_mot_in_mot_out_keeps_every_labelled_row_and_gives_the_cone_a_free_track(cli_runs):
    """motmetrics reads the input and the output MOT files: every input row is in the output with its track id and
    box (none of them is changed: covering changes visibility, not the box); the cone's rows take track id 13, after
    the largest labelled id, and are the COCO-video file's inserted boxes."""
    root = cli_runs
    given, written = _mot_rows(root / "gt.txt"), _mot_rows(root / "m" / "mot.txt")
    for key, box in given.items():
        assert written[key] == pytest.approx(box, abs=1e-4), key
    cone = {k: v for k, v in written.items() if k not in given}
    assert cone and {i for _, i in cone} == {max(TRACKS.values()) + 1}
    coco = COCO(str(root / "m" / "annotations.json"))
    frame_of = {im["id"]: im["frame_id"] for im in coco.dataset["images"]}
    inserted = {
        (frame_of[a["image_id"]] + 1, a["track_id"]): a["bbox"] for a in coco.dataset["annotations"] if a["inserted"]
    }
    assert inserted.keys() == cone.keys()
    for key, box in inserted.items():
        assert cone[key] == pytest.approx(box, abs=0.01)
    labelled = [a for a in coco.dataset["annotations"] if not a["inserted"]]
    assert {coco.cats[a["category_id"]]["name"] for a in labelled} == {"pedestrian"}
    assert {(frame_of[a["image_id"]] + 1, a["track_id"]) for a in labelled} == given.keys()
    rec = json.loads((root / "m" / "record.json").read_text())
    assert rec["objects"][0]["track_id"] == 13 and rec["labels"]["format"] == "mot"
    assert rec["labels"]["boxes"] == len(given) and rec["labels"]["occluder_masks"]["grabcut_masks"] >= 2
    vis = {t["track_id"]: t for t in rec["labels"]["tracks"]}
    assert vis[TRACKS["near"]]["min_visibility"] == 1.0 and vis[TRACKS["apart"]]["min_visibility"] == 1.0
    assert vis[TRACKS["far"]]["min_visibility"] < 0.9


def test_coco_video_labels_give_the_same_annotations_as_the_same_labels_in_mot(cli_runs):
    """The same boxes as COCO-video (frames matched by file name, class named by the file) and as MOT (class from
    --labels-category): the same tracks, boxes, visibilities and frames."""
    root = cli_runs
    a, b = COCO(str(root / "m" / "annotations.json")), COCO(str(root / "c" / "annotations.json"))

    def rows(coco):
        return sorted(
            (x["image_id"], x["track_id"], tuple(x["bbox"]), x["visibility"], coco.cats[x["category_id"]]["name"])
            for x in coco.dataset["annotations"]
        )

    assert rows(a) == rows(b)
    assert (root / "m" / "mot.txt").read_bytes() == (root / "c" / "mot.txt").read_bytes()
    for f in sorted((root / "m" / "frames").glob("*.jpg")):
        assert f.read_bytes() == (root / "c" / "frames" / f.name).read_bytes()


@pytest.mark.parametrize(
    ("text", "fmt", "needle"),
    [
        ("1,1,10,10,5\n", None, "5 columns"),
        ("1,-1,10,10,5,5,1,-1,-1,-1\n", None, "id -1 is a detection"),
        ("0,1,10,10,5,5\n", None, "frames are whole numbers from 1"),
        ("1,1,10,10,0,5\n", None, "width and height must be > 0"),
        ("1,1,10,10,5,5\n1,1,20,20,5,5\n", None, "track 1 twice in frame 1"),
        ("1,1,nan,10,5,5\n", None, "NaN"),
        ("900,1,10,10,5,5\n", None, "none of its 1 boxes is in the clip's frames"),
        ('{"images": []}', None, "no images and annotations"),
        ("1,1,10,10,5,5\n", "coco-video", "not JSON"),
    ],
)
def test_bad_labels_are_one_line_errors_before_anything_is_written(painted, tmp_path, capsys, text, fmt, needle):
    root, _ = painted
    labels = tmp_path / "gt.txt"
    labels.write_text(text)
    out = tmp_path / "out"
    args = ["--input", str(root / "frames"), "--camera", str(SEQ / "calib.txt"), "--poses", str(SEQ / "poses.txt")]
    args += ["--labels", str(labels), "--out", str(out)] + (["--labels-format", fmt] if fmt else [])
    assert main(args) == 2
    err = capsys.readouterr().err
    assert needle in err and err.count("\n") == 1 and "Traceback" not in err, err
    assert not out.exists()


def test_labels_options_are_for_clips_and_need_labels(painted, tmp_path, capsys):
    root, _ = painted
    args = ["--input", str(root / "frames"), "--camera", str(SEQ / "calib.txt"), "--poses", str(SEQ / "poses.txt")]
    assert main([*args, "--labels-format", "mot", "--out", str(tmp_path / "o")]) == 2
    assert "need --labels" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        main(["--images", str(root / "frames"), "--labels", str(root / "gt.txt"), "--out", str(tmp_path / "p")])
    assert "for clips" in capsys.readouterr().err

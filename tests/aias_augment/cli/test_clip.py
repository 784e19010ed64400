"""aias-augment on a posed clip (KITTI 06 frames, GT poses): COCO track, analytic contact, pose formats, resume."""

import json

import numpy as np
import pytest
from pycocotools.coco import COCO
from scipy.spatial.transform import Rotation

from aias_augment.cli.augment import main
from aias_augment.cli.clip import ClipJob, read_camera, read_cams_from_world
from aias_augment.core.config import data_root

SEQ = data_root() / "kitti06_seq"
N = 8


@pytest.fixture(scope="module")
def clip_run(tmp_path_factory):
    if not SEQ.exists():
        pytest.skip("shared KITTI data not available")
    out = tmp_path_factory.mktemp("clip")
    args = [
        "--input",
        str(SEQ / "image_l"),
        "--camera",
        str(SEQ / "calib.txt"),
        "--poses",
        str(SEQ / "poses.txt"),
        "--max-frames",
        str(N),
        "--lighting",
        "ambient",
        "--seed",
        "3",
        "--out",
        str(out),
    ]
    assert main(args) == 0
    return out, args


def test_clip_boxes_follow_the_analytic_projection_of_one_world_point(clip_run):
    out, _ = clip_run
    rec = json.loads((out / "record.json").read_text())
    coco = COCO(str(out / "annotations.json"))
    assert len(coco.getImgIds()) == N and rec["frames"] == N
    anns = coco.loadAnns(coco.getAnnIds())
    assert len(anns) >= N // 2 and {a["track_id"] for a in anns} == {1}  # it leaves the view beside the last camera
    # Independent projection: KITTI P0 and the world_from_cam lines of poses.txt, by hand.
    P0 = np.array(
        [float(v) for v in (SEQ / "calib.txt").read_text().splitlines()[0].split() if not v.endswith(":")]
    ).reshape(3, 4)
    rows = np.loadtxt(SEQ / "poses.txt")[:N].reshape(N, 3, 4)
    c_w = np.array(rec["contact_in_world"])
    for a in anns:
        i = a["image_id"] - 1
        R, t = rows[i, :, :3], rows[i, :, 3]
        p = R.T @ (c_w - t)  # cam_from_world applied to the contact
        u, v = P0[0, 0] * p[0] / p[2] + P0[0, 2], P0[1, 1] * p[1] / p[2] + P0[1, 2]
        x, y, w, h = a["amodal_bbox"]
        assert x - 1 <= u <= x + w + 1, (i, u, a["amodal_bbox"])  # the base centre is under the object ...
        height = coco.loadImgs(a["image_id"])[0]["height"]
        if y + h < height - 1:  # ... at its bottom edge
            assert abs(v - (y + h)) <= 0.15 * h + 2, (i, v, a["amodal_bbox"])
        else:  # ... or below the image when the box is cut by the bottom border
            assert v >= y + h - 0.15 * h - 2, (i, v, a["amodal_bbox"])
    img = out / coco.loadImgs(1)[0]["file_name"]
    assert img.exists() and (out / "side_by_side.mp4").stat().st_size > 0 and (out / "contact_sheet.jpg").exists()
    assert rec["modules"]["harmonize"].startswith("fast: one colour transform")


def test_grey_clip_stays_grey(clip_run):
    import cv2

    out, _ = clip_run
    im = cv2.imread(str(sorted((out / "frames").glob("*.jpg"))[0]), cv2.IMREAD_COLOR)
    assert np.abs(im.astype(int) - im[..., :1].astype(int)).max() <= 2  # JPEG chroma noise only


def test_rerun_with_same_arguments_does_not_rewrite(clip_run):
    out, args = clip_run

    def stamps():  # the run lock records the pid of its holder: not an output
        return {p: p.stat().st_mtime_ns for p in out.rglob("*") if p.is_file() and p.name != ".aias-augment.lock"}

    before = stamps()
    assert main(args) == 0
    assert stamps() == before


def test_tum_poses_read_as_the_same_cameras(tmp_path):
    if not SEQ.exists():
        pytest.skip("shared KITTI data not available")
    kitti = read_cams_from_world(SEQ / "poses.txt")[:N]
    rows = np.loadtxt(SEQ / "poses.txt")[:N].reshape(N, 3, 4)
    lines = [
        " ".join(f"{v:.9f}" for v in [float(i), *r[:, 3], *Rotation.from_matrix(r[:, :3]).as_quat()])
        for i, r in enumerate(rows)
    ]
    (tmp_path / "tum.txt").write_text("# timestamp tx ty tz qx qy qz qw\n" + "\n".join(lines) + "\n")
    tum = read_cams_from_world(tmp_path / "tum.txt")
    assert np.allclose(tum, kitti, atol=1e-6)


def test_bad_clip_inputs_raise(tmp_path, capsys):
    (tmp_path / "cam.yaml").write_text("fx: 500\nfy: 500\ncx: 320\n")
    with pytest.raises(ValueError, match="cy"):
        read_camera(tmp_path / "cam.yaml", 640, 480)
    (tmp_path / "poses.txt").write_text("1 2 3 4 5\n")
    with pytest.raises(ValueError, match="KITTI"):
        read_cams_from_world(tmp_path / "poses.txt")
    with pytest.raises(ValueError, match="lighting"):
        ClipJob("a", "b", "c", "d", lighting="sunny")
    if SEQ.exists():
        short = tmp_path / "short.txt"
        short.write_text("\n".join((SEQ / "poses.txt").read_text().splitlines()[:3]) + "\n")
        args = ["--input", str(SEQ / "image_l"), "--camera", str(SEQ / "calib.txt"), "--poses", str(short)]
        assert main([*args, "--max-frames", "5", "--out", str(tmp_path / "o")]) == 2
        assert "3 poses, but frame 4" in capsys.readouterr().err


VTEST = data_root() / "video" / "vtest.avi"


def test_the_static_check_tells_a_tripod_from_a_drive():
    """vtest.avi is filmed from a fixed camera (people walk through it); KITTI 06 from a driving car."""
    if not (VTEST.exists() and SEQ.exists()):
        pytest.skip("shared video data not available")
    from aias_augment.cli.clip import read_clip_frames
    from aias_augment.scenes.video import static_camera_check

    tripod, _ = read_clip_frames(VTEST, 0, 12, 5)
    drive, _ = read_clip_frames(SEQ / "image_l", 0, 12, 1)
    still, moving = static_camera_check(tripod), static_camera_check(drive)
    assert still.static and max(still.median_flow_px) < 0.2
    assert not moving.static and min(moving.median_flow_px) > 2.0
    assert moving.reason().startswith("moving camera")


def test_a_static_cameras_clip_needs_no_poses_and_its_object_stays_put(tmp_path, capsys):
    """With a static camera the world is the camera: one object standing on the ground projects to the same pixels in
    every frame, so its box is the same in every frame, to the last digit."""
    if not (VTEST.exists() and SEQ.exists()):
        pytest.skip("shared video data not available")
    out = tmp_path / "vtest"
    args = ["--input", str(VTEST), "--max-frames", "6", "--stride", "10", "--camera-height", "3"]
    assert main(args + ["--lighting", "ambient", "--seed", "1", "--out", str(out)]) == 0
    record = json.loads((out / "record.json").read_text())
    assert record["modules"]["camera"].startswith("static camera")
    coco = COCO(str(out / "annotations.json"))
    boxes = [tuple(a["bbox"]) for a in coco.dataset["annotations"]]
    assert len(boxes) == record["frames"] == 6 and len(set(boxes)) == 1
    capsys.readouterr()
    assert main(["--input", str(SEQ / "image_l"), "--max-frames", "6", "--out", str(tmp_path / "drive")]) == 2
    assert "moving camera" in capsys.readouterr().err


def test_clip_outputs_are_coco_video_with_masks_and_motchallenge(clip_run):
    """pycocotools reads the COCO-video file; each visible mask (RLE) has the annotation's box as its own bounding box
    and its pixel count as the area; mot.txt has MOTChallenge's ten columns, frames from 1, the same boxes in its
    pixels from 1 (bb_left = x + 1, as motmetrics reads them)."""
    from pycocotools import mask as mask_utils

    out, _ = clip_run
    coco = COCO(str(out / "annotations.json"))
    assert coco.dataset["videos"][0]["id"] == 1
    frame_of = {im["id"]: im["frame_id"] for im in coco.dataset["images"]}
    assert sorted(frame_of.values()) == list(range(N)) and all(im["video_id"] == 1 for im in coco.dataset["images"])
    by_frame = {}
    for a in coco.dataset["annotations"]:
        m = coco.annToMask(a)
        ys, xs = np.nonzero(m)
        assert a["area"] == m.sum() == mask_utils.area(a["segmentation"])
        assert np.allclose(a["bbox"], [xs.min(), ys.min(), xs.max() + 1 - xs.min(), ys.max() + 1 - ys.min()], atol=1)
        by_frame[frame_of[a["image_id"]] + 1] = a["bbox"]
    rows = [line.split(",") for line in (out / "mot.txt").read_text().splitlines()]
    assert rows and all(len(r) == 10 and r[1] == "1" and r[6:] == ["1", "-1", "-1", "-1"] for r in rows)
    assert {int(r[0]): [float(v) for v in r[2:6]] for r in rows}.keys() == by_frame.keys()
    for r in rows:
        x, y, w, h = by_frame[int(r[0])]
        assert np.allclose([float(v) for v in r[2:6]], [x + 1, y + 1, w, h], atol=0.01)


def test_several_objects_each_have_their_own_track(clip_run, tmp_path):
    """--objects 2: object 1 is drawn exactly as in the one-object run (same seed: its track, world pose and the
    frames where it shows), object 2 stands on the other side of the camera's path; each has its own track in the
    COCO-video file and in mot.txt, and where they do not overlap object 1's boxes are the one-object run's."""
    out1, args = clip_run
    out2 = tmp_path / "two"
    args2 = [v if v != str(out1) else str(out2) for v in args] + ["--objects", "2"]
    assert main(args2) == 0
    rec1 = json.loads((out1 / "record.json").read_text())
    rec2 = json.loads((out2 / "record.json").read_text())
    assert len(rec2["objects"]) == 2
    assert np.allclose(rec2["objects"][0]["world_from_object"], rec1["world_from_object"])
    poses = read_cams_from_world(SEQ / "poses.txt")[:N]
    sides = []
    for obj in rec2["objects"]:
        c = poses[0, :3, :3] @ np.asarray(obj["contact_in_world"]) + poses[0, :3, 3]
        sides.append(np.sign(c[0]))
    assert sides[0] == -sides[1]  # opposite sides of the path (camera x)
    coco1, coco2 = COCO(str(out1 / "annotations.json")), COCO(str(out2 / "annotations.json"))
    tracks = {a["track_id"] for a in coco2.dataset["annotations"]}
    assert tracks == {1, 2}
    rows = [line.split(",") for line in (out2 / "mot.txt").read_text().splitlines()]
    assert {r[1] for r in rows} == {"1", "2"}
    frame_of = {im["id"]: im["frame_id"] for im in coco2.dataset["images"]}
    one = {frame_of[a["image_id"]]: a for a in coco1.dataset["annotations"]}
    both = {}
    for a in coco2.dataset["annotations"]:
        both.setdefault(frame_of[a["image_id"]], {})[a["track_id"]] = a
    assert set(k for k, v in both.items() if 1 in v) == set(one)
    for f, a in one.items():
        other = both[f].get(2)
        overlap = other is not None and (coco2.annToMask(other) & coco1.annToMask(a)).any()
        if not overlap:
            assert np.allclose(both[f][1]["bbox"], a["bbox"])


def test_objects_that_would_stand_in_one_spot_are_drawn_apart(tmp_path):
    """Lateral offset 0 and lookahead 0 put both objects on the ground under the first camera, in one spot: the
    second is redrawn further from the path until the two footprints are apart, and the record says how many draws
    it took. Truth by hand: the contacts' distance on the ground exceeds the two bases' half-widths. (Under the camera
    neither is in view: the plans are read before the command refuses to write such a clip.)"""
    from aias_augment.cli.clip import read_clip_inputs, render_clip
    from aias_augment.pipeline.clip_objects import COLLISION_STEP_M

    if not SEQ.exists():
        pytest.skip("shared KITTI data not available")
    job = ClipJob(
        input=str(SEQ / "image_l"),
        camera=str(SEQ / "calib.txt"),
        poses=str(SEQ / "poses.txt"),
        out=str(tmp_path / "apart"),
        max_frames=3,
        lighting="ambient",
        harmonize="none",
        lookahead_frames=0,
        lateral_offset_m=0.0,
        objects=2,
        seed=1,
    )
    clip = render_clip(job, read_clip_inputs(job))
    assert len(clip.objects) == 2 and clip.skipped_objects == []
    assert clip.draws[0] == 1 and clip.draws[1] >= 2
    c1, c2 = (np.asarray(r.contact_in_world) for r in clip.results)
    poses = read_cams_from_world(SEQ / "poses.txt")
    right = np.linalg.inv(poses[0])[:3, 0]  # the first camera's x axis in the world
    apart = np.linalg.norm(c2 - c1)
    assert apart == pytest.approx(COLLISION_STEP_M * (clip.draws[1] - 1), abs=0.05)
    assert abs((c2 - c1) @ right) == pytest.approx(apart, abs=0.05)  # moved sideways, across the path
    assert apart > 0.2 + 0.1  # cones' bases are under 0.5 m wide: half of each plus the margin


def _amodal_boxes_by_frame(out) -> dict:
    """{frame_id: amodal box} of a clip run's COCO-video file."""
    coco = COCO(str(out / "annotations.json"))
    frame_of = {im["id"]: im["frame_id"] for im in coco.dataset["images"]}
    return {frame_of[a["image_id"]]: a["amodal_bbox"] for a in coco.dataset["annotations"]}


def test_topple_knocks_the_object_over_where_it_stands(clip_run, tmp_path):
    """--topple 0.5 at 10 fps: the same object at the same world pose as the standing run (same seed) falls over
    five frames from a frame drawn in the plan (recorded). Before the fall its boxes are the standing run's; once it
    has turned past 30 deg, its box is wider than tall where the standing cone's is taller than wide."""
    out1, args = clip_run
    out2 = tmp_path / "topple"
    assert main([v if v != str(out1) else str(out2) for v in args] + ["--topple", "0.5"]) == 0
    rec1, rec2 = (json.loads((o / "record.json").read_text()) for o in (out1, out2))
    assert np.allclose(rec2["world_from_object"], rec1["world_from_object"])
    assert "knocked over" in rec2["modules"]["motion"]
    fall = rec2["objects"][0]["topple"]
    start, rest = fall["start"], fall["rest_angle"]
    assert fall["frames"] == 5 and rec1["objects"][0]["topple"] is None
    boxes = [_amodal_boxes_by_frame(o) for o in (out1, out2)]
    standing, fallen = boxes
    for f in range(start + 1):
        if f in standing:
            assert np.allclose(fallen[f], standing[f], atol=0.01)
    late = [f for f in fallen if f in standing and rest * ((f - start) / 5) ** 2 > np.pi / 6]
    assert late, "the fall past 30 deg is seen in at least one frame"
    for f in late:
        assert fallen[f][2] > fallen[f][3] and standing[f][2] < standing[f][3]


def test_a_stereo_clip_without_poses_gets_them_from_stereo_odometry(clip_run, tmp_path):
    """--stereo-right instead of --poses: the poses come from the stereo pair (metric, no prior). Against the
    published poses (the same seed's run with --poses): the object's world contact within 15 cm and its boxes
    within a few pixels in every frame both see it."""
    out1, args = clip_run
    out2 = tmp_path / "stereo"
    i = args.index("--poses")
    args2 = args[:i] + args[i + 2 :] + ["--stereo-right", str(SEQ / "image_r")]
    assert main([v if v != str(out1) else str(out2) for v in args2]) == 0
    rec1, rec2 = (json.loads((o / "record.json").read_text()) for o in (out1, out2))
    assert "stereo odometry" in rec2["modules"]["camera"] and "7 of 7 steps" in rec2["modules"]["camera"]
    assert np.linalg.norm(np.subtract(rec2["contact_in_world"], rec1["contact_in_world"])) < 0.15
    boxes = [_amodal_boxes_by_frame(o) for o in (out1, out2)]
    common = set(boxes[0]) & set(boxes[1])
    assert len(common) >= N // 2
    for f in common:
        assert np.allclose(boxes[1][f], boxes[0][f], atol=6.0)
    with pytest.raises(SystemExit):
        main(args + ["--stereo-right", str(SEQ / "image_r")])  # poses given and estimated: refused


def test_a_moving_clip_with_a_camera_and_no_poses_gets_them_from_monocular_odometry(clip_run, tmp_path):
    """No --poses and no right camera, but --camera: the poses come from essential matrices, each step scaled by the
    ground 1.65 m below (KITTI's camera height). Against the published poses (the same seed's run with --poses): the
    object's world contact within 15 % of the 8.4 m the camera travels to it (per-pair ground scales scatter by
    about +-15 %, and 7 steps average only part of it), and while the object is still far, its box as tall as a
    15 % depth error allows (near it, the same error is a larger part of the distance)."""
    out1, args = clip_run
    out2 = tmp_path / "mono"
    i = args.index("--poses")
    args2 = args[:i] + args[i + 2 :]
    assert main([v if v != str(out1) else str(out2) for v in args2]) == 0
    rec1, rec2 = (json.loads((o / "record.json").read_text()) for o in (out1, out2))
    assert "monocular odometry" in rec2["modules"]["camera"] and "on the ground" in rec2["modules"]["camera"]
    assert np.linalg.norm(np.subtract(rec2["contact_in_world"], rec1["contact_in_world"])) < 0.15 * 8.4
    boxes = [_amodal_boxes_by_frame(o) for o in (out1, out2)]
    common = set(boxes[0]) & set(boxes[1])
    assert len(common) >= N // 2

    def whole(b):  # not cut by the 1226 x 370 frame
        return b[0] > 1 and b[1] > 1 and b[0] + b[2] < 1224 and b[1] + b[3] < 368

    far = [f for f in common if boxes[0][f][3] < 120 and whole(boxes[0][f]) and whole(boxes[1][f])]
    assert far and all(0.85 <= boxes[1][f][3] / boxes[0][f][3] <= 1.18 for f in far)

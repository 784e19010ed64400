"""The clip command's data safety: every bad input one stderr line and exit 2 before anything is written; a clip
whose object is never visible exit 1 with nothing written; inputs never touched; another run's folder refused."""

import hashlib
import json
import shutil

import cv2
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from aias_augment.cli.augment import main
from aias_augment.core.config import data_root

SEQ = data_root() / "kitti06_seq"
N = 6

pytestmark = pytest.mark.skipif(not SEQ.exists(), reason="shared KITTI data not available")


def kitti_rows(n=N):
    return np.loadtxt(SEQ / "poses.txt")[:n]


def kitti_text(rows):
    return "".join(" ".join(f"{v:.9e}" for v in r) + "\n" for r in rows)


def tum_lines(rows, stamps=None):
    """8-column TUM lines (timestamp tx ty tz qx qy qz qw) of KITTI world_from_cam rows."""
    stamps = np.arange(len(rows), dtype=float) if stamps is None else stamps
    out = []
    for t, r in zip(stamps, rows.reshape(-1, 3, 4)):
        out.append([t, *r[:, 3], *Rotation.from_matrix(r[:, :3]).as_quat()])
    return np.array(out)


def tum_text(table):
    return "".join(" ".join(f"{v:.9g}" for v in r) + "\n" for r in table)


def write(tmp, name, text):
    p = tmp / name
    p.write_bytes(text) if isinstance(text, bytes) else p.write_text(text)
    return p


def frame_folder(tmp, name="frames", n=N):
    d = tmp / name
    d.mkdir()
    for f in sorted((SEQ / "image_l").iterdir())[:n]:
        shutil.copy(f, d / f.name)
    return d


def yaml_camera(tmp, fx=707.09, fy=707.09, cx=601.89, cy=183.11):
    return write(tmp, "cam.yaml", f"fx: {fx}\nfy: {fy}\ncx: {cx}\ncy: {cy}\n")


def poses_with(tmp, text):
    return {"--poses": write(tmp, "poses.txt", text)}


def nan_pose(tmp):
    rows = kitti_rows()
    rows[2, 3] = np.nan
    return poses_with(tmp, kitti_text(rows))


def inf_tum(tmp):
    table = tum_lines(kitti_rows())
    table[3, 2] = np.inf
    return poses_with(tmp, tum_text(table))


def tum_out_of_order(tmp):
    table = tum_lines(kitti_rows())
    table[[2, 3], 0] = table[[3, 2], 0]
    return poses_with(tmp, tum_text(table))


def tum_repeated_stamp(tmp):
    return poses_with(tmp, tum_text(tum_lines(kitti_rows(), stamps=np.array([0, 1, 1, 2, 3, 4.0]))))


def not_a_rotation(tmp):
    rows = kitti_rows().reshape(-1, 3, 4)
    rows[1, :, :3] *= 2
    return poses_with(tmp, kitti_text(rows.reshape(-1, 12)))


def tum_quaternion(norm):
    def make(tmp):
        table = tum_lines(kitti_rows())
        table[1, 4:] *= norm
        return poses_with(tmp, tum_text(table))

    return make


def ragged(tmp):
    rows = kitti_text(kitti_rows()).splitlines()
    rows[4] = " ".join(rows[4].split()[:7])
    return poses_with(tmp, "\n".join(rows) + "\n")


def camera(**k):
    return lambda tmp: {"--camera": yaml_camera(tmp, **k)}


def camera_text(name, text):
    return lambda tmp: {"--camera": write(tmp, name, text)}


def corrupt_frame(tmp):
    d = frame_folder(tmp)
    f = sorted(d.iterdir())[3]
    f.write_bytes(f.read_bytes()[:200])
    return {"--input": d}


def odd_size_frame(tmp):
    d = frame_folder(tmp)
    f = sorted(d.iterdir())[2]
    cv2.imwrite(str(f), cv2.resize(cv2.imread(str(f)), (600, 200)))
    return {"--input": d}


def twin_names(tmp):
    d = frame_folder(tmp)
    f = sorted(d.iterdir())[1]
    cv2.imwrite(str(d / (f.stem + ".jpg")), cv2.imread(str(f)))
    return {"--input": d}


def empty_folder(tmp):
    (tmp / "empty").mkdir()
    return {"--input": tmp / "empty"}


def out_inside_input(tmp):
    d = frame_folder(tmp)
    return {"--input": d, "--out": d / "aug"}


def poses_inside_out(tmp):
    (tmp / "out").mkdir()
    return {"--poses": write(tmp / "out", "poses.txt", kitti_text(kitti_rows()))}


def out_is_a_file(tmp):
    return {"--out": write(tmp, "out", "a file\n")}


# Each: (what it is, a function of tmp_path giving the arguments it replaces, a word the error must hold)
BAD_INPUTS = [
    ("5 poses for 6 frames", lambda t: poses_with(t, kitti_text(kitti_rows(5))), "5 poses"),
    ("NaN pose", nan_pose, "NaN"),
    ("infinite TUM pose", inf_tum, "infinite"),
    ("TUM out of time order", tum_out_of_order, "time order"),
    ("TUM repeated timestamp", tum_repeated_stamp, "time order"),
    ("KITTI pose not a rotation", not_a_rotation, "pose 2"),
    ("TUM zero quaternion", tum_quaternion(0.0), "unit quaternion"),
    ("TUM quaternion of norm 2", tum_quaternion(2.0), "unit quaternion"),
    ("5 numbers per pose", lambda t: poses_with(t, "1 2 3 4 5\n" * N), "5 numbers"),
    ("ragged pose lines", ragged, "--poses"),
    ("text in a pose", lambda t: poses_with(t, "1 2 three 4 5 6 7\n"), "--poses"),
    ("no poses", lambda t: poses_with(t, "# nothing\n"), "no poses"),
    ("poses file missing", lambda t: {"--poses": t / "nope.txt"}, "no such file"),
    ("fx 0.001", camera(fx=0.001, fy=0.001), "fx 0.001"),
    ("fx 1e9", camera(fx=1e9, fy=1e9), "fx 1e+09"),
    ("fx negative", camera(fx=-700), "fx -700"),
    ("fx / fy 10", camera(fx=700, fy=70), "fx / fy"),
    ("cx 1e6", camera(cx=1e6), "cx"),
    ("camera yaml without cy", camera_text("c.yaml", "fx: 700\nfy: 700\ncx: 600\n"), "cy"),
    ("camera yaml a list", camera_text("c.yaml", "- 700\n- 700\n"), "mapping"),
    ("camera fx text", camera_text("c.yaml", "fx: abc\nfy: 700\ncx: 600\ncy: 180\n"), "abc"),
    ("camera yaml broken", camera_text("c.yaml", "fx: [700, 700\n"), "YAML"),
    ("camera not UTF-8", camera_text("c.yaml", b"fx: 700\xff\xfe\n"), "UTF-8"),
    ("calib.txt without P0", camera_text("calib.txt", "P5: 1 2 3\n"), "P0"),
    ("camera file missing", lambda t: {"--camera": t / "nope.txt"}, "no such file"),
    ("camera height 1e6", lambda t: {"--camera-height": "1e6"}, "camera-height"),
    ("camera height 0", lambda t: {"--camera-height": "0"}, "camera-height"),
    ("camera height NaN", lambda t: {"--camera-height": "nan"}, "camera-height"),
    ("stride 0", lambda t: {"--stride": "0"}, "stride"),
    ("fps 0", lambda t: {"--fps": "0"}, "fps"),
    ("objects 0", lambda t: {"--objects": "0"}, "objects"),
    ("start past the last frame", lambda t: {"--start": "1000"}, "from frame 1000"),
    ("no frames in the folder", empty_folder, "no "),
    ("truncated frame", corrupt_frame, "000003"),
    ("frames of two sizes", odd_size_frame, "one size"),
    ("two frames of one name", twin_names, "000001"),
    ("--out inside --input", out_inside_input, "--out"),
    ("--poses inside --out", poses_inside_out, "--out"),
    ("--out a file", out_is_a_file, "--out"),
]


def clip_args(tmp, changes: dict) -> list[str]:
    base = {
        "--input": SEQ / "image_l",
        "--camera": SEQ / "calib.txt",
        "--poses": SEQ / "poses.txt",
        "--max-frames": N,
        "--lighting": "ambient",
        "--out": tmp / "out",
    }
    base.update(changes)
    return [str(v) for kv in base.items() for v in kv]


def tree_hashes(root):
    """Every path under ``root``: a file's sha256, a folder's "folder"."""
    return {
        str(p.relative_to(root)): hashlib.sha256(p.read_bytes()).hexdigest() if p.is_file() else "folder"
        for p in root.rglob("*")
    }


@pytest.mark.parametrize("make, word", [c[1:] for c in BAD_INPUTS], ids=[c[0] for c in BAD_INPUTS])
def test_a_bad_clip_input_is_one_line_and_exit_2_before_anything_is_written(tmp_path, capsys, make, word):
    changes = make(tmp_path)
    before = tree_hashes(tmp_path)
    assert main(clip_args(tmp_path, changes)) == 2
    err = capsys.readouterr().err
    lines = [line for line in err.splitlines() if line.strip()]
    assert len(lines) == 1 and lines[0].startswith("aias-augment: error: "), err
    assert "Traceback" not in err and word in lines[0], lines[0]
    assert tree_hashes(tmp_path) == before  # not one byte or folder written, changed or removed


def reversed_drive(tmp):
    """The clip's poses with the camera driving backwards (another clip's poses): the object, beside where the
    camera is in the last frame, stands behind every camera."""
    rows = kitti_rows().reshape(-1, 3, 4)
    rows[:, :, 3] *= -1
    return poses_with(tmp, kitti_text(rows.reshape(-1, 12)))


def test_a_clip_whose_object_is_never_visible_exits_1_and_writes_nothing(tmp_path, capsys):
    changes = reversed_drive(tmp_path)
    assert main(clip_args(tmp_path, changes)) == 1
    err = capsys.readouterr().err
    lines = [line for line in err.splitlines() if line.startswith("aias-augment")]
    assert len(lines) == 1 and "visible in none of the 6 frames" in lines[0] and "nothing written" in lines[0], err
    out = tmp_path / "out"
    assert {p.name for p in out.iterdir()} <= {".aias-augment.lock"}  # no frame, no manifest, no annotations


def test_the_inputs_are_never_written_8_column_tum_in_a_read_only_folder(tmp_path, capsys):
    ds = tmp_path / "ds"
    ds.mkdir()
    frames = frame_folder(ds)
    shutil.copy(SEQ / "calib.txt", ds / "calib.txt")
    write(ds, "poses.txt", "# timestamp tx ty tz qx qy qz qw\n" + tum_text(tum_lines(kitti_rows())))
    write(ds, "poses.txt.tum7.tmp", "the user's own file\n")  # the name the reader once used beside the poses
    for p in [*ds.rglob("*"), ds]:
        p.chmod(0o555 if p.is_dir() else 0o444)
    before = tree_hashes(ds)
    try:
        args = clip_args(tmp_path, {"--input": frames, "--camera": ds / "calib.txt", "--poses": ds / "poses.txt"})
        assert main(args) == 0, capsys.readouterr().err
        assert tree_hashes(ds) == before
        rec = json.loads((tmp_path / "out" / "record.json").read_text())
        assert rec["frames"] == N and rec["visible_frames"] >= 1
    finally:
        for p in [ds, *ds.rglob("*")]:
            p.chmod(0o755 if p.is_dir() else 0o644)


def test_another_run_into_a_finished_clip_folder_is_refused_and_overwrite_replaces_only_its_files(tmp_path, capsys):
    args = clip_args(tmp_path, {"--max-frames": 8})
    assert main(args) == 0
    out = tmp_path / "out"
    (out / "notes.txt").write_text("the user's\n")
    first = tree_hashes(out)
    capsys.readouterr()
    assert main([*args, "--seed", "7"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "seed: 0 -> 7" in err and "--overwrite" in err
    assert tree_hashes(out) == first
    assert main([*args, "--seed", "7", "--overwrite"]) == 0
    manifest = json.loads((out / "manifest.json").read_text())
    assert manifest["complete"] and manifest["seed"] == 7
    assert (out / "notes.txt").read_text() == "the user's\n"  # not in any manifest: never touched


def test_a_clip_folder_holding_files_of_its_names_that_no_manifest_lists_is_refused(tmp_path, capsys):
    out = tmp_path / "out"
    (out / "frames").mkdir(parents=True)
    (out / "frames" / "000000.jpg").write_bytes(b"someone's photo")
    assert main(clip_args(tmp_path, {"--max-frames": 8})) == 2
    assert "never written over" in capsys.readouterr().err
    assert (out / "frames" / "000000.jpg").read_bytes() == b"someone's photo"

import json
import shutil
from pathlib import Path

import pytest

from aias_augment.assets.bank.catalog import load_catalog
from aias_augment.cli.assets import main

FIXTURES = Path(__file__).parents[1] / "assets" / "bank" / "fixtures"


def test_import_list_show(tmp_path, capsys):
    d = tmp_path / "meshes"
    d.mkdir()
    for f in ("good_textured.obj", "good_textured.mtl", "checker.png", "nan_vertices.obj"):
        shutil.copy(FIXTURES / f, d / f)
    (d / "good_textured.yaml").write_text("category: traffic_cone\nheight_m: 0.5\nup_axis: Z\n")
    (d / "nan_vertices.yaml").write_text("category: rock\nheight_m: 0.3\nup_axis: Z\n")
    cache = tmp_path / "cache"
    empty = tmp_path / "empty"
    empty.mkdir()
    base = ["--cache-dir", str(cache)]
    assert (
        main(
            base
            + [
                "import",
                "--sh3f-dir",
                str(empty),
                "--gazebo-dir",
                str(empty),
                "--sidecar",
                str(d),
                "--quiet",
                "--report",
                str(tmp_path / "r.json"),
            ]
        )
        == 0
    )
    recs = {r.id: r for r in load_catalog(cache / "catalog.json")}
    good, bad = recs["sidecar:meshes/good_textured.obj"], recs["sidecar:meshes/nan_vertices.obj"]
    assert good.status == "ok" and good.textured and good.triangle_count == 4
    assert abs(good.dimensions_m[2] - 0.5) < 1e-9
    assert bad.status == "rejected" and "non-finite" in bad.notes[0]
    report = json.loads((tmp_path / "r.json").read_text())
    assert report["status"]["rejected"] == 1 and "sidecar:meshes/nan_vertices.obj" in report["rejected"]
    capsys.readouterr()
    assert main(base + ["list", "--status", "rejected"]) == 0
    out = capsys.readouterr().out
    assert "nan_vertices" in out and "good_textured" not in out
    assert main(base + ["show", "sidecar:meshes/good_textured.obj"]) == 0
    assert "extents [0.5 0.5 0.5] m" in capsys.readouterr().out


def test_box_convention_cli_measures_the_labels_and_augment_takes_it(tmp_path, capsys):
    """A YOLO folder whose cone labels lie 10 % of their width outside the drawn cone on the left and right: the
    command writes those margins, and aias-augment's --box-convention puts them in the run's config."""
    import cv2
    import numpy as np
    import pytest

    from aias_augment.adapters.boundary import InputError
    from aias_augment.cli.augment import insertion_config
    from tests.aias_augment.assets.bank.test_lift import _label_with_margins, draw_cone, noise_background

    img_dir, lab_dir = tmp_path / "images", tmp_path / "labels"
    img_dir.mkdir()
    lab_dir.mkdir()
    for k in range(2):
        img = noise_background(240, 320, k)
        tight = draw_cone(img, 140 + 40 * k, 200, 130, 35) + [0, 0, 1, 1]
        b = _label_with_margins(tight, (0.1, 0.0, 0.1, 0.0))
        cv2.imwrite(str(img_dir / f"{k}.png"), img[..., ::-1])
        (lab_dir / f"{k}.txt").write_text(
            f"0 {(b[0] + b[2]) / 640} {(b[1] + b[3]) / 480} {(b[2] - b[0]) / 320} {(b[3] - b[1]) / 240}\n"
        )
    out = tmp_path / "convention.json"
    rc = main(["box-convention", "--yolo", str(img_dir), "--class-names", "cone", "--label", "cone", "--out", str(out)])
    assert rc == 0
    written = json.loads(out.read_text())
    assert written["instances_measured"] == 2
    assert np.allclose(written["box_convention"], [0.1, 0.0, 0.1, 0.0], atol=0.015)
    cfg = insertion_config("fast", None, None, None, box_convention_file=str(out))
    assert cfg.box_convention == tuple(written["box_convention"])
    (tmp_path / "bad.json").write_text(json.dumps({"box_convention": [0.6, 0, 0, 0]}))
    with pytest.raises(InputError, match="box_convention"):
        insertion_config("fast", None, None, None, box_convention_file=str(tmp_path / "bad.json"))
    with pytest.raises(InputError, match="--box-convention"):
        insertion_config("fast", None, None, None, box_convention_file=str(tmp_path / "missing.json"))
    rc = main(["box-convention", "--yolo", str(img_dir), "--class-names", "cone", "--label", "sign", "--out", str(out)])
    assert rc == 1 and "no labelled instance" in capsys.readouterr().err


def _png_header_only(path, width: int, height: int) -> None:
    """A PNG whose header says ``width`` x ``height`` and that holds no pixel data: what a reader sees before
    decoding (a 20000x20000 PNG of one colour is a 1.2 MB file; the header is all the check needs)."""
    import struct
    import zlib

    def chunk(kind: bytes, data: bytes) -> bytes:
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))

    ihdr = struct.pack(">IIBBBBB", width, height, 8, 2, 0, 0, 0)
    path.write_bytes(b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", ihdr) + chunk(b"IEND", b""))


def _run(argv, capsys) -> tuple[int, str]:
    try:
        rc = main(argv)
    except SystemExit as e:  # argparse
        rc = e.code
    return rc, capsys.readouterr().err


def _views_file(folder: Path, K, pose=None, spec=None) -> Path:
    import cv2
    import numpy as np

    folder.mkdir(parents=True, exist_ok=True)
    img = np.full((32, 32, 3), 90, np.uint8)
    mask = np.zeros((32, 32), np.uint8)
    mask[8:24, 10:22] = 255
    cv2.imwrite(str(folder / "a.png"), img)
    cv2.imwrite(str(folder / "m.png"), mask)
    pose = np.eye(4).tolist() if pose is None else pose
    view = {"image": "a.png", "mask": "m.png", "K": K, "cam_from_object": pose}
    (folder / "views.json").write_text(json.dumps({"views": [view, view]} if spec is None else spec))
    return folder / "views.json"


K_OK = [[40.0, 0, 16], [0, 40.0, 16], [0, 0, 1]]


def _error_cases(tmp: Path) -> dict[str, tuple[list[str], str]]:
    """name: (argv, a phrase the one-line message must hold)."""
    (tmp / "a_file").write_text("not a folder")
    (tmp / "corrupt").mkdir(exist_ok=True)
    (tmp / "corrupt" / "bank.json").write_text('{"report": {"assets": [')
    bank = str(tmp / "bank")
    deform = ["deform", "--category", "traffic_cone", "--out", bank]
    nan_pose = [[float("nan")] * 4] * 4
    rec = ["reconstruct", "--category", "traffic_cone", "--out", bank, "--views"]
    yolo = ["from-labels", "--yolo", str(tmp), "--category", "traffic_cone"]
    return {
        "deform seed -1": ([*deform, "--seed", "-1"], "--seed"),
        "deform size 0": ([*deform, "--seed", "0", "--size", "0"], "--size"),
        "deform count 0": ([*deform, "--seed", "0", "--count", "0"], "--count"),
        "deform count 1e6": ([*deform, "--seed", "0", "--count", "1000000"], "--count"),
        "deform out a file": (
            ["deform", "--category", "traffic_cone", "--seed", "0", "--out", str(tmp / "a_file")],
            "is a file",
        ),
        "deform corrupt bank.json": (
            ["deform", "--category", "traffic_cone", "--seed", "0", "--out", str(tmp / "corrupt")],
            "not a readable bank index",
        ),
        "from-labels out a file": ([*yolo, "--out", str(tmp / "a_file")], "is a file"),
        "from-labels corrupt bank.json": ([*yolo, "--out", str(tmp / "corrupt")], "bank.json"),
        "from-labels height nan": ([*yolo, "--out", bank, "--height-m", "nan"], "--height-m"),
        "box-convention out a folder": (
            ["box-convention", "--yolo", str(tmp), "--label", "cone", "--out", str(tmp)],
            "is a folder",
        ),
        "reconstruct [] views": ([*rec, str(_views_file(tmp / "v0", K_OK, spec=[]))], "a views file is"),
        "reconstruct no views": ([*rec, str(_views_file(tmp / "v1", K_OK, spec={"views": []}))], "two views"),
        "reconstruct 2x2 K": ([*rec, str(_views_file(tmp / "v2", [[40.0, 0], [0, 40.0]]))], "K must be 3x3"),
        "reconstruct NaN pose": ([*rec, str(_views_file(tmp / "v3", K_OK, nan_pose))], "NaN"),
        "reconstruct not json": ([*rec, str(_views_file(tmp / "v4", K_OK, spec="x")) + "x"], "views file"),
        "reconstruct out a file": (
            [
                "reconstruct",
                "--category",
                "traffic_cone",
                "--out",
                str(tmp / "a_file"),
                "--views",
                str(_views_file(tmp / "v5", K_OK)),
            ],
            "is a file",
        ),
        "reconstruct corrupt bank.json": (
            [
                "reconstruct",
                "--category",
                "traffic_cone",
                "--out",
                str(tmp / "corrupt"),
                "--views",
                str(_views_file(tmp / "v6", K_OK)),
            ],
            "bank index",
        ),
        "reconstruct texture 8192": ([*rec, str(_views_file(tmp / "v7", K_OK)), "--texture-px", "8192"], "texture_px"),
        "reconstruct seed -1": ([*rec, str(_views_file(tmp / "v8", K_OK)), "--seed", "-1"], "--seed"),
    }


CASES = [
    "deform seed -1",
    "deform size 0",
    "deform count 0",
    "deform count 1e6",
    "deform out a file",
    "deform corrupt bank.json",
    "from-labels out a file",
    "from-labels corrupt bank.json",
    "from-labels height nan",
    "box-convention out a folder",
    "reconstruct [] views",
    "reconstruct no views",
    "reconstruct 2x2 K",
    "reconstruct NaN pose",
    "reconstruct not json",
    "reconstruct out a file",
    "reconstruct corrupt bank.json",
    "reconstruct texture 8192",
    "reconstruct seed -1",
]


@pytest.mark.parametrize("case", CASES)
def test_every_aias_assets_error_is_one_line_exit_2_and_writes_no_bank(case, tmp_path, capsys):
    argv, phrase = _error_cases(tmp_path)[case]
    corrupt = (tmp_path / "corrupt" / "bank.json").read_bytes()
    rc, err = _run(argv, capsys)
    assert rc == 2, err
    assert "Traceback" not in err and len(err.strip().splitlines()) == 1, err
    assert phrase in err
    assert not (tmp_path / "bank").exists()  # checked before the bank is written
    assert (tmp_path / "corrupt" / "bank.json").read_bytes() == corrupt


def test_from_labels_skips_a_huge_png_from_its_header_and_a_truncated_jpeg(tmp_path, capsys):
    """A 20000x20000 PNG is refused from its header (its decode would take 1.2 GB); a truncated JPEG is skipped and
    counted, not partly decoded (OpenCV fills the missing rows with grey); the good image is lifted."""
    import cv2

    from tests.aias_augment.assets.bank.test_lift import draw_cone, noise_background

    img_dir, lab_dir = tmp_path / "images", tmp_path / "labels"
    img_dir.mkdir()
    lab_dir.mkdir()
    img = noise_background(240, 320)
    b = draw_cone(img, 160, 200, 130, 35)
    row = f"0 {(b[0] + b[2]) / 640} {(b[1] + b[3]) / 480} {(b[2] - b[0]) / 320} {(b[3] - b[1]) / 240}\n"
    cv2.imwrite(str(img_dir / "good.png"), img[..., ::-1])
    ok, jpg = cv2.imencode(".jpg", img[..., ::-1])
    (img_dir / "cut.jpg").write_bytes(jpg.tobytes()[: len(jpg) // 2])
    _png_header_only(img_dir / "huge.png", 20000, 20000)
    for name in ("good", "cut", "huge"):
        (lab_dir / f"{name}.txt").write_text(row)
    import resource

    peak_before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    rc = main(
        [
            "from-labels",
            "--yolo",
            str(img_dir),
            "--class-names",
            "cone",
            "--category",
            "traffic_cone",
            "--out",
            str(tmp_path / "bank"),
        ]
    )
    assert rc == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["lifted"] == 1
    assert summary["images_skipped"] == {"corrupt image": 1, "image too large": 1}
    grown_mb = (resource.getrusage(resource.RUSAGE_SELF).ru_maxrss - peak_before) / 1024
    assert grown_mb < 400  # a decode of 20000x20000 RGB alone is 1200 MB

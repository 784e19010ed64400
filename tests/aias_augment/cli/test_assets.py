import json
import shutil
from pathlib import Path

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

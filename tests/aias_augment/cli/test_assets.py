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

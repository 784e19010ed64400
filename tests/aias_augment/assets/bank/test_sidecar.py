import shutil
from pathlib import Path

import numpy as np
import pytest

from aias_augment.assets.asset import AssetError
from aias_augment.assets.bank.sidecar import load_sidecar_parts, read_sidecar_records
from aias_augment.assets.bank.taxonomy import load_taxonomy

FIXTURES = Path(__file__).parent / "fixtures"


def _folder(tmp_path, sidecar_text, mesh="good_textured.obj"):
    d = tmp_path / "mine"
    d.mkdir()
    for f in (mesh, mesh.replace(".obj", ".mtl"), "checker.png"):
        if (FIXTURES / f).exists():
            shutil.copy(FIXTURES / f, d / f)
    (d / mesh).with_suffix(".yaml").write_text(sidecar_text)
    return d


def test_height_sidecar_sizes_the_mesh_and_keeps_texture(tmp_path):
    d = _folder(tmp_path, "category: traffic_cone\nheight_m: 0.7\nup_axis: Z\nlicence: CC0\n")
    recs, skipped = read_sidecar_records(d, load_taxonomy())
    assert skipped == [] and len(recs) == 1 and recs[0].category == "traffic_cone" and recs[0].licence == "CC0"
    parts, notes = load_sidecar_parts(recs[0])
    b = parts[0].bounds
    # the fixture is a 1 x 1 x 1 pyramid (z up): uniform scale 0.7
    np.testing.assert_allclose(b[1] - b[0], [0.7, 0.7, 0.7], rtol=1e-9)
    assert parts[0].visual.material.image is not None and notes == []


def test_scale_sidecar_and_y_up(tmp_path):
    d = _folder(tmp_path, "category: rock\nscale: 0.5\n")  # OBJ default Y up: the pyramid's z (1) becomes depth
    parts, _ = load_sidecar_parts(read_sidecar_records(d, load_taxonomy())[0][0])
    b = parts[0].bounds
    np.testing.assert_allclose(b[1] - b[0], [0.5, 0.5, 0.5], rtol=1e-9)
    assert b[0, 2] == pytest.approx(0)


@pytest.mark.parametrize(
    "text, reason",
    [
        ("category: rock\n", "exactly one of height_m"),
        ("category: rock\nheight_m: 1\nscale: 2\n", "exactly one of height_m"),
        ("category: rock\nheight_m: -1\n", "positive"),
        ("category: rock\nheight_m: 1\ncolour: red\n", "unknown config keys"),
        ("category: unicorn\nheight_m: 1\n", "not in the taxonomy"),
    ],
)
def test_bad_sidecars_are_reported(tmp_path, text, reason):
    d = _folder(tmp_path, text)
    recs, skipped = read_sidecar_records(d, load_taxonomy())
    assert recs == [] and len(skipped) == 1 and reason in skipped[0]


def test_missing_sidecar_and_missing_texture(tmp_path):
    d = _folder(tmp_path, "category: rock\nheight_m: 0.3\n", mesh="missing_texture.obj")
    shutil.copy(FIXTURES / "some_degenerate.obj", d / "nosidecar.obj")
    recs, skipped = read_sidecar_records(d, load_taxonomy())
    assert len(recs) == 1 and len(skipped) == 1 and "no sidecar" in skipped[0]
    _, notes = load_sidecar_parts(recs[0])
    assert notes == ["missing texture no_such_texture.jpg: diffuse colour used"]
    with pytest.raises(AssetError, match="not found"):
        read_sidecar_records(tmp_path / "nope", load_taxonomy())

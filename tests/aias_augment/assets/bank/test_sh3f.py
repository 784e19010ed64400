import zipfile

import numpy as np
import pytest

from aias_augment.assets.asset import AssetError
from aias_augment.assets.bank.sh3f import (
    DEFAULT_SH3F_DIR,
    find_sh3f_files,
    load_sh3f_parts,
    parse_properties,
    read_sh3f_catalog,
    sh3d_to_canonical,
)
from aias_augment.assets.bank.taxonomy import load_taxonomy

ROAD_IDS = {
    "traffic_cone": "sh3f:Scopia#cone",
    "stroller": "sh3f:Scopia#stroller",
    "dog": "sh3f:Scopia#dog",
    "rock": "sh3f:Blend Swap CC-0#rock1",
}


def test_parse_properties_java_rules():
    text = (
        "# comment\n! also comment\nname#1=Caf\\u00e9 \\\n    table\nkey\\=with\\:seps : value = x\n"
        "width#1 = 12.5\nempty=\n"
    )
    p = parse_properties(text)
    assert p["name#1"] == "Café table"
    assert p["key=with:seps"] == "value = x"
    assert p["width#1"] == "12.5"
    assert p["empty"] == ""


def test_installed_catalogs_yield_700_assets_with_categories_and_sizes():
    files = find_sh3f_files(DEFAULT_SH3F_DIR)
    if len(files) < 5:
        pytest.skip("sweethome3d-furniture not installed")
    tax = load_taxonomy()
    records = [r for f in files for r in read_sh3f_catalog(f, tax)[0]]
    assert len(records) >= 700
    assert len({r.id for r in records}) == len(records)
    assert all(r.category in tax.categories for r in records)
    assert all(r.dimensions_m is not None and min(r.dimensions_m) > 0 for r in records)
    assert all(r.licence for r in records)
    cats = {r.category for r in records}
    assert {"traffic_cone", "stroller", "person", "dog", "rock", "barrel", "car", "bus", "bicycle"} <= cats


def test_road_objects_are_classified(sh3f_records):
    for cat, rid in ROAD_IDS.items():
        assert sh3f_records[rid].category == cat


@pytest.mark.parametrize("category", sorted(ROAD_IDS))
def test_import_matches_catalog_size(sh3f_records, category):
    rec = sh3f_records[ROAD_IDS[category]]
    parts, notes = load_sh3f_parts(rec)
    b = np.array([p.bounds for p in parts])
    lo, hi = b[:, 0].min(0), b[:, 1].max(0)
    np.testing.assert_allclose(hi - lo, rec.dimensions_m, rtol=1e-6)  # (width, depth, height) in metres
    assert abs(lo[2]) < 1e-9 and np.allclose((lo + hi)[:2] / 2, 0, atol=1e-9)  # on z = 0, centred in x/y
    assert all(np.all(np.isfinite(p.vertices)) for p in parts)


def test_rock_keeps_its_texture(sh3f_records):
    """rock1.obj has more vt than v: the UVs (and thus the photo texture) must survive the import."""
    parts, _ = load_sh3f_parts(sh3f_records[ROAD_IDS["rock"]])
    assert parts[0].visual.uv is not None and parts[0].visual.material.image is not None


def test_model_rotation_and_axes():
    """A box 1 x 2 x 3 (x, y, z) in sh3d Y-up; the catalog says width 30, depth 10, height 20 cm after a rotation
    of -90 deg about y that swaps x and z: the canonical extents must be (width, depth, height)."""
    import trimesh

    box = trimesh.creation.box(extents=[1, 2, 3])
    R = [0, 0, -1, 0, 1, 0, 1, 0, 0]  # row-major: x' = -z, z' = x
    parts, notes = sh3d_to_canonical([box], (0.3, 0.1, 0.2), R, "box")
    b = parts[0].bounds
    np.testing.assert_allclose(b[1] - b[0], [0.3, 0.1, 0.2], rtol=1e-9)
    assert notes == []  # rotated extents (3, 2, 1) -> (0.3, 0.2, 0.1): one uniform scale, no stretching
    _, notes = sh3d_to_canonical([box], (0.3, 0.1, 0.2), None, "box")  # unrotated: (1, 2, 3) -> (0.3, 0.2, 0.1)
    assert notes == ["catalog size stretches the model anisotropically (x9.00)"]


def test_broken_catalogs_give_clear_errors(tmp_path):
    tax = load_taxonomy()
    bad = tmp_path / "bad.sh3f"
    bad.write_bytes(b"PK\x03\x04 truncated")
    with pytest.raises(AssetError, match="not a furniture catalog"):
        read_sh3f_catalog(bad, tax)
    nolist = tmp_path / "nolist.sh3f"
    with zipfile.ZipFile(nolist, "w") as z:
        z.writestr("x/x.obj", "v 0 0 0\n")
    with pytest.raises(AssetError, match="not a furniture catalog"):
        read_sh3f_catalog(nolist, tax)
    partial = tmp_path / "partial.sh3f"
    with zipfile.ZipFile(partial, "w") as z:
        z.writestr(
            "PluginFurnitureCatalog.properties",
            "id#1=a\nname#1=A\nmodel#1=/a/a.obj\nwidth#1=1\ndepth#1=1\nheight#1=1\n"
            "id#2=b\nname#2=B\nmodel#2=/b/b.obj\nwidth#2=-3\ndepth#2=1\nheight#2=1\n",
        )
        z.writestr("a/a.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
        z.writestr("b/b.obj", "v 0 0 0\n")
    recs, skipped = read_sh3f_catalog(partial, tax)
    assert [r.name for r in recs] == ["A"]
    assert len(skipped) == 1 and "non-positive size" in skipped[0]

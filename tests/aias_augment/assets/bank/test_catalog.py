import pytest

from aias_augment.assets.bank.catalog import CatalogRecord, load_catalog, save_catalog


def _rec(i, **kw):
    return CatalogRecord(
        id=f"t:{i}",
        name="n",
        category="rock",
        dimensions_m=(0.1, 0.2, 0.3),
        importer="sidecar",
        source="s",
        tags=("a", "b"),
        notes=("x",),
        params={"k": [1, 2]},
        **kw,
    )


def test_round_trip(tmp_path):
    recs = [_rec(0), _rec(1, triangle_count=12, textured=True, status="repaired")]
    path = save_catalog(recs, tmp_path / "c.json")
    assert load_catalog(path) == recs


def test_invalid_records_are_refused(tmp_path):
    with pytest.raises(ValueError, match="dimensions_m"):
        CatalogRecord(id="a", name="a", category="rock", dimensions_m=(0, 1, 1), importer="x", source="s")
    with pytest.raises(ValueError, match="status"):
        CatalogRecord(id="a", name="a", category="rock", dimensions_m=None, importer="x", source="s", status="meh")
    with pytest.raises(ValueError, match="duplicate"):
        save_catalog([_rec(0), _rec(0)], tmp_path / "d.json")
    (tmp_path / "e.json").write_text('{"version": 99, "records": []}')
    with pytest.raises(ValueError, match="version"):
        load_catalog(tmp_path / "e.json")
    (tmp_path / "f.json").write_text('{"version": 1, "records": [{"id": "a", "bogus": 1}]}')
    with pytest.raises(KeyError, match="bogus"):
        load_catalog(tmp_path / "f.json")

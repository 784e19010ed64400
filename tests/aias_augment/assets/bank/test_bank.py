from pathlib import Path

import numpy as np
import pytest

from aias_augment.assets.asset import AssetError
from aias_augment.assets.bank import AssetBank, discover_records, get_bank
from aias_augment.assets.bank.cache import MeshCache
from aias_augment.assets.bank.catalog import CatalogRecord

FIXTURES = Path(__file__).parent / "fixtures"


@pytest.fixture()
def small_bank(sh3f_records, tmp_path):
    recs = [sh3f_records["sh3f:Scopia#cone"], sh3f_records["sh3f:Blend Swap CC-0#rock1"]]
    broken = CatalogRecord(
        id="sidecar:x/nan_vertices.obj",
        name="broken",
        category="barrel",
        dimensions_m=None,
        importer="sidecar",
        source=str(FIXTURES / "nan_vertices.obj"),
        params={"mesh": str(FIXTURES / "nan_vertices.obj"), "height_m": 1.0, "scale": None, "up_axis": "Z"},
    )
    procedural = [r for r in discover_records(sh3f_dir=None, gazebo_dir=None)[0]]
    return AssetBank(recs + [broken] + procedural, MeshCache(tmp_path))


def test_sample_is_real_size_jittered_and_seeded(small_bank):
    a = small_bank.sample("traffic_cone", np.random.default_rng(5))
    b = small_bank.sample("traffic_cone", np.random.default_rng(5))
    assert a.category == "traffic_cone" and a.meta["record_id"] == "sh3f:Scopia#cone"
    assert 0.70 * 0.88 - 1e-9 <= a.height_m <= 0.70 * 1.12 + 1e-9  # catalog height 70 cm, +-12 % jitter
    np.testing.assert_array_equal(a.meshes[0].vertices, b.meshes[0].vertices)
    heights = {round(small_bank.sample("traffic_cone", np.random.default_rng(s)).height_m, 4) for s in range(5)}
    assert len(heights) == 5


def test_broken_asset_is_skipped_with_its_reason(small_bank):
    with pytest.raises(AssetError, match="failed to load"):
        small_bank.sample("barrel", np.random.default_rng(0), max_tries=2)
    assert any("non-finite" in s for s in small_bank.skipped)
    assert small_bank.record("sidecar:x/nan_vertices.obj").status == "rejected"
    assert "barrel" not in small_bank.categories()
    with pytest.raises(KeyError, match="no usable asset"):
        small_bank.sample("barrel", np.random.default_rng(0))


def test_procedural_stone_borrows_the_real_rock_texture(small_bank):
    a = small_bank.load("procedural:stone", np.random.default_rng(1))
    assert a.procedural and a.category == "rock"
    assert a.meta["texture_from"] and a.meshes[0].visual.material.image is not None
    with pytest.raises(ValueError, match="procedural"):
        small_bank.load("procedural:stone")
    sheet = small_bank.sample("debris", np.random.default_rng(2))
    assert sheet.procedural and 0.01 < sheet.height_m < 0.2


def test_get_bank_discovers_without_a_catalog(tmp_path, sh3f_records):
    bank = get_bank(tmp_path)
    assert bank is get_bank(tmp_path)
    assert len(bank) >= 700
    assert {"traffic_cone", "stroller", "dog", "rock", "person", "car"} <= set(bank.categories())
    assert get_bank(tmp_path, refresh=True) is not bank

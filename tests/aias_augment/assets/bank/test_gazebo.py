import numpy as np
import pytest

from aias_augment.assets.bank.gazebo import default_gazebo_dir, load_gazebo_parts, read_gazebo_records
from aias_augment.assets.bank.taxonomy import load_taxonomy


@pytest.fixture(scope="module")
def records():
    if not (default_gazebo_dir() / "construction_cone" / "model.sdf").is_file():
        pytest.skip("gazebo models not in $AIAS_DATA")
    return {r.id: r for r in read_gazebo_records(default_gazebo_dir(), load_taxonomy())}


def test_records_are_classified(records):
    cats = {rid: r.category for rid, r in records.items()}
    assert cats["gazebo:construction_cone"] == "traffic_cone"
    assert cats["gazebo:construction_barrel"] == "barrel"
    assert cats["gazebo:cinder_block"] == "concrete_block"
    assert cats["gazebo:hatchback"] == "car"
    assert all(r.licence.startswith("CC-BY-3.0") for r in records.values())


def test_cone_size_from_sdf_scale_and_collada_unit(records):
    """model.sdf scales by 10 a COLLADA in inches (unit 0.0254): the cone is 0.5029 m wide (SOURCE.txt: ~1.09 m tall)."""
    parts, notes = load_gazebo_parts(records["gazebo:construction_cone"])
    b = np.array([p.bounds for p in parts])
    ext = b[:, 1].max(0) - b[:, 0].min(0)
    np.testing.assert_allclose(ext[:2], [0.50292, 0.50292], rtol=1e-4)
    assert 1.0 < ext[2] < 1.2 and b[:, 0, 2].min() == pytest.approx(0, abs=1e-9)


def test_obj_model_keeps_textures_and_size(records):
    """The hatchback is an OBJ whose MTL names textures that live in materials/textures (gazebo layout)."""
    from aias_augment.assets.asset import load_asset

    parts, notes = load_gazebo_parts(records["gazebo:hatchback"])
    assert all(p.visual.uv is not None and p.visual.material.image is not None for p in parts)
    assert notes == []
    b = np.array([p.bounds for p in parts])
    ref = load_asset(records["gazebo:hatchback"].params["model_dir"]).extents_m  # sdf scale 0.0254
    np.testing.assert_allclose(b[:, 1].max(0) - b[:, 0].min(0), ref, rtol=1e-9)

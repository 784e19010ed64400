import numpy as np
import pytest

from aias_augment.assets import AssetError, PathAssets, default_asset, load_asset, read_collada_unit
from aias_augment.config import data_root

GAZEBO = data_root() / "meshes" / "gazebo_models"
needs_data = pytest.mark.skipif(not GAZEBO.exists(), reason="shared data not present")


@needs_data
def test_collada_units_are_read_from_the_file():
    assert read_collada_unit(GAZEBO / "construction_cone" / "meshes" / "construction_cone.dae") == (0.0254, "Z_UP")
    assert read_collada_unit(GAZEBO / "fire_hydrant" / "meshes" / "fire_hydrant.dae")[0] == 0.01


@needs_data
def test_gazebo_cone_in_metres_resting_on_ground():
    cone = default_asset("traffic_cone")
    lo, hi = cone.bounds_m
    # model.sdf scale 10 x inch (0.0254) -> about 1.09 m (SOURCE.txt), z up, base on z = 0, centred in x/y.
    assert 1.0 < cone.height_m < 1.2
    assert abs(lo[2]) < 1e-9 and np.allclose((lo[:2] + hi[:2]) / 2, 0, atol=1e-9)
    assert cone.extents_m[2] > cone.extents_m[0]  # a cone is taller than wide: the up axis is right


@needs_data
def test_obj_car_scale_from_sdf():
    car = load_asset(GAZEBO / "hatchback", category="car")
    assert 1.2 < car.height_m < 2.0 and 3.0 < car.extents_m.max() < 5.0


def test_bad_mesh_path_gives_clear_error(tmp_path):
    with pytest.raises(AssetError, match="not found"):
        load_asset(tmp_path / "missing.obj")
    bad = tmp_path / "broken.obj"
    bad.write_text("this is not an obj\n")
    with pytest.raises(AssetError):
        load_asset(bad)
    nan = tmp_path / "nan.obj"
    nan.write_text("v 0 0 0\nv 1 0 nan\nv 0 1 0\nf 1 2 3\n")
    with pytest.raises(AssetError, match="non-finite"):
        load_asset(nan)
    with pytest.raises(AssetError, match="unsupported"):
        load_asset(tmp_path / "x.txt") if (tmp_path / "x.txt").write_text("x") else None


def test_scaled_keeps_contact_plane():
    from tests.aias_augment.fixtures import box_asset
    b = box_asset().scaled(2.5)
    assert np.isclose(b.height_m, 2.5) and np.isclose(b.bounds_m[0, 2], 0)
    with pytest.raises(AssetError):
        box_asset().scaled(float("nan"))


def test_path_assets_pickles_without_meshes(tmp_path):
    import pickle
    (tmp_path / "a.obj").write_text("v 0 0 0\nv 1 0 0\nv 0 1 1\nf 1 2 3\n")
    pa = PathAssets({"box": [str(tmp_path / "a.obj")]})
    assert pickle.loads(pickle.dumps(pa)).paths == pa.paths


def test_path_assets_missing_path_and_unit_guess(tmp_path):
    """Issue 16: a missing mesh is refused at construction; a pedestrian modelled in centimetres (187 units tall)
    is rescaled to 1.87 m with a warning naming the guess."""
    with pytest.raises(AssetError, match="do not exist"):
        PathAssets({"person": [str(tmp_path / "nope.glb")]})
    import trimesh
    trimesh.creation.box(extents=(50, 187, 30)).export(tmp_path / "ped.obj")   # OBJ: y up
    a = PathAssets({"person": [str(tmp_path / "ped.obj")]}).sample("person", np.random.default_rng(0))
    assert np.isclose(a.height_m, 1.87) and "centimetres" in a.meta["unit_guess"]

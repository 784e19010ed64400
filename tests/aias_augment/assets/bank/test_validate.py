from pathlib import Path

import numpy as np
import pytest
import trimesh
from PIL import Image

from aias_augment.assets.asset import AssetError
from aias_augment.assets.bank.meshio import load_raw_parts, missing_obj_textures
from aias_augment.assets.bank.validate import check_size, repair_parts

FIXTURES = Path(__file__).parent / "fixtures"


def _load_repair(name):
    return repair_parts(load_raw_parts(FIXTURES / name), where=name)


@pytest.mark.parametrize(
    "name, message",
    [
        ("nan_vertices.obj", "non-finite vertex coordinates in 75.0% of faces"),
        ("all_degenerate.obj", "no usable triangles"),
        ("bad_index.obj", "failed to load"),
        ("garbage.ply", "failed to load"),
        ("empty.obj", "no triangle"),
        ("does_not_exist.obj", "not found"),
    ],
)
def test_broken_meshes_give_clear_errors(name, message):
    with pytest.raises(AssetError, match=message) as e:
        _load_repair(name)
    assert name in str(e.value)  # the message names the file


def test_unsupported_format_is_refused(tmp_path):
    p = tmp_path / "mesh.xyz"
    p.write_text("1 2 3\n")
    with pytest.raises(AssetError, match="unsupported mesh format"):
        load_raw_parts(p)


def test_degenerate_faces_are_removed_with_a_note():
    parts, notes = _load_repair("some_degenerate.obj")
    # faces (1,2,5) is collinear (all on the x axis) and (3,3,4) repeats an index: 6 - 2 = 4 faces remain
    assert sum(len(p.faces) for p in parts) == 4
    assert notes == ["removed 2 degenerate faces"]


def test_few_nonfinite_vertices_are_cut_out():
    sphere = trimesh.creation.icosphere(subdivisions=2)
    v = sphere.vertices.copy()
    v[0] = [np.nan, 0, 0]
    n_touching = int((sphere.faces == 0).any(1).sum())
    mesh = trimesh.Trimesh(v, sphere.faces, process=False)
    parts, notes = repair_parts([mesh], where="sphere")
    assert len(parts[0].faces) == len(sphere.faces) - n_touching
    assert np.all(np.isfinite(parts[0].vertices))
    assert notes == [f"removed {n_touching} faces with non-finite vertices"]


def test_texture_without_uv_becomes_its_mean_colour():
    box = trimesh.creation.box()
    img = Image.fromarray(
        np.dstack([np.full((4, 4), 200, np.uint8), np.zeros((4, 4), np.uint8), np.full((4, 4), 100, np.uint8)])
    )
    mat = trimesh.visual.material.SimpleMaterial(image=img, diffuse=[255, 255, 255, 255])
    box.visual = trimesh.visual.TextureVisuals(uv=None, material=mat)
    parts, notes = repair_parts([box], where="box")
    assert "texture without valid UVs" in notes[0]
    assert parts[0].visual.material.image is None
    np.testing.assert_array_equal(parts[0].visual.material.diffuse[:3], [200, 0, 100])


def test_missing_texture_is_detected():
    assert missing_obj_textures(FIXTURES / "missing_texture.obj") == ["no_such_texture.jpg"]
    assert missing_obj_textures(FIXTURES / "good_textured.obj") == []


@pytest.mark.parametrize("height, ok", [(0.7, True), (0.1, True), (0.05, False), (70.0, False), (5000.0, False)])
def test_absurd_scale_is_rejected(height, ok):
    ext = np.array([0.4, 0.4, height])
    if ok:
        check_size(ext, "traffic_cone", (0.25, 1.1), where="cone")
    else:
        with pytest.raises(AssetError, match="absurd"):
            check_size(ext, "traffic_cone", (0.25, 1.1), where="cone")

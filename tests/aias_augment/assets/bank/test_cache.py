import os

import numpy as np
import trimesh
from PIL import Image

from aias_augment.assets.bank.cache import MeshCache, default_cache_dir, source_stamp


def _textured_box():
    box = trimesh.creation.box(extents=[1, 2, 3])
    uv = np.random.default_rng(0).uniform(0, 1, (len(box.vertices), 2))
    img = Image.fromarray(np.arange(16 * 16 * 3, dtype=np.uint8).reshape(16, 16, 3) * 0 + 77)
    mat = trimesh.visual.material.SimpleMaterial(image=img, diffuse=[250, 240, 230, 255])
    box.visual = trimesh.visual.TextureVisuals(uv=uv, material=mat)
    return box


def test_round_trip_keeps_geometry_uv_texture_and_colours(tmp_path):
    cache = MeshCache(tmp_path)
    tex = _textured_box()
    plain = trimesh.creation.icosphere()
    plain.visual = trimesh.visual.TextureVisuals(
        material=trimesh.visual.material.SimpleMaterial(diffuse=[10, 20, 30, 128])
    )
    vc = trimesh.creation.box()
    vc.visual = trimesh.visual.ColorVisuals(vc, vertex_colors=np.tile([[1, 2, 3, 255]], (len(vc.vertices), 1)))
    key = cache.key("x", "stamp")
    assert cache.load(key) is None
    cache.save(key, [tex, plain, vc], ["a repair"])
    (a, b, c), notes = cache.load(key)
    assert notes == ["a repair"]
    np.testing.assert_allclose(a.vertices, tex.vertices, atol=1e-6)
    np.testing.assert_array_equal(a.faces, tex.faces)
    np.testing.assert_allclose(a.visual.uv, tex.visual.uv, atol=1e-6)
    assert np.abs(np.asarray(a.visual.material.image, int) - 77).max() <= 2  # JPEG-encoded flat texture
    np.testing.assert_array_equal(a.visual.material.diffuse, [250, 240, 230, 255])
    np.testing.assert_array_equal(b.visual.material.diffuse, [10, 20, 30, 128])
    assert b.visual.uv is None
    np.testing.assert_array_equal(c.visual.vertex_colors[:, :3], np.tile([[1, 2, 3]], (len(vc.vertices), 1)))


def test_corrupt_entry_is_a_miss_and_removed(tmp_path):
    cache = MeshCache(tmp_path)
    key = cache.key("y", "s")
    cache.save(key, [trimesh.creation.box()])
    cache.path(key).write_bytes(b"garbage")
    assert cache.load(key) is None
    assert not cache.path(key).exists()


def test_key_changes_with_source(tmp_path):
    f = tmp_path / "m.obj"
    f.write_text("v 0 0 0\n")
    s1 = source_stamp(f, "v1")
    os.utime(f, (1, 1))
    s2 = source_stamp(f, "v1")
    assert MeshCache.key("a", s1) != MeshCache.key("a", s2) != MeshCache.key("b", s2)
    assert source_stamp(f, "v1") != source_stamp(f, "v2")


def test_default_cache_dir_is_outside_the_repo(monkeypatch, tmp_path):
    monkeypatch.delenv("AIAS_CACHE", raising=False)
    repo = __import__("pathlib").Path(__file__).resolve().parents[4]
    assert repo not in default_cache_dir().resolve().parents
    monkeypatch.setenv("AIAS_CACHE", str(tmp_path))
    assert default_cache_dir() == tmp_path

import json
from dataclasses import replace

import numpy as np

from aias_augment.analyse.analysis import SceneAnalysis, analyse_scene, scene_key
from aias_augment.core.frame import Frame
from aias_augment.core.geometry import Intrinsics
from aias_augment.pipeline.config import InsertionConfig

K = Intrinsics(500.0, 500.0, 319.5, 239.5, 640, 480)
CFG = InsertionConfig(categories=("box",), harmonize=False, ssaa=1)


def road_image(seed=0):
    """Sky over a grey road with a darker band (a cast shadow) so the lighting has something to estimate."""
    rng = np.random.default_rng(seed)
    img = np.full((K.height, K.width, 3), 110, np.uint8)
    img[: K.height // 2] = (150, 180, 220)
    img[300:340, 200:420] = 60
    return np.clip(img + rng.integers(-8, 8, img.shape), 0, 255).astype(np.uint8)


def test_analysis_is_a_function_of_the_frame_only():
    f = Frame(road_image(), K)
    a, b = analyse_scene(f, CFG), analyse_scene(Frame(road_image(), K), CFG)
    assert a.key == b.key
    assert json.dumps(a.to_dict()) == json.dumps(b.to_dict())
    assert np.array_equal(a.region.mask, b.region.mask)
    assert a.modules["camera"] == "given" and "region" in a.modules and "lighting" in a.modules


def test_scene_key_follows_what_the_analysis_reads():
    img = road_image()
    k0 = scene_key(Frame(img, K), CFG)
    img2 = img.copy()
    img2[0, 0, 0] ^= 1  # one bit of one pixel
    assert scene_key(Frame(img2, K), CFG) != k0
    assert scene_key(Frame(img, None), CFG) != k0
    assert scene_key(Frame(img, K, depth=np.full((480, 640), 5.0, np.float32)), CFG) != k0
    assert scene_key(Frame(img, K), replace(CFG, camera_height_m=1.2)) != k0
    from aias_augment.analyse.lighting.estimate import LightingConfig

    assert scene_key(Frame(img, K), replace(CFG, lighting_cfg=LightingConfig(analysis_width=200))) != k0
    # Fields the analysis does not read do not split the cache.
    assert scene_key(Frame(img, K), replace(CFG, ssaa=3, max_objects=5, harmonize=True)) == k0
    # Collision inputs belong to the plan, not to the scene analysis.
    assert scene_key(Frame(img, K, meta={"lidar_points_in_cam": np.zeros((3, 3))}), CFG) == k0


def test_save_load_round_trip(tmp_path):
    a = analyse_scene(Frame(road_image(), K), CFG)
    a.save(tmp_path / "a.npz")
    b = SceneAnalysis.load(tmp_path / "a.npz")
    assert json.dumps(a.to_dict()) == json.dumps(b.to_dict())
    assert np.array_equal(a.region.mask, b.region.mask) and b.region.mask.dtype == bool
    assert b.ground == a.ground and b.intrinsics == a.intrinsics
    assert np.array_equal(a.lighting.ambient_sh, b.lighting.ambient_sh)


def test_ablation_without_placement_has_no_ground_and_says_why():
    a = analyse_scene(Frame(road_image(), None), replace(CFG, naive_paste=True))
    assert a.ground is None and a.region is None
    assert a.modules["placement"].startswith("skipped") and a.modules["lighting"].startswith("skipped")
    assert "naive paste" in a.modules["mode"]


def test_cheap_analysis_runs_on_a_small_copy_and_says_so():
    """analysis_max_width: camera and lighting from a shrunk copy, intrinsics and region at the frame's size, the
    record names what was done; a frame not wider than the limit is analysed as given."""
    cfg = replace(CFG, analysis_max_width=160)
    a = analyse_scene(Frame(road_image(), None), cfg)
    assert "160x120 copy" in a.modules["analysis"]
    assert (a.intrinsics.width, a.intrinsics.height) == (K.width, K.height)
    assert a.region.mask.shape == (K.height, K.width)
    full = analyse_scene(Frame(road_image(), None), CFG)
    assert abs(a.intrinsics.fx - full.intrinsics.fx) / full.intrinsics.fx < 0.05
    assert np.degrees(np.arccos(np.clip(a.ground.normal @ full.ground.normal, -1, 1))) < 10.0
    # Given intrinsics are kept as given; the key differs from the full-resolution analysis' key.
    b = analyse_scene(Frame(road_image(), K), cfg)
    assert b.intrinsics == K or np.allclose(b.intrinsics.K, K.K)
    assert scene_key(Frame(road_image(), K), cfg) != scene_key(Frame(road_image(), K), CFG)
    small = analyse_scene(Frame(road_image()[:120, :160], None), cfg)
    assert "analysis" not in small.modules

"""The camera-pipeline stage after the colour harmonizer (``InsertionConfig.camera_match``, balanced and accurate
presets): the object gets the surroundings' noise and JPEG, its colour is left to the harmonizer, pixels outside the
object are the input's, and a replay from the JSON record gives the same bytes."""

import json
from dataclasses import replace

import cv2
import numpy as np

from aias_augment.analyse.analysis import analyse_scene
from aias_augment.apply.harmonize.api import match_camera
from aias_augment.apply.harmonize.camera_pipeline import noise_level_function
from aias_augment.apply.stages import apply_plan
from aias_augment.core.frame import Frame
from aias_augment.pipeline.config import load_preset
from aias_augment.plan.insertion import plan_insertion
from tests.aias_augment.analyse.test_analysis import CFG, K, road_image
from tests.aias_augment.analyse.test_cache import OneAsset
from tests.aias_augment.fixtures import box_asset


def _jpeg(img: np.ndarray, q: int) -> np.ndarray:
    ok, buf = cv2.imencode(".jpg", img[..., ::-1], [cv2.IMWRITE_JPEG_QUALITY, q])
    return cv2.imdecode(buf, cv2.IMREAD_COLOR)[..., ::-1].copy()


def _grainy_jpeg_road(q: int = 80, sigma: float = 6.0) -> np.ndarray:
    rng = np.random.default_rng(4)
    img = road_image().astype(np.float64) + rng.normal(0, sigma, (K.height, K.width, 3))
    return _jpeg(np.clip(np.round(img), 0, 255).astype(np.uint8), q)


def test_match_camera_adds_the_surroundings_noise_and_keeps_colour_and_background():
    img = _grainy_jpeg_road()
    comp = img.copy()
    mask = np.zeros(img.shape[:2], np.float32)
    mask[300:380, 280:340] = 1.0
    mask[299, 280:340] = 0.5  # a soft edge row
    comp[299:380, 280:340] = (200, 90, 40)  # a flat, noise-free pasted object
    out, info = match_camera(comp, mask, np.random.default_rng(0), source_rgb_uint8=img)
    assert info["jpeg_quality"] is not None and 70 <= info["jpeg_quality"] <= 90  # the source's q80, estimated
    assert np.array_equal(out[mask == 0], comp[mask == 0])  # outside the object: bit for bit
    inner = np.zeros(mask.shape, bool)
    inner[305:375, 285:335] = True
    # colour is the harmonizer's job: the mean stays within 2 levels (noise and JPEG only)
    assert np.abs(out[inner].mean(0) - comp[inner].mean(0)).max() < 2.0
    # noise: the object's noise level function now reaches the background's (it had none)
    gray = lambda a: (a.astype(np.float32) / 255.0) @ np.array([0.299, 0.587, 0.114], np.float32)
    bg = np.zeros(mask.shape, bool)
    bg[250:470, 100:260] = True
    a_bg, b_bg = noise_level_function(gray(img), bg)
    s_bg = np.sqrt(a_bg * gray(img)[inner].mean() + b_bg)
    s_obj = (
        np.std(cv2.filter2D(gray(out), cv2.CV_32F, np.array([[1, -2, 1], [-2, 4, -2], [1, -2, 1]], np.float32))[inner])
        / 6.0
    )
    assert np.ptp(comp[inner], axis=0).max() == 0 and 0.5 * s_bg < s_obj < 2.0 * s_bg
    # same generator seed, same bytes
    again, _ = match_camera(comp, mask, np.random.default_rng(0), source_rgb_uint8=img)
    assert np.array_equal(again, out)


def test_camera_match_stage_after_the_fast_harmonizer_replays_to_the_same_bytes():
    from aias_augment.pipeline.image import insert_into_image
    from aias_augment.pipeline.replay import replay

    img = _grainy_jpeg_road()
    asset = box_asset()
    cfg = type(CFG)(categories=("box",), harmonize=True, harmonize_method="fast", camera_match=True, ssaa=1)
    res = insert_into_image(img, rng=np.random.default_rng(8), cfg=cfg, intrinsics=K, bank=OneAsset(asset), n_objects=2)
    assert res.record.modules["camera_match"].startswith("blur, noise, JPEG q")
    record = json.loads(json.dumps(res.record.to_dict()))
    out = replay(record, Frame(img, K), cfg, assets=lambda p: asset)
    assert np.array_equal(out.image, res.image)
    # the stage changed the object (and nothing else) against the same plan without it
    f = Frame(img, K)
    an = analyse_scene(f, cfg)
    plan = plan_insertion(an, cfg, np.random.default_rng(8), bank=OneAsset(asset), n_objects=2)
    without = apply_plan(f, an, plan, replace(cfg, camera_match=False))
    assert "camera_match" not in without.modules
    diff = (without.image != res.image).any(-1)
    assert diff.sum() > 50 and not (diff & (without.cover == 0)).any()


def test_presets_balanced_and_accurate_match_the_camera_fast_does_not():
    assert load_preset("balanced").camera_match and load_preset("accurate").camera_match
    assert not load_preset("fast").camera_match


def test_match_camera_in_its_window_gives_the_whole_image_bytes():
    from dataclasses import replace

    from aias_augment.apply.harmonize.api import CAMERA_STAGE_PARAMS
    from aias_augment.apply.harmonize.camera_pipeline import camera_match, chroma_subsampled, estimate_jpeg_quality
    from aias_augment.apply.harmonize.color import to_float, to_uint8

    img = _grainy_jpeg_road()
    comp = img.copy()
    mask = np.zeros(img.shape[:2], np.float32)
    for y0, y1, x0, x1 in ((300, 380, 283, 341), (250, 290, 501, 523), (440, 480, 10, 60)):  # one at the border
        mask[y0:y1, x0:x1] = 1.0
        comp[y0:y1, x0:x1] = (200, 90, 40)
    mask[299, 283:341] = 0.4
    out, info = match_camera(comp, mask, np.random.default_rng(5), source_rgb_uint8=img)
    q = estimate_jpeg_quality(img)
    p = replace(CAMERA_STAGE_PARAMS, jpeg_quality=q)
    whole = to_float(camera_match(comp, mask > 0, np.random.default_rng(5), p, chroma_420=chroma_subsampled(img)))
    m = mask[..., None]
    ref = np.where(m > 0, to_uint8(to_float(comp) * (1 - m) + whole * m), comp)
    assert info["jpeg_quality"] == q
    assert np.array_equal(out, ref)

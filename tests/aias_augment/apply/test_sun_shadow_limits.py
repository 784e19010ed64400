"""An uncertain sun never casts a black hard shadow (issue 53 item 1): below confidence 0.8 no shadow pixel of the
output is darker than 0.5 of the road around it, and the shadow's edge widens as the confidence drops.

Measured on the output image only: a flat grey road (one sRGB level) and a 1 m box under a sun from the left; the
shadow's share of the road's light is each ground pixel's linear luminance over the road's; the edge width is the
shadow's depth over its steepest gradient (99th percentile of the Sobel magnitude), which a Gaussian-blurred step
of sigma s gives as about 2.5 s.
"""

from dataclasses import replace

import cv2
import numpy as np
import pytest
from pycocotools import mask as mask_utils

from aias_augment.analyse.cache import SceneCache
from aias_augment.analyse.lighting.estimate import LightingEstimate
from aias_augment.apply.composite import to_linear
from aias_augment.apply.shadows import sun_shadow_limits
from aias_augment.apply.stages import apply_plan
from aias_augment.core.frame import Frame
from aias_augment.pipeline.image import InsertionConfig
from aias_augment.plan.insertion import plan_insertion
from tests.aias_augment.fixtures import box_asset
from tests.aias_augment.pipeline.test_image import K, OneAsset

ROAD = 110
LUMA = np.array([0.2126, 0.7152, 0.0722], np.float32)
SWEEP = (1.0, 0.9, 0.8, 0.79, 0.7, 0.6, 0.5, 0.3)


@pytest.fixture(scope="module", params=["catcher", "projected"])
def measured(request):
    img = np.full((K.height, K.width, 3), ROAD, np.uint8)
    img[: K.height // 2] = (150, 180, 220)
    cfg = InsertionConfig(categories=("box",), harmonize=False, ssaa=1, shadow_method=request.param)
    frame = Frame(img, K)
    analysis = SceneCache(max_items=0).get(frame, cfg)
    rng = np.random.default_rng(5)
    plan = plan_insertion(analysis, cfg, rng, bank=OneAsset(box_asset(extents=(0.5, 0.5, 1.0))), n_objects=1)
    sun = np.array([-0.6, -0.55, -0.3])
    road = float(to_linear(np.full((1, 1, 3), ROAD, np.uint8))[0, 0] @ LUMA)
    out = {}
    for c in SWEEP:
        # a sun 6x the sky on the ground: a full shadow leaves 1/7 of the light
        light = LightingEstimate(sun, np.full(3, 3.0), analysis.lighting.ambient_sh, 6.0, True, c, "image_cues")
        applied = apply_plan(frame, replace(analysis, lighting=light), plan, cfg)
        drawn = mask_utils.decode(applied.annotations[0].rle).astype(np.uint8)
        ground = ~(cv2.dilate(drawn, np.ones((9, 9), np.uint8)) > 0)
        ground[: K.height // 2 + 5] = False
        share = (to_linear(applied.image) @ LUMA) / road
        depth = np.where(ground, 1.0 - share, 0.0).astype(np.float32)
        g = np.hypot(cv2.Sobel(depth, cv2.CV_32F, 1, 0, ksize=3), cv2.Sobel(depth, cv2.CV_32F, 0, 1, ksize=3)) / 8
        g[~(cv2.erode(ground.astype(np.uint8), np.ones((3, 3), np.uint8)) > 0)] = 0
        out[c] = (float(share[ground].min()), float(depth.max() / np.percentile(g[g > 0], 99)))
    return out


def test_no_shadow_darker_than_half_the_road_below_confidence_08(measured):
    assert measured[1.0][0] < 0.2  # a sure sun keeps its measured strength: the scene casts a dark shadow
    for c, (darkest, _) in measured.items():
        if c < 0.8:
            assert darkest >= 0.5, (c, darkest)


def test_the_shadow_lightens_and_its_edge_softens_as_the_confidence_drops(measured):
    darkest = [measured[c][0] for c in SWEEP]
    width = [measured[c][1] for c in SWEEP]
    assert all(b >= a - 0.01 for a, b in zip(darkest, darkest[1:])), darkest
    assert all(b >= a - 0.05 for a, b in zip(width, width[1:])), width
    assert measured[0.5][1] >= 2.0 * measured[1.0][1], width


def test_limits_are_continuous_and_monotone():
    cs = np.linspace(0.0, 1.0, 101)
    lim = [sun_shadow_limits(c) for c in cs]
    darkest = np.array([x.darkest for x in lim])
    assert np.all(np.diff(darkest) <= 1e-12) and np.max(np.abs(np.diff(darkest))) < 0.03  # no jump
    assert np.all(darkest[cs < 0.8] >= 0.5) and darkest[-1] == 0.0 and darkest[0] == 1.0
    assert np.all(np.diff([x.angular_radius_rad for x in lim]) < 0)
    for x in lim:  # a full open-sky shadow under the limited sun/sky ratio is no darker than the limit
        assert 1.0 / (1.0 + x.sun_sky_ratio(50.0)) >= x.darkest - 1e-9

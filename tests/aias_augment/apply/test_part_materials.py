"""Materials per part: the glossy coating lies on the cone's plastic body, not on its rubber base.

A procedural cone with a black base stands on the road of ``road_image`` far enough away that its base top is
seen at a grazing angle (where a coating's Fresnel term mirrors the sky). Its base and body pixels are found from
the geometry alone: the projection of the base's box (its half width and height from the cone's draws) minus the
projection of the body (a cone frustum from the base top to the tip), each eroded away from its edges. Rendered
with the preset's coating and with none (``coating_f0`` 0, matte), the base keeps its matte brightness and the
body does not, in the full render and in the view cache's warp."""

from dataclasses import replace

import cv2
import numpy as np
import pytest

from aias_augment.analyse.analysis import analyse_scene
from aias_augment.apply.stages import apply_plan
from aias_augment.assets.bank.procedural import procedural_asset_from_seed
from aias_augment.core.frame import Frame
from aias_augment.core.geometry import Intrinsics, project_points, transform_points
from aias_augment.pipeline.config import InsertionConfig
from aias_augment.plan.insertion import InsertionPlan, PlannedObject
from aias_augment.plan.placement import object_pose_on_ground, placement_at
from tests.aias_augment.analyse.test_analysis import road_image

K = Intrinsics(900.0, 900.0, 319.5, 239.5, 640, 480)
CONTACT_PX = (320.0, 465.0)


def _black_based_cone():
    for seed in range(200):
        a = procedural_asset_from_seed("traffic_cone", seed)
        if a.meta["base_colour"] == "black" and a.meta["shape"] == "cone" and a.meta["base_shape"] == "square":
            return a.scaled(0.9 / a.height_m)
    raise AssertionError("no black-based square cone in 200 seeds")


def _hull_mask(points_obj, T, erode_px=0):
    uv, _ = project_points(transform_points(T, points_obj), K.K)
    m = np.zeros((K.height, K.width), np.uint8)
    cv2.fillConvexPoly(m, cv2.convexHull(np.round(uv).astype(np.int32)), 1)
    if erode_px:
        m = cv2.erode(m, np.ones((2 * erode_px + 1, 2 * erode_px + 1), np.uint8))
    return m.astype(bool)


def _part_masks(asset, T):
    """Base and body pixels from the cone's draws (metres of the unscaled cone, times its scale)."""
    s, p = asset.meta["scale"], asset.meta
    a, zb, h = p["base_half_width_m"] * s, p["base_height_m"] * s, asset.height_m
    base_box = np.array([[x, y, z] for x in (-a, a) for y in (-a, a) for z in (0.0, zb)])
    t = np.linspace(0, 2 * np.pi, 64, endpoint=False)
    r0 = p["body_bottom_radius_m"] * s * 1.02
    ring = np.c_[r0 * np.cos(t), r0 * np.sin(t), np.full(len(t), zb)]
    body = np.r_[ring, [[0.0, 0.0, h]]]
    body_hull = _hull_mask(body, T)
    base = _hull_mask(base_box, T, erode_px=3) & ~cv2.dilate(body_hull.astype(np.uint8), np.ones((7, 7))).astype(bool)
    bands = np.zeros_like(body_hull)
    for lo, hi in p["bands_z_m"]:  # the sleeves are left out of the body's pixels: the body is plain plastic
        sl = np.c_[np.r_[ring[:, :2], ring[:, :2]], np.r_[np.full(64, lo * s), np.full(64, hi * s)]]
        bands |= _hull_mask(sl, T)
    return base, _hull_mask(body, T, erode_px=3) & ~cv2.dilate(bands.astype(np.uint8), np.ones((7, 7))).astype(bool)


@pytest.mark.parametrize("method", ["full", "view_cache"])
def test_a_coated_cone_keeps_its_black_base_matte(method):
    frame = Frame(road_image(), K)
    base_cfg = InsertionConfig(categories=("traffic_cone",), harmonize=False, shadow=False, ssaa=2)
    an = analyse_scene(frame, base_cfg)
    asset = _black_based_cone()
    p = an.ground.intersect_pixels(np.array([CONTACT_PX]), K)[0]
    T = object_pose_on_ground(p, an.ground, 0.2)
    plan = InsertionPlan((PlannedObject(placement_at(asset, T, K, 0.2, an.ground), asset),), 0, 1)
    base, body = _part_masks(asset, T)
    assert base.sum() >= 80 and body.sum() >= 300, (base.sum(), body.sum())
    out = {}
    for f0 in (0.04, 0.0):
        cfg = replace(base_cfg, coating_f0=f0, render_method=method)
        out[f0] = apply_plan(frame, an, plan, cfg).image.astype(float)
    v = {f0: img.max(-1) for f0, img in out.items()}  # V of HSV
    base_coated, base_matte = v[0.04][base].mean(), v[0.0][base].mean()
    assert abs(base_coated / base_matte - 1) <= 0.10, (base_coated, base_matte)
    body_diff = np.abs(out[0.04][body] - out[0.0][body]).mean()
    assert body_diff >= 2.0, body_diff  # the body's coating is there (sRGB levels)

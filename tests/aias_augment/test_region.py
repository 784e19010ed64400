import numpy as np
import pytest

from aias_augment.geometry import Intrinsics, make_rigid
from aias_augment.ground import prior_ground_plane
from aias_augment.region import (RegionConfig, below_horizon_mask, multi_frame_plane_consistency, placeable_region,
                                 plane_homography)

INTR = Intrinsics(300, 300, 159.5, 119.5, 320, 240)
GROUND = prior_ground_plane(1.5)


def _plane_depth(ground=GROUND):
    v, u = np.mgrid[0:INTR.height, 0:INTR.width]
    pts = ground.intersect_pixels(np.stack([u, v], -1).astype(float), INTR)
    return np.where(np.isfinite(pts[..., 2]), pts[..., 2], 0).astype(np.float32)


def test_below_horizon_level_camera():
    m = below_horizon_mask(GROUND, INTR, margin_px=0)
    assert not m[:120].any() and m[120:].all()  # horizon through cy = 119.5


def test_depth_evidence_excludes_obstacle():
    depth = _plane_depth()
    depth[150:200, 100:140] = 6.0  # a box standing in front of the ground
    region = placeable_region(INTR, GROUND, depth=depth)
    assert region.evidence == "depth"
    assert region.mask[220, 300] and not region.mask[180, 120] and not region.mask[50, 50]


def test_semantic_classes_configurable():
    sem = np.zeros((240, 320), int)
    sem[200:, :160] = 7  # road
    sem[200:, 160:] = 8  # sidewalk
    road = placeable_region(INTR, GROUND, depth=_plane_depth(), semantic=sem, cfg=RegionConfig(semantic_classes=(7,)))
    assert road.evidence == "semantic" and road.mask[220, 10] and not road.mask[220, 300]
    # no classes configured: semantics ignored, geometry decides
    assert placeable_region(INTR, GROUND, depth=_plane_depth(), semantic=sem).evidence == "depth"
    with pytest.raises(ValueError):
        placeable_region(INTR, GROUND, semantic=sem[:10], cfg=RegionConfig(semantic_classes=(7,)))


def test_prior_only():
    r = placeable_region(INTR, GROUND)
    assert r.evidence == "prior:below_horizon" and r.fraction == pytest.approx(0.5, abs=0.03)


def test_plane_homography_maps_ground_points():
    cam2_from_cam1 = make_rigid(np.eye(3), [0.2, 0.0, -1.0])  # camera moved 1 m forward, 0.2 m left
    H = plane_homography(GROUND, cam2_from_cam1, INTR)
    p1 = GROUND.intersect_pixels(np.array([200.0, 200.0]), INTR)
    p2 = cam2_from_cam1[:3, :3] @ p1 + cam2_from_cam1[:3, 3]
    uv2 = INTR.K @ p2
    x = H @ np.array([200.0, 200.0, 1.0])
    np.testing.assert_allclose(x[:2] / x[2], uv2[:2] / uv2[2], atol=1e-9)


def test_multi_frame_consistency_on_textured_plane():
    rng = np.random.default_rng(0)
    tex = (rng.integers(0, 255, (60, 80)).astype(np.uint8))
    import cv2
    tex = cv2.resize(tex, (320, 240), interpolation=cv2.INTER_LINEAR)
    img1 = tex.copy()
    cam2_from_cam1 = make_rigid(np.eye(3), [0.0, 0.0, -0.3])
    H = plane_homography(GROUND, cam2_from_cam1, INTR)
    img2 = cv2.warpPerspective(img1, H, (320, 240))  # frame 2 = the plane seen after moving
    ok = multi_frame_plane_consistency(img1, img2, GROUND, cam2_from_cam1, INTR)
    assert ok.mask[150:230, 60:260].mean() > 0.9
    wrong = multi_frame_plane_consistency(img1, img2, prior_ground_plane(0.5), cam2_from_cam1, INTR)
    assert wrong.mask[150:230, 60:260].mean() < 0.5

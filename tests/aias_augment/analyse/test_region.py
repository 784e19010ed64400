import cv2
import numpy as np
import pytest

from aias_augment.analyse.ground import prior_ground_plane
from aias_augment.analyse.region import (
    RegionConfig,
    below_horizon_mask,
    multi_frame_plane_consistency,
    placeable_region,
    plane_homography,
)
from aias_augment.core.geometry import Intrinsics, make_rigid

INTR = Intrinsics(300, 300, 159.5, 119.5, 320, 240)
GROUND = prior_ground_plane(1.5)


def _plane_depth(ground=GROUND):
    v, u = np.mgrid[0 : INTR.height, 0 : INTR.width]
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
    tex = rng.integers(0, 255, (60, 80)).astype(np.uint8)
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


# --- single image: the road from the image alone (region.image_ground_region) -------------------------------------
# Truth by construction: a synthetic street seen by a level camera (horizon through cy). The road is a polygon
# converging to the vanishing point; left and right of it grass-like (green, coarse texture) and a wall; a parked
# car (dark red body, black tyres, bright window edge) stands on the road; the bottom rows are the ego vehicle's
# bonnet (smooth, bright). The region must stay on the road polygon and off the car, the bonnet and the verges.
STREET_INTR = Intrinsics(400, 400, 319.5, 179.5, 640, 360)


def _street(grey: bool = False, seed: int = 0):
    rng = np.random.default_rng(seed)
    h, w = STREET_INTR.height, STREET_INTR.width
    vv, uu = np.mgrid[0:h, 0:w].astype(float)
    img = np.empty((h, w, 3), np.float32)
    img[:] = (150, 190, 230)  # sky
    grass = np.array([70, 120, 50]) + rng.normal(0, 28, (h, w, 1))  # coarse texture
    img[180:] = grass[180:]
    # road: between two lines through the vanishing point (319.5, 179.5), 1.5 m camera height, 7 m wide
    x_at = lambda v, lateral: 319.5 + lateral * (v - 179.5) / 1.5  # noqa: E731  (ground x = lateral at row v)
    road = (vv > 182) & (uu > x_at(vv, -3.5)) & (uu < x_at(vv, 3.5))
    asphalt = 105 + rng.normal(0, 3, (h, w)) + 0.04 * (vv - 180)  # fine texture, slow shading
    img[road] = asphalt[road][:, None]
    img[(vv > 120) & (vv < 215) & (uu > 420) & (uu > x_at(vv, 5.0))] = (200, 185, 160)  # a house wall
    car = (vv >= 230) & (vv < 285) & (uu >= 380) & (uu < 470)  # parked car on the road
    img[car] = (90, 15, 20)
    img[(vv >= 238) & (vv < 255) & (uu >= 392) & (uu < 458)] = (210, 220, 230)  # its window
    img[(vv >= 272) & (vv < 288) & (((uu >= 388) & (uu < 404)) | ((uu >= 444) & (uu < 460)))] = (15, 15, 15)
    car_px = car | ((vv >= 272) & (vv < 288) & (uu >= 388) & (uu < 460))
    bonnet = vv >= 340
    img[bonnet] = (230, 230, 235)
    img = np.clip(img, 0, 255).astype(np.uint8)
    if grey:
        g = cv2.cvtColor(img, cv2.COLOR_RGB2GRAY)
        img = np.repeat(g[..., None], 3, axis=2)
    return img, road & ~car_px & ~bonnet, car_px, bonnet


@pytest.mark.parametrize("grey", [False, True])
def test_image_region_stays_on_the_road_and_off_the_car(grey):
    img, road, car, bonnet = _street(grey)
    region = placeable_region(STREET_INTR, GROUND, image=img)
    assert region.evidence == "image:road_appearance"
    m = region.mask
    assert (m & road).sum() / m.sum() >= 0.98  # precision against the known road polygon
    assert (m & road).sum() / road.sum() >= 0.5  # and most of the road
    assert not (m & car).any() and not (m & bonnet).any()
    assert not m[:180].any()  # nothing above the horizon
    far_row = 179.5 + 400 * 1.5 / RegionConfig().image_max_distance_m  # ground 40 m away (f h / Z below cy)
    assert not m[: int(far_row)].any() and m[int(far_row) + 3 :].any()
    assert set(region.excluded) >= {"colour or texture unlike the road", "eroded border"}


def test_image_region_avoids_the_car_borders():
    img, road, car, _ = _street()
    m = placeable_region(STREET_INTR, GROUND, image=img).mask
    near_car = cv2.dilate(car.astype(np.uint8), np.ones((5, 5), np.uint8)).astype(bool)
    assert not (m & near_car).any()  # eroded: contacts keep off the occluder's edge


def test_image_region_needs_nothing_measured_and_can_be_switched_off():
    img, *_ = _street()
    assert placeable_region(STREET_INTR, GROUND, depth=_street_depth(), image=img).evidence == "depth"
    off = placeable_region(STREET_INTR, GROUND, image=img, cfg=RegionConfig(image_region=False))
    assert off.evidence == "prior:below_horizon"


def _street_depth():
    v, u = np.mgrid[0 : STREET_INTR.height, 0 : STREET_INTR.width]
    pts = GROUND.intersect_pixels(np.stack([u, v], -1).astype(float), STREET_INTR)
    return np.where(np.isfinite(pts[..., 2]), pts[..., 2], 0).astype(np.float32)


def test_image_without_a_road_surface_falls_back_to_the_prior():
    rng = np.random.default_rng(1)
    noise = rng.integers(0, 256, (STREET_INTR.height, STREET_INTR.width, 3), dtype=np.uint8)  # no smooth surface
    r = placeable_region(STREET_INTR, GROUND, image=noise)
    assert r.evidence == "prior:below_horizon" and "image region too small" in r.excluded
    assert r.mask.sum() == below_horizon_mask(GROUND, STREET_INTR, RegionConfig().horizon_margin_px).sum()


def test_single_image_analysis_and_plan_use_the_image_region():
    from aias_augment.analyse.analysis import analyse_scene
    from aias_augment.core.frame import Frame
    from aias_augment.pipeline.config import InsertionConfig
    from aias_augment.plan.insertion import plan_insertion

    img, road, car, _ = _street()
    cfg = InsertionConfig(lighting=False, estimate_camera=False, camera_height_m=1.5, min_objects=3, max_objects=3)
    analysis = analyse_scene(Frame(img, STREET_INTR), cfg)
    assert analysis.region.evidence == "image:road_appearance"
    assert "excluded" in analysis.modules["region"]
    contacts = []
    for seed in range(4):
        plan = plan_insertion(analysis, cfg, np.random.default_rng(seed))
        contacts += [o.placement.contact_pixel for o in plan.objects]
    assert len(contacts) >= 6
    for u, v in contacts:
        assert road[int(round(v)), int(round(u))] and not car[int(round(v)), int(round(u))]


@pytest.mark.parametrize("n_keys", [7, 11 * 33 * 33, 10**9])
def test_colour_bins_are_numpys_unique(n_keys):
    """The road histogram's bins: counted (few possible keys) or sorted (many), the inverse and the counts of
    np.unique, in its order."""
    from aias_augment.analyse.region import _unique_bins

    key = np.random.default_rng(n_keys).integers(0, n_keys, 5000)
    _, want_inverse, want_counts = np.unique(key, return_inverse=True, return_counts=True)
    inverse, counts = _unique_bins(key, n_keys)
    np.testing.assert_array_equal(inverse, want_inverse)
    np.testing.assert_array_equal(counts, want_counts)


def _road_mode_on_stacked_features(feat, cfg):
    """The road's feature from the zone's (N, 4) features: histogram peak by np.unique, medians over axis 0."""
    q = np.floor(feat[:, :3] / [cfg.image_luma_tol, cfg.image_chroma_tol, cfg.image_chroma_tol]).astype(np.int64)
    _, inverse, counts = np.unique(q, axis=0, return_inverse=True, return_counts=True)
    inverse = inverse.reshape(-1)
    centre = np.stack([np.bincount(inverse, feat[:, j]) / counts for j in range(3)], axis=1)
    chroma = np.hypot(centre[:, 1] - 128.0, centre[:, 2] - 128.0)
    lo, hi = cfg.image_road_luma
    prior = np.where((centre[:, 0] >= lo) & (centre[:, 0] <= hi) & (chroma <= cfg.image_road_chroma), 1.0, 0.25)

    def similar(road):
        return (
            (np.abs(feat[:, 0] - road[0]) <= cfg.image_luma_tol)
            & (np.abs(feat[:, 1:3] - road[1:3]) <= cfg.image_chroma_tol).all(axis=1)
            & (feat[:, 3] <= cfg.image_texture_tol * road[3] + cfg.image_texture_floor)
        )

    mode = np.median(feat[inverse == np.argmax(counts * prior)], axis=0)
    for _ in range(3):
        if not similar(mode).any():
            break
        mode = np.median(feat[similar(mode)], axis=0)
    return mode, similar(mode)


@pytest.mark.parametrize("n", [5000, 5001])
def test_road_mode_on_feature_planes_is_the_stacked_computation(n):
    """The seed zone's road colour from four feature planes: the same float32 mode and inliers as from the stacked
    (N, 4) features (np.unique's bins, medians over axis 0), odd and even counts, a road among cars and shadows."""
    from aias_augment.analyse.region import RegionConfig, _road_mode

    rng = np.random.default_rng(n)
    road = rng.normal([120.0, 128.0, 130.0, 3.0], [12.0, 2.0, 2.0, 1.0], (n, 4))
    other = rng.uniform([0.0, 90.0, 90.0, 0.0], [255.0, 170.0, 170.0, 30.0], (n // 3, 4))
    feat = np.concatenate([road, other]).astype(np.float32)
    cfg = RegionConfig()
    want_mode, want_ok = _road_mode_on_stacked_features(feat, cfg)
    mode, ok = _road_mode([np.ascontiguousarray(feat[:, j]) for j in range(4)], cfg)
    assert mode.dtype == want_mode.dtype == np.float32
    np.testing.assert_array_equal(mode, want_mode)
    np.testing.assert_array_equal(ok, want_ok)

"""placement.sample_placement: local ground refit around the contact point (synthetic road + kerb-high sidewalk)."""

import numpy as np
import pytest
import trimesh

from aias_augment.analyse.ground import GroundPlane, prior_ground_plane
from aias_augment.assets.asset import Asset
from aias_augment.core.geometry import Intrinsics
from aias_augment.plan.placement import PlacementConfig, refit_local_ground, sample_placement

K = Intrinsics(500.0, 500.0, 319.5, 239.5, 640, 480)
CAM_HEIGHT = 1.6
KERB_X = 2.0  # sidewalk for x >= 2 m (camera frame, x right)
KERB_RISE = 0.10  # sidewalk 10 cm above the road at the kerb
CROSS_SLOPE = 0.02  # and rising 2 % to the right (tilted normal: the object must follow it)

# Sidewalk: y = (CAM_HEIGHT - KERB_RISE) - CROSS_SLOPE (x - KERB_X)  <=>  y + CROSS_SLOPE x = C
_C = CAM_HEIGHT - KERB_RISE + CROSS_SLOPE * KERB_X
_n = -np.array([CROSS_SLOPE, 1.0, 0.0])
SIDEWALK = GroundPlane(_n, _C, "truth")  # -(0.02 x + y) + C = 0; the constructor normalises n and d
ROAD = prior_ground_plane(CAM_HEIGHT)


def _asset():
    return Asset(
        "box",
        "barrel",
        (trimesh.creation.box((0.5, 0.5, 1.0), trimesh.transformations.translation_matrix([0, 0, 0.5])),),
        "test",
    )


def _scene():
    """Analytic z-depth of road + kerb face + sloped sidewalk; also which surface each pixel sees."""
    u, v = np.meshgrid(np.arange(K.width), np.arange(K.height))
    x = (u - K.cx) / K.fx
    y = (v - K.cy) / K.fy  # ray (x, y, 1): z-depth = ray parameter t
    with np.errstate(divide="ignore", invalid="ignore"):
        t_side = _C / (y + CROSS_SLOPE * x)
        t_road = CAM_HEIGHT / y
        t_kerb = KERB_X / x
    on_side = (t_side > 0) & (t_side * x >= KERB_X)
    on_road = ~on_side & (t_road > 0) & (t_road * x < KERB_X)
    on_kerb = ~on_side & ~on_road & (t_kerb > 0) & (y > 0)
    depth = np.select([on_side, on_road, on_kerb], [t_side, t_road, t_kerb], 0.0)
    depth = np.where(np.isfinite(depth) & (depth < 60), depth, 0.0).astype(np.float32)
    return depth, on_side, on_road, x * depth


def test_sidewalk_contact_gets_sidewalk_height_and_normal():
    """Coarse plane = the road. Contacts on the sidewalk (>= 3.5 m from the kerb, so the 3 m local window sees
    only sidewalk) must lie on the sidewalk within 1 cm, not on the road 10+ cm below, and stand along its normal."""
    depth, on_side, _, x_m = _scene()
    region = on_side & (x_m > KERB_X + 3.5) & (depth > 6) & (depth < 20)
    cfg = PlacementConfig(max_tries=40, min_box_height_px=4)
    n_local = 0
    for seed in range(4):
        pl, report = sample_placement(
            _asset(),
            ROAD,
            K,
            np.random.default_rng(seed),
            depth=depth,
            region_mask=region,
            cfg=cfg,
            height_range_m=(1.0, 1.0),
        )
        assert pl is not None, report.to_dict()
        c = np.array(pl.contact_point_in_cam)
        assert pl.ground_used == "local" and pl.ground_num_inliers > 100
        assert abs(float(SIDEWALK.signed_distance(c))) < 0.01
        assert float(ROAD.signed_distance(c)) > KERB_RISE  # what the coarse plane would have given: 10+ cm off
        # The coarse contact on the same pixel ray would have been on the road plane.
        coarse = ROAD.intersect_pixels(np.array(pl.contact_pixel), K)
        assert abs(float(SIDEWALK.signed_distance(coarse))) > 0.09
        up_obj = pl.cam_from_object_matrix[:3, 2]
        angle = np.degrees(np.arccos(np.clip(up_obj @ SIDEWALK.normal, -1, 1)))
        assert angle < 0.2, angle  # follows the 1.15 deg cross-slope, not the road normal
        n_local += 1
    assert n_local == 4


def test_contact_near_the_kerb_follows_the_surface_under_it():
    """Sidewalk contacts 1.1-1.6 m from the kerb: the 3 m window also holds road, which may win the RANSAC vote;
    the support check (points under the contact) must still give the sidewalk height, else reject."""
    depth, on_side, _, x_m = _scene()
    region = on_side & (x_m > KERB_X + 1.1) & (x_m < KERB_X + 1.6) & (depth > 5) & (depth < 12)
    cfg = PlacementConfig(max_tries=40, min_box_height_px=4)
    for seed in range(4):
        pl, report = sample_placement(
            _asset(),
            ROAD,
            K,
            np.random.default_rng(seed),
            depth=depth,
            region_mask=region,
            cfg=cfg,
            height_range_m=(1.0, 1.0),
        )
        assert pl is not None, report.to_dict()
        assert pl.ground_used == "local"
        assert abs(float(SIDEWALK.signed_distance(np.array(pl.contact_point_in_cam)))) < 0.01


def test_support_check_keeps_the_contact_on_a_narrow_raised_island():
    """A 1.6 m wide island 10 cm above the road: within the 3 m window the road wins the vote. Without the support
    check the contact lands on the road (10 cm off); with it, within local_support_max_residual_m of the island."""
    xs, zs = np.meshgrid(np.arange(-6, 9, 0.1), np.arange(5, 20, 0.1))
    xs, zs = xs.ravel(), zs.ravel()
    island = (xs > 2.2) & (xs < 3.8)
    pts = np.column_stack([xs, np.where(island, CAM_HEIGHT - 0.1, CAM_HEIGHT), zs])
    coarse_contact = np.array([3.0, CAM_HEIGHT, 12.0])
    cfg = PlacementConfig()
    off = PlacementConfig(local_support_min_points=10**9)  # never enough points: check disabled
    errs_on, errs_off = [], []
    for seed in range(3):
        _, c = refit_local_ground(pts, ROAD, coarse_contact, np.random.default_rng(seed), cfg)
        errs_on.append(abs(c[1] - (CAM_HEIGHT - 0.1)))
        _, c = refit_local_ground(pts, ROAD, coarse_contact, np.random.default_rng(seed), off)
        errs_off.append(abs(c[1] - (CAM_HEIGHT - 0.1)))
    assert max(errs_on) <= cfg.local_support_max_residual_m, errs_on
    assert max(errs_off) > 0.09, errs_off


def test_road_contact_corrects_a_biased_coarse_plane():
    """Coarse plane 5 cm too low: a road contact (> 3 m from the kerb) is refitted onto the true road."""
    depth, _, on_road, x_m = _scene()
    region = on_road & (x_m < KERB_X - 3.5) & (depth > 5) & (depth < 20)
    biased = prior_ground_plane(CAM_HEIGHT + 0.05)
    pl, report = sample_placement(
        _asset(),
        biased,
        K,
        np.random.default_rng(0),
        depth=depth,
        region_mask=region,
        cfg=PlacementConfig(max_tries=40, min_box_height_px=4),
        height_range_m=(1.0, 1.0),
    )
    assert pl is not None, report.to_dict()
    c = np.array(pl.contact_point_in_cam)
    assert pl.ground_used == "local" and abs(float(ROAD.signed_distance(c))) < 0.01
    assert abs(pl.ground_d - CAM_HEIGHT) < 0.01


def test_without_measurements_the_global_plane_is_used_and_candidates_match():
    """No depth/points: contact on the given plane, recorded as global. The refit's randomness is drawn from a
    child generator, so the same seed picks the same contact pixel with or without depth."""
    depth, on_side, _, x_m = _scene()
    region = on_side & (x_m > KERB_X + 3.5) & (depth > 6) & (depth < 20)
    cfg = PlacementConfig(max_tries=40, min_box_height_px=4)
    a, _ = sample_placement(
        _asset(), ROAD, K, np.random.default_rng(1), region_mask=region, cfg=cfg, height_range_m=(1.0, 1.0)
    )
    b, _ = sample_placement(
        _asset(), ROAD, K, np.random.default_rng(1), depth=depth, region_mask=region, cfg=cfg, height_range_m=(1.0, 1.0)
    )
    assert a.ground_used == "global" and abs(float(ROAD.signed_distance(np.array(a.contact_point_in_cam)))) < 1e-9
    assert b.ground_used == "local" and a.contact_pixel == b.contact_pixel and a.yaw_rad == b.yaw_rad


def test_refit_failure_falls_back_or_rejects_as_configured():
    """Measured points only beyond the farthest contact (z > 70 m): no local ground near any contact -> global plane,
    or a counted rejection with local_fallback='reject'."""
    xs, zs = np.meshgrid(np.linspace(-20, 20, 41), np.linspace(70, 80, 11))
    far = np.column_stack([xs.ravel(), np.full(xs.size, CAM_HEIGHT), zs.ravel()])
    cfg = PlacementConfig(max_tries=10, local_max_depth_m=100.0)
    pl, report = sample_placement(
        _asset(), ROAD, K, np.random.default_rng(0), points_in_cam=far, cfg=cfg, height_range_m=(1.0, 1.0)
    )
    assert pl is not None and pl.ground_used == "global" and report.local_refit_failed >= 1
    none, report = sample_placement(
        _asset(),
        ROAD,
        K,
        np.random.default_rng(0),
        points_in_cam=far,
        cfg=PlacementConfig(max_tries=10, local_max_depth_m=100.0, local_fallback="reject"),
        height_range_m=(1.0, 1.0),
    )
    assert none is None and report.rejected["no local ground around the contact point"] >= 5
    assert set(report.rejected) <= {"no local ground around the contact point", "distance out of range"}


def test_bad_config_raises():
    with pytest.raises(ValueError, match="local_fallback"):
        PlacementConfig(local_fallback="nearest")


def test_pipeline_passes_dgp_meta_so_insertions_avoid_lidar_clusters_and_3d_boxes():
    """insert_into_image(meta={"lidar_points_in_cam", "boxes_in_cam"}): no inserted object intersects an existing
    3D box, a LiDAR cluster, or another insertion; the same seeds without meta do hit them (the test can fail)."""
    from aias_augment.core.geometry import make_rigid
    from aias_augment.pipeline.image import InsertionConfig, insert_into_image
    from aias_augment.plan.collision import OrientedBox, boxes_intersect, points_inside_box
    from tests.aias_augment.fixtures import box_asset

    class OneAsset:
        def __init__(self, asset):
            self.asset = asset

        def sample(self, category, rng):
            return self.asset

    intr = Intrinsics(250.0, 250.0, 159.5, 119.5, 320, 240)
    img = np.full((240, 320, 3), 110, np.uint8)
    asset = box_asset(extents=(0.8, 0.8, 1.2), category="box")
    # Existing car-sized box on the ground straight ahead (object z up = camera -y), 6 m wide, 12 m long.
    R_up = np.array([[1, 0, 0], [0, 0, -1], [0, 1, 0]], float)
    car = OrientedBox.standing_on_ground(make_rigid(R_up, [0.5, CAM_HEIGHT, 13.0]), (6.0, 12.0, 1.5), "car")
    # A LiDAR "hedge" on the left: points 0.3..2 m above the ground.
    xs, hs, zs = np.meshgrid(np.linspace(-9, -2.5, 27), np.linspace(0.3, 2.0, 6), np.linspace(3.5, 25, 87))
    hedge = np.column_stack([xs.ravel(), CAM_HEIGHT - hs.ravel(), zs.ravel()])
    cfg = InsertionConfig(categories=("box",), harmonize=False, lighting=False, shadow=False, ssaa=1)
    hits = {True: 0, False: 0}
    placed = {True: 0, False: 0}
    for with_meta in (True, False):
        meta = {"lidar_points_in_cam": hedge, "boxes_in_cam": [car]} if with_meta else None
        for seed in range(4):
            res = insert_into_image(
                img,
                rng=np.random.default_rng(seed),
                cfg=cfg,
                intrinsics=intr,
                meta=meta,
                bank=OneAsset(asset),
                n_objects=3,
            )
            boxes = [
                OrientedBox.standing_on_ground(p.cam_from_object_matrix, tuple(asset.extents_m * p.scale))
                for p in res.record.placements
            ]
            placed[with_meta] += len(boxes)
            for i, b in enumerate(boxes):
                hits[with_meta] += int(
                    boxes_intersect(b, car)
                    or points_inside_box(hedge, b).sum() >= 3
                    or any(boxes_intersect(b, o) for o in boxes[:i])
                )
            if with_meta:
                assert res.record.modules["collision"].startswith(f"3D checks: {len(hedge)} scene points, 1 existing")
    assert placed[True] >= 8 and hits[True] == 0
    assert hits[False] >= 2


# ------------------------------------------------------------------ pixel-size targets


def test_predicted_box_height_matches_pinhole_formula_on_a_level_road():
    # Level camera CAM_HEIGHT above the road: a ground pixel at row v sees z = f H / (v - cy); a vertical segment
    # of height h standing there spans f h / z pixels (top at height h is at y = H - h, same z).
    from aias_augment.plan.placement import predicted_box_heights_px

    v = np.array([260.0, 300.0, 400.0, 479.0])
    uv = np.c_[np.full_like(v, 100.0), v]
    z = K.fy * CAM_HEIGHT / (v - K.cy)
    expected = K.fy * 0.7 / z
    np.testing.assert_allclose(predicted_box_heights_px(uv, 0.7, ROAD, K), expected, rtol=1e-9)
    above = predicted_box_heights_px(np.array([[100.0, 200.0]]), 0.7, ROAD, K)  # above the horizon: no ground
    assert np.isnan(above).all()


@pytest.mark.parametrize("target_frac", [0.06, 0.12, 0.2])
def test_box_height_target_sets_the_projected_size(target_frac):
    cfg = PlacementConfig(box_height_frac_range=(target_frac, target_frac), box_height_tolerance=0.1, local_refit=False)
    heights = []
    for seed in range(12):
        p, report = sample_placement(_asset(), ROAD, K, np.random.default_rng(seed), cfg=cfg, height_range_m=(1.0, 1.0))
        assert p is not None, report.to_dict()
        heights.append((p.amodal_box_xyxy[3] - p.amodal_box_xyxy[1]) / K.height)
        assert report.to_dict()["target_box_height_px"] == pytest.approx(target_frac * K.height)
    # the box of a 0.5 m wide box is a little taller than its vertical edge (its top face shows): within 25 %
    assert np.median(heights) == pytest.approx(target_frac, rel=0.25), heights


def test_unreachable_box_height_target_falls_back_and_says_so():
    # Nearest visible road (bottom row) is f H / 240 = 3.3 m away: a 1 m object is at most ~150 px; ask for 90 %.
    cfg = PlacementConfig(box_height_frac_range=(0.9, 0.9), max_box_height_frac=1.0, local_refit=False)
    p, report = sample_placement(_asset(), ROAD, K, np.random.default_rng(0), cfg=cfg, height_range_m=(1.0, 1.0))
    assert p is not None
    assert "not reachable" in report.chosen_because
    assert p.amodal_box_xyxy[3] > 0.9 * K.height  # the nearest sizes: the bottom of the image


def test_box_height_samples_follow_the_given_distribution():
    small, large = 0.05, 0.2
    cfg = PlacementConfig(
        box_height_frac_samples=(small, large), box_height_jitter=0.0, box_height_tolerance=0.1, local_refit=False
    )
    heights = []
    for seed in range(30):
        p, _ = sample_placement(_asset(), ROAD, K, np.random.default_rng(seed), cfg=cfg, height_range_m=(1.0, 1.0))
        heights.append((p.amodal_box_xyxy[3] - p.amodal_box_xyxy[1]) / K.height)
    heights = np.array(heights)
    assert ((heights < 0.1).sum() >= 8) and ((heights > 0.14).sum() >= 8)  # both modes drawn
    assert not ((heights > 0.1) & (heights < 0.14)).any()  # and nothing between them


def test_candidate_cache_changes_nothing_and_sees_a_mask_changed_in_place():
    """Planning again on the same scene reuses the candidate pixels (box_size.GROUND_CANDIDATES); the result must
    be the one a cold computation gives, every contact must respect the analytic horizon and the region, and a
    region edited in place (same array object) must not be served from the cache."""
    from aias_augment.plan import box_size

    region = np.zeros((K.height, K.width), bool)
    region[300:, :320] = True  # left half of the lower image
    cfg = PlacementConfig(max_tries=40, min_box_height_px=4, box_height_frac_range=(0.05, 0.2))

    def draw(seed):
        pl, _ = sample_placement(
            _asset(), ROAD, K, np.random.default_rng(seed), region_mask=region, cfg=cfg, height_range_m=(1.0, 1.0)
        )
        return pl

    box_size.GROUND_CANDIDATES._entries.clear()
    cold = [draw(s) for s in range(6)]
    warm = [draw(s) for s in range(6)]  # cache hits now
    assert cold == warm and all(p is not None for p in cold)
    for p in cold:
        u, v = p.contact_pixel
        assert v > K.cy + 8 - 0.5 and region[int(round(v)), int(round(u))]  # level camera: horizon row = cy
    region[:] = False
    region[300:, 320:] = True  # in place: now only the right half
    moved = [draw(s) for s in range(6)]
    assert all(p.contact_pixel[0] >= 319.5 for p in moved)


def test_object_pose_on_ground_is_a_yawed_frame_standing_on_the_plane():
    """For tilted planes and yaws: a proper rotation, object z = the plane normal, the origin at the contact point,
    yaw 0's x axis = camera x projected onto the plane (normalised), and yaw turning x about the normal by yaw."""
    from aias_augment.analyse.ground import GroundPlane
    from aias_augment.plan.placement import object_pose_on_ground

    for normal in ([0.0, -1.0, 0.0], [0.1, -0.98, 0.17], [0.99, -0.1, 0.05]):
        n = np.asarray(normal) / np.linalg.norm(normal)
        g = GroundPlane(n, 1.6, "test")
        p = np.array([0.3, 1.5, 8.0])
        T0 = object_pose_on_ground(p, g, 0.0)
        x_ref = np.array([1.0, 0, 0]) - n[0] * n
        np.testing.assert_allclose(T0[:3, 0], x_ref / np.linalg.norm(x_ref), atol=1e-12)
        for yaw in (0.0, 0.7, -2.5):
            T = object_pose_on_ground(p, g, yaw)
            R = T[:3, :3]
            np.testing.assert_allclose(R @ R.T, np.eye(3), atol=1e-12)
            assert np.isclose(np.linalg.det(R), 1.0)
            np.testing.assert_allclose(R[:, 2], n, atol=1e-12)
            np.testing.assert_allclose(T[:3, 3], p)
            np.testing.assert_allclose(T[3], [0, 0, 0, 1])
            assert np.isclose(np.arctan2(np.cross(T0[:3, 0], R[:, 0]) @ n, T0[:3, 0] @ R[:, 0]), yaw)


def test_ground_point_of_a_pixel_is_intersect_pixels():
    """placement's scalar ray-plane intersection against GroundPlane.intersect_pixels: the same point below the
    horizon (to 1e-12), None where that gives NaN (above the horizon, on it)."""
    from aias_augment.analyse.ground import GroundPlane
    from aias_augment.core.geometry import Intrinsics
    from aias_augment.plan.placement import _ground_point

    K = Intrinsics.from_fov(640, 480, 70.0)
    kt = (K.fx, K.fy, K.cx, K.cy, float(K.K[0, 1]))
    rng = np.random.default_rng(0)
    for n in ([0.0, -1.0, 0.0], [0.05, -0.99, 0.12], [0.0, -0.2, 0.98]):
        g = GroundPlane(np.asarray(n) / np.linalg.norm(n), 1.65, "test")
        uv = np.c_[rng.uniform(-50, 690, 400), rng.uniform(-50, 530, 400)]
        ref = g.intersect_pixels(uv, K)
        for q, r in zip(uv, ref):
            got = _ground_point(g, q, kt)
            if np.all(np.isfinite(r)):
                np.testing.assert_allclose(got, r, rtol=1e-12, atol=1e-12)
            else:
                assert got is None

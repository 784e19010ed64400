"""video.insert_into_clip on KITTI 06 (GT poses): one world pose, analytic contact track, smooth object size."""

import numpy as np
import pytest

from aias_augment.analyse.ground import prior_ground_plane
from aias_augment.core.config import data_root
from aias_augment.core.geometry import Intrinsics
from aias_augment.pipeline.clip import VideoInsertionConfig, insert_into_clip
from tests.aias_augment.fixtures import box_asset

SEQ = data_root() / "kitti06_seq"


@pytest.fixture(scope="module")
def kitti_clip():
    if not SEQ.exists():
        pytest.skip("shared KITTI data not available")
    from aias_augment.scenes.kitti import open_kitti_sequence

    seq = open_kitti_sequence(SEQ)
    n = 16
    frames = [seq.frame(i).image for i in range(n)]
    poses = np.stack([seq.cam_from_world(i) for i in range(n)])
    return seq, frames, poses


def _box_on_kitti(kitti_clip, yaw_rad: float, layer_params=None, **cfg_fields):
    """A 1 m box beside the camera of frame 15, 2.5 m to its right, on the 1.65 m level prior, seed 0."""
    seq, frames, poses = kitti_clip
    cfg = VideoInsertionConfig(lookahead_frames=15, lateral_offset_m=2.5, height_m=1.0, **cfg_fields)
    return insert_into_clip(
        frames,
        seq.intrinsics,
        poses,
        np.random.default_rng(0),
        cfg,
        asset=box_asset(),
        ground_in_cam0=prior_ground_plane(1.65),
        yaw_rad=yaw_rad,
        layer_params=layer_params,
    )


def test_clip_contact_track_is_the_projection_and_size_is_smooth(kitti_clip):
    seq, frames, poses = kitti_clip
    K = seq.intrinsics
    res = _box_on_kitti(kitti_clip, 0.3)
    c_w = res.contact_in_world
    # Contact: under camera 15, 2.5 m to its right, 1.65 m below it (the camera-relative level prior).
    cam15 = np.linalg.inv(poses[15])
    assert abs(float((cam15[:3, 3] - c_w) @ (cam15[:3, :3] @ [0, -1.0, 0])) - 1.65) < 0.05
    for i in range(len(frames)):
        p = poses[i, :3, :3] @ c_w + poses[i, :3, 3]  # K [R | t] by hand
        uv = np.array([K.fx * p[0] / p[2] + K.cx, K.fy * p[1] / p[2] + K.cy])
        if p[2] > 0.1:
            assert np.allclose(res.contact_track_uv[i], uv, atol=1e-6)
        else:  # beside / behind the camera (the last frame: the object is next to it)
            assert np.all(np.isnan(res.contact_track_uv[i])) and not res.contact_visible[i]
    # One world pose: the object frame seen from every camera is the same world transform.
    assert res.world_from_object.shape == (4, 4)
    inside = [
        i
        for i, b in enumerate(res.amodal_boxes_xywh)
        if b is not None and b[0] > 0 and b[0] + b[2] < K.width - 1 and b[1] + b[3] < K.height - 1
    ]
    assert len(inside) >= 10 and inside[0] == 0
    heights = np.array([res.amodal_boxes_xywh[i][3] for i in inside], float)
    assert np.all(np.diff(heights) > 0)  # approaching: grows every frame
    # Geometric trend: an upright object of height H at depth z has ~ fy H / z pixels; the rendered height must
    # follow a smooth curve in the frame index (cubic fit), no jitter above 1 px.
    coeffs = np.polyfit(inside, heights, 3)
    jitter = heights - np.polyval(coeffs, inside)
    assert np.max(np.abs(jitter)) <= 1.0, jitter
    # The rendered object covers its own contact track (base centre) in every frame where it is in view.
    for i in inside:
        x, y, w, h = res.amodal_boxes_xywh[i]
        u, v = res.contact_track_uv[i]
        assert x - 1 <= u <= x + w + 1 and y + 0.5 * h <= v <= y + h + 1
    anns = res.coco_annotations("box")
    assert len(anns) >= len(inside) and not np.array_equal(res.frames[0], frames[0])


def test_bad_clip_inputs_raise():
    K = Intrinsics(100.0, 100.0, 31.5, 23.5, 64, 48)
    frames = [np.zeros((48, 64, 3), np.uint8)] * 2
    with pytest.raises(ValueError, match="one 4x4"):
        insert_into_clip(
            frames,
            K,
            np.stack([np.eye(4)] * 3),
            np.random.default_rng(0),
            asset=box_asset(),
            ground_in_cam0=prior_ground_plane(1.6),
        )
    with pytest.raises(ValueError, match="contact"):
        VideoInsertionConfig(contact="random")


def test_clip_shadow_is_fixed_in_the_world_and_points_away_from_the_sun(kitti_clip):
    """One world pose + one world sun: the cast shadow is the same ground patch in every frame, on the side of the
    object opposite the sun (derived by unprojecting the darkened pixels onto each frame's ground)."""
    from aias_augment.analyse.lighting.estimate import LightingEstimate
    from aias_augment.core.geometry import invert_rigid

    seq, frames, poses = kitti_clip
    n = 10
    frames, poses, K = frames[:n], poses[:n], seq.intrinsics
    up_w = np.linalg.inv(poses[0])[:3, :3] @ np.array([0.0, -1.0, 0.0])
    right_w = np.linalg.inv(poses[0])[:3, :3] @ np.array([1.0, 0.0, 0.0])
    elev = np.radians(40.0)
    sun_w = -np.cos(elev) * right_w + np.sin(elev) * up_w  # sun to the left: the shadow falls to the right
    sh = np.zeros((9, 3))
    sh[0] = 0.3
    lights = [
        LightingEstimate(poses[i, :3, :3] @ sun_w, np.full(3, 3.0), sh, 4.0, True, 1.0, "test", poses[i, :3, :3] @ up_w)
        for i in range(n)
    ]
    ground0 = prior_ground_plane(1.65)
    cfg = VideoInsertionConfig(lookahead_frames=n - 1, lateral_offset_m=2.5, height_m=1.0)
    run = lambda shadow: insert_into_clip(  # noqa: E731
        frames,
        K,
        poses,
        np.random.default_rng(0),
        VideoInsertionConfig(**{**cfg.__dict__, "shadow": shadow}),
        asset=box_asset(),
        ground_in_cam0=ground0,
        lighting=lights,
        yaw_rad=0.0,
    )
    with_shadow, without = run(True), run(False)
    assert with_shadow.modules["shadow"].startswith("shadow catcher")
    c_w = with_shadow.contact_in_world
    centroids = []
    for i in range(n):
        dark = (without.frames[i].astype(int) - with_shadow.frames[i].astype(int)).max(axis=2) > 3
        if dark.sum() < 20 or dark[:, [0, -1]].any() or dark[[0, -1], :].any():
            continue  # too small, or cut by the image border (its visible centroid is then not the patch's)
        vv, uu = np.nonzero(dark)
        # Ground of frame i: the world ground (the prior plane under the lookahead camera, where the object stands)
        # seen from camera i.
        world_ground = ground0.transformed(invert_rigid(poses[n - 1]))
        g_i = world_ground.transformed(poses[i])
        pts = g_i.intersect_pixels(np.stack([uu, vv], -1).astype(float), K)
        ok = np.all(np.isfinite(pts), axis=1)
        centroids.append(transform_world(invert_rigid(poses[i]), pts[ok]).mean(axis=0))
    assert len(centroids) >= 4
    centroids = np.array(centroids)
    spread = np.linalg.norm(centroids - np.median(centroids, axis=0), axis=1)
    assert spread.max() < 0.3, spread  # the same world patch from every viewpoint
    offset = np.median(centroids, axis=0) - c_w
    offset -= (offset @ up_w) * up_w
    sun_h = sun_w - (sun_w @ up_w) * up_w
    cosang = float(offset @ -sun_h / (np.linalg.norm(offset) * np.linalg.norm(sun_h)))
    assert cosang > np.cos(np.radians(20)), np.degrees(np.arccos(np.clip(cosang, -1, 1)))
    assert 0.2 < np.linalg.norm(offset) < 2.0  # a 1 m box under a 40 deg sun: shadow ~1.2 m long


def transform_world(T, pts):
    return pts @ T[:3, :3].T + T[:3, 3]


def test_flow_refine_keeps_the_object_on_its_ground_point_under_pose_drift():
    """Drifting poses make a world-fixed object skate; with flow_refine its contact stays on the true ground point
    (synthetic drive over a textured plane: the true projection is analytic)."""
    from tests.aias_augment.fixtures import synthetic_ground_drive
    from tests.aias_augment.plan.test_stabilize import drifted

    K, frames, gt = synthetic_ground_drive(10, 1.5)
    poses = drifted(gt)
    cfg = VideoInsertionConfig(lookahead_frames=9, lateral_offset_m=1.5, height_m=0.8, shadow=False)
    runs = {
        f: insert_into_clip(
            frames,
            K,
            poses,
            np.random.default_rng(0),
            VideoInsertionConfig(**{**cfg.__dict__, "flow_refine": f}),
            asset=box_asset(),
            ground_in_cam0=prior_ground_plane(1.5),
            yaw_rad=0.0,
        )
        for f in (False, True)
    }
    c_w = runs[True].contact_in_world
    assert np.allclose(c_w, runs[False].contact_in_world)
    true_uv = np.stack([(K.K @ (T[:3, :3] @ c_w + T[:3, 3]))[:2] / (T[:3, :3] @ c_w + T[:3, 3])[2] for T in gt])
    front = np.all(np.isfinite(runs[False].contact_track_uv), axis=1)
    front[0] = False  # the anchor frame: no drift yet
    err = {f: np.linalg.norm(r.contact_track_uv - true_uv, axis=1)[front] for f, r in runs.items()}
    assert front.sum() >= 6 and np.median(err[False]) > 10 and np.median(err[True]) < 1.0, err
    assert runs[True].modules["stabilize"].startswith("KLT")
    # The rendered object sits on the corrected contact: its base centre is within a pixel or two of the truth.
    for i, b in enumerate(runs[True].amodal_boxes_xywh):
        if b is not None and b[1] + b[3] < K.height - 1:
            x, y, w, h = b
            assert x - 1 <= true_uv[i, 0] <= x + w + 1


def _weighted_cov(mask: np.ndarray) -> np.ndarray:
    ys, xs = np.nonzero(mask > 0)
    w = mask[ys, xs].astype(np.float64)
    pts = np.c_[xs, ys].astype(np.float64)
    mu = (w[:, None] * pts).sum(0) / w.sum()
    d = pts - mu
    return (w[:, None, None] * d[:, :, None] * d[:, None, :]).sum(0) / w.sum()


def test_clip_motion_blur_streaks_each_frame_along_the_objects_motion(kitti_clip):
    """Convolving a coverage with a normalised line adds the line's variance (L^2 / 12) along the line and keeps the
    coverage's mass: measured per frame on the visible mask, with the direction from the analytic contact track."""
    seq, frames, poses = kitti_clip
    length = 12.0
    plain = _box_on_kitti(kitti_clip, 0.3)
    blurred = _box_on_kitti(kitti_clip, 0.3, {"motion_blur_px": {"length_px": length, "angle_deg": 0.0}})
    assert "motion_blur_px" in blurred.modules["layers"] and "layers" not in plain.modules
    checked = 0
    for i in range(1, 12):
        b = plain.amodal_boxes_xywh[i]
        K = seq.intrinsics
        if b is None or min(b[0], b[1], K.width - b[0] - b[2], K.height - b[1] - b[3]) < 20:  # streak in frame
            continue
        motion = plain.contact_track_uv[i + 1] - plain.contact_track_uv[i - 1]
        if not np.all(np.isfinite(motion)):
            continue
        u = motion / np.linalg.norm(motion)
        m0, m1 = plain.masks[i], blurred.masks[i]
        assert abs(m1.sum() - m0.sum()) < 0.01 * m0.sum()
        extra = _weighted_cov(m1) - _weighted_cov(m0)
        along, across = u @ extra @ u, np.array([-u[1], u[0]]) @ extra @ np.array([-u[1], u[0]])
        assert abs(along - length**2 / 12) < 0.15 * length**2 / 12 and abs(across) < 1.0, (i, along, across)
        checked += 1
    assert checked >= 5


def test_a_moving_object_follows_its_heading_at_its_speed_and_stands_on_its_projected_contact(kitti_clip):
    """Truth by hand: the contact moves 0.25 m per frame along the object's own x axis (its heading) in the world;
    each frame's contact pixel is K [R | t] of that point, and the rendered object stands on it."""
    seq, frames, poses = kitti_clip
    K = seq.intrinsics
    res = _box_on_kitti(kitti_clip, 1.2, speed_m_per_frame=0.25)
    track = res.contact_track_in_world
    step = np.diff(track, axis=0)
    heading = res.world_from_object[:3, 0]
    assert np.allclose(step, 0.25 * heading[None, :], atol=1e-9) and abs(np.linalg.norm(heading) - 1) < 1e-9
    assert np.allclose(track[0], res.contact_in_world)
    drawn = 0
    for i in range(len(frames)):
        p = poses[i, :3, :3] @ track[i] + poses[i, :3, 3]
        if p[2] <= 0.1:
            continue
        uv = np.array([K.fx * p[0] / p[2] + K.cx, K.fy * p[1] / p[2] + K.cy])
        assert np.allclose(res.contact_track_uv[i], uv, atol=1e-6)
        b = res.amodal_boxes_xywh[i]
        if b is not None and b[0] > 0 and b[0] + b[2] < K.width - 1 and b[1] + b[3] < K.height - 1:
            x, y, w, h = b
            assert x - 1 <= uv[0] <= x + w + 1 and y + 0.5 * h <= uv[1] <= y + h + 1
            drawn += 1
    assert drawn >= 8 and "moving 0.250 m per frame" in res.modules["motion"]
    with pytest.raises(ValueError, match="flow_refine"):
        VideoInsertionConfig(speed_m_per_frame=0.1, flow_refine=True)


def _forward_drive(n: int = 3, step_m: float = 1.0):
    """A camera 1.65 m above level ground driving straight ahead ``step_m`` per frame over a textured grey frame."""
    K = Intrinsics(500.0, 500.0, 320.0, 240.0, 640, 480)
    frame = np.random.default_rng(3).integers(100, 140, (480, 640, 3), dtype=np.uint8)
    poses = []
    for i in range(n):
        world_from_cam = np.eye(4)
        world_from_cam[2, 3] = i * step_m
        poses.append(np.linalg.inv(world_from_cam))
    return K, [frame.copy() for _ in range(n)], np.stack(poses)


def test_several_objects_occlude_each_other_far_to_near():
    """Two 1 m boxes 0.3 m right of the camera's path, 4 m and 8 m ahead of frame 0: by the pinhole projection the
    near one's image (x 19-81 px right of centre down to 206 px below) covers the far one's lower part. The near
    object keeps its own box; the far one loses what the near one covers, and no pixel is counted for both."""
    from aias_augment.pipeline.clip import apply_clip, apply_clip_objects, plan_clip

    K, frames, poses = _forward_drive(step_m=4.0)
    ground = prior_ground_plane(1.65)

    def plan(lookahead):
        cfg = VideoInsertionConfig(lookahead_frames=lookahead, lateral_offset_m=0.3, height_m=1.0, shadow=False)
        return plan_clip(
            frames, K, poses, np.random.default_rng(0), cfg, asset=box_asset(), ground_in_cam0=ground, yaw_rad=0.0
        )

    near, far = plan(1), plan(2)  # beside where the camera is at frames 1 and 2: 4 m and 8 m ahead of frame 0
    cfg = VideoInsertionConfig(shadow=False)
    alone_near, alone_far = apply_clip(frames, K, near, cfg), apply_clip(frames, K, far, cfg)
    both_far, both_near = apply_clip_objects(frames, K, [far, near], cfg)
    assert both_near.frames is both_far.frames
    m_near, m_far = alone_near.masks[0] > 0.5, alone_far.masks[0] > 0.5
    assert (m_near & m_far).sum() > 50  # the two projections overlap in frame 0
    assert both_near.boxes_xywh[0] == pytest.approx(alone_near.boxes_xywh[0])
    hidden = m_far.sum() - (both_far.masks[0] > 0.5).sum()
    assert hidden == pytest.approx((m_near & m_far).sum(), abs=5)  # it loses exactly what the near one covers
    assert ((both_far.masks[0] > 0.5) & m_near).sum() == 0
    assert np.all(both_near.masks[0] + both_far.masks[0] <= 1.0 + 1e-5)
    # where the near object covers, the frame shows it as it shows alone
    inside = np.asarray(both_near.masks[0]) > 0.999
    assert np.array_equal(both_near.frames[0][inside], alone_near.frames[0][inside])


def test_first_collision_is_the_frame_where_a_moving_object_meets_a_standing_one():
    """Truth by hand on a straight drive (1 m per frame, world = camera 0, forward = +z): a 1 m cube stands 10 m
    ahead; another leaves 2 m ahead at 1 m per frame along the path (yaw pi/2 points its heading forward). Their
    centres are 8 - i metres apart in frame i, so boxes inflated by ``m`` meet first when 8 - i <= 1 + 2 m: frame 7
    for m = 0.1, frame 6 for m = 0.6. Side by side at the same spot, 1.1 m apart: they meet only with a margin."""
    from aias_augment.pipeline.clip import first_collision, object_boxes_in_world, plan_clip

    K, frames, poses = _forward_drive(n=12, step_m=1.0)
    ground, cube = prior_ground_plane(1.65), box_asset(extents=(1.0, 1.0, 1.0))

    def plan(lookahead, lateral=0.0, speed=0.0):
        cfg = VideoInsertionConfig(
            lookahead_frames=lookahead, lateral_offset_m=lateral, height_m=1.0, shadow=False, speed_m_per_frame=speed
        )
        return plan_clip(
            frames, K, poses, np.random.default_rng(0), cfg, asset=cube, ground_in_cam0=ground, yaw_rad=np.pi / 2
        )

    standing, moving = plan(10), plan(2, speed=1.0)
    centres = np.array([b.cam_from_box[:3, 3] for b in object_boxes_in_world(moving)])
    assert np.allclose(centres[:, 2], 2.0 + np.arange(12), atol=1e-9)  # forward 1 m per frame
    assert np.allclose(centres[:, 1], 1.65 - 0.5, atol=1e-9)  # the cube's centre 0.5 m above the ground (y down)
    assert first_collision(moving, standing, margin_m=0.1) == 7
    assert first_collision(standing, moving, margin_m=0.6) == 6
    assert first_collision(plan(2), standing, margin_m=0.1) is None
    left, right = plan(5, lateral=-0.55), plan(5, lateral=0.55)
    assert first_collision(left, right, margin_m=0.0) is None
    assert first_collision(left, right, margin_m=0.1) == 0


def test_a_toppling_cube_turns_about_its_base_edge_and_lands_on_a_face():
    """Truth by hand for a 1 m cube knocked over (fall over frames 2-6, direction drawn in the plan): it turns about
    the base edge on its falling side, so its centre, (-0.5, 0.5) from that edge (along the fall, up), is at
    (-0.5 cos t + 0.5 sin t, 0.5 cos t + 0.5 sin t) after turning by t; t = 90 deg (t / T)^2 of the 90 deg at which
    it lies on a face. Nothing goes below the ground, and the landed cube's rendered box is the pinhole projection
    of the upright cube's corners moved 1 m along the fall."""
    from aias_augment.pipeline.clip import apply_clip, object_boxes_in_world, plan_clip

    K = Intrinsics(500.0, 500.0, 320.0, 240.0, 640, 480)
    frame = np.random.default_rng(3).integers(100, 140, (480, 640, 3), dtype=np.uint8)
    poses = np.stack([np.eye(4)] * 10)
    poses[9, 2, 3] = -6.0  # the last camera 6 m ahead: the cube stands there (lookahead 9), seen by frames 0-8
    frames = [frame.copy() for _ in range(10)]
    cfg = VideoInsertionConfig(
        lookahead_frames=9, lateral_offset_m=0.0, height_m=1.0, shadow=False, topple_frames=4, topple_start=2
    )
    cube = box_asset(extents=(1.0, 1.0, 1.0))
    plan = plan_clip(
        frames,
        K,
        poses,
        np.random.default_rng(5),
        cfg,
        asset=cube,
        ground_in_cam0=prior_ground_plane(1.65),
        yaw_rad=0.3,
    )
    up = np.array([0.0, -1.0, 0.0])
    azimuth = plan.asset_at(8).meta["tipped"]["azimuth"]
    f = plan.world_from_object[:3, :3] @ np.array([np.cos(azimuth), np.sin(azimuth), 0.0])
    upright = plan.world_from_object[:3, 3] + 0.5 * up
    for i in range(9):
        W = plan.worlds_from_object[i]
        v = np.asarray(plan.asset_at(i).meshes[0].vertices) @ W[:3, :3].T + W[:3, 3]
        height = (v - plan.world_from_object[:3, 3]) @ up
        assert height.min() == pytest.approx(0.0, abs=1e-9)  # on the ground, never in it
        t = np.pi / 2 * np.clip((i - 2) / 4, 0, 1) ** 2
        centre = v.mean(0)  # the cube's 8 vertices
        moved = centre - upright
        u = -0.5 * np.cos(t) + 0.5 * np.sin(t) + 0.5  # along the fall, from the upright centre
        assert moved @ f == pytest.approx(u, abs=1e-9)
        assert (centre - plan.world_from_object[:3, 3]) @ up == pytest.approx(
            0.5 * np.cos(t) + 0.5 * np.sin(t), abs=1e-9
        )
    boxes = object_boxes_in_world(plan)
    assert np.allclose(boxes[8].cam_from_box[:3, 3], upright + f, atol=1e-9)
    res = apply_clip(frames, K, plan, VideoInsertionConfig(shadow=False))
    corners = np.array([[x, y, z] for x in (-0.5, 0.5) for y in (-0.5, 0.5) for z in (0.0, 1.0)])
    W = plan.world_from_object
    p = corners @ W[:3, :3].T + W[:3, 3] + f  # the upright cube moved 1 m along the fall (poses[8] is the identity)
    uv = np.c_[K.fx * p[:, 0] / p[:, 2] + K.cx, K.fy * p[:, 1] / p[:, 2] + K.cy]
    x0, y0 = uv.min(0)
    x1, y1 = uv.max(0)
    assert res.amodal_boxes_xywh[8] == pytest.approx((x0, y0, x1 - x0, y1 - y0), abs=1.0)
    assert res.amodal_boxes_xywh[1] != pytest.approx(res.amodal_boxes_xywh[8], abs=5.0)
    assert "knocked over" in res.modules["motion"]
    with pytest.raises(ValueError, match="toppling"):
        VideoInsertionConfig(topple_frames=3, speed_m_per_frame=0.1)


def test_a_parked_object_pulls_out_standing_then_speeding_up_at_a_constant_acceleration():
    """Truth by hand: 0.4 m per frame, standing 3 frames after the start, reaching that speed over 4 frames: from
    frame k = i - 3 > 0 it has gone 0.4 k^2 / 8 (k <= 4), then 0.8 + 0.4 (k - 4) metres along its heading, and its
    contact is that far from the parked one in the world."""
    from aias_augment.pipeline.clip import plan_clip, travel_m

    K, frames, poses = _forward_drive(n=12, step_m=0.0)
    cfg = VideoInsertionConfig(
        lookahead_frames=0,
        lateral_offset_m=4.0,
        height_m=1.0,
        shadow=False,
        speed_m_per_frame=0.4,
        move_after_frames=3,
        accelerate_frames=4,
    )
    k = np.clip(np.arange(12) - 3, 0, None).astype(float)
    truth = np.where(k <= 4, 0.4 * k**2 / 8, 0.8 + 0.4 * (k - 4))
    assert np.allclose(travel_m(12, 0, cfg), truth, atol=1e-12)
    plan = plan_clip(
        frames, K, poses, np.random.default_rng(0), cfg, asset=box_asset(), ground_in_cam0=prior_ground_plane(1.65)
    )
    moved = np.linalg.norm(plan.contact_track_in_world - plan.contact_track_in_world[0], axis=1)
    assert np.allclose(moved, truth, atol=1e-9)
    assert "standing 3 frames" in plan.modules["motion"]
    with pytest.raises(ValueError, match="move_after_frames"):
        VideoInsertionConfig(speed_m_per_frame=0.1, move_after_frames=-1)

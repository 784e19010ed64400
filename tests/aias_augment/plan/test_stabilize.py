"""Optical-flow stabilisation: with deliberately drifted poses, the tracked contact follows the true projection of
the world point (known exactly on a synthetic drive over a textured ground), which the drifted poses miss."""

import numpy as np
import pytest

from aias_augment.analyse.ground import prior_ground_plane
from aias_augment.core.geometry import Intrinsics, make_rigid, project_points, rotation_about_axis
from aias_augment.plan.stabilize import FlowRefineConfig, refined_cam_from_object, track_contact_with_flow
from tests.aias_augment.fixtures import synthetic_ground_drive

N = 12
HEIGHT_M = 1.5
K_SYN = Intrinsics(500.0, 500.0, 320.0, 200.0, 640, 360)


def _project(T_cam_from_world, p_w, K):
    p = T_cam_from_world[:3, :3] @ p_w + T_cam_from_world[:3, 3]
    return np.array([K.fx * p[0] / p[2] + K.cx, K.fy * p[1] / p[2] + K.cy])


@pytest.fixture(scope="module")
def clip():
    return synthetic_ground_drive(N, HEIGHT_M, K_SYN)


def drifted(gt: np.ndarray) -> np.ndarray:  # also used by test_video
    """Odometry-like drift growing with the frame index: 0.3 deg yaw and 5 cm sideways per frame."""
    return np.stack(
        [
            make_rigid(rotation_about_axis([0, 1, 0], np.radians(0.3 * i)), [0.05 * i, 0, 0]) @ T
            for i, T in enumerate(gt)
        ]
    )


def test_flow_track_follows_the_true_projection_under_pose_drift(clip):
    K, frames, gt = clip
    c_w = np.array([1.5, HEIGHT_M, 16.0])  # on the ground, ahead right
    true_uv = np.stack([_project(T, c_w, K) for T in gt])
    poses = drifted(gt)
    pred_uv = np.stack([_project(T, c_w, K) for T in poses])
    track = track_contact_with_flow(
        frames, pred_uv, [prior_ground_plane(HEIGHT_M)] * N, K, np.random.default_rng(0), poses
    )
    err_pose = np.linalg.norm(pred_uv - true_uv, axis=1)[1:]
    err_flow = np.linalg.norm(track.uv - true_uv, axis=1)[1:]
    assert all(st == "flow" for st in track.status[1:]), track.status
    assert np.median(err_pose) > 10  # the drift is visible ...
    assert np.median(err_flow) < 0.5 and err_flow.max() < 1.0, err_flow  # ... and the flow track removes it
    assert track.status[0] == "anchor" and np.array_equal(track.uv[0], pred_uv[0])


def test_flow_track_with_exact_poses_stays_on_the_prediction(clip):
    K, frames, gt = clip
    c_w = np.array([-2.0, HEIGHT_M, 20.0])
    pred_uv = np.stack([_project(T, c_w, K) for T in gt])
    track = track_contact_with_flow(
        frames, pred_uv, [prior_ground_plane(HEIGHT_M)] * N, K, np.random.default_rng(1), gt, start=5
    )  # anchored mid-clip: both directions
    assert track.status[5] == "anchor" and sum(st == "flow" for st in track.status) == N - 1, track.status
    assert np.median(np.linalg.norm(track.uv - pred_uv, axis=1)) < 1.0


def test_refined_pose_puts_the_contact_on_the_target_pixel():
    K = Intrinsics(500.0, 500.0, 320.0, 240.0, 640, 480)
    ground = prior_ground_plane(1.5, pitch_rad=np.radians(5))
    contact = ground.intersect_pixels(np.array([[300.0, 400.0]]), K)[0]
    cam_from_object = make_rigid(rotation_about_axis([0, 1, 0], 0.4), contact)
    target = np.array([350.0, 380.0])
    T = refined_cam_from_object(cam_from_object, contact, target, ground, K)
    new_contact = T[:3, 3]  # the object origin is its contact point here
    uv, _ = project_points(new_contact[None], K.K)
    assert np.allclose(uv[0], target, atol=1e-6)
    assert abs(ground.signed_distance(new_contact)) < 1e-9  # still on the ground
    assert np.allclose(T[:3, :3], cam_from_object[:3, :3])  # orientation kept
    sky = refined_cam_from_object(cam_from_object, contact, np.array([320.0, 10.0]), ground, K)
    assert np.array_equal(sky, cam_from_object)  # a pixel above the horizon: no change


def test_bad_inputs_raise(clip):
    K, frames, gt = clip
    with pytest.raises(ValueError, match="one predicted pixel"):
        track_contact_with_flow(
            frames, np.zeros((N - 1, 2)), [prior_ground_plane()] * N, K, np.random.default_rng(0), gt
        )
    with pytest.raises(ValueError, match="anchor"):
        track_contact_with_flow(
            frames, np.full((N, 2), np.nan), [prior_ground_plane()] * N, K, np.random.default_rng(0), gt
        )
    with pytest.raises(ValueError):
        FlowRefineConfig(min_inliers=2)

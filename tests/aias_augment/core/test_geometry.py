import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from aias_augment.core.geometry import (
    OPENGL_FROM_OPENCV,
    Intrinsics,
    check_rigid,
    invert_rigid,
    make_rigid,
    opengl_from_opencv,
    project_points,
    rotation_about_axis,
    transform_points,
    unproject_points,
)

K = Intrinsics(500.0, 480.0, 320.0, 240.0, 640, 480)


def test_project_known_point():
    # x = fx * X / Z + cx, computed by hand.
    uv, z = project_points(np.array([1.0, -0.5, 4.0]), K.K)
    assert np.allclose(uv, [500 * 0.25 + 320, 480 * -0.125 + 240])
    assert z == 4.0


@settings(max_examples=50, deadline=None)
@given(st.floats(-1e3, 1e3), st.floats(-1e3, 1e3), st.floats(1e-3, 1e5))
def test_project_unproject_round_trip(x, y, z):
    p = np.array([x, y, z])
    uv, d = project_points(p, K.K)
    assert np.allclose(unproject_points(uv, d, K.K), p, rtol=1e-9, atol=1e-6 * max(1.0, abs(z)))


def test_points_behind_camera_are_nan():
    uv, _ = project_points(np.array([[0, 0, -1.0], [0, 0, 0.0], [0, 0, 1.0]]), K.K)
    assert np.isnan(uv[:2]).all() and np.isfinite(uv[2]).all()


def test_batch_shapes():
    p = np.random.default_rng(0).normal(size=(2, 5, 3)) + [0, 0, 10]
    uv, z = project_points(p, K.K)
    assert uv.shape == (2, 5, 2) and z.shape == (2, 5)


def test_rigid_inverse_and_chain():
    T = make_rigid(rotation_about_axis([1, 2, 3], 0.7), [1, -2, 3])
    assert np.allclose(invert_rigid(T) @ T, np.eye(4))
    p = np.array([0.3, 0.2, -1.0])
    assert np.allclose(transform_points(invert_rigid(T), transform_points(T, p)), p)


def test_opengl_conversion_flips_y_and_z_only():
    # A point 2 m in front of an OpenCV camera, 1 m below the axis, is at z=-2, y=-1 in OpenGL.
    p_gl = transform_points(opengl_from_opencv(np.eye(4)), np.array([0.5, 1.0, 2.0]))
    assert np.allclose(p_gl, [0.5, -1.0, -2.0])
    assert np.allclose(OPENGL_FROM_OPENCV @ OPENGL_FROM_OPENCV, np.eye(4))


@pytest.mark.parametrize("bad", [np.full((4, 4), np.nan), np.diag([1, 1, -1, 1.0]), np.ones((3, 4))])
def test_check_rigid_rejects(bad):
    with pytest.raises(ValueError):
        check_rigid(bad)


def test_intrinsics_validation_and_scaling():
    with pytest.raises(ValueError):
        Intrinsics(float("nan"), 1, 0, 0, 10, 10)
    with pytest.raises(ValueError):
        Intrinsics(-1, 1, 0, 0, 10, 10)
    s = K.scaled(0.5)
    # Pixel-centre aligned resize: the image centre stays the image centre.
    assert np.isclose(s.cx, (K.cx + 0.5) * 0.5 - 0.5) and s.width == 320


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_norm3_is_numpys_norm_bit_for_bit(dtype):
    """The norm over a last axis of length 3 from the planes equals np.linalg.norm's, bit for bit, from tiny to huge
    vectors, with and without the kept axis."""
    from aias_augment.core.geometry import norm3

    rng = np.random.default_rng(3)
    x = (rng.normal(0.0, 1.0, (50, 70, 3)) * 10.0 ** rng.uniform(-20, 20, (50, 70, 1))).astype(dtype)
    np.testing.assert_array_equal(norm3(x), np.linalg.norm(x, axis=-1))
    np.testing.assert_array_equal(
        norm3(x.reshape(-1, 3), keepdims=True), np.linalg.norm(x.reshape(-1, 3), axis=1, keepdims=True)
    )
    assert norm3(x).dtype == dtype

"""Camera geometry in the OpenCV convention.

Conventions (written once, used everywhere):
- Camera frame: OpenCV, x right, y down, z forward (metres). Pixel (u, v): u right, v down, the centre of the
  top-left pixel is (0, 0).
- Rigid transforms are 4x4 float64 matrices named ``a_from_b``: ``points_in_a = a_from_b @ points_in_b``, so chains
  read right to left: ``cam_from_object = cam_from_world @ world_from_object``.
- World frame of a scene is whatever the data source uses; the project's canonical object frame is z-up metres
  with the object resting on z = 0 (see ``assets``).
- OpenGL/pyrender camera (x right, y up, z backward) is reached only through :func:`opengl_from_opencv`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = [
    "Intrinsics",
    "check_shape",
    "check_finite",
    "check_rigid",
    "invert_rigid",
    "transform_points",
    "project_points",
    "unproject_points",
    "OPENGL_FROM_OPENCV",
    "opengl_from_opencv",
    "make_rigid",
    "rotation_about_axis",
]

#: Smallest positive depth (metres) treated as "in front of the camera" in projections.
MIN_DEPTH = 1e-6

#: The one prior for the camera's height above the ground when nothing measures it (no depth, no poses): a
#: car-mounted camera (KITTI's is 1.65 m above the road). Every stage that needs the prior uses this value.
CAMERA_HEIGHT_PRIOR_M = 1.65


def check_shape(x: np.ndarray, shape: tuple, name: str = "array") -> np.ndarray:
    """Raise ``ValueError`` unless ``x`` matches ``shape`` ("*" = any leading dims, None = any size)."""
    x = np.asarray(x)
    dims = list(shape)
    if dims and dims[0] == "*":
        tail = dims[1:]
        if x.ndim < len(tail):
            raise ValueError(f"{name}: expected shape (*, {', '.join(map(str, tail))}), got {x.shape}")
        got = x.shape[x.ndim - len(tail) :]
    else:
        tail = dims
        if x.ndim != len(tail):
            raise ValueError(f"{name}: expected shape {tuple(shape)}, got {x.shape}")
        got = x.shape
    for g, w in zip(got, tail):
        if w is not None and g != w:
            raise ValueError(f"{name}: expected shape {tuple(shape)}, got {x.shape}")
    return x


def check_finite(x: np.ndarray, name: str = "array") -> np.ndarray:
    x = np.asarray(x)
    if not np.all(np.isfinite(x)):
        raise ValueError(f"{name}: contains NaN or Inf")
    return x


_EYE3 = np.eye(3)


def check_rigid(T: np.ndarray, name: str = "pose", atol: float = 1e-4) -> np.ndarray:
    """Validate a 4x4 rigid transform: finite, last row (0,0,0,1), orthonormal rotation with det +1 (closeness as
    ``np.allclose(..., atol=atol)``: ``|a - b| <= atol + 1e-5 |b|``)."""
    T = np.asarray(T, dtype=np.float64)
    if T.shape != (4, 4):
        check_shape(T, (4, 4), name)
    if not np.isfinite(T).all():
        raise ValueError(f"{name}: contains NaN or Inf")
    r0, r1, r2, last = T.tolist()
    if abs(last[0]) > atol or abs(last[1]) > atol or abs(last[2]) > atol or abs(last[3] - 1.0) > atol + 1e-5:
        raise ValueError(f"{name}: last row must be (0, 0, 0, 1), got {T[3]}")
    R = T[:3, :3]
    det = (
        r0[0] * (r1[1] * r2[2] - r1[2] * r2[1])
        - r0[1] * (r1[0] * r2[2] - r1[2] * r2[0])
        + r0[2] * (r1[0] * r2[1] - r1[1] * r2[0])
    )
    if (np.abs(R @ R.T - _EYE3) > atol + 1e-5 * _EYE3).any() or det < 0:
        raise ValueError(f"{name}: rotation part is not a proper rotation")
    return T


def norm3(x: np.ndarray, keepdims: bool = False) -> np.ndarray:
    """The Euclidean norm over a last axis of length 3: ``np.linalg.norm(x, axis=-1)``, the same numbers (squares
    summed in numpy's order, then the root) from the three planes, several times faster (a reduction over a short
    last axis loops per element)."""
    x0, x1, x2 = x[..., 0], x[..., 1], x[..., 2]
    out = np.sqrt((x0 * x0 + x1 * x1) + x2 * x2)
    return out[..., None] if keepdims else out


def make_rigid(R: np.ndarray, t: np.ndarray) -> np.ndarray:
    T = np.eye(4)
    T[:3, :3] = R
    T[:3, 3] = np.asarray(t, dtype=np.float64).reshape(3)
    return T


def invert_rigid(a_from_b: np.ndarray) -> np.ndarray:
    """Inverse of a rigid transform, exact (R^T, -R^T t), (4, 4) -> (4, 4)."""
    R = a_from_b[:3, :3]
    t = a_from_b[:3, 3]
    return make_rigid(R.T, -R.T @ t)


def transform_points(a_from_b: np.ndarray, points_in_b: np.ndarray) -> np.ndarray:
    """Apply a 4x4 rigid/affine transform to points, (*, 3) -> (*, 3)."""
    p = check_shape(points_in_b, ("*", 3), "points")
    return p @ a_from_b[:3, :3].T + a_from_b[:3, 3]


def rotation_about_axis(axis: np.ndarray, angle_rad: float) -> np.ndarray:
    """Rodrigues rotation matrix (3, 3) about a (not necessarily unit) axis."""
    axis = np.asarray(axis, dtype=np.float64)
    n = np.linalg.norm(axis)
    if n < 1e-12:
        raise ValueError("rotation axis has zero length")
    k = axis / n
    Kx = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + np.sin(angle_rad) * Kx + (1 - np.cos(angle_rad)) * Kx @ Kx


@dataclass(frozen=True)
class Intrinsics:
    """Pinhole intrinsics in pixels (OpenCV convention) with the image size they belong to."""

    fx: float
    fy: float
    cx: float
    cy: float
    width: int
    height: int

    def __post_init__(self):
        vals = np.array([self.fx, self.fy, self.cx, self.cy], dtype=np.float64)
        if not np.all(np.isfinite(vals)):
            raise ValueError(f"Intrinsics: non-finite value in {vals}")
        if self.fx <= 0 or self.fy <= 0:
            raise ValueError(f"Intrinsics: focal lengths must be positive, got fx={self.fx}, fy={self.fy}")
        if self.width <= 0 or self.height <= 0:
            raise ValueError(f"Intrinsics: image size must be positive, got {self.width}x{self.height}")

    @property
    def K(self) -> np.ndarray:
        return np.array([[self.fx, 0, self.cx], [0, self.fy, self.cy], [0, 0, 1]], dtype=np.float64)

    @classmethod
    def from_matrix(cls, K: np.ndarray, width: int, height: int) -> "Intrinsics":
        K = check_finite(check_shape(np.asarray(K, dtype=np.float64), (3, 3), "K"), "K")
        if abs(K[0, 1]) > 1e-9 or abs(K[2, 2] - 1) > 1e-9 or np.any(np.abs(K[2, :2]) > 1e-9):
            raise ValueError(f"K must be [[fx,0,cx],[0,fy,cy],[0,0,1]] (no skew), got {K.tolist()}")
        return cls(float(K[0, 0]), float(K[1, 1]), float(K[0, 2]), float(K[1, 2]), int(width), int(height))

    @classmethod
    def from_fov(cls, width: int, height: int, hfov_deg: float) -> "Intrinsics":
        f = 0.5 * width / np.tan(np.deg2rad(hfov_deg) / 2)
        return cls(f, f, (width - 1) / 2, (height - 1) / 2, width, height)

    def scaled(self, sx: float, sy: float | None = None) -> "Intrinsics":
        """Intrinsics after resizing the image by (sx, sy) with pixel-centre alignment."""
        sy = sx if sy is None else sy
        return Intrinsics(
            self.fx * sx,
            self.fy * sy,
            (self.cx + 0.5) * sx - 0.5,
            (self.cy + 0.5) * sy - 0.5,
            int(round(self.width * sx)),
            int(round(self.height * sy)),
        )


def project_points(points_in_cam: np.ndarray, K: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Pinhole projection, (*, 3) -> pixels (*, 2) and depth (*,).

    Points with z <= MIN_DEPTH (on or behind the camera plane) get NaN pixels: callers must treat them as not visible.
    """
    p = check_shape(points_in_cam, ("*", 3), "points_in_cam").astype(np.float64)
    z = p[..., 2]
    in_front = z > MIN_DEPTH
    zs = np.where(in_front, z, 1.0)
    u = K[0, 0] * p[..., 0] / zs + K[0, 1] * p[..., 1] / zs + K[0, 2]
    v = K[1, 1] * p[..., 1] / zs + K[1, 2]
    uv = np.stack([u, v], axis=-1)
    uv[~in_front] = np.nan
    return uv, z


def unproject_points(uv: np.ndarray, depth: np.ndarray, K: np.ndarray) -> np.ndarray:
    """Inverse of :func:`project_points` for z-depth: pixels (*, 2) and depth (*,) -> points (*, 3)."""
    uv = check_shape(uv, ("*", 2), "uv").astype(np.float64)
    depth = np.asarray(depth, dtype=np.float64)
    y = (uv[..., 1] - K[1, 2]) / K[1, 1]
    x = (uv[..., 0] - K[0, 2] - K[0, 1] * y) / K[0, 0]
    return np.stack([x * depth, y * depth, depth], axis=-1)


#: The one OpenCV <-> OpenGL camera-axis change: flip y and z. It is its own inverse.
OPENGL_FROM_OPENCV = np.diag([1.0, -1.0, -1.0, 1.0])


def opengl_from_opencv(cv_from_x: np.ndarray) -> np.ndarray:
    """Re-express a transform whose target frame is an OpenCV camera in the OpenGL camera frame.

    ``glcam_from_world = opengl_from_opencv(cam_from_world)``; pyrender wants the camera node pose
    ``world_from_glcam = invert_rigid(glcam_from_world)``.
    """
    return OPENGL_FROM_OPENCV @ cv_from_x

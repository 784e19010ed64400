"""Order-2 (9-coefficient) real spherical harmonics for diffuse irradiance (Ramamoorthi and Hanrahan 2001).

Coefficients are the projection of the incident *radiance* L(w): ``c_lm = sum_w L(w) Y_lm(w) dOmega`` (shape (9, 3) for
RGB), in whatever frame the directions were given (env, world or camera; :func:`rotate_sh` changes frames).
Irradiance on a surface with unit normal n is ``E(n) = sum_lm A_l c_lm Y_lm(n)`` with A = (pi, 2 pi / 3, pi / 4), and
a white Lambertian surface reflects radiance ``E(n) / pi``. Basis order: (0,0), (1,-1), (1,0), (1,1), (2,-2), (2,-1),
(2,0), (2,1), (2,2), i.e. 1, y, z, x, xy, yz, 3z^2 - 1, xz, x^2 - y^2.
"""

from __future__ import annotations

import numpy as np

from aias_augment.analyse.lighting.envmap import pixel_directions, pixel_solid_angles
from aias_augment.core.geometry import check_shape

__all__ = [
    "SH_BAND_OF_COEFF",
    "sh_basis",
    "project_radiance_to_sh",
    "project_envmap_to_sh",
    "sh_irradiance",
    "brute_force_irradiance",
    "rotate_sh",
    "fibonacci_sphere",
]

SH_BAND_OF_COEFF = np.array([0, 1, 1, 1, 2, 2, 2, 2, 2])
#: Convolution of the clamped cosine with each band: A_0 = pi, A_1 = 2 pi / 3, A_2 = pi / 4.
_A_BAND = np.array([np.pi, 2.0 * np.pi / 3.0, np.pi / 4.0])
_A_COEFF = _A_BAND[SH_BAND_OF_COEFF]


# Exact normalisation constants (0.282095, 0.488603, 1.092548, 0.315392, 0.546274).
SH_C0 = 0.5 * np.sqrt(1.0 / np.pi)
_C1 = np.sqrt(3.0 / (4.0 * np.pi))
_C2 = 0.5 * np.sqrt(15.0 / np.pi)
_C20 = 0.25 * np.sqrt(5.0 / np.pi)
_C22 = 0.25 * np.sqrt(15.0 / np.pi)


def sh_basis(directions: np.ndarray) -> np.ndarray:
    """Real SH basis up to l = 2 at unit directions, (*, 3) -> (*, 9)."""
    d = check_shape(directions, ("*", 3), "directions").astype(np.float64)
    x, y, z = d[..., 0], d[..., 1], d[..., 2]
    return np.stack(
        [
            np.full_like(x, SH_C0),
            _C1 * y,
            _C1 * z,
            _C1 * x,
            _C2 * x * y,
            _C2 * y * z,
            _C20 * (3.0 * z * z - 1.0),
            _C2 * x * z,
            _C22 * (x * x - y * y),
        ],
        axis=-1,
    )


def project_radiance_to_sh(radiance: np.ndarray, directions: np.ndarray, solid_angles: np.ndarray) -> np.ndarray:
    """Quadrature projection: radiance (N, C), unit directions (N, 3), solid angles (N,) -> coefficients (9, C)."""
    L = np.asarray(radiance, dtype=np.float64).reshape(len(directions), -1)
    w = np.asarray(solid_angles, dtype=np.float64).reshape(-1)
    return sh_basis(directions).T @ (L * w[:, None])


def project_envmap_to_sh(radiance: np.ndarray, frame_from_env: np.ndarray | None = None) -> np.ndarray:
    """SH (9, 3) of an equirectangular map (see ``envmap`` conventions), expressed in ``frame_from_env``'s target frame.

    Rotating the quadrature directions is exact; no SH rotation error is introduced.
    """
    rad = np.asarray(radiance, dtype=np.float64)
    h, w = rad.shape[:2]
    dirs = pixel_directions(h, w).reshape(-1, 3)
    if frame_from_env is not None:
        dirs = dirs @ np.asarray(frame_from_env, dtype=np.float64).T
    omega = np.broadcast_to(pixel_solid_angles(h, w), (h, w)).reshape(-1)
    return project_radiance_to_sh(rad.reshape(-1, rad.shape[2]), dirs, omega)


def sh_irradiance(coeffs: np.ndarray, normals: np.ndarray) -> np.ndarray:
    """Irradiance E(n) from radiance SH (9, C) at unit normals (*, 3) -> (*, C). Clamped at 0 (ringing can go < 0)."""
    c = check_shape(np.asarray(coeffs, dtype=np.float64), (9, None), "sh coeffs")
    E = sh_basis(normals) @ (c * _A_COEFF[:, None])
    return np.maximum(E, 0.0)


def brute_force_irradiance(
    radiance: np.ndarray, normals: np.ndarray, frame_from_env: np.ndarray | None = None, chunk: int = 256
) -> np.ndarray:
    """Reference irradiance: sum over every map pixel of L * max(0, n . w) * dOmega, normals (N, 3) -> (N, 3)."""
    rad = np.asarray(radiance, dtype=np.float64)
    h, w = rad.shape[:2]
    dirs = pixel_directions(h, w).reshape(-1, 3)
    if frame_from_env is not None:
        dirs = dirs @ np.asarray(frame_from_env, dtype=np.float64).T
    Lw = rad.reshape(-1, 3) * np.broadcast_to(pixel_solid_angles(h, w), (h, w)).reshape(-1, 1)
    n = check_shape(np.asarray(normals, dtype=np.float64), (None, 3), "normals")
    out = np.empty((n.shape[0], 3))
    for i in range(0, n.shape[0], chunk):
        cos = np.maximum(n[i : i + chunk] @ dirs.T, 0.0)
        out[i : i + chunk] = cos @ Lw
    return out


def fibonacci_sphere(n: int) -> np.ndarray:
    """n near-uniform unit directions (n, 3) (deterministic)."""
    if n < 1:
        raise ValueError("fibonacci_sphere: n must be >= 1")
    i = np.arange(n) + 0.5
    z = 1.0 - 2.0 * i / n
    r = np.sqrt(np.clip(1.0 - z * z, 0.0, 1.0))
    phi = np.pi * (3.0 - np.sqrt(5.0)) * i
    return np.stack([r * np.cos(phi), r * np.sin(phi), z], axis=-1)


_ROT_SAMPLES = fibonacci_sphere(64)
_ROT_PINV = np.linalg.pinv(sh_basis(_ROT_SAMPLES))


def rotate_sh(coeffs: np.ndarray, b_from_a: np.ndarray) -> np.ndarray:
    """Re-express SH coefficients (9, C) given in frame a in frame b (3x3 rotation ``b_from_a``).

    Each band is closed under rotation, so fitting the rotated function on 64 directions is exact (to float rounding).
    """
    R = check_shape(np.asarray(b_from_a, dtype=np.float64), (3, 3), "b_from_a")
    # L_b(d_b) = L_a(R^T d_b); with row vectors R^T d = d @ R.
    M = _ROT_PINV @ sh_basis(_ROT_SAMPLES @ R)
    return M @ np.asarray(coeffs, dtype=np.float64)

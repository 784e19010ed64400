"""Preetham, Shirley and Smits (1999) analytic clear-sky model: the sky the camera never saw.

Sky radiance (without the solar disc) for a view direction at zenith angle theta and angle gamma from the sun is
``Y = Y_z * F(theta, gamma) / F(0, theta_s)`` with the Perez function
``F = (1 + A exp(B / cos theta)) (1 + C exp(D gamma) + E cos^2 gamma)``; chromaticity x, y follow the same form. Output
is linear sRGB in relative units (Y in kcd/m^2 as in the paper; callers rescale to their image).

Numerics: ``cos theta`` is clamped to >= ``MIN_COS_VIEW`` so the horizon and directions below it take the horizon
value (B < 0, so exp(B / cos theta) -> 0 there); the sun may sit at or below the horizon (theta_s up to 90 deg is used,
the zenith-luminance formula is clamped to stay positive).
"""

from __future__ import annotations

import numpy as np

from aias_augment.core.geometry import check_shape

__all__ = [
    "perez_coefficients",
    "preetham_zenith",
    "preetham_luminance_ratio",
    "preetham_sky_radiance",
    "preetham_exposure_fit_cost",
    "MIN_COS_VIEW",
]

MIN_COS_VIEW = 0.01
#: Elements of one block of :func:`preetham_exposure_fit_cost`'s (N, P) grid (128 KiB of float32: in L2 with its copies).
_BLOCK_ELEMENTS = 32768
_XYZ_TO_LINEAR_SRGB = np.array(
    [[3.2404542, -1.5371385, -0.4985314], [-0.9692660, 1.8760108, 0.0415560], [0.0556434, -0.2040259, 1.0572252]]
)


def perez_coefficients(turbidity: float) -> dict[str, np.ndarray]:
    """Perez A..E for luminance Y and chromaticities x, y (each a (5,) array) at turbidity T (Preetham 1999, App. A.2)."""
    T = float(turbidity)
    if not 1.0 <= T <= 20.0:
        raise ValueError(f"turbidity must be in [1, 20], got {T}")
    return {
        "Y": np.array(
            [0.1787 * T - 1.4630, -0.3554 * T + 0.4275, -0.0227 * T + 5.3251, 0.1206 * T - 2.5771, -0.0670 * T + 0.3703]
        ),
        "x": np.array(
            [
                -0.0193 * T - 0.2592,
                -0.0665 * T + 0.0008,
                -0.0004 * T + 0.2125,
                -0.0641 * T - 0.8989,
                -0.0033 * T + 0.0452,
            ]
        ),
        "y": np.array(
            [
                -0.0167 * T - 0.2608,
                -0.0950 * T + 0.0092,
                -0.0079 * T + 0.2102,
                -0.0441 * T - 1.6537,
                -0.0109 * T + 0.0529,
            ]
        ),
    }


def _perez(coef: np.ndarray, cos_theta: np.ndarray, gamma: np.ndarray, cos2_gamma=None) -> np.ndarray:
    """The Perez function; ``cos2_gamma``: ``np.cos(gamma) ** 2`` when the caller has it (the same numbers)."""
    A, B, C, D, E = coef
    ct = np.maximum(cos_theta, MIN_COS_VIEW)
    c2 = np.cos(gamma) ** 2 if cos2_gamma is None else cos2_gamma
    return (1.0 + A * np.exp(B / ct)) * (1.0 + C * np.exp(D * gamma) + E * c2)


def preetham_zenith(turbidity: float, sun_zenith_rad: float) -> tuple[float, float, float]:
    """Zenith luminance Y_z (kcd/m^2) and chromaticity (x_z, y_z). The sun zenith is clamped to [0, pi/2]."""
    T = float(turbidity)
    ts = float(np.clip(sun_zenith_rad, 0.0, np.pi / 2))
    chi = (4.0 / 9.0 - T / 120.0) * (np.pi - 2.0 * ts)
    Yz = max((4.0453 * T - 4.9710) * np.tan(chi) - 0.2155 * T + 2.4192, 1e-3)
    t = np.array([T * T, T, 1.0])
    s = np.array([ts**3, ts**2, ts, 1.0])
    mx = np.array(
        [
            [0.00166, -0.00375, 0.00209, 0.0],
            [-0.02903, 0.06377, -0.03202, 0.00394],
            [0.11693, -0.21196, 0.06052, 0.25886],
        ]
    )
    my = np.array(
        [
            [0.00275, -0.00610, 0.00317, 0.0],
            [-0.04214, 0.08970, -0.04153, 0.00516],
            [0.15346, -0.26756, 0.06670, 0.26688],
        ]
    )
    return float(Yz), float(t @ mx @ s), float(t @ my @ s)


def preetham_luminance_ratio(cos_theta: np.ndarray, gamma: np.ndarray, sun_zenith_rad, turbidity: float) -> np.ndarray:
    """Relative luminance ``F(theta, gamma) / F(0, theta_s)``; ``sun_zenith_rad`` may broadcast against the others."""
    c = perez_coefficients(turbidity)["Y"]
    ts = np.clip(np.asarray(sun_zenith_rad, dtype=np.float64), 0.0, np.pi / 2)
    return _perez(c, cos_theta, gamma) / _perez(c, np.ones_like(ts), ts)


def preetham_exposure_fit_cost(
    log_luminance: np.ndarray, cos_theta: np.ndarray, cos_gamma: np.ndarray, turbidities=(3.0,)
) -> np.ndarray:
    """Per candidate sun: the smallest (over ``turbidities``) mean squared residual of
    ``log Y_p = log(F(theta_p, gamma_np) / F(0, theta_s,n)) + c_n`` with the exposure ``c_n`` solved in closed form.

    ``log_luminance`` (P,) of sky pixels, ``cos_theta`` (P,) their view zenith cosines, ``cos_gamma`` (N, P) the
    cosines of their angles to each candidate sun. The same numbers as fitting :func:`preetham_luminance_ratio`
    directly (tested), at a fraction of the cost: ``log F`` splits into a per-pixel term (theta), a per-pixel and
    candidate term (gamma) and a per-candidate constant (theta_s), and the exposure absorbs the constant; the
    residual variance is var(h) + var(g_n) - 2 cov(h, g_n) with h the pixels' log Y minus the theta term, so only
    the gamma term is evaluated on the (N, P) grid (one exp and one log per element and turbidity)."""
    ly = np.asarray(log_luminance, dtype=np.float64)
    ct = np.maximum(np.asarray(cos_theta, dtype=np.float64), MIN_COS_VIEW)
    cg = np.asarray(cos_gamma, dtype=np.float64)
    p = ly.shape[0]
    if ly.shape != ct.shape or cg.ndim != 2 or cg.shape[1] != p or p == 0:
        raise ValueError(f"preetham_exposure_fit_cost: need (P,), (P,), (N, P), got {ly.shape}, {ct.shape}, {cg.shape}")
    # The (N, P) gamma term in float32 (7x faster exp/log; ~1e-7 relative error per element), its reductions
    # accumulated in float64: the costs agree with a float64 evaluation to ~1e-8 (tested against the direct fit).
    # Evaluated a block of candidates at a time (element-wise and per row, so the same numbers as on the whole grid)
    # so that the chain of element-wise passes stays in the CPU cache; the product with h is one BLAS call on the
    # whole grid (a BLAS call's rounding may depend on how its threads split the rows).
    n = cg.shape[0]
    rows = max(1, _BLOCK_ELEMENTS // p)
    c32 = cg.astype(np.float32)  # rounding then clipping to [-1, 1] (both float32): the same as the other way round
    np.clip(c32, np.float32(-1.0), np.float32(1.0), out=c32)
    gamma, cg2 = np.arccos(c32), np.square(c32)
    best = np.full(n, np.inf)
    g_buf, e_buf = np.empty((rows, p), np.float32), np.empty((rows, p), np.float32)
    g64 = np.empty((n, p))
    gm, gg = np.empty(n), np.empty(n)
    # Row sums of the float64 copy are those of the float32 rows accumulated in float64; einsum's agree while a row
    # fits one of numpy's cast buffers (einsum with dtype= sums a longer row buffer by buffer).
    whole_rows = p <= np.getbufsize()
    for T in turbidities:
        A, B, C, D, E = perez_coefficients(T)["Y"]
        # the floors (1e-12) never bind for turbidities in [1, 20]; they keep the logs finite
        h = ly - np.log(np.maximum(1.0 + A * np.exp(B / ct), 1e-12))
        h -= h.mean()
        for s in range(0, n, rows):
            e = min(n, s + rows)
            g, eg = g_buf[: e - s], e_buf[: e - s]
            np.multiply(gamma[s:e], np.float32(D), out=g)
            np.exp(g, out=g)
            g *= np.float32(C)
            g += np.float32(1.0)
            np.multiply(cg2[s:e], np.float32(E), out=eg)
            g += eg
            np.maximum(g, np.float32(1e-12), out=g)
            np.log(g, out=g)
            g64[s:e] = g
            gm[s:e] = g64[s:e].mean(axis=1)
            gg[s:e] = (
                np.einsum("ij,ij->i", g64[s:e], g64[s:e])
                if whole_rows
                else np.einsum("ij,ij->i", g, g, dtype=np.float64)
            )
        gh = g64 @ h
        cost = (h @ h) / p + gg / p - gm * gm - 2.0 * gh / p
        np.minimum(best, np.maximum(cost, 0.0), out=best)
    return best


def preetham_sky_radiance(
    directions: np.ndarray, sun_direction: np.ndarray, up: np.ndarray = (0.0, 0.0, 1.0), turbidity: float = 3.0
) -> np.ndarray:
    """Linear sRGB sky radiance (*, 3) for unit view directions (*, 3); ``sun_direction`` and ``up`` unit (3,).

    Directions below the horizon get the horizon value (callers put ground there). Always finite and >= 0.
    """
    d = check_shape(np.asarray(directions, dtype=np.float64), ("*", 3), "directions")
    s = np.asarray(sun_direction, dtype=np.float64).reshape(3)
    up = np.asarray(up, dtype=np.float64).reshape(3)
    s = s / max(np.linalg.norm(s), 1e-12)
    up = up / max(np.linalg.norm(up), 1e-12)
    cos_theta = d @ up
    gamma = np.arccos(np.clip(d @ s, -1.0, 1.0))
    ts = float(np.arccos(np.clip(s @ up, -1.0, 1.0)))
    coef = perez_coefficients(turbidity)
    Yz, xz, yz = preetham_zenith(turbidity, ts)
    ts_c = min(ts, np.pi / 2)

    cos2_gamma = np.cos(gamma) ** 2  # shared by the three channels

    def channel(name, zenith_value):
        return (
            zenith_value
            * _perez(coef[name], cos_theta, gamma, cos2_gamma)
            / _perez(coef[name], np.array(1.0), np.array(ts_c))
        )

    Y = channel("Y", Yz)
    x = channel("x", xz)
    y = np.maximum(channel("y", yz), 1e-4)  # eps: chromaticity y is ~0.3 for any real sky
    X = x * Y / y
    Z = (1.0 - x - y) * Y / y
    rgb = np.stack([X, Y, Z], axis=-1) @ _XYZ_TO_LINEAR_SRGB.T
    return np.clip(np.nan_to_num(rgb, nan=0.0, posinf=0.0, neginf=0.0), 0.0, None)

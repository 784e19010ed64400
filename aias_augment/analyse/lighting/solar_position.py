"""Where the sun is from GPS, time and the camera's orientation: its direction in ENU (pvlib's solar position, with
refraction) and in the camera frame, the orientation read from a frame's metadata (ENU: x east, y north, z up)."""

from __future__ import annotations

import numpy as np

__all__ = [
    "enu_from_cam_from_metadata",
    "rotation_of",
    "solar_direction_enu",
    "sun_direction_in_cam_from_metadata",
]


def solar_direction_enu(lat_deg: float, lon_deg: float, utc: str) -> np.ndarray:
    """Unit direction to the sun in ENU from latitude/longitude (deg) and an ISO UTC time, via pvlib (SPA, apparent
    elevation including refraction). Below the horizon the vector simply points below (z < 0)."""
    import pandas as pd
    import pvlib

    if not (-90.0 <= float(lat_deg) <= 90.0 and -180.0 <= float(lon_deg) <= 360.0):
        raise ValueError(f"invalid GPS position lat={lat_deg}, lon={lon_deg}")
    try:
        ts = pd.Timestamp(utc)
    except (ValueError, TypeError) as e:
        raise ValueError(f"cannot parse UTC time {utc!r}: {e}") from e
    ts = ts.tz_localize("UTC") if ts.tzinfo is None else ts.tz_convert("UTC")
    sp = pvlib.solarposition.get_solarposition(pd.DatetimeIndex([ts]), float(lat_deg), float(lon_deg))
    el = np.deg2rad(float(sp["apparent_elevation"].iloc[0]))
    az = np.deg2rad(float(sp["azimuth"].iloc[0]))  # clockwise from north
    return np.array([np.sin(az) * np.cos(el), np.cos(az) * np.cos(el), np.sin(el)])


def rotation_of(T) -> np.ndarray:
    T = np.asarray(T, dtype=np.float64)
    if T.shape == (4, 4):
        T = T[:3, :3]
    if T.shape != (3, 3) or not np.allclose(T @ T.T, np.eye(3), atol=1e-4):
        raise ValueError(f"expected a 3x3 rotation (or 4x4 rigid), got shape {T.shape}")
    return T


def enu_from_cam_from_metadata(meta: dict, cam_from_world: np.ndarray | None = None) -> np.ndarray | None:
    """Camera orientation in ENU from metadata, or None when the metadata does not say.

    Accepted keys (first match wins): ``enu_from_cam`` (3x3); ``enu_from_world`` (3x3, combined with
    ``cam_from_world``); ``heading_deg`` (camera forward azimuth, clockwise from north, level camera) with optional
    ``pitch_deg`` (up positive) and ``roll_deg``.
    """
    if "enu_from_cam" in meta:
        return rotation_of(meta["enu_from_cam"])
    if "enu_from_world" in meta:
        if cam_from_world is None:
            raise ValueError("meta['enu_from_world'] needs cam_from_world")
        return rotation_of(meta["enu_from_world"]) @ rotation_of(cam_from_world).T
    if "heading_deg" in meta:
        from aias_augment.analyse.lighting.envmap import cam_from_env_look

        # Env frame with x = east, y = north is exactly ENU; env azimuth is counter-clockwise from east.
        yaw = np.deg2rad(90.0 - float(meta["heading_deg"]))
        cam_from_enu = cam_from_env_look(
            yaw, np.deg2rad(float(meta.get("pitch_deg", 0.0))), np.deg2rad(float(meta.get("roll_deg", 0.0)))
        )
        return cam_from_enu.T
    return None


def sun_direction_in_cam_from_metadata(meta: dict, cam_from_world: np.ndarray | None = None) -> np.ndarray | None:
    """Sun direction in the camera frame from ``meta['lat'], meta['lon'], meta['utc']`` plus an orientation (see
    :func:`enu_from_cam_from_metadata`); None when position/time or orientation are missing."""
    if not all(k in meta for k in ("lat", "lon", "utc")):
        return None
    enu_from_cam = enu_from_cam_from_metadata(meta, cam_from_world)
    if enu_from_cam is None:
        return None
    return enu_from_cam.T @ solar_direction_enu(meta["lat"], meta["lon"], meta["utc"])

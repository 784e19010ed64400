"""Rendered thumbnails of bank assets and a labelled contact sheet, drawn by the ``render`` callable passed in
(:func:`aias_augment.apply.render.render_object`)."""

from __future__ import annotations

import logging

import cv2
import numpy as np

from aias_augment.assets.asset import Asset, AssetError
from aias_augment.assets.rendering import RenderObject
from aias_augment.core.geometry import Intrinsics, make_rigid
from aias_augment.core.hdr import linear_to_srgb

log = logging.getLogger(__name__)

__all__ = ["look_at_cam_from_object", "framing_camera", "render_thumbnail", "contact_sheet"]


def look_at_cam_from_object(
    eye_in_object: np.ndarray, target_in_object: np.ndarray, up_in_object: np.ndarray = np.array([0.0, 0.0, 1.0])
) -> np.ndarray:
    """(4, 4) OpenCV ``cam_from_object`` for a camera at ``eye`` looking at ``target`` (x right, y down, z forward)."""
    z = np.asarray(target_in_object, float) - np.asarray(eye_in_object, float)
    z /= np.linalg.norm(z)
    x = np.cross(z, up_in_object)
    if np.linalg.norm(x) < 1e-9:
        raise ValueError("look_at: viewing direction parallel to up")
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    R = np.stack([x, y, z])
    return make_rigid(R, -R @ np.asarray(eye_in_object, float))


def framing_camera(
    asset: Asset,
    tile_px: int,
    azimuth_deg: float = 35.0,
    elevation_deg: float = 20.0,
    fov_deg: float = 30.0,
    margin: float = 1.15,
) -> tuple[np.ndarray, Intrinsics]:
    """A camera that frames the asset's bounding sphere in a square ``tile_px`` image."""
    lo, hi = asset.bounds_m
    centre = (lo + hi) / 2
    radius = float(np.linalg.norm(hi - lo) / 2)
    f = tile_px / 2 / np.tan(np.radians(fov_deg) / 2)
    dist = margin * radius / np.sin(np.radians(fov_deg) / 2)
    az, el = np.radians(azimuth_deg), np.radians(elevation_deg)
    eye = centre + dist * np.array([np.sin(az) * np.cos(el), -np.cos(az) * np.cos(el), np.sin(el)])
    intr = Intrinsics(f, f, (tile_px - 1) / 2, (tile_px - 1) / 2, tile_px, tile_px)
    return look_at_cam_from_object(eye, centre), intr


def render_thumbnail(
    asset: Asset, tile_px: int = 160, background=(235, 235, 235), *, render: RenderObject
) -> np.ndarray:
    """(tile, tile, 3) uint8 sRGB: albedo (drawn by ``render``) shaded by a fixed key light from the camera's upper
    left."""
    cam_from_object, intr = framing_camera(asset, tile_px)
    layers = render(asset, cam_from_object, intr, ssaa=2, znear=0.01, zfar=1000.0)
    light_in_cam = np.array([-0.4, -0.6, -0.7])
    light_in_cam /= np.linalg.norm(light_in_cam)
    shade = 0.45 + 0.55 * np.clip(layers.normals_in_cam @ light_in_cam, 0, 1)
    rgb = linear_to_srgb(layers.albedo_linear * shade[..., None])
    a = layers.alpha[..., None]
    out = rgb * a + (np.asarray(background, np.float32) / 255.0) * (1 - a)
    return np.clip(out * 255 + 0.5, 0, 255).astype(np.uint8)


def contact_sheet(
    bank, record_ids: list[str], tile_px: int = 160, columns: int = 10, seed: int = 0, *, render: RenderObject
) -> tuple[np.ndarray, int]:
    """A labelled grid of thumbnails (category, name, height; :func:`render_thumbnail`, drawn by ``render``);
    failures show their reason in red."""
    rng = np.random.default_rng(seed)
    label_h = 28
    rows = max(1, -(-len(record_ids) // columns))
    sheet = np.full((rows * (tile_px + label_h), columns * tile_px, 3), 255, np.uint8)
    ok = 0
    for i, rid in enumerate(record_ids):
        r, c = divmod(i, columns)
        y0, x0 = r * (tile_px + label_h), c * tile_px
        rec = bank.record(rid)
        try:
            asset = bank.load(rid, rng)
            tile = render_thumbnail(asset, tile_px, render=render)
            text2, colour = f"{rec.name[:18]} {asset.height_m:.2f}m", (40, 40, 40)
            ok += 1
        except (AssetError, ValueError) as e:
            log.warning("thumbnail %s failed: %s", rid, e)
            tile = np.full((tile_px, tile_px, 3), 255, np.uint8)
            text2, colour = "FAILED: " + str(e)[:20], (200, 0, 0)
        sheet[y0 : y0 + tile_px, x0 : x0 + tile_px] = tile
        label = np.full((label_h, tile_px, 3), 255, np.uint8)  # drawn apart so text never spills into a neighbour
        for j, t in enumerate((rec.category, text2)):
            cv2.putText(label, t, (3, 11 + 13 * j), cv2.FONT_HERSHEY_SIMPLEX, 0.33, colour, 1, cv2.LINE_AA)
        sheet[y0 + tile_px : y0 + tile_px + label_h, x0 : x0 + tile_px] = label
    return sheet, ok

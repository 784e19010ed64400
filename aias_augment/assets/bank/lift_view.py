"""The source view of a lifted asset: the camera that sees it as its photo did (a far, level camera, the same pixel
scale), for round-trip checks and side-by-side pictures."""

from __future__ import annotations

import numpy as np

from aias_augment.core.geometry import Intrinsics


def source_view(cut, asset, distance_m: float = 200.0) -> tuple[np.ndarray, Intrinsics]:
    """(cam_from_object, intrinsics over the cutout's crop) that project the lifted ``asset`` onto the cutout's
    silhouette: the object's base centre at the silhouette's bottom edge and mean centre column, its height at the
    silhouette's height in pixels. ``distance_m`` far (200 m against a ~1 m object: perspective changes the scale
    across the object by < 0.5 %)."""
    from aias_augment.assets.bank.lift import silhouette_profile

    rows, centre, _ = silhouette_profile(cut.mask)
    h_px = float(len(rows))
    f = h_px * distance_m / asset.height_m
    hh, ww = cut.mask.shape
    intr = Intrinsics(f, f, ww / 2.0, hh / 2.0, ww, hh)
    # The profile is in pixel-edge coordinates (pixel k spans [k, k + 1)); OpenCV's have pixel centres on integers.
    base_u, base_v = float(np.mean(centre)) - 0.5, float(rows[-1] + 1) - 0.5
    # OpenCV camera: x right, y down, z forward; the object (z up) seen from its -y side.
    R = np.array([[1.0, 0, 0], [0, 0, -1.0], [0, 1.0, 0]])
    t = np.array([(base_u - intr.cx) * distance_m / f, (base_v - intr.cy) * distance_m / f, distance_m])
    cam_from_object = np.eye(4)
    cam_from_object[:3, :3], cam_from_object[:3, 3] = R, t
    return cam_from_object, intr

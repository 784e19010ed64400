"""Small self-made test assets (no shared data needed)."""

import numpy as np
import trimesh

from aias_augment.assets.asset import Asset, normalise_meshes


def box_asset(extents=(0.4, 0.6, 1.0), category="box", color=(200, 60, 20)) -> Asset:
    m = trimesh.creation.box(extents=extents)
    m.visual.face_colors = np.array([*color, 255], np.uint8)
    return Asset("box", category, normalise_meshes([m]), "tests:box")


def synthetic_ground_drive(
    n: int = 12, height_m: float = 1.5, K=None, baseline_m: float | None = None, step_m: float = 1.0
):
    """A synthetic drive over a textured ground plane with known poses (world = camera 0, ground y = 1.5 m);
    with ``baseline_m`` also the rectified right camera's frames (its centre that far along the left's +x), returned
    as a fourth value.

    The texture (seeded grain at two scales, like asphalt) lies on the ground at 20 px per metre; each frame is its
    exact perspective image (a homography per frame), so the true image track of any ground point is known
    analytically.
    """
    import cv2

    from aias_augment.core.geometry import Intrinsics, invert_rigid, make_rigid, rotation_about_axis

    K = K or Intrinsics(500.0, 500.0, 320.0, 200.0, 640, 360)
    rng = np.random.default_rng(0)
    fine = cv2.GaussianBlur(rng.random((1600, 800)).astype(np.float32), (0, 0), 1.5)
    coarse = cv2.resize(rng.random((100, 50)).astype(np.float32), (800, 1600), interpolation=cv2.INTER_CUBIC)
    tex = cv2.normalize(fine + 0.5 * coarse, None, 0, 255, cv2.NORM_MINMAX).astype(np.uint8)  # asphalt-like grain
    s, x0, z0 = 20.0, -20.0, 80.0  # texture (u, v) -> ground X = u / s + x0, Z = z0 - v / s
    gt, frames, rights = [], [], []
    A = np.array([[1 / s, 0, x0], [0, 0, height_m], [0, -1 / s, z0]])  # texture (u, v, 1) -> world point

    def view(T):
        H = K.K @ (T[:3, :3] @ A + np.outer(T[:3, 3], [0, 0, 1]))
        img = cv2.warpPerspective(tex, H, (K.width, K.height), flags=cv2.INTER_LINEAR)
        return np.repeat(img[..., None], 3, axis=2)

    for i in range(n):  # step_m forward per frame, turning 0.4 deg per frame
        R = rotation_about_axis([0, 1, 0], np.radians(0.4 * i))
        world_from_cam = make_rigid(R, [0.0, 0.0, step_m * i])
        T = invert_rigid(world_from_cam)
        frames.append(view(T))
        gt.append(T)
        if baseline_m is not None:
            right_from_left = make_rigid(np.eye(3), [-baseline_m, 0.0, 0.0])
            rights.append(view(right_from_left @ T))
    if baseline_m is not None:
        return K, frames, np.stack(gt), rights
    return K, frames, np.stack(gt)


def tracon_train_photo(name: str, max_side: int) -> np.ndarray:
    """A TraCon train photo as RGB, area-downscaled so its longer side is ``max_side``; skips the test when the
    shared data is absent."""
    import os
    from pathlib import Path

    import cv2
    import pytest

    p = Path(os.environ.get("AIAS_DATA", "../shared/data")) / "tracon" / "images" / "train" / name
    if not p.is_file():
        pytest.skip(f"{p} missing (AIAS_DATA)")
    img = cv2.cvtColor(cv2.imread(str(p)), cv2.COLOR_BGR2RGB)
    s = max_side / max(img.shape[:2])
    return cv2.resize(img, (round(img.shape[1] * s), round(img.shape[0] * s)), interpolation=cv2.INTER_AREA)

"""camera_analysis_width: the camera (vanishing lines: horizon, pitch, roll) of a cheap analysis is estimated on its
own, wider copy; the lighting's copy stays as it was."""

from dataclasses import replace

import cv2
import numpy as np
import pytest

from aias_augment.analyse.analysis import ANALYSIS_SEED, analyse_scene, scene_key
from aias_augment.analyse.single_image import SingleImageConfig, estimate_camera_from_image
from aias_augment.core.frame import Frame
from aias_augment.pipeline.config import InsertionConfig, load_preset

CFG = InsertionConfig(categories=("box",), harmonize=False, ssaa=1, analysis_max_width=160)


def level_road(rng: np.random.Generator, width: int = 960, height: int = 800) -> np.ndarray:
    """A level camera's street, principal point at the centre: sky, asphalt, lane marks meeting at the vanishing
    point on the centre row, and thin (1 px) poles, image-vertical as a level camera sees them."""
    img = np.full((height, width, 3), 105, np.uint8)
    cx, cy = (width - 1) / 2, (height - 1) / 2
    img[: int(cy)] = (165, 185, 215)
    for x0 in (-900, -450, -150, 150, 450, 900):
        far = (int(cx + 0.1 * x0), int(cy + 0.1 * (height - 1 - cy)))
        cv2.line(img, (int(cx + x0), height - 1), far, (225, 225, 225), 2, cv2.LINE_AA)
    for _ in range(14):
        x, base = int(rng.uniform(0, width)), int(rng.uniform(cy + 20, height - 10))
        cv2.line(img, (x, base), (x, int(base - rng.uniform(80, 260))), (40, 40, 40), 1, cv2.LINE_AA)
    return np.clip(img.astype(int) + rng.integers(-6, 7, img.shape), 0, 255).astype(np.uint8)


def tilted_road(theta_deg: float, seed: int = 0) -> np.ndarray:
    """The level road turned by ``theta_deg`` (counter-clockwise on screen) about its centre, the central 640x480
    cut out: the photo of a camera rolled by -theta about its optical axis (principal point at the centre)."""
    big = level_road(np.random.default_rng(seed))
    h, w = big.shape[:2]
    rot = cv2.warpAffine(big, cv2.getRotationMatrix2D(((w - 1) / 2, (h - 1) / 2), theta_deg, 1.0), (w, h))
    y0, x0 = (h - 480) // 2, (w - 640) // 2
    return np.ascontiguousarray(rot[y0 : y0 + 480, x0 : x0 + 640])


def test_camera_copy_width_reaches_the_estimate():
    """The ground of a cheap analysis with camera_analysis_width 480 is the vanishing-line estimate on the 480 px
    area-averaged copy (computed here directly), the lighting still runs on its 320 px copy, and the field is part
    of the scene key."""
    img = tilted_road(8.0)
    cfg = replace(CFG, camera_analysis_width=480)
    a = analyse_scene(Frame(img, None), cfg)
    copy = cv2.resize(img, (480, 360), interpolation=cv2.INTER_AREA)
    direct = estimate_camera_from_image(
        copy,
        np.random.default_rng(ANALYSIS_SEED),
        cfg=SingleImageConfig(hfov_prior_deg=cfg.default_hfov_deg, camera_height_m=cfg.camera_height_m),
    )
    assert np.allclose(a.ground.normal, direct.ground.normal, atol=1e-12)
    assert a.intrinsics.fx == pytest.approx(direct.intrinsics.fx * 640 / 480)
    assert "camera estimated on a 480x360 copy" in a.modules["analysis"]
    assert "lighting on 320x240 copy" in a.modules["analysis"]
    assert scene_key(Frame(img, None), cfg) != scene_key(Frame(img, None), CFG)
    # wider than the frame: the camera on the frame itself, the lighting still on its copy
    b = analyse_scene(Frame(img, None), replace(CFG, camera_analysis_width=1024))
    assert "camera estimated on the full image" in b.modules["analysis"]
    assert "lighting on 320x240 copy" in b.modules["analysis"]


def test_camera_analysis_width_is_checked():
    with pytest.raises(ValueError, match="camera_analysis_width"):
        InsertionConfig(categories=("box",), camera_analysis_width=32)


@pytest.mark.parametrize("theta_deg", [8.0, -8.0, 4.0])
def test_fast_preset_roll_on_a_tilted_road(theta_deg):
    """The fast preset's roll on a road photo turned by a known angle is within 2 deg of the truth (-theta). On a
    160 px copy the 1 px poles are gone, no vertical vanishing point is found and the roll falls to 0."""
    a = analyse_scene(Frame(tilted_road(theta_deg), None), load_preset("fast"))
    roll = np.degrees(a.ground.pitch_roll_rad()[1])
    assert roll == pytest.approx(-theta_deg, abs=2.0), a.modules["ground"]

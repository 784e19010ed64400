import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from aias_augment.analyse.lighting import envmap as em
from aias_augment.analyse.lighting import sun
from aias_augment.analyse.lighting.estimate import (
    LightingConfig,
    LightingEstimate,
    estimate_lighting,
    estimate_lighting_clip,
)
from aias_augment.core.config import data_root
from aias_augment.core.geometry import Intrinsics

KITTI = data_root() / "kitti06_color_snippet"


def _finite(e: LightingEstimate):
    assert np.all(np.isfinite(e.ambient_sh)) and np.all(np.isfinite(e.sun_irradiance_rgb))
    assert np.isfinite(e.sun_sky_ratio) and 0 <= e.confidence <= 1
    if e.sun_direction_in_cam is not None:
        assert np.linalg.norm(e.sun_direction_in_cam) == pytest.approx(1.0)


def test_envmap_source_rotated_into_camera(blender_world):
    env = em.EnvironmentMap.from_file(blender_world("sunrise"))
    found = sun.sun_from_envmap(env.radiance)
    R = em.cam_from_env_look(0.4, 0.1)
    cam_from_world = np.eye(4)
    cam_from_world[:3, :3] = R
    e = estimate_lighting(np.zeros((32, 48, 3), np.uint8), cam_from_world=cam_from_world, envmap=env)
    _finite(e)
    assert e.source == "envmap" and e.dominant_sun
    assert sun.angle_between_deg(e.sun_direction_in_cam, R @ found.direction_in_env) < 1e-6
    assert np.allclose(e.up_in_cam, R @ [0, 0, 1.0])


def test_envmap_indoor_flag_gives_environment_light_only(blender_world):
    env = em.EnvironmentMap.from_file(blender_world("interior"))
    e = estimate_lighting(np.zeros((32, 48, 3), np.uint8), envmap=env, meta={"indoor": True})
    assert not e.dominant_sun and e.sun_direction_in_cam is None and np.all(e.sun_irradiance_rgb == 0)
    assert e.ambient_sh[0].min() > 0


def test_envmap_sun_at_horizon_is_not_dominant():
    d = em.pixel_directions(32)
    rad = np.full((32, 64, 3), 0.5, np.float32)
    s = em.azimuth_elevation_to_direction(0.0, np.deg2rad(-1.0))
    rad[np.arccos(np.clip(d @ s, -1, 1)) < np.deg2rad(4)] = 1e5
    e = estimate_lighting(np.zeros((16, 16, 3), np.uint8), envmap=em.EnvironmentMap(rad))
    _finite(e)
    assert not e.dominant_sun


@pytest.mark.skipif(not (KITTI / "kitti06-12-color.png").is_file(), reason="shared KITTI data not present")
def test_kitti_sunny_frame():
    from PIL import Image

    img = np.array(Image.open(KITTI / "kitti06-12-color.png").convert("RGB"))
    K = Intrinsics(707.0912, 707.0912, 601.8873, 183.1104, 1226, 370)
    e = estimate_lighting(img, K)
    _finite(e)
    assert e.dominant_sun and e.source == "image_cues"
    assert 2.0 < e.sun_sky_ratio < 12.0  # clear-day sun/sky ratios on the ground
    assert e.sun_direction_in_cam @ e.up_in_cam > 0


def test_metadata_source_and_determinism():
    img = np.full((60, 80, 3), 120, np.uint8)
    meta = {"lat": 49.0, "lon": 8.4, "utc": "2011-09-30T12:00:00Z", "heading_deg": 180.0}
    e1 = estimate_lighting(img, Intrinsics.from_fov(80, 60, 60.0), meta=meta)
    e2 = estimate_lighting(img, Intrinsics.from_fov(80, 60, 60.0), meta=meta)
    assert e1.source == "metadata"
    assert e1.to_dict() == e2.to_dict()


def test_bad_inputs():
    with pytest.raises(ValueError):
        estimate_lighting(np.zeros((10, 10), np.uint8))
    with pytest.raises(ValueError):
        estimate_lighting(np.zeros((10, 10, 3), np.float32))
    with pytest.raises(ValueError):
        estimate_lighting(np.zeros((30, 40, 3), np.uint8), Intrinsics.from_fov(50, 30, 60.0))


@pytest.mark.parametrize("value", [0, 255])
def test_black_and_white_images(value):
    e = estimate_lighting(np.full((48, 64, 3), value, np.uint8), Intrinsics.from_fov(64, 48, 60.0))
    _finite(e)
    assert not e.dominant_sun


@settings(max_examples=8, deadline=None)
@given(st.integers(0, 2**32 - 1))
def test_random_images_never_nan(seed):
    rng = np.random.default_rng(seed)
    img = rng.integers(0, 256, (24, 32, 3), dtype=np.uint8)
    img[:4] = 255
    _finite(estimate_lighting(img))


def test_config_validation():
    with pytest.raises(ValueError):
        LightingConfig(ambient_map_height=2)


def test_clip_fusion_finds_the_rendered_sun_from_two_views_without_it():
    """Two views of one rendered clear sky (Preetham sun at azimuth -60 deg, elevation 25 deg), neither containing
    the sun: the clip's fused sun, back in the world, points at the sun the sky was rendered with, and every frame
    gets that one direction (or none, where it finds no dominant sun)."""
    from aias_augment.analyse.lighting import sky
    from aias_augment.analyse.lighting.estimate import estimate_sun_direction_clip
    from aias_augment.core import hdr

    h = 128
    d = em.pixel_directions(h)
    truth_az, truth_el = -60.0, 25.0
    s = em.azimuth_elevation_to_direction(np.deg2rad(truth_az), np.deg2rad(truth_el))
    rad = sky.preetham_sky_radiance(d, s) * 0.01
    rad[d[..., 2] < 0] = 0.05
    rad = rad.astype(np.float32)
    K = Intrinsics.from_fov(160, 100, 70.0)
    images, poses = [], []
    for yaw in (-10.0, -120.0):  # neither view contains the sun
        R = em.cam_from_env_look(np.deg2rad(yaw), np.deg2rad(5.0))
        view = em.render_perspective(rad, K, R)
        exposure = 0.18 / float(np.median(hdr.luminance(view)))
        images.append(np.round(hdr.linear_to_srgb(view * exposure) * 255).astype(np.uint8))
        T = np.eye(4)
        T[:3, :3] = R
        poses.append(T)
    up = {"up_in_world": [0.0, 0.0, 1.0]}
    # The fused direction itself (returned whether or not the sun is judged dominant): the rendered truth.
    fused = estimate_sun_direction_clip(images, K, poses, up).direction_in_world
    az, el = np.rad2deg(np.arctan2(fused[1], fused[0])), np.rad2deg(np.arcsin(np.clip(fused[2], -1, 1)))
    assert abs((az - truth_az + 180) % 360 - 180) < 10.0
    assert 0.0 < el < truth_el + 10.0 and sun.angle_between_deg(fused, s) < 15.0

    ests = estimate_lighting_clip(images, K, poses, up)
    assert len(ests) == 2 and all(e.source == "image_cues_clip" for e in ests)
    for e, T in zip(ests, poses):
        _finite(e)
        if e.dominant_sun:  # the fused direction, in this frame's camera
            assert np.allclose(e.sun_direction_in_cam, T[:3, :3] @ fused, atol=1e-9)
        else:
            assert e.sun_direction_in_cam is None
    with pytest.raises(ValueError):
        estimate_lighting_clip(images, K, poses[:1])


NYU = data_root() / "nyu_rgbd"
VIDEO = data_root() / "video" / "vtest.avi"


@pytest.mark.skipif(not (NYU / "color" / "1.png").is_file(), reason="shared NYU data not present")
@pytest.mark.parametrize("idx", [1, 2, 5])
def test_indoor_frames_have_no_dominant_sun(idx):
    # Without any 'indoor' flag: dark and bright furniture must not pass for lit and shadowed ground.
    from PIL import Image

    img = np.array(Image.open(NYU / "color" / f"{idx}.png").convert("RGB"))
    e = estimate_lighting(img, Intrinsics(518.0, 519.0, 325.5, 253.5, 640, 480))
    _finite(e)
    assert not e.dominant_sun and e.sun_direction_in_cam is None


@pytest.mark.skipif(not VIDEO.is_file(), reason="shared video not present")
def test_overcast_video_frame_has_no_dominant_sun():
    import cv2

    cap = cv2.VideoCapture(str(VIDEO))
    cap.set(cv2.CAP_PROP_POS_FRAMES, 240)
    ok, frame = cap.read()
    cap.release()
    assert ok
    e = estimate_lighting(cv2.cvtColor(frame, cv2.COLOR_BGR2RGB))
    _finite(e)
    assert not e.dominant_sun


def test_side_agreement_lowers_confidence_when_cues_do_not_pick_the_shadow_end():
    from aias_augment.analyse.lighting.sun_direction import _side_agreement

    up = np.array([0.0, 0.0, 1.0])
    grid, _ = sun.sun_direction_grid()
    east = np.array([1.0, 0, 0.3])
    east_side = grid[:, 0]  # side evidence: linear in the east component
    # Decisive evidence for the chosen end (margin 2 x 10 x cos(el) >> 1 nat): factor ~1.
    assert _side_agreement(10.0 * east_side, grid, east, up, 0.5) == pytest.approx(1.0, abs=1e-3)
    # Evidence symmetric about the axis (north-south only): a coin flip.
    assert _side_agreement(10.0 * grid[:, 1], grid, east, up, 0.5) == pytest.approx(0.5, abs=1e-3)
    # Evidence for the other end (the axis term overrode it): a coin flip at best.
    assert _side_agreement(-10.0 * east_side, grid, east, up, 0.5) == pytest.approx(0.5)
    # Margin m nats: 0.5 + 0.5 tanh(m / 2) (log-odds -> probability of the side).
    m = float(0.5 * east_side.max() - 0.5 * east_side[grid[:, 0] < 0].max())
    assert _side_agreement(0.5 * east_side, grid, east, up, 0.5) == pytest.approx(0.5 + 0.5 * np.tanh(m / 2))
    assert _side_agreement(-east_side, grid, east, up, 0.0) == 1.0  # no cast-shadow axis: nothing to qualify


@pytest.mark.skipif(not (KITTI / "kitti06-12-color.png").is_file(), reason="shared KITTI data not present")
@pytest.mark.parametrize("idx", [12, 14])
def test_kitti_sun_is_on_the_left(idx):
    """Reference read off the frames by eye (studies/lighting/README.md): the facades facing the road from the right are
    sunlit, the left ones shaded, and the poles' shadows run across the road to the right: the sun is LEFT (x < 0)."""
    from PIL import Image

    img = np.array(Image.open(KITTI / f"kitti06-{idx}-color.png").convert("RGB"))
    K = Intrinsics(707.0912, 707.0912, 601.8873, 183.1104, 1226, 370)
    e = estimate_lighting(img, K)
    _finite(e)
    assert e.dominant_sun and e.sun_direction_in_cam[0] < 0


def test_sky_side_mixture_caps_the_side_vote_and_keeps_the_peak():
    from aias_augment.analyse.lighting.sun_direction import _half_turn_index, sky_side_mixture

    grid, azel = sun.sun_direction_grid()
    half = _half_turn_index(azel)
    # The half turn maps each candidate to the same elevation and the azimuth + 180 deg.
    assert np.allclose(grid[half][:, :2], -grid[:, :2], atol=1e-9) and np.allclose(grid[half][:, 2], grid[:, 2])
    p = 0.85
    target = np.array([np.cos(0.3), np.sin(0.3), 0.0]) * np.cos(0.2) + np.array([0, 0, np.sin(0.2)])
    ll = 200.0 * (grid @ target - 1.0)  # a sharp, one-sided sky peak (vMF, kappa 200)
    out = sky_side_mixture(ll, half, p)
    best = int(np.argmax(ll))
    assert int(np.argmax(out)) == best  # the peak stays where the sky put it
    near = grid @ target > np.cos(np.deg2rad(15.0))
    # Near the peak the mirror term is negligible (exp(-200 x ~2) apart): the shape is ll + log p.
    assert np.allclose(out[near], ll[near] + np.log(p), atol=1e-9)
    # The best candidate on the other half-plane is the mirror of the peak, log(p / (1 - p)) below it.
    other = grid @ np.array([target[0], target[1], 0.0]) < 0
    assert out[best] - out[other].max() == pytest.approx(np.log(p / (1 - p)), abs=1e-9)
    # A sky that says nothing about the side (symmetric under the half turn) is unchanged.
    sym = 5.0 * grid[:, 2] - 3.0 * (grid[:, 0] ** 2)
    assert np.allclose(sky_side_mixture(sym, half, p), sym, atol=1e-12)
    with pytest.raises(ValueError):
        sky_side_mixture(ll, half, 1.0)
    with pytest.raises(ValueError):
        LightingConfig(sky_out_of_view_side_prob=0.3)


def test_sky_colour_weight_reaches_the_sky_cue():
    """The production estimator's colour weight is the sky cue's: on a sky of constant luminance whose blue
    chromaticity falls toward one side (whiter toward the sun), the estimate moves toward that side only when the weight
    is on, and to the other side when the gradient is mirrored."""
    from aias_augment.analyse.lighting.estimate import estimate_sun_direction

    with pytest.raises(ValueError):
        LightingConfig(sky_colour_weight=-1.0)
    K = Intrinsics.from_fov(320, 200, 70.0)
    R = em.cam_from_env_look(0.0, np.deg2rad(10.0))
    d = em.camera_ray_directions(K) @ R  # camera rays in the world (env) frame, z up
    up = np.array([0.0, 0.0, 1.0])

    def sky(sign: float) -> np.ndarray:
        # Constant luminance Y (the luminance fit cannot tell left from right), blue chromaticity b = B / (R + G + B)
        # falling toward sign x world +y (the camera looks along +x, so +y is its left); R = G, so
        # Y = S ((0.2126 + 0.7152) (1 - b) / 2 + 0.0722 b) with S = R + G + B.
        blue = 0.42 - 0.10 * sign * d[..., 1]
        S = 0.35 / ((0.2126 + 0.7152) * (1 - blue) / 2 + 0.0722 * blue)
        rgb = np.stack([S * (1 - blue) / 2, S * (1 - blue) / 2, S * blue], -1)
        img = np.round(255 * np.clip(rgb, 0, 1) ** (1 / 2.2)).astype(np.uint8)
        img[d[..., 2] < 0] = 90  # flat grey ground
        return img

    def sun_y(img, weight):
        return estimate_sun_direction(
            img,
            K,
            R,
            {"up_in_world": up},
            config=LightingConfig(sky_colour_weight=weight),
        ).direction_in_world[1]

    assert abs(sun_y(sky(1.0), 0.0)) < 1e-6 and abs(sun_y(sky(-1.0), 0.0)) < 1e-6  # colour off: no side
    assert sun_y(sky(1.0), 3.0) > 0.05 and sun_y(sky(-1.0), 3.0) < -0.05  # colour on: toward the whiter side


@pytest.mark.skipif(not (KITTI / "kitti06-17-color.png").is_file(), reason="shared KITTI data not present")
def test_kitti_clip_sun_is_on_the_left_and_one_world_direction():
    """The four colour frames fused with their ground-truth poses (06.txt: world_from_cam, 3x4 rows): one sun in the
    world (stop 11: azimuth -89 deg, elevation 26-27 deg in the cameras), on the left of the camera in every frame
    (the by-eye reference of test_kitti_sun_is_on_the_left)."""
    from PIL import Image

    poses = np.loadtxt(KITTI / "06.txt").reshape(-1, 3, 4)
    frames = [12, 13, 14, 17]
    imgs = [np.array(Image.open(KITTI / f"kitti06-{i}-color.png").convert("RGB")) for i in frames]
    K = Intrinsics(707.0912, 707.0912, 601.8873, 183.1104, 1226, 370)
    cams = []
    for i in frames:
        T = np.eye(4)
        T[:3, :4] = poses[i]
        cams.append(np.linalg.inv(T))
    ests = estimate_lighting_clip(imgs, K, cams, {"up_in_world": [0.0, -1.0, 0.0]})
    worlds = []
    for e, T in zip(ests, cams):
        _finite(e)
        assert e.dominant_sun and e.sun_direction_in_cam[0] < 0
        worlds.append(T[:3, :3].T @ e.sun_direction_in_cam)
    # One world sun in all frames (measured: within 0.02 deg of each other).
    assert all(np.rad2deg(np.arccos(np.clip(w @ worlds[0], -1, 1))) < 0.1 for w in worlds)


# --- Fallback ground boxes: a lit lane with the street's shadows on the verge ----------------
# Ray-cast scenes (synthetic_scene: geometry and Lambert's law only). Poles on the left verge, a sun from the right
# 35 deg high: their shadows fall on the verge (x < -1.8 m), none on the lane box (-1.5..1.5 m). Truth: the sun/sky
# ratio on the ground is sun_irradiance sin(el) / sky_irradiance = 6 sin 35 deg.
_KS = Intrinsics(360.0, 360.0, 319.5, 119.5, 640, 240)


def _verge_poles():
    from tests.aias_augment.analyse.lighting.synthetic_scene import Box

    return [Box((-2.0, 1.65 - 3.0, z), (-1.8, 1.65, z + 0.2)) for z in np.arange(6.0, 19.0, 2.0)]


def test_shadows_on_the_verge_give_a_sun_when_the_lane_has_none():
    from tests.aias_augment.analyse.lighting.synthetic_scene import render, sun_direction

    s = sun_direction(0.0, 35.0)
    img, _ = render(_verge_poles(), s, _KS, rng=np.random.default_rng(0))
    # The cue decision (a measured lit/shadow pair) is what these verges test; the synthetic sky is a clear
    # Preetham sky even without a sun, which the evidence decision reads as sunny.
    cues = LightingConfig(sun_decision="cues")
    lane_only = estimate_lighting(img, _KS, config=LightingConfig(fallback_ground_boxes_m=(), sun_decision="cues"))
    assert not lane_only.dominant_sun  # the lane box alone sees no cast shadow
    e = estimate_lighting(img, _KS, config=cues)
    _finite(e)
    assert e.dominant_sun
    # 4.8 against 3.4: the poles' own shaded faces (sky light on a vertical face: half the ground's) stand in the same
    # box and join the dark mode, as real poles do; the lit mode is exact
    truth = 6.0 * np.sin(np.deg2rad(35.0))
    assert 0.8 * truth < e.sun_sky_ratio < 1.5 * truth
    assert e.sun_direction_in_cam @ e.up_in_cam > 0  # (its azimuth comes from the sky and side cues, not the verge)
    overcast, _ = render(_verge_poles(), s, _KS, sun_irradiance=0.0, rng=np.random.default_rng(0))
    assert not estimate_lighting(overcast, _KS, config=cues).dominant_sun


def test_a_bright_strip_on_a_dark_verge_is_not_a_sun():
    # Overcast: a dark flat verge (albedo 0.06) with one bright strip (0.35, the ground's): bimodal, lit/dark 5.8,
    # but the dark mode is most of the verge (a bright patch on dark ground, not lit ground with shadows).
    from tests.aias_augment.analyse.lighting.synthetic_scene import Box, render, sun_direction

    verge = [
        Box((-6.0, 1.645, 3.0), (-3.0, 1.65, 25.0), albedo=(0.06, 0.06, 0.06)),
        Box((-2.4, 1.645, 3.0), (-1.5, 1.65, 25.0), albedo=(0.06, 0.06, 0.06)),
    ]
    img, _ = render(verge, sun_direction(0.0, 35.0), _KS, sun_irradiance=0.0, rng=np.random.default_rng(0))
    cues = LightingConfig(sun_decision="cues")  # the cue decision's measurement is under test (see above)
    assert not estimate_lighting(img, _KS, config=cues).dominant_sun
    from aias_augment.analyse.lighting.frame import fallback_measurement_ok
    from aias_augment.analyse.lighting.ratio import ground_region_mask, measure_lit_shadow
    from aias_augment.core.hdr import srgb_to_linear

    box = ground_region_mask(_KS, np.array([0.0, -1.0, 0.0]), 1.65, (-6.0, -1.5), (4.0, 20.0))
    m = measure_lit_shadow(srgb_to_linear(img), box)
    assert m is not None and m.dominant_sun and m.shadow_fraction > 0.6  # what the main-box test alone would accept
    assert not fallback_measurement_ok(m, LightingConfig())


def test_from_dict_gives_back_the_estimate_bit_for_bit():
    """Through JSON and back, every field to the last bit, the sun direction included (normalising a unit vector
    again moves the last bit of about one in a hundred)."""
    import json

    rng = np.random.default_rng(0)
    for _ in range(500):
        e = LightingEstimate(
            rng.normal(size=3), rng.uniform(0, 5, 3), rng.normal(size=(9, 3)), 2.5, True, 0.7, "image_cues"
        )
        back = LightingEstimate.from_dict(json.loads(json.dumps(e.to_dict())))
        for name in ("sun_direction_in_cam", "sun_irradiance_rgb", "ambient_sh", "up_in_cam"):
            assert getattr(back, name).tobytes() == getattr(e, name).tobytes()
        assert back.to_dict() == e.to_dict()
    none = LightingEstimate(None, np.zeros(3), np.zeros((9, 3)), 0.0, False, 0.0, "none")
    assert LightingEstimate.from_dict(json.loads(json.dumps(none.to_dict()))).to_dict() == none.to_dict()


def _searched_in_full(img, K, config):
    """The estimate computed the long way: the lit/shadow measurement and the image-cue sun search always run."""
    from aias_augment.analyse.lighting.estimate import _finish
    from aias_augment.analyse.lighting.frame import prepare_frame
    from aias_augment.analyse.lighting.sun_direction import image_cue_sun
    from aias_augment.analyse.lighting.sun_evidence import direct_sun_probability

    ctx = prepare_frame(img, K, np.eye(3), {}, config)
    est = image_cue_sun([ctx], ctx.up_in_world, config)
    conf = est.confidence * (1.0 if ctx.known_camera else 0.5)
    p = direct_sun_probability(img)
    return _finish(ctx, ctx.R_cw @ est.direction_in_world, conf, "image_cues", est.sky_cues[0], config, p), p


@pytest.mark.skipif(not (KITTI / "kitti06-17-color.png").is_file(), reason="shared KITTI data not present")
@pytest.mark.parametrize("threshold", [0.99, 0.05])
def test_a_sun_the_evidence_rules_out_is_not_searched_and_changes_nothing(threshold, monkeypatch):
    """Where the evidence decides there is no sun, the estimate skips the sun search and the lit/shadow measurement
    and is bit for bit the one computed with both; where it decides a sun, the search runs."""
    from PIL import Image

    from aias_augment.analyse.lighting import estimate as est_mod

    img = np.array(Image.open(KITTI / "kitti06-12-color.png").convert("RGB"))
    K = Intrinsics(707.0912, 707.0912, 601.8873, 183.1104, img.shape[1], img.shape[0])
    config = LightingConfig(sun_threshold=threshold)
    full, p = _searched_in_full(img, K, config)
    ruled_out = p < threshold
    assert ruled_out == (threshold == 0.99) and full.dominant_sun == (not ruled_out)
    calls = []
    search = est_mod.image_cue_sun
    monkeypatch.setattr(est_mod, "image_cue_sun", lambda *a, **k: calls.append(1) or search(*a, **k))
    e = estimate_lighting(img, K, config=config)
    assert e.to_dict() == full.to_dict()
    assert len(calls) == (0 if ruled_out else 1)
    clip = estimate_lighting_clip([img, img], K, [np.eye(4), np.eye(4)], config=config)
    assert len(calls) == (0 if ruled_out else 2)
    if ruled_out:
        assert [c.to_dict() for c in clip] == [{**full.to_dict(), "source": "image_cues_clip"}] * 2

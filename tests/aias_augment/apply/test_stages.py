import numpy as np

from aias_augment.analyse.analysis import analyse_scene
from aias_augment.apply.stages import apply_plan
from aias_augment.core.frame import Frame
from aias_augment.plan.insertion import plan_insertion
from tests.aias_augment.analyse.test_analysis import CFG, K, road_image
from tests.aias_augment.analyse.test_cache import OneAsset
from tests.aias_augment.fixtures import box_asset


def test_apply_is_pure_and_only_touches_the_objects_and_their_shadows():
    img = road_image()
    f = Frame(img, K)
    an = analyse_scene(f, CFG)
    plan = plan_insertion(an, CFG, np.random.default_rng(3), bank=OneAsset(box_asset()), n_objects=2)
    a = apply_plan(f, an, plan, CFG)
    b = apply_plan(f, an, plan, CFG)
    assert np.array_equal(a.image, b.image)
    assert np.array_equal(f.image, img)  # the frame is not modified
    assert len(a.annotations) == 2
    changed = (a.image != img).any(-1)
    assert changed.sum() > 100
    # Every changed pixel lies in the union of the objects' amodal boxes grown by their own size (shadow, penumbra).
    allowed = np.zeros_like(changed)
    for p in a.placements:
        x0, y0, x1, y1 = p.amodal_box_xyxy
        w, h = x1 - x0, y1 - y0
        allowed[max(0, int(y0 - h)) : int(y1 + h) + 1, max(0, int(x0 - 2 * w)) : int(x1 + 2 * w) + 1] = True
    assert not (changed & ~allowed).any()
    assert a.cover.max() > 0.99 and a.cover.min() == 0.0


def test_projected_and_catcher_shadow_ratios_agree_in_the_pipeline_stage():
    """The shadow stage (strength from the sun/sky ratio, penumbra, contact occlusion) with either visibility: the
    darkened ground agrees (IoU >= 0.8 of ratio < 0.8 where the object does not cover the ground: the catcher's
    shadowed pass sees the object there, not the ground) and the darkest values are within 0.1."""
    from aias_augment.analyse.lighting.estimate import LightingEstimate
    from aias_augment.apply.render import render_object_window
    from aias_augment.apply.stages import _object_shadow_window
    from aias_augment.core.geometry import make_rigid

    sh = np.zeros((9, 3))
    sh[0] = 0.3
    sun_cam = np.array([0.5, -0.6, 0.3]) / np.linalg.norm([0.5, -0.6, 0.3])
    light = LightingEstimate(sun_cam, np.full(3, 3.0), sh, 3.0, True, 0.9, "metadata", np.array([0.0, -1.0, 0.0]))
    T = make_rigid(np.array([[1.0, 0, 0], [0, 0, -1], [0, 1, 0]]), [-0.5, 1.6, 6.0])
    a = box_asset(extents=(0.5, 0.4, 0.9))
    roi_c, rc = _object_shadow_window(a, T, K, light, None, "catcher")
    roi_p, rp = _object_shadow_window(a, T, K, light, None, "projected")
    assert roi_c == roi_p
    oroi, ol = render_object_window(a, T, K, ssaa=1, with_normals=False)
    ground = np.ones(rc.shape, bool)
    x0, y0 = oroi[0] - roi_c[0], oroi[1] - roi_c[1]
    ground[y0 : y0 + ol.alpha.shape[0], x0 : x0 + ol.alpha.shape[1]] &= ol.alpha == 0
    dc, dp = (rc < 0.8) & ground, (rp < 0.8) & ground
    assert dc.sum() > 200
    assert (dc & dp).sum() / (dc | dp).sum() >= 0.8
    assert abs(float(rc.min()) - float(rp.min())) < 0.1


def test_replay_from_the_json_record_gives_the_same_bytes():
    import json

    from aias_augment.pipeline.image import insert_into_image
    from aias_augment.pipeline.replay import replay

    img = road_image()
    asset = box_asset()
    cfg = type(CFG)(
        categories=("box",), harmonize=True, harmonize_method="camera", ssaa=2
    )  # camera: draws from the seed
    res = insert_into_image(img, rng=np.random.default_rng(8), cfg=cfg, intrinsics=K, bank=OneAsset(asset), n_objects=2)
    assert len(res.record.placements) == 2
    record = json.loads(json.dumps(res.record.to_dict()))
    out = replay(record, Frame(img, K), cfg, assets=lambda p: asset)
    assert np.array_equal(out.image, res.image)
    assert not np.array_equal(out.image, img)


def test_fast_harmonizer_in_the_context_window_gives_the_whole_image_bytes():
    """apply's fast harmonizer runs on the objects' context window only: same bytes as on the whole image (objects
    in the middle, at a border and two apart, so components and clipped context crops are exercised)."""
    import pytest

    from aias_augment.apply.frame_steps import _harmonize, _harmonize_window
    from aias_augment.apply.harmonize import harmonize
    from aias_augment.apply.harmonize.api import DEFAULT_CHECKPOINTS

    if not DEFAULT_CHECKPOINTS["fast"].is_file():
        pytest.skip("fast harmonizer checkpoint not present")
    img = road_image(3)
    cfg = type(CFG)(categories=("box",), harmonize=True, harmonize_method="fast", harmonize_test_time_views=False)
    for boxes in ([(300, 250, 330, 310)], [(0, 400, 25, 480)], [(100, 300, 120, 340), (160, 310, 190, 360)]):
        mask = np.zeros(img.shape[:2], np.float32)
        for x0, y0, x1, y1 in boxes:
            mask[y0:y1, x0:x1] = 1.0
            mask[y0, x0:x1] = 0.5  # a soft edge
        comp = img.copy()
        comp[mask > 0] = (200, 90, 30)
        whole = harmonize(comp, mask, method="fast", test_time_views=False, rng=np.random.default_rng(0))
        win, model = _harmonize_window(mask, cfg)
        assert win is not None and model is not None and (win[2] - win[0]) * (win[3] - win[1]) < mask.size
        out, how = _harmonize(comp, mask, cfg, np.random.default_rng(0))
        assert "window" in how
        assert np.array_equal(out, whole)
        ys, xs = np.nonzero(mask)  # the caller's window holding the mask (apply passes the objects' window)
        within = (max(0, xs.min() - 3), max(0, ys.min() - 3), xs.max() + 4, ys.max() + 4)
        assert _harmonize_window(mask, cfg, within)[0] == win
        mbox = (xs.min(), ys.min(), xs.max() + 1, ys.max() + 1)  # apply passes the mask's box when it has it
        assert _harmonize_window(mask, cfg, None, mbox)[0] == win
        assert np.array_equal(_harmonize(comp, mask, cfg, np.random.default_rng(0), within=within)[0], whole)
        assert np.array_equal(_harmonize(comp, mask, cfg, np.random.default_rng(0), mask_box=mbox)[0], whole)


def test_fast_harmonizer_blended_on_the_mask_only_gives_harmonize_bytes():
    """harmonize_fast_masked (apply's fast path) against harmonize(method="fast"), one view and test-time views,
    two components with soft edges: the same bytes."""
    import pytest

    from aias_augment.apply.harmonize import harmonize
    from aias_augment.apply.harmonize.api import DEFAULT_CHECKPOINTS
    from aias_augment.apply.harmonize.fast import harmonize_fast_masked, load_fast

    if not DEFAULT_CHECKPOINTS["fast"].is_file():
        pytest.skip("fast harmonizer checkpoint not present")
    img = road_image(3)
    mask = np.zeros(img.shape[:2], np.float32)
    mask[250:330, 300:340] = 1.0
    mask[250, 300:340] = 0.3
    mask[100:120, 10:30] = 0.7
    comp = img.copy()
    comp[mask > 0] = (200, 90, 30)
    for tta in (False, True):
        assert np.array_equal(
            harmonize_fast_masked(load_fast(DEFAULT_CHECKPOINTS["fast"]), comp, mask, tta),
            harmonize(comp, mask, method="fast", test_time_views=tta, rng=np.random.default_rng(0)),
        )


def test_a_monochrome_camera_gets_grey_objects_and_a_colour_one_keeps_colour():
    """A grey frame stored as RGB (R = G = B, like KITTI's grey cameras) is recorded as a monochrome camera and its
    inserted cone is written as luminance (every output pixel has R = G = B, and the cone changed pixels); the scene
    from a colour camera
    keeps an orange cone (R well above B on the object)."""
    from aias_augment.analyse.analysis import analyse_scene, is_monochrome
    from aias_augment.apply.stages import apply_plan
    from aias_augment.core.frame import Frame
    from aias_augment.pipeline.config import load_preset
    from aias_augment.plan.insertion import plan_insertion

    rng = np.random.default_rng(0)
    grey = np.full((240, 320), 120, np.uint8)
    grey[:100] = 200  # sky
    grey = np.clip(grey + rng.integers(-6, 7, grey.shape), 0, 255).astype(np.uint8)
    mono = np.repeat(grey[..., None], 3, axis=2)
    colour = np.full((240, 320, 3), 120, np.int16)  # the same scene from a colour camera: grey road,
    colour[:100] = (150, 180, 220)  # blue sky, noise per channel
    colour = np.clip(colour + rng.integers(-6, 7, colour.shape), 0, 255).astype(np.uint8)
    assert is_monochrome(mono) and not is_monochrome(colour)
    cfg = load_preset("fast", categories=("traffic_cone",), min_objects=1, max_objects=1)
    for img, expect_grey in ((mono, True), (colour, False)):
        frame = Frame(img)
        analysis = analyse_scene(frame, cfg)
        assert ("colour" in analysis.modules) == expect_grey
        plan = plan_insertion(analysis, cfg, np.random.default_rng(3))
        assert plan.objects
        out = apply_plan(frame, analysis, plan, cfg)
        obj = out.cover > 0.5
        assert obj.sum() > 20 and np.abs(out.image.astype(int) - img.astype(int))[obj].max() > 10
        if expect_grey:
            assert (out.image[..., 0] == out.image[..., 1]).all() and (out.image[..., 1] == out.image[..., 2]).all()
        else:
            px = out.image[obj].astype(int)
            assert np.mean(px[:, 0] - px[:, 2] > 30) > 0.2  # the orange body stays orange (base black, bands white)


def test_keep_chromaticity_takes_the_brightness_and_keeps_the_colour():
    """Per pixel, in linear light: the result's chromaticity is ``before``'s and its luminance ``after``'s (to the
    8-bit rounding); pixels ``after`` left as they were stay byte-identical."""
    from aias_augment.apply.composite import to_linear
    from aias_augment.apply.frame_steps import keep_chromaticity

    rng = np.random.default_rng(0)
    before = rng.integers(40, 200, (30, 40, 3)).astype(np.uint8)
    after = before.copy()
    after[5:25, 5:35] = np.clip(before[5:25, 5:35] * np.array([1.3, 0.9, 0.8]) + 10, 0, 255).astype(np.uint8)
    out = keep_chromaticity(before, after)
    same = np.all(before == after, axis=-1)
    assert np.array_equal(out[same], after[same])
    w = np.array([0.2126, 0.7152, 0.0722])
    b, a, o = (to_linear(x[~same]).astype(np.float64) for x in (before, after, out))
    assert np.allclose(o @ w, a @ w, rtol=0.03, atol=2e-3)
    chroma = lambda x: x / x.sum(-1, keepdims=True)
    assert np.abs(chroma(o) - chroma(b)).max() < 0.01
    assert np.abs(chroma(a) - chroma(b)).max() > 0.03  # the harmonizer did change the colour


def test_harmonize_colour_luminance_keeps_white_white_on_a_red_context():
    """A white box inserted into a scene dominated by red: the learnt harmonizer ('full') pulls its colour toward
    the red context; with harmonize_colour='luminance' the object's pixels keep the chromaticity they had before
    harmonization (the same plan with harmonize off)."""
    from dataclasses import replace

    import pytest

    from aias_augment.apply.composite import to_linear
    from aias_augment.apply.harmonize.api import DEFAULT_CHECKPOINTS

    if not DEFAULT_CHECKPOINTS["fast"].is_file():
        pytest.skip("fast harmonizer checkpoint not present")
    img = road_image(2)
    img[: img.shape[0] // 2] = (190, 40, 35)  # red above the horizon
    f = Frame(img, K)
    an = analyse_scene(f, CFG)
    plan = plan_insertion(
        an, CFG, np.random.default_rng(1), bank=OneAsset(box_asset(color=(230, 230, 230))), n_objects=1
    )
    assert plan.objects
    cfg = replace(CFG, harmonize=True, harmonize_method="fast", harmonize_test_time_views=False)
    raw = apply_plan(f, an, plan, CFG)
    full = apply_plan(f, an, plan, replace(cfg, harmonize_colour="full"))
    lum = apply_plan(f, an, plan, replace(cfg, harmonize_colour="luminance"))
    obj = (raw.cover > 0.99) & (raw.image.max(-1) < 250) & (raw.image.min(-1) > 10)
    assert obj.sum() > 50
    rg = lambda x: float(np.median(to_linear(x[obj])[:, 0] / np.maximum(to_linear(x[obj])[:, 1], 1e-4)))
    assert abs(rg(lum.image) / rg(raw.image) - 1) < 0.02
    assert abs(rg(full.image) / rg(raw.image) - 1) > 0.05  # not vacuous: the harmonizer does tint it
    assert "luminance only" in lum.modules["harmonize"]

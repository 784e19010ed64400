"""The looks of labelled cones, measured on renders whose looks are known.

Each cone is drawn with a chosen :class:`ConeLook` (body colour, base colour, sleeves), rendered by the real renderer
standing on the road of ``road_image`` about 4 m from the camera, and measured on the output image inside its
projected box: the fit must give back the look that was drawn."""

import cv2
import numpy as np
import pytest

from aias_augment.analyse.analysis import analyse_scene
from aias_augment.analyse.instances import fit_cone_look, fit_cone_looks
from aias_augment.apply.stages import apply_plan
from aias_augment.assets.bank.procedural import ConeLook, procedural_asset_from_seed
from aias_augment.core.frame import Frame
from aias_augment.core.geometry import Intrinsics
from aias_augment.pipeline.config import InsertionConfig
from aias_augment.plan.insertion import InsertionPlan, PlannedObject
from aias_augment.plan.placement import object_pose_on_ground, placement_at
from tests.aias_augment.analyse.test_analysis import road_image

K = Intrinsics(900.0, 900.0, 319.5, 239.5, 640, 480)

LOOKS = [
    ConeLook((255.0, 72.0, 18.0), "black", 2, 0.12),
    ConeLook((210.0, 28.0, 34.0), "body", 0, 0.0),
    ConeLook((252.0, 196.0, 8.0), "grey", 1, 0.2),
]


def _hue(rgb) -> float:
    r, g, b = (float(c) / 255.0 for c in rgb)
    mx, mn = max(r, g, b), min(r, g, b)
    if mx == mn:
        return 0.0
    if mx == r:
        h = (g - b) / (mx - mn) % 6
    elif mx == g:
        h = (b - r) / (mx - mn) + 2
    else:
        h = (r - g) / (mx - mn) + 4
    return 60.0 * h


def _render(look: ConeLook, seed: int = 3):
    frame = Frame(road_image(), K)
    cfg = InsertionConfig(categories=("traffic_cone",), harmonize=False, shadow=False, ssaa=2)
    an = analyse_scene(frame, cfg)
    asset = procedural_asset_from_seed("traffic_cone", seed, look)
    asset = asset.scaled(0.7 / asset.height_m)
    p = an.ground.intersect_pixels(np.array([[320.0, 420.0]]), K)[0]
    T = object_pose_on_ground(p, an.ground, 0.3)
    placement = placement_at(asset, T, K, 0.3, an.ground)
    plan = InsertionPlan((PlannedObject(placement, asset),), 0, 1)
    out = apply_plan(frame, an, plan, cfg)
    return out.image, np.asarray(placement.amodal_box_xyxy, float)


@pytest.mark.parametrize("look", LOOKS, ids=["black-2-sleeves", "body-base-plain", "grey-1-sleeve"])
def test_the_fit_gives_back_the_drawn_look(look):
    image, box = _render(look)
    assert box[3] - box[1] >= 80, box  # large enough to measure sleeves
    fit = fit_cone_look(image, box)
    assert fit is not None
    assert fit.base_colour == look.base_colour
    assert fit.bands == look.bands
    if look.bands:
        assert abs(fit.band_width_frac - look.band_width_frac) <= 0.04, (fit.band_width_frac, look.band_width_frac)
    gap = abs(_hue(fit.colour_rgb) - _hue(look.colour_rgb)) % 360
    assert min(gap, 360 - gap) <= 12.0, (fit.colour_rgb, look.colour_rgb)


@pytest.mark.parametrize("base_value", [0.3, 0.6])
def test_the_fit_reads_the_base_and_body_brightness_it_was_drawn_with(base_value):
    """A base drawn at 0.3 or 0.6 of the body's brightness is read back within 25 % (the light on the base's faces
    and the body's slope is not the same), and the two ordered; the body's brightness is its measured HSV value."""
    image, box = _render(ConeLook((255.0, 72.0, 18.0), "grey", 1, 0.12, base_value))
    fit = fit_cone_look(image, box)
    assert abs(np.log(fit.base_value / base_value)) <= np.log(1.25), (fit.base_value, base_value)
    x0, y0, x1, y1 = box
    col = image[
        int(round(y0 + 0.15 * (y1 - y0))) : int(round(y0 + 0.88 * (y1 - y0))), int(round(x0 + 0.45 * (x1 - x0)))
    ]
    assert abs(fit.body_value - np.median(col.max(-1)) / 255.0) <= 0.05  # the body fills the column's middle


def test_boxes_that_cannot_be_measured_give_no_look():
    image, box = _render(LOOKS[0])
    cut = box.copy()
    cut[1] = 0.0  # cut by the frame's top edge: its height is unknown
    tiny = np.array([box[0], box[3] - 12, box[0] + 6, box[3]])  # 12 px tall
    road = np.array([10.0, 400.0, 60.0, 470.0])  # grey road: no saturated body
    assert fit_cone_look(image, cut) is None
    assert fit_cone_look(image, tiny) is None
    assert fit_cone_look(image, road) is None
    assert len(fit_cone_looks(image, np.stack([box, cut, tiny, road]))) == 1


def test_a_drawn_look_changes_colours_and_sleeves_only_and_rebuilds_from_its_record():
    look = LOOKS[0]
    plain = procedural_asset_from_seed("traffic_cone", 11)
    looked = procedural_asset_from_seed("traffic_cone", 11, look)
    for key in ("shape", "base_shape", "base_half_width_m", "base_height_m", "body_bottom_radius_m", "height_m"):
        assert looked.meta[key] == plain.meta[key], key
    assert looked.meta["base_colour"] == "black" and len(looked.meta["bands_z_m"]) == 2
    assert looked.meta["colour_rgb"] == list(look.colour_rgb)
    again = procedural_asset_from_seed("traffic_cone", 11, looked.meta["look"])  # what a replay reads
    a, b = looked.meshes[0], again.meshes[0]
    np.testing.assert_array_equal(a.vertices, b.vertices)
    np.testing.assert_array_equal(np.asarray(a.visual.material.image), np.asarray(b.visual.material.image))


@pytest.mark.parametrize(
    "kwargs",
    [
        {"colour_rgb": (255.0, 72.0, 18.0), "base_colour": "blue", "bands": 1, "band_width_frac": 0.1},
        {"colour_rgb": (255.0, 72.0, 18.0), "base_colour": "black", "bands": 5, "band_width_frac": 0.1},
        {"colour_rgb": (300.0, 72.0, 18.0), "base_colour": "black", "bands": 1, "band_width_frac": 0.1},
        {"colour_rgb": (255.0, 72.0, 18.0), "base_colour": "black", "bands": 1, "band_width_frac": 0.9},
        {"colour_rgb": (255.0, 72.0, 18.0), "base_colour": "grey", "bands": 0, "band_width_frac": 0, "base_value": 0},
        {"colour_rgb": (255.0, 72.0, 18.0), "base_colour": "grey", "bands": 0, "band_width_frac": 0, "body_value": 1.5},
    ],
)
def test_a_look_out_of_range_is_refused_at_construction(kwargs):
    with pytest.raises(ValueError, match="ConeLook"):
        ConeLook(**kwargs)


def test_the_labelled_objects_ground_is_found_by_its_look():
    """A grey asphalt ground (textured, shaded along the rows) with a red sign and a pale kerb standing on it, and two
    orange cone boxes on the asphalt: the ground beside the cones' bases marks the asphalt (most of it, far from
    the cones too), never the sign, the kerb or the sky, never a pixel inside a labelled box; without enough ground
    beside the bases there is no mask."""
    from aias_augment.analyse.instances import labelled_ground

    rng = np.random.default_rng(3)
    h, w = 240, 320
    img = np.empty((h, w, 3), np.float64)
    img[:100] = (150, 190, 235)  # sky
    shade = np.linspace(70, 95, h - 100)[:, None, None]  # asphalt, lit more toward the camera
    img[100:] = shade + rng.normal(0, 3, (h - 100, w, 1)) + np.array([0.0, 1.0, 3.0])
    img[120:200, 200:260] = (200, 30, 30)  # a red sign on the ground
    img[200:230, 0:60] = (190, 190, 180)  # a pale kerb
    img = np.clip(img, 0, 255).astype(np.uint8)
    cones = np.array([[60.0, 130.0, 90.0, 180.0], [140.0, 150.0, 180.0, 215.0]])
    for x0, y0, x1, y1 in cones.astype(int):
        img[y0:y1, x0:x1] = (255, 90, 20)
    g = labelled_ground(img, cones)
    assert g is not None
    mask = g.mask()
    assert mask.shape == (h, w)
    asphalt = np.zeros((h, w), bool)
    asphalt[100:] = True
    asphalt[120:200, 200:260] = asphalt[200:230, 0:60] = False
    for x0, y0, x1, y1 in cones.astype(int):
        asphalt[y0:y1, x0:x1] = False
        assert not mask[y0:y1, x0:x1].any()
    assert mask[asphalt].mean() > 0.9 and mask[asphalt[:, ::-1] & asphalt].mean() > 0.9  # beside them and far off
    assert not mask[:100].any() and not mask[120:200, 200:260].any() and not mask[200:230, 0:60].any()
    assert labelled_ground(img, np.array([[0.0, 0.0, 4.0, 4.0]])) is None  # 4 px of sky beside a box: too few
    # asked pixel by pixel, as a row's sites ask it: the answers of the whole frame converted at once, its range
    # tested channel by channel, outside every box
    lab = cv2.cvtColor(img, cv2.COLOR_RGB2LAB)
    whole = np.all((lab >= g.lo) & (lab <= g.hi), axis=-1)
    for x0, y0, x1, y1 in cones.astype(int):
        whole[y0:y1, x0:x1] = False
    some = np.random.default_rng(0).choice(h * w, 500, replace=False)
    assert np.array_equal(g.at(some), whole.reshape(-1)[some]) and np.array_equal(mask, whole)
    assert g.at(np.zeros(0, int)).shape == (0,)


def test_the_labelled_ground_at_the_frames_edges():
    """Boxes half outside the frame, of zero width, or covering it all: never an error; the ground is never inside a
    labelled box, and a box over the whole frame leaves no ground to sample (None)."""
    from aias_augment.analyse.instances import labelled_ground

    img = np.full((120, 160, 3), 90, np.uint8)
    edge = np.array([[-30.0, 60.0, 20.0, 130.0], [150.0, -10.0, 200.0, 50.0], [80.0, 40.0, 80.0, 90.0]])
    g = labelled_ground(img, edge)
    assert g is not None
    m = g.mask()
    assert not m[60:, :20].any() and not m[:50, 150:].any() and m[:, 30:140].mean() > 0.5
    assert labelled_ground(img, np.array([[-5.0, -5.0, 170.0, 130.0]])) is None
    assert labelled_ground(img, np.zeros((0, 4))) is None

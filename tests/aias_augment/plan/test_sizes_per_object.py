"""Per-object sizes beside the scene's labelled objects: each inserted object is sized for its own drawn height, and
the scene's scale comes from the labelled kind (a barrel drawn first does not rescale the cones).

The scene: the assumed-scale road of ``road_image`` seen from a camera 0.8 m above the ground (the assumed plane
scaled about the camera), with four labelled 0.7 m cones whose boxes are the projected corners of a real cone
mesh. What an inserted cone is compared with is derived from that truth alone: the box the same real cone has
when it stands where the inserted one stands (same contact pixel, same ground)."""

from dataclasses import replace

import cv2
import numpy as np

from aias_augment.analyse.analysis import analyse_scene
from aias_augment.analyse.ground import prior_ground_plane
from aias_augment.analyse.instances import LabelledGround
from aias_augment.assets.bank.procedural import procedural_asset_from_seed
from aias_augment.core.frame import Frame
from aias_augment.core.geometry import project_points, transform_points
from aias_augment.plan.insertion import plan_insertion
from aias_augment.plan.placement import object_pose_on_ground, scaled_ground
from tests.aias_augment.analyse.test_analysis import CFG, K, road_image
from tests.aias_augment.fixtures import box_asset
from tests.aias_augment.plan.test_insertion import _joined

REAL_CONE_M = 0.7
REAL_PIXELS = [[110.0, 300.0], [330.0, 340.0], [520.0, 390.0], [220.0, 440.0]]


class ConesAndBarrels:
    """A bank: a new procedural cone per draw (its own height, 0.3-1.0 m) and a 1 m barrel-sized box."""

    def __init__(self):
        self.barrel = box_asset(extents=(0.6, 0.6, 1.0), category="barrel")

    def sample(self, category, rng):
        if category == "barrel":
            return self.barrel
        return procedural_asset_from_seed("traffic_cone", int(rng.integers(2**31)))


def _real_cone():
    a = procedural_asset_from_seed("traffic_cone", 12345)
    return a.scaled(REAL_CONE_M / a.height_m)


def _box_on_ground(asset, ground, pixel, yaw=0.3):
    p = ground.intersect_pixels(np.asarray([pixel], float), K)[0]
    uv, _ = project_points(transform_points(object_pose_on_ground(p, ground, yaw), asset.corners_m()), K.K)
    return np.r_[uv.min(0), uv.max(0)]


def _scene():
    an = analyse_scene(Frame(road_image(), K), CFG)
    truth = scaled_ground(an.ground, 0.8 / an.ground.d)
    real = _real_cone()
    boxes = np.array([_box_on_ground(real, truth, px) for px in REAL_PIXELS])
    return an, truth, real, boxes


def test_inserted_cones_are_the_size_of_the_real_cones_on_their_row_even_after_a_barrel():
    an, truth, real, boxes = _scene()
    cfg = replace(CFG, categories=("barrel", "traffic_cone"))
    bank = ConesAndBarrels()
    ratios, barrel_first, analytic = [], 0, []
    for s in range(30):
        plan = plan_insertion(
            an,
            cfg,
            np.random.default_rng(s),
            bank=bank,
            n_objects=3,
            existing_boxes_xyxy=boxes,
            existing_labels=["traffic_cone"] * len(boxes),
        )
        cats = [o.placement.category for o in plan.objects]
        barrel_first += bool(cats) and cats[0] == "barrel" and "traffic_cone" in cats
        for o in plan.objects:
            if o.placement.category != "traffic_cone":
                continue
            x0, y0, x1, y1 = o.placement.amodal_box_xyxy
            rx0, ry0, rx1, ry1 = _box_on_ground(real, truth, o.placement.contact_pixel, o.placement.yaw_rad)
            ratios.append((y1 - y0) / (ry1 - ry0))
            # the drawn height projected at the contact point, against the box: a cone's box adds its base's depth, up to a
            # quarter of its height where the camera looks down at a wide base
            base = np.asarray(o.placement.contact_point_in_cam)
            top = base + o.asset.height_m * np.asarray(o.placement.ground_normal_in_cam)
            seg = abs(K.fy * (base[1] / base[2] - top[1] / top[2]))
            analytic.append((y1 - y0) / seg)
    ratios = np.array(ratios)
    assert barrel_first >= 3, "the sample must hold plans whose first object is a barrel"
    assert len(ratios) >= 20
    inside = np.mean((ratios >= 0.8) & (ratios <= 1.25))
    assert inside >= 0.9, (inside, np.round(np.sort(ratios), 2))
    analytic = np.array(analytic)
    assert np.all((analytic >= 1.0) & (analytic <= 1.25)), np.round(analytic, 3)


def test_scene_scale_comes_from_the_labelled_kind_not_the_first_object():
    """Barrel first or cone first, every object of the plan stands on the truth's 0.8 m camera height."""
    an, truth, real, boxes = _scene()
    bank = ConesAndBarrels()
    cfg = replace(CFG, categories=("barrel", "traffic_cone"))
    firsts = set()
    for s in range(12):
        plan = plan_insertion(
            an,
            cfg,
            np.random.default_rng(s),
            bank=bank,
            n_objects=2,
            existing_boxes_xyxy=boxes,
            existing_labels=["traffic_cone"] * len(boxes),
        )
        assert plan.objects and "reference boxes" in plan.modules["scene_scale"]
        firsts.add(plan.objects[0].placement.category)
        for o in plan.objects:
            # the real cones' boxes are their mesh's box (base depth included): within 5 % of the truth
            assert abs(o.placement.ground_d / 0.8 - 1) < 0.05, (s, plan.modules["scene_scale"])
    assert firsts == {"barrel", "traffic_cone"}


def _row_ratios(an, truth, boxes, real, pcfg, arrangement="independent") -> np.ndarray:
    """Inserted cones' box heights over the real cone's on the true ground with its box's bottom on the same row
    (its contact pixel found by bisection along the box's centre column)."""
    ratios = []
    for s in range(12):
        plan = plan_insertion(
            an,
            replace(CFG, categories=("traffic_cone",), placement_cfg=pcfg, arrangement=arrangement),
            np.random.default_rng(s),
            bank=ConesAndBarrels(),
            n_objects=3,
            existing_boxes_xyxy=boxes,
            existing_labels=["traffic_cone"] * len(boxes),
        )
        for o in plan.objects:
            x0, y0, x1, y1 = o.placement.amodal_box_xyxy
            lo, hi = 0.0, float(K.height)
            for _ in range(40):
                mid = (lo + hi) / 2
                lo, hi = (mid, hi) if _box_on_ground(real, truth, [(x0 + x1) / 2, mid])[3] < y1 else (lo, mid)
            ry0, ry1 = _box_on_ground(real, truth, [(x0 + x1) / 2, lo])[[1, 3]]
            ratios.append((y1 - y0) / (ry1 - ry0))
    return np.array(ratios)


def test_cones_take_their_row_size_when_the_camera_estimate_is_far_off():
    """The labelled cones stand on a ground pitched 30 deg more than the image's (level) estimate, which is kept
    (no pitch fit): inserted cones still have the real cone's box height on their rows; without the row sizes they
    spread far wider."""
    an = analyse_scene(Frame(road_image(), K), CFG)
    truth = prior_ground_plane(3.0, an.ground.pitch_roll_rad()[0] + np.radians(30.0))
    real = _real_cone()
    pixels = [[110.0, 260.0], [330.0, 320.0], [520.0, 380.0], [220.0, 440.0]]
    boxes = np.array([_box_on_ground(real, truth, px) for px in pixels])
    pcfg = replace(CFG.placement_cfg, pitch_from_references=False)
    rows = _row_ratios(an, truth, boxes, real, pcfg)
    assert len(rows) >= 15
    assert np.all((rows >= 0.8) & (rows <= 1.25)), np.round(np.sort(rows), 2)
    # cones standing in rows (their sites from the first cone's ground) take the same row sizes
    lined = _row_ratios(an, truth, boxes, real, pcfg, arrangement="line")
    assert len(lined) >= 15 and np.mean((lined >= 0.8) & (lined <= 1.25)) >= 0.9, np.round(np.sort(lined), 2)
    assert abs(np.log(np.median(lined))) < 0.1, np.round(np.sort(lined), 2)
    off = _row_ratios(an, truth, boxes, real, replace(pcfg, sizes_from_rows=False))
    # the row sizes leave only the drawn jitter (0.06 in log); the ground estimate alone spreads them far wider
    assert np.std(np.log(off)) > 2 * np.std(np.log(rows)), (np.round(np.sort(rows), 2), np.round(np.sort(off), 2))


def _row_plans(an, boxes, seeds: int, **kw) -> list:
    """Plans of 3 cones with ``arrangement: row`` beside the labelled cones ``boxes``, seeds 0 to ``seeds - 1``."""
    cfg = replace(CFG, categories=("traffic_cone",), arrangement="row")
    return [
        plan_insertion(
            an,
            cfg,
            np.random.default_rng(s),
            bank=ConesAndBarrels(),
            n_objects=3,
            existing_boxes_xyxy=boxes,
            existing_labels=["traffic_cone"] * len(boxes),
            **kw,
        )
        for s in range(seeds)
    ]


def test_row_continues_the_labelled_cones_row():
    """Three labelled cones stand 2 m apart on a straight row across the ground (placed in 3D on the image's own
    ground, their boxes projected): with ``arrangement: row`` every inserted cone that joins stands on that row's
    line (within 0.5 m: the plan's ground is the one the labelled boxes' sizes scale) and over 0.75 m from every
    labelled cone (beyond the ends or in the gap); the record names the row's spacing as measured from the
    boxes (2.00 +- 0.3 m)."""
    an = analyse_scene(Frame(road_image(), K), CFG)
    g = an.ground
    real = _real_cone()
    n = np.asarray(g.normal)
    start = g.intersect_pixels(np.array([[250.0, 330.0]]), K)[0]
    forward = np.array([0.0, 0.0, 1.0]) - n[2] * n
    forward /= np.linalg.norm(forward)
    side = np.cross(n, forward)
    u = np.cos(0.5) * forward + np.sin(0.5) * side  # the row's direction on the ground
    feet = [start + s * u for s in (0.0, 2.0, 6.0)]  # a gap of two steps between the 2nd and 3rd
    boxes = []  # mask-tight, as labels are: the box of the cone's outline standing at its foot
    for f in feet:
        uv, _ = project_points(transform_points(object_pose_on_ground(f, g, 0.3), real.outline_m()), K.K)
        boxes.append(np.r_[uv.min(0), uv.max(0)])
    boxes = np.array(boxes)
    joined_total = 0
    for s, plan in enumerate(_row_plans(an, boxes, 8)):
        note = plan.modules["arrangement"]
        spacing = float(note.split("labelled, ")[1].split(" m apart")[0])
        assert abs(spacing - 2.0) < 0.3, note
        joined = _joined(plan)
        joined_total += len(joined)
        for i in joined:
            c = np.asarray(plan.objects[i].placement.contact_point_in_cam)
            rel = c - start
            t = float(rel @ u)
            off_line = np.linalg.norm(rel - t * u - (rel @ n) * n)
            assert off_line < 0.5, (s, i, off_line)
            assert min(abs(t - f) for f in (0.0, 2.0, 6.0)) > 0.75, (s, i, t)  # on no labelled cone's place
    assert joined_total >= 12
    # the row's ground by its look (labelled_ground): its sites are those pixels alone, whatever the scene's region
    h, w = an.image_shape
    grey = cv2.cvtColor(np.full((1, 1, 3), 128, np.uint8), cv2.COLOR_RGB2LAB)[0, 0]
    for half, cols in (("left", slice(0, w // 2)), ("right", slice(w // 2, w))):
        look = np.zeros((h, w, 3), np.uint8)
        look[..., 0] = 200  # red: not ground
        look[:, cols] = 128  # grey: the ground's colour
        ground = LabelledGround(look, np.zeros((h, w), bool), grey, grey)
        ground_px = ground.mask()
        assert ground_px[:, cols].all() and ground_px.sum() == h * (cols.stop - cols.start)
        joined_here = 0
        for s, plan in enumerate(_row_plans(an, boxes, 6, labelled_ground=ground)):
            for i in _joined(plan):
                cu, cv = plan.objects[i].placement.contact_pixel
                assert ground_px[int(round(cv)), int(round(cu))], (half, s, i, cu, cv)
                joined_here += 1
        assert joined_here >= 3, half
    # one labelled cone is no row: every object stands on its own, draw for draw as "independent" places it
    alone = [
        plan_insertion(
            an,
            replace(CFG, categories=("traffic_cone",), arrangement=kind),
            np.random.default_rng(5),
            bank=ConesAndBarrels(),
            n_objects=3,
            existing_boxes_xyxy=boxes[:1],
            existing_labels=["traffic_cone"],
        )
        for kind in ("row", "independent")
    ]
    assert len(alone[0].objects) == 3
    assert [repr(o.placement) for o in alone[0].objects] == [repr(o.placement) for o in alone[1].objects]

import json
from dataclasses import replace

import numpy as np

from aias_augment.analyse.analysis import analyse_scene
from aias_augment.core.frame import Frame
from aias_augment.plan.insertion import plan_insertion
from tests.aias_augment.analyse.test_analysis import CFG, K, road_image
from tests.aias_augment.analyse.test_cache import OneAsset
from tests.aias_augment.fixtures import box_asset


def test_same_generator_same_plan_and_json_record():
    an = analyse_scene(Frame(road_image(), K), CFG)
    bank = OneAsset(box_asset())
    a = plan_insertion(an, CFG, np.random.default_rng(1), bank=bank, n_objects=3)
    b = plan_insertion(an, CFG, np.random.default_rng(1), bank=bank, n_objects=3)
    c = plan_insertion(an, CFG, np.random.default_rng(2), bank=bank, n_objects=3)
    assert len(a.objects) == 3
    assert json.dumps(a.to_dict()) == json.dumps(b.to_dict())
    assert json.dumps(a.to_dict()) != json.dumps(c.to_dict())


def test_objects_stand_in_the_region_and_avoid_existing_boxes():
    an = analyse_scene(Frame(road_image(), K), CFG)
    existing = np.array([[0.0, 240.0, 320.0, 480.0]])  # the lower-left quarter is taken
    p = plan_insertion(
        an, CFG, np.random.default_rng(4), bank=OneAsset(box_asset()), n_objects=3, existing_boxes_xyxy=existing
    )
    assert p.objects
    for o in p.objects:
        u, v = o.placement.contact_pixel
        assert an.region.mask[int(round(v)), int(round(u))]
        x0, y0, x1, y1 = o.placement.amodal_box_xyxy
        inter = max(0.0, min(x1, 320) - max(x0, 0)) * max(0.0, min(y1, 480) - max(y0, 240))
        assert inter < 0.5 * (x1 - x0) * (y1 - y0)


def test_sizes_from_existing_boxes_make_objects_the_scene_objects_size():
    """With placement_cfg.sizes_from_existing, objects are drawn at the existing boxes' heights (the scene's own
    objects of that kind), against the analytic box height of the planned pose; without boxes, the config's own
    distribution; off, sizes follow the geometry alone."""

    from aias_augment.plan.insertion import scene_sized_placement

    an = analyse_scene(Frame(road_image(), K), CFG)
    bank = OneAsset(box_asset(extents=(0.3, 0.3, 0.7)))
    existing = np.array([[600.0, 300.0, 630.0, 380.0], [10.0, 320.0, 40.0, 400.0]])  # two 80 px tall objects
    # at the assumed camera height (a scaled scene sees the box from lower, its top face differently)
    cfg = replace(
        CFG,
        placement_cfg=replace(
            CFG.placement_cfg,
            sizes_from_existing=True,
            box_height_tolerance=0.1,
            box_height_jitter=0.0,
            scene_scale_from_sizes=False,
        ),
        arrangement="independent",  # a row's members take the size perspective gives them, not a flat target
    )
    heights = []
    for s in range(6):
        p = plan_insertion(
            an,
            cfg,
            np.random.default_rng(s),
            bank=bank,
            n_objects=2,
            existing_boxes_xyxy=existing,
            existing_labels=["box", "box"],
        )
        assert p.modules["sizes"].startswith("box heights drawn from the image's 2 existing boxes")
        heights += [o.placement.amodal_box_xyxy[3] - o.placement.amodal_box_xyxy[1] for o in p.objects]
    assert len(heights) >= 6
    # the box of a standing 0.7 m object whose vertical extent is predicted at 80 px (+-10 %; the box adds the
    # object's depth extent under perspective, a few px)
    # (+ the box's top face under perspective, ~10-20 % for this box seen from above); without the flag the same
    # draws give 17 ... 119 px on this scene
    assert all(70 <= h <= 110 for h in heights) and max(heights) / min(heights) < 1.3, heights
    pc = cfg.placement_cfg
    assert scene_sized_placement(pc, [], 480) is pc
    assert (
        scene_sized_placement(replace(pc, sizes_from_existing=False), list(existing), 480).box_height_frac_samples == ()
    )
    assert scene_sized_placement(pc, list(existing), 480).box_height_frac_samples == (80 / 480, 80 / 480)


def _analytic_height_px(placement, height_m, intr):
    """Image height of a vertical segment of ``height_m`` standing at the placement's contact point on its plane."""
    base = np.asarray(placement.contact_point_in_cam)
    top = base + height_m * np.asarray(placement.ground_normal_in_cam)
    v = [intr.fy * p[1] / p[2] + intr.cy for p in (base, top)]
    return abs(v[0] - v[1])


def test_scene_scale_from_sizes_hosts_targets_the_assumed_camera_height_cannot():
    """A level camera 1.65 m up with f = 500 px sees a 0.7 m object on the ground at most ~102 px tall (its nearest
    visible ground, the bottom row, is 500 * 1.65 / 240 = 3.4 m away). A 216 px target (0.45 of the frame) needs
    the assumed-scale scene scaled about the camera: every object then stands on the one scaled plane, at the
    target size by the analytic projection of its contact point, and the camera height lies in the allowed range."""

    an = analyse_scene(Frame(road_image(), K), CFG)
    assert an.ground.source.split(":")[0] in ("prior", "single_image")
    bank = OneAsset(box_asset(extents=(0.3, 0.3, 0.7)))
    sized = replace(CFG.placement_cfg, box_height_frac_samples=(0.45,), box_height_jitter=0.0, box_height_tolerance=0.1)
    off = replace(CFG, placement_cfg=replace(sized, scene_scale_from_sizes=False))
    on = replace(CFG, placement_cfg=sized)  # the default
    for s in range(4):
        p_off = plan_insertion(an, off, np.random.default_rng(s), bank=bank, n_objects=1)
        assert all(_analytic_height_px(o.placement, 0.7, K) < 110 for o in p_off.objects)
        p = plan_insertion(an, on, np.random.default_rng(s), bank=bank, n_objects=2)
        assert p.objects and p.modules["scene_scale"].startswith("camera ")
        d = {o.placement.ground_d for o in p.objects}
        assert len(d) == 1 and 0.4 <= d.pop() < 1.65 * 0.8
        for o in p.objects:
            assert abs(_analytic_height_px(o.placement, 0.7, K) / 216 - 1) <= 0.1 + 1e-6
            assert o.placement.ground_source.endswith(":scaled")


def test_scene_scale_keeps_measured_grounds_and_the_camera_height_range():
    from aias_augment.analyse.ground import GroundPlane
    from aias_augment.plan.placement import PlacementConfig, scene_scale_for_sizes

    up = np.array([0.0, -1.0, 0.0])
    cfg = PlacementConfig(scene_scale_from_sizes=True, camera_height_range_m=(1.2, 2.0))
    k, why = scene_scale_for_sizes(GroundPlane(up, 1.65, "depth"), K, np.random.default_rng(0), cfg, 0.7, 0.45)
    assert k == 1.0 and why.startswith("measured ground")
    # 0.45 of the frame needs a camera ~0.6 m up: outside 1.2-2.0 m, the nearest allowed height is used and said
    k, why = scene_scale_for_sizes(
        GroundPlane(up, 1.65, "prior", assumed_scale=True), K, np.random.default_rng(0), cfg, 0.7, 0.45
    )
    assert abs(k * 1.65 - 1.2) < 1e-9 and "outside" in why
    # a small target is hosted near the horizon at the assumed height or a higher one
    k, why = scene_scale_for_sizes(
        GroundPlane(up, 1.65, "prior", assumed_scale=True),
        K,
        np.random.default_rng(0),
        PlacementConfig(scene_scale_from_sizes=True),
        0.7,
        0.05,
    )
    assert 0.4 <= k * 1.65 <= 4.0 and why.startswith("camera ")
    import pytest

    with pytest.raises(ValueError, match="camera_height_range_m"):
        PlacementConfig(camera_height_range_m=(2.0, 1.0))


def _arranged(kind, seed, **kw):
    cfg = replace(CFG, arrangement=kind, min_objects=4, max_objects=4, **kw)
    an = analyse_scene(Frame(road_image(), K), cfg)
    return an, plan_insertion(an, cfg, np.random.default_rng(seed), bank=OneAsset(box_asset(extents=(0.3, 0.3, 0.7))))


def test_a_line_stands_on_the_ground_at_its_spacing_along_one_direction():
    """Line arrangement at a fixed 2 m spacing: every member's contact is a whole number of steps from the first
    (within the 10 % tolerance), all on one straight line on the plane."""
    placed = 0
    for seed in range(6):
        an, p = _arranged("line", seed, arrangement_spacing_m=(2.0, 2.0))
        joined = _joined(p)
        pts = np.array([o.placement.contact_point_in_cam for o in p.objects])[[0, *joined]]
        if len(pts) < 3:
            continue
        placed += 1
        d = np.linalg.norm(pts[1:] - pts[0], axis=1)
        steps = np.round(d / 2.0)
        assert np.all(steps >= 1) and np.all(np.abs(d - 2.0 * steps) <= 0.2 * steps + 0.05)
        u = (pts[1:] - pts[0]) / d[:, None]
        assert np.all(np.abs(u @ u[0]) > 0.99), "members not on one line"
        n = np.asarray(an.ground.normal)
        assert np.all(np.abs(pts @ n + an.ground.d) < 0.02), "members off the ground plane"
    assert placed >= 2


def _joined(plan) -> list[int]:
    """The indices of the objects the record says joined the first one's arrangement."""
    inside = plan.modules["arrangement"].split("[", 1)[1].split("]", 1)[0]
    return [] if inside == "none" else [int(i) for i in inside.split(", ")]


def test_a_cluster_stays_within_its_radius_of_the_first():
    placed = 0
    for seed in range(6):
        _, p = _arranged("cluster", seed, arrangement_cluster_radius_m=1.0)
        pts = np.array([o.placement.contact_point_in_cam for o in p.objects])[[0, *_joined(p)]]
        if len(pts) < 2:
            continue
        placed += 1
        assert np.all(np.linalg.norm(pts[1:] - pts[0], axis=1) <= 1.0 + 0.15)
    assert placed >= 2


def test_one_object_draws_no_arrangement_mixed_records_the_same_per_seed():
    """A single object has no arrangement to stand in: every kind gives the independent plan, draw for draw."""
    an = analyse_scene(Frame(road_image(), K), CFG)
    one = [
        plan_insertion(
            an,
            replace(CFG, arrangement=kind, min_objects=1, max_objects=1),
            np.random.default_rng(3),
            bank=OneAsset(box_asset(extents=(0.3, 0.3, 0.7))),
        )
        for kind in ("independent", "line", "cluster", "mixed")
    ]
    assert len(one[0].objects) == 1 and "arrangement" not in one[0].modules
    assert len({json.dumps(p.to_dict()) for p in one}) == 1
    m1, m2 = _arranged("mixed", 5)[1], _arranged("mixed", 5)[1]
    assert json.dumps(m1.to_dict()) == json.dumps(m2.to_dict())


def _standing_boxes(ground, intr, pixels, height_m, half_width_px=12.0):
    """xyxy boxes of vertical ``height_m`` segments standing on ``ground`` at the ground pixels ``pixels``: base
    and top projected forward (the inverse of what a scale search does)."""
    from aias_augment.core.geometry import project_points

    base = ground.intersect_pixels(np.asarray(pixels, float), intr)
    top = base + height_m * ground.normal[None, :]
    ub, _ = project_points(base, intr.K)
    ut, _ = project_points(top, intr.K)
    return np.c_[ub[:, 0] - half_width_px, ut[:, 1], ub[:, 0] + half_width_px, ub[:, 1]]


def test_scene_scale_from_boxes_recovers_the_camera_height_the_boxes_were_made_at():
    """Boxes of 0.7 m objects projected from a camera 0.8 m above the ground (the assumed plane scaled about the
    camera) give back 0.8 m; a box cut by the bottom edge is left out; a measured ground keeps its scale."""
    from aias_augment.plan.placement import PlacementConfig, scaled_ground, scene_scale_from_boxes

    an = analyse_scene(Frame(road_image(), K), CFG)
    g = an.ground
    assert g.assumed_scale
    truth = scaled_ground(g, 0.8 / g.d)
    boxes = _standing_boxes(truth, K, [[100, 300], [320, 360], [500, 420]], 0.7)
    cut = np.array([[200.0, 400.0, 230.0, K.height]])  # touches the bottom edge: its base is not seen
    k, note = scene_scale_from_boxes(g, K, np.r_[boxes, cut], 0.7, PlacementConfig())
    assert abs(k * g.d - 0.8) < 0.01 * 0.8, note
    assert "3 reference boxes" in note
    k2, _ = scene_scale_from_boxes(g, K, boxes, 0.7, PlacementConfig(camera_height_range_m=(1.0, 4.0)))
    assert abs(k2 * g.d - 1.0) < 1e-9  # clamped into the allowed range
    assert scene_scale_from_boxes(g, K, cut, 0.7, PlacementConfig())[0] is None
    measured = replace(g, assumed_scale=False)
    assert scene_scale_from_boxes(measured, K, boxes, 0.7, PlacementConfig())[0] == 1.0


def test_objects_of_the_inserted_kind_set_the_scene_scale_and_others_do_not():
    """Existing boxes labelled with the inserted category (here "box") make the plan's scene the one they were
    projected from: every object stands on the 0.8 m plane, as tall as a 0.7 m object is there. Boxes labelled
    with another kind ("car") and unlabelled boxes change no size."""
    from aias_augment.plan.placement import scaled_ground

    an = analyse_scene(Frame(road_image(), K), CFG)
    g = an.ground
    truth = scaled_ground(g, 0.8 / g.d)
    boxes = _standing_boxes(truth, K, [[100, 300], [320, 360], [500, 420]], 0.7)
    bank = OneAsset(box_asset(extents=(0.3, 0.3, 0.7)))
    for s in range(3):
        p = plan_insertion(
            an,
            CFG,
            np.random.default_rng(s),
            bank=bank,
            n_objects=2,
            existing_boxes_xyxy=boxes,
            existing_labels=["box"] * 3,
        )
        assert p.objects and "reference boxes" in p.modules["scene_scale"]
        for o in p.objects:
            assert abs(o.placement.ground_d - 0.8) < 0.01
        for labels in (["car"] * 3, None):
            q = plan_insertion(
                an,
                CFG,
                np.random.default_rng(s),
                bank=bank,
                n_objects=2,
                existing_boxes_xyxy=boxes,
                existing_labels=labels,
            )
            assert "sizes" not in q.modules and "reference boxes" not in q.modules.get("scene_scale", "")


def test_a_line_keeps_the_count_members_without_ground_placed_on_their_own():
    """A 60 m spacing puts every member's place beyond the road's visible ground: none can join the line, so each
    is placed on its own and the plan holds as many objects as an independent one (the record says so)."""
    for seed in range(3):
        _, far = _arranged("line", seed, arrangement_spacing_m=(60.0, 60.0))
        _, alone = _arranged("independent", seed)
        assert len(far.objects) == len(alone.objects) >= 3
        assert _joined(far) == [] and f"{len(far.objects) - 1} placed on their own" in far.modules["arrangement"]


def test_only_the_leaders_category_joins_its_line():
    """Cones and barrels (the same 0.7 m box under two names) in a 2 m line: only objects of the first object's
    category join it, each a whole number of steps from the first."""

    class TwoKinds:
        def sample(self, category, rng):
            return box_asset(extents=(0.3, 0.3, 0.7), category=category)

    on_line, off_line = 0, 0
    for seed in range(8):
        cfg = replace(
            CFG,
            arrangement="line",
            arrangement_spacing_m=(2.0, 2.0),
            min_objects=4,
            max_objects=4,
            categories=("traffic_cone", "barrel"),
        )
        an = analyse_scene(Frame(road_image(), K), cfg)
        p = plan_insertion(an, cfg, np.random.default_rng(seed), bank=TwoKinds())
        lead = p.objects[0].placement
        joined = _joined(p)
        kinds = [o.placement.category for o in p.objects]
        assert all(kinds[i] == lead.category for i in joined)
        on_line += len(joined)
        off_line += sum(c != lead.category for c in kinds[1:])
        p0 = np.asarray(lead.contact_point_in_cam)
        for i in joined:  # each a whole number of 2 m steps from the first (the search's pixel is the box's
            # front edge, the contact its centre: half a scaled 0.3 m depth more)
            o = p.objects[i].placement
            d = float(np.linalg.norm(np.asarray(o.contact_point_in_cam) - p0))
            steps = max(round(d / 2.0), 1)
            assert abs(d - 2.0 * steps) <= 0.2 * steps + 0.05 + 0.15 * max(o.scale, lead.scale)
    assert on_line >= 6 and off_line >= 3


def test_within_pixels_draws_as_a_region_mask_of_them_would():
    """A placement search limited to a few pixels by their flat indices gives the same placement and report as the
    same search with those pixels cut out of the region mask (the candidates are the same, in the same order)."""
    from aias_augment.plan.placement import sample_placement

    an = analyse_scene(Frame(road_image(), K), CFG)
    asset = box_asset(extents=(0.3, 0.3, 0.7))
    region = an.region.mask
    h, w = region.shape
    placed = 0
    for seed in range(6):
        pick = np.random.default_rng(seed)
        y0, x0 = int(pick.integers(h // 2, h - 40)), int(pick.integers(0, w - 40))
        window = np.zeros((h, w), bool)
        window[y0 : y0 + 30, x0 : x0 + 30] = pick.uniform(size=(30, 30)) < 0.5
        runs = []
        for kw in ({"region_mask": region & window}, {"region_mask": region, "within_pixels": np.flatnonzero(window)}):
            p, report = sample_placement(asset, an.ground, K, np.random.default_rng(seed), **kw)
            runs.append((None if p is None else repr(p), report.to_dict()))
        assert runs[0] == runs[1]
        placed += runs[0][0] is not None
    assert placed >= 3

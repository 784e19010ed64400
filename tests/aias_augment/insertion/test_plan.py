import json

import numpy as np

from aias_augment.insertion import analyse_scene, plan_insertion
from aias_augment.scene import Frame
from tests.aias_augment.fixtures import box_asset
from tests.aias_augment.insertion.test_analyse import CFG, K, road_image
from tests.aias_augment.insertion.test_cache import OneAsset


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
    p = plan_insertion(an, CFG, np.random.default_rng(4), bank=OneAsset(box_asset()), n_objects=3,
                       existing_boxes_xyxy=existing)
    assert p.objects
    for o in p.objects:
        u, v = o.placement.contact_pixel
        assert an.region.mask[int(round(v)), int(round(u))]
        x0, y0, x1, y1 = o.placement.amodal_box_xyxy
        inter = max(0.0, min(x1, 320) - max(x0, 0)) * max(0.0, min(y1, 480) - max(y0, 240))
        assert inter < 0.5 * (x1 - x0) * (y1 - y0)

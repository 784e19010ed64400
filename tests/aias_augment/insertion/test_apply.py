import numpy as np

from aias_augment.insertion import analyse_scene, apply_plan, plan_insertion
from aias_augment.scene import Frame
from tests.aias_augment.fixtures import box_asset
from tests.aias_augment.insertion.test_analyse import CFG, K, road_image
from tests.aias_augment.insertion.test_cache import OneAsset


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
        allowed[max(0, int(y0 - h)):int(y1 + h) + 1, max(0, int(x0 - 2 * w)):int(x1 + 2 * w) + 1] = True
    assert not (changed & ~allowed).any()
    assert a.cover.max() > 0.99 and a.cover.min() == 0.0

import json
from dataclasses import replace

import numpy as np

from aias_augment.analyse.analysis import analyse_scene
from aias_augment.assets.bank.procedural import CATEGORY_SPECS, generate
from aias_augment.core.frame import Frame
from aias_augment.plan.insertion import plan_insertion
from tests.aias_augment.analyse.test_analysis import CFG, K, road_image


def test_procedural_source_same_seed_same_cones_and_the_record_carries_their_draws():
    cfg = replace(CFG, categories=("traffic_cone",), asset_source="procedural")
    an = analyse_scene(Frame(road_image(), K), cfg)
    a = plan_insertion(an, cfg, np.random.default_rng(1), n_objects=2)
    b = plan_insertion(an, cfg, np.random.default_rng(1), n_objects=2)
    assert len(a.objects) == 2
    assert json.dumps(a.to_dict()) == json.dumps(b.to_dict())
    recs = [p["asset_meta"] for p in a.to_dict()["placements"]]
    assert all(r["generator"] == "traffic_cone" for r in recs) and recs[0]["seed"] != recs[1]["seed"]
    for o, r in zip(a.objects, recs):
        assert o.placement.asset_source == "procedural:traffic_cone"
        rebuilt = generate(CATEGORY_SPECS["traffic_cone"], np.random.default_rng(r["seed"]))  # from the record alone
        np.testing.assert_allclose(
            o.asset.meshes[0].vertices, rebuilt.meshes[0].vertices * o.placement.scale, atol=1e-9
        )
        assert r["bands_z_m"] == rebuilt.meta["bands_z_m"]

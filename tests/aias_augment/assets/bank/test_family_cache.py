"""A finite procedural family (assets/bank/family_cache.py, ``InsertionConfig.family_members``): the same members in
every process, a record that replays to the same bytes, and member views that the view cache reuses."""

import hashlib
import json
import multiprocessing

import cv2
import numpy as np
import pytest

from aias_augment.apply.render import render_object_window
from aias_augment.apply.view_cache import ViewCache, render_from_view_cache
from aias_augment.assets.bank.family_cache import ProceduralFamily, member_seed
from aias_augment.assets.bank.procedural import procedural_asset_from_seed
from aias_augment.core.config import ConfigValueError, data_root
from aias_augment.core.frame import Frame
from aias_augment.pipeline.image import insert_into_image, load_preset
from aias_augment.pipeline.replay import replay
from tests.aias_augment.apply.test_view_cache import POSES, K, _box, _in, _iou, _lighting, _pose, _shaded_srgb

ROAD = data_root() / "tracon" / "images" / "train" / "cone (102).jpg"


def _asset_digest(asset) -> str:
    """Vertices, faces and texture pixels of an asset's meshes: what it looks like, independent of the object."""
    h = hashlib.sha256()
    for m in asset.meshes:
        h.update(np.ascontiguousarray(m.vertices, np.float64).tobytes())
        h.update(np.ascontiguousarray(m.faces, np.int64).tobytes())
        h.update(m.visual.material.image.tobytes())
    return h.hexdigest()


def draw_member(args) -> tuple[int, int, str]:
    """(index, member seed, digest) of the member that a generator seeded ``call_seed`` draws (run in a worker)."""
    members, family_seed, call_seed = args
    fam = ProceduralFamily("traffic_cone", members, family_seed)
    i = fam.draw_index(np.random.default_rng(call_seed))
    return i, member_seed(family_seed, i), _asset_digest(fam.member(i))


def test_two_spawned_processes_draw_the_same_member_for_the_same_seed():
    jobs = [(64, 11, s) for s in (0, 5)]
    with multiprocessing.get_context("spawn").Pool(2) as pool:
        a = pool.map(draw_member, jobs)
        b = pool.map(draw_member, jobs[::-1])[::-1]
    assert a == b
    assert a[0][0] != a[1][0]  # two call seeds, two members (the check below compares different cones)
    for i, seed, digest in a:  # the parent agrees, and the member is the procedural asset of its recorded seed
        assert draw_member((64, 11, [0, 5][a.index((i, seed, digest))])) == (i, seed, digest)
        assert _asset_digest(procedural_asset_from_seed("traffic_cone", seed)) == digest
    # another family seed: other members
    assert member_seed(12, a[0][0]) != a[0][1]


def test_members_are_built_once_and_kept_in_a_bounded_lru():
    fam = ProceduralFamily("traffic_cone", 8, 3, max_assets=2)
    m0 = fam.member(0)
    assert fam.member(0) is m0 and (fam.built, fam.hits) == (1, 1)
    assert m0.meta["family"] == {"category": "traffic_cone", "members": 8, "seed": 3, "index": 0}
    fam.member(1), fam.member(2)
    assert len(fam) == 2 and fam.member(0) is not m0 and fam.built == 4  # evicted, rebuilt
    assert _asset_digest(fam.member(0)) == _asset_digest(m0)


@pytest.mark.parametrize(
    "kw, match",
    [
        ({"family_members": 64}, "family_seed"),
        ({"family_members": 64, "family_seed": 1, "asset_source": "default"}, "procedural"),
        ({"family_members": 0, "family_seed": 1}, "family_members"),
        ({"family_members": 8, "family_seed": -1}, "family_seed"),
    ],
)
def test_a_family_without_its_seed_or_source_is_refused_at_construction(kw, match):
    with pytest.raises(ConfigValueError, match=match):
        load_preset("fast", **kw)


@pytest.mark.skipif(not ROAD.exists(), reason="shared data not present")
def test_a_family_record_replays_to_the_same_bytes_and_a_repeat_renders_nothing():
    img = cv2.resize(cv2.imread(str(ROAD))[..., ::-1], (640, 480), interpolation=cv2.INTER_AREA)
    cfg = load_preset("fast", min_objects=2, max_objects=2, family_members=16, family_seed=4)
    cache = ViewCache()
    res = insert_into_image(img, None, None, np.random.default_rng(2), cfg, view_cache=cache)
    record = json.loads(json.dumps(res.record.to_dict()))
    fams = [p["asset_meta"]["family"] for p in record["placements"]]
    assert fams and all(f["members"] == 16 and f["seed"] == 4 and 0 <= f["index"] < 16 for f in fams)
    assert all(p["asset_meta"]["seed"] == member_seed(4, f["index"]) for p, f in zip(record["placements"], fams))
    # the same draws again: the same members (the same objects), so every view is a cache hit and no GL render runs
    misses = cache.misses
    again = insert_into_image(img, None, None, np.random.default_rng(2), cfg, view_cache=cache)
    assert cache.misses == misses and np.array_equal(again.image, res.image)
    # the record alone (members rebuilt from their recorded seeds, views rendered anew) gives the same bytes
    replayed = replay(record, Frame(img, None), cfg)
    assert np.array_equal(replayed.image, res.image)


@pytest.mark.parametrize("pose", POSES[:3])
def test_a_members_cached_view_matches_a_fresh_render_of_the_member(pose):
    """The view cache's bounds for the cone (tests/aias_augment/apply/test_view_cache.py): box IoU >= 0.95, mask IoU
    >= 0.9, <= 12 sRGB levels over the pixels both call the object, depth within 3 %; the view read from the cache
    (a hit) is the one that was rendered."""
    fam = ProceduralFamily("traffic_cone", 64, 9)
    member = fam.member(5)
    cache, light, T = ViewCache(), _lighting(), _pose(*pose)
    roi_v, view = render_from_view_cache(member, T, K, cache)
    hits = cache.hits
    roi_h, hit = render_from_view_cache(fam.member(5), T, K, cache)
    assert cache.hits == hits + 1 and roi_h == roi_v and np.array_equal(hit.albedo_linear, view.albedo_linear)
    fresh = procedural_asset_from_seed("traffic_cone", member_seed(9, 5))  # the same member, made anew
    roi_f, full = render_object_window(fresh, T, K, ssaa=4)
    win = (min(roi_f[0], roi_v[0]), min(roi_f[1], roi_v[1]), max(roi_f[2], roi_v[2]), max(roi_f[3], roi_v[3]))
    a, al_a = _shaded_srgb(full, win, roi_f, light)
    b, al_b = _shaded_srgb(view, win, roi_v, light)
    ma, mb = al_a > 0.5, al_b > 0.5
    assert _iou(_box(ma), _box(mb)) >= 0.95
    assert (ma & mb).sum() / (ma | mb).sum() >= 0.9
    assert float(np.abs(a - b)[ma & mb].mean()) <= 12.0
    da, db = _in(win, roi_f, full.depth), _in(win, roi_v, view.depth)
    assert np.median(np.abs(da - db)[ma & mb] / da[ma & mb]) < 0.03

import numpy as np

from aias_augment.analyse.cache import SceneCache
from aias_augment.core.frame import Frame
from aias_augment.pipeline.image import insert_into_image
from tests.aias_augment.analyse.test_analysis import CFG, K, road_image
from tests.aias_augment.fixtures import box_asset


class OneAsset:
    def __init__(self, asset):
        self.asset = asset

    def sample(self, category, rng):
        return self.asset


def test_lru_hits_and_evicts():
    c = SceneCache(max_items=2)
    frames = [Frame(road_image(s), K) for s in range(3)]
    a0 = c.get(frames[0], CFG)
    assert c.get(Frame(road_image(0), K), CFG) is a0 and (c.hits, c.misses) == (1, 1)
    c.get(frames[1], CFG)
    c.get(frames[2], CFG)  # evicts frame 0 (least recently used)
    assert len(c) == 2
    assert c.get(frames[0], CFG) is not a0 and c.misses == 4


def test_disk_cache_is_shared_and_gives_the_same_pixels(tmp_path):
    img = road_image()
    asset = box_asset()
    run = lambda cache: insert_into_image(
        img,
        rng=np.random.default_rng(5),
        cfg=CFG,
        intrinsics=K,  # noqa: E731
        bank=OneAsset(asset),
        n_objects=2,
        scene_cache=cache,
    )
    plain = run(None)
    first = SceneCache(directory=tmp_path)
    a = run(first)
    assert first.misses == 1 and len(list(tmp_path.rglob("*.npz"))) == 1
    other = SceneCache(directory=tmp_path)  # another process / run: reads the folder
    b = run(other)
    assert other.disk_hits == 1 and other.misses == 0
    assert len(plain.record.placements) == 2
    assert np.array_equal(plain.image, a.image) and np.array_equal(a.image, b.image)
    assert np.array_equal(plain.bboxes, b.bboxes)


def test_damaged_disk_entry_is_recomputed(tmp_path):
    f = Frame(road_image(), K)
    c = SceneCache(directory=tmp_path)
    a = c.get(f, CFG)
    p = next(tmp_path.rglob("*.npz"))
    p.write_bytes(b"not an npz")
    c2 = SceneCache(directory=tmp_path)
    b = c2.get(f, CFG)
    assert c2.misses == 1 and b.to_dict() == a.to_dict()


def test_pickles_empty():
    import pickle

    c = SceneCache(max_items=4)
    c.get(Frame(road_image(), K), CFG)
    d = pickle.loads(pickle.dumps(c))
    assert len(d) == 0 and d.max_items == 4

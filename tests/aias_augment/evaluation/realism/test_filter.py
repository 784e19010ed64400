import numpy as np
import pytest

from aias_augment.evaluation.realism.features import Lite0Features
from aias_augment.evaluation.realism.filter import RealismFilter, best_of


def _scene(rng: np.random.Generator, outlined: bool):
    """A grey textured road with one orange cone (a triangle); ``outlined``: a dark halo around it, the kind of
    edge artefact a paste leaves. Returns (image, boxes_xyxy, outlined)."""
    import cv2

    img = np.clip(rng.normal(120, 12, (160, 160, 3)), 0, 255).astype(np.uint8)
    x, y, h = int(rng.integers(40, 110)), int(rng.integers(70, 120)), int(rng.integers(30, 45))
    tri = np.array([[x, y - h], [x - h // 3, y], [x + h // 3, y]], np.int32)
    if outlined:
        cv2.polylines(img, [tri], True, (15, 15, 15), 4)
    cv2.fillPoly(img, [tri], (250, 90, 30))
    return img, np.array([[x - h / 3 - 2, y - h - 2, x + h / 3 + 2, y + 2]]), outlined


@pytest.fixture(scope="module")
def judge():
    rng = np.random.default_rng(0)
    real, ins = [_scene(rng, False) for _ in range(30)], [_scene(rng, True) for _ in range(30)]
    from aias_augment.evaluation.realism.crops import object_crops

    def crops(scenes):
        out = []
        for img, b, _ in scenes:
            out += object_crops(img, b, rng)[0]
        return out

    return RealismFilter.fit(
        crops(real),
        list(range(30)),
        crops(ins),
        list(range(30)),
        Lite0Features(input_size=96),
        np.random.default_rng(1),
    )


def test_the_filter_separates_an_edge_artefact_and_thresholds_at_the_real_median(judge):
    """Out of fold it tells the outlined cones from the clean ones; half the real crops lie at or below the
    threshold by construction, and few outlined ones do."""
    assert judge.fit_report["out_of_fold_auc"] > 0.9
    assert judge.fit_report["inserted_accepted_share"] < 0.2
    rng = np.random.default_rng(5)
    clean = [judge.score(*_scene(rng, False)[:2], rng)[0] for _ in range(10)]
    dirty = [judge.score(*_scene(rng, True)[:2], rng)[0] for _ in range(10)]
    assert np.median(clean) < judge.threshold < np.median(dirty)


def test_best_of_redraws_what_looks_inserted_and_keeps_the_first_draw_when_it_passes(judge):
    """Draws that are outlined half of the time: with 4 attempts the kept ones are almost never outlined (half
    of them would be without the filter); one attempt is the unfiltered draw itself, on the same stream."""

    def draw(g):
        return _scene(g, bool(g.uniform() < 0.5))

    kept = [best_of(draw, lambda r: r[:2], judge, np.random.default_rng([7, s]), 4)[0] for s in range(20)]
    assert sum(r[2] for r in kept) <= 2
    for s in range(5):
        r, info = best_of(draw, lambda r: r[:2], judge, np.random.default_rng([8, s]), 1)
        want = draw(np.random.default_rng([8, s]))
        assert np.array_equal(r[0], want[0]) and info["attempt"] == 0 and len(info["scores"]) == 1
    with pytest.raises(ValueError):
        best_of(draw, lambda r: r[:2], judge, np.random.default_rng(0), 0)

"""The image door's labelled objects occlude by depth order (issue 53 item 2): a labelled object standing nearer
than an inserted one hides it, a farther one is covered by it, and both visibilities follow.

A synthetic road (the test_image frame, known K) gets two painted objects, each labelled by a box 3 px around
it: a near one (its base below the inserted object's) over the inserted object's lower left, and a far one (its
base above) behind its right side. The same seed and insertion site with and without the labels: the painted
pixels are the truth the checks use, not the GrabCut masks the door computes.
"""

from dataclasses import replace

import cv2
import numpy as np
import pytest
from pycocotools import mask as mask_utils

from aias_augment.core.frame import Frame
from aias_augment.pipeline.image import InsertionConfig, InsertionRecord, insert_into_image, load_preset
from aias_augment.pipeline.replay import replay
from aias_augment.plan.placement import PlacementConfig
from tests.aias_augment.fixtures import box_asset
from tests.aias_augment.pipeline.test_image import K, OneAsset, road_frame

ASSET = box_asset(extents=(1.0, 1.0, 1.5), category="box")
NEAR = np.array([[105, 330], [125, 330], [150, 462], [80, 462]], np.int32)  # a cone-like trapezoid, base row 462
FAR = np.array([[165, 235], [255, 235], [255, 382], [165, 382]], np.int32)  # base row 382: behind the object
RIM = np.ones((5, 5), np.uint8)  # 2 px


def _cfg(preset: str | None) -> InsertionConfig:
    base = InsertionConfig(harmonize=False, ssaa=1) if preset is None else load_preset(preset)
    return replace(base, categories=("box",), placement_cfg=PlacementConfig(max_overlap_existing=1.0))


def _painted():
    img = road_frame()
    rng = np.random.default_rng(1)
    masks = []
    for poly, colour in ((NEAR, (235, 110, 25)), (FAR, (40, 70, 170))):
        m = np.zeros(img.shape[:2], np.uint8)
        cv2.fillPoly(m, [poly], 1)
        img[m > 0] = np.clip(np.array(colour) + rng.integers(-6, 6, (int(m.sum()), 3)), 0, 255)
        masks.append(m > 0)
    boxes = []
    for m in masks:
        ys, xs = np.nonzero(m)
        boxes.append([xs.min() - 3, ys.min() - 3, xs.max() - xs.min() + 7, ys.max() - ys.min() + 7])
    return img, masks, np.array(boxes, float)


def _site(shape) -> np.ndarray:
    """The insertion site fixed to the one an unpainted road gives seed 5 (the paint changes the analysis' region)."""
    site = np.zeros(shape[:2], bool)
    site[406:411, 149:154] = True
    return site


def _run(img, cfg, boxes=None, labels=None):
    return insert_into_image(
        img,
        boxes,
        labels,
        rng=np.random.default_rng(5),
        cfg=cfg,
        intrinsics=K,
        bank=OneAsset(ASSET),
        n_objects=1,
        meta={"placeable_mask": _site(img.shape)},
    )


@pytest.fixture(scope="module", params=[None, "balanced"], ids=["plain", "balanced"])
def runs(request):
    img, masks, boxes = _painted()
    cfg = _cfg(request.param)
    plain = _run(img.copy(), cfg)
    labelled = _run(img.copy(), cfg, boxes, ["person", "sign"])
    return img, masks, boxes, plain, labelled, cfg


def _visible(ann) -> np.ndarray:
    return mask_utils.decode(ann.rle).astype(bool)


def test_the_same_placement_with_and_without_labels(runs):
    _, _, _, plain, labelled, _ = runs
    assert plain.record.placements == labelled.record.placements
    assert "2 meet an inserted object" in labelled.record.modules["occlusion"]


def test_a_nearer_labelled_object_is_untouched_and_hides_its_share(runs):
    """Inside the near object (minus a 2 px rim) the output is the input's bytes (without the labels the inserted
    object is drawn there); the inserted object's visibility drops by the share of its visible mask there."""
    img, (near, _), _, plain, labelled, _ = runs
    core = cv2.erode(near.astype(np.uint8), RIM) > 0
    assert (plain.image[core] != img[core]).any(-1).mean() > 0.5  # the defect: drawn over the nearer object
    np.testing.assert_array_equal(labelled.image[core], img[core])
    a_plain, a_lab = plain.record.annotations[0], labelled.record.annotations[0]
    amodal = a_plain.area / a_plain.visibility
    vis_plain = _visible(a_plain)
    rim = (cv2.dilate(near.astype(np.uint8), RIM) > 0) & ~core
    hidden = np.count_nonzero(vis_plain & near) / amodal
    slack = np.count_nonzero(vis_plain & rim) / amodal
    assert hidden > 0.1
    assert abs((a_plain.visibility - a_lab.visibility) - hidden) <= slack
    assert not (_visible(a_lab) & core).any()
    assert labelled.record.existing_visibility[0] == 1.0  # nothing nearer covers the near object


def test_a_farther_labelled_object_is_covered_and_loses_its_share(runs):
    """Over the far object the inserted object is drawn as without labels, and the far box's visibility is the
    share of it the inserted object's visible mask leaves uncovered."""
    img, (_, far), boxes, plain, labelled, _ = runs
    vis_lab = _visible(labelled.record.annotations[0])
    over = _visible(plain.record.annotations[0]) & far
    assert over.sum() > 1000
    assert (vis_lab & over).sum() == over.sum()
    x, y, w, h = boxes[1].astype(int)
    in_box = vis_lab[y : y + h, x : x + w]
    # the record counts the soft (anti-aliased) coverage, the mask is it at 0.5: they differ on its edge pixels
    edge = (cv2.dilate(in_box.astype(np.uint8), np.ones((3, 3), np.uint8)) > 0) & ~(
        cv2.erode(in_box.astype(np.uint8), np.ones((3, 3), np.uint8)) > 0
    )
    assert labelled.record.existing_visibility[1] == pytest.approx(1.0 - in_box.mean(), abs=edge.mean() / 2)
    assert labelled.record.existing_visibility[1] < 0.7
    assert (labelled.image[over] != img[over]).any(-1).mean() > 0.9


def test_replay_of_a_labelled_record_gives_the_same_bytes(runs):
    img, _, _, _, labelled, cfg = runs
    record = InsertionRecord.from_dict(labelled.record.to_dict()).to_dict()
    assert len(record["labelled_boxes_xywh"]) == 2
    frame = Frame(img.copy(), K, meta={"placeable_mask": _site(img.shape)})
    again = replay(record, frame, cfg, assets=lambda p: ASSET)
    np.testing.assert_array_equal(again.image, labelled.image)

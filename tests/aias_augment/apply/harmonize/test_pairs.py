import json

import numpy as np
import pytest

from aias_augment.apply.harmonize.pairs import (
    PerturbRanges,
    apply_perturbation,
    grabcut_mask,
    random_region_mask,
    read_coco_boxes,
    read_yolo_boxes,
    sample_perturbation,
)


def test_perturbation_changes_only_the_mask(street_rgb):
    rng = np.random.default_rng(3)
    mask = random_region_mask(street_rgb.shape[:2], rng)
    p = sample_perturbation(PerturbRanges(blur_probability=1.0, noise_probability=1.0), rng)
    before = street_rgb.copy()
    out = apply_perturbation(street_rgb, mask.astype(np.float32), p, rng)
    np.testing.assert_array_equal(street_rgb, before)
    np.testing.assert_array_equal(out[~mask], street_rgb[~mask])
    assert np.abs(out[mask].astype(int) - street_rgb[mask]).mean() > 2


def test_exposure_one_stop_doubles_linear_light():
    img = np.full((8, 8, 3), 100, np.uint8)
    p = sample_perturbation(
        PerturbRanges(
            exposure_stops_range=(1, 1),
            wb_log_sigma=0,
            saturation_range=(1, 1),
            gamma_range=(1, 1),
            blur_probability=0,
            noise_probability=0,
        ),
        np.random.default_rng(0),
    )
    out = apply_perturbation(img, np.ones((8, 8), np.float32), p, np.random.default_rng(0))
    lin = lambda v: ((v / 255 + 0.055) / 1.055) ** 2.4  # noqa: E731
    assert lin(out[0, 0, 0]) == pytest.approx(2 * lin(100), rel=0.02)


def test_same_seed_same_perturbation():
    r = PerturbRanges()
    assert sample_perturbation(r, np.random.default_rng(5)) == sample_perturbation(r, np.random.default_rng(5))


def test_yolo_and_coco_boxes(tmp_path):
    (tmp_path / "a.txt").write_text("0 0.5 0.5 0.2 0.4\n\n")
    assert read_yolo_boxes(tmp_path / "a.txt", 100, 50) == [(40, 15, 60, 35)]
    assert read_yolo_boxes(tmp_path / "missing.txt", 100, 50) == []
    (tmp_path / "bad.txt").write_text("0 0.5 0.5\n")
    with pytest.raises(ValueError):
        read_yolo_boxes(tmp_path / "bad.txt", 100, 50)
    coco = {
        "images": [
            {"id": 1, "file_name": "x.jpg", "width": 100, "height": 50},
            {"id": 2, "file_name": "y.jpg", "width": 100, "height": 50},
        ],
        "annotations": [{"id": 1, "image_id": 1, "bbox": [10, 5, 20, 10], "category_id": 1}],
    }
    (tmp_path / "c.json").write_text(json.dumps(coco))
    assert read_coco_boxes(tmp_path / "c.json") == {"x.jpg": [(10, 5, 30, 15)], "y.jpg": []}


def test_grabcut_segments_a_disc_from_its_box():
    rng = np.random.default_rng(0)
    img = (rng.integers(90, 140, (120, 160, 1)) * np.ones(3)).astype(np.uint8)  # grey textured ground
    yy, xx = np.mgrid[:120, :160]
    disc = (xx - 80) ** 2 + (yy - 60) ** 2 <= 25**2
    img[disc] = (230, 120, 20)
    mask = grabcut_mask(img, (50, 30, 111, 91))
    assert mask is not None
    iou = (mask & disc).sum() / (mask | disc).sum()
    assert iou > 0.85

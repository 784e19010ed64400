import numpy as np
import pytest

from aias_augment.scenes.retrieval.features import FeatureConfig, extract_features, rootsift, to_bgr

SMALL = FeatureConfig(max_side_px=480, seg_max_side_px=240, n_features=500)


def test_rootsift_is_unit_norm_hellinger():
    rng = np.random.default_rng(0)
    a, b = rng.uniform(0, 50, (2, 128)).astype(np.float32)
    ra, rb = rootsift(np.stack([a, b]))
    assert np.linalg.norm(ra) == pytest.approx(1.0, abs=1e-5)
    # dot product of RootSIFT = Hellinger kernel of the L1-normalised SIFT
    assert ra @ rb == pytest.approx(np.sum(np.sqrt(a / a.sum() * b / b.sum())), rel=1e-5)
    assert np.all(np.isfinite(rootsift(np.zeros((1, 128)))))


def test_features_are_region_balanced_and_in_original_pixels(frames):
    img = frames[0][1]
    f = extract_features(img, SMALL)
    h, w = img.shape[:2]
    assert 100 < len(f) <= SMALL.n_features + 200
    assert f.xy[:, 0].max() < w and f.xy[:, 1].max() < h and f.xy.min() >= -0.5
    assert f.image_size == (w, h)
    counts = np.bincount(f.region)
    assert (counts > 0).sum() >= 5  # many regions contribute
    assert counts.max() < 0.5 * len(f)  # no single region takes most keypoints


def test_mask_restricts_keypoints(frames):
    img = frames[0][1]
    mask = np.zeros(img.shape[:2], bool)
    mask[:, : img.shape[1] // 3] = True
    f = extract_features(img, SMALL, mask=mask)
    assert len(f) > 10 and f.xy[:, 0].max() < img.shape[1] / 3 + 2


def test_input_checks():
    with pytest.raises(ValueError, match="uint8"):
        to_bgr(np.zeros((8, 8), np.float32))
    with pytest.raises(ValueError, match="shape"):
        to_bgr(np.zeros((8, 8, 2), np.uint8))
    with pytest.raises(ValueError):
        FeatureConfig(max_side_px=10)
    f = extract_features(np.zeros((64, 64), np.uint8), SMALL)  # a blank frame has no features, no crash
    assert len(f) == 0

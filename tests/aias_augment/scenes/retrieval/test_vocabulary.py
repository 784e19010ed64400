import numpy as np
import pytest
from sklearn.metrics import pairwise_distances_argmin

from aias_augment.scenes.retrieval.vocabulary import Vocabulary, train_vocabulary


def test_assign_is_nearest_centre():
    rng = np.random.default_rng(1)
    v = Vocabulary(rng.uniform(0, 1, (50, 128)).astype(np.float32))
    x = rng.uniform(0, 1, (1000, 128)).astype(np.float32)
    np.testing.assert_array_equal(v.assign(x, chunk=97), pairwise_distances_argmin(x, v.centers))


def test_training_is_seeded_and_recovers_clusters():
    rng = np.random.default_rng(0)
    centres = rng.uniform(0, 1, (8, 128)).astype(np.float32)
    x = np.repeat(centres, 200, axis=0) + rng.normal(0, 0.01, (1600, 128)).astype(np.float32)
    a = train_vocabulary(x, 8, np.random.default_rng(3))
    b = train_vocabulary(x, 8, np.random.default_rng(3))
    np.testing.assert_array_equal(a.centers, b.centers)
    labels = a.assign(x)
    assert len(np.unique(labels)) == 8  # each true cluster gets its own word
    assert all(len(np.unique(labels[i * 200 : (i + 1) * 200])) == 1 for i in range(8))
    with pytest.raises(ValueError, match="at least"):
        train_vocabulary(x[:5], 8, rng)

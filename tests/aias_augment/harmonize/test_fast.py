import numpy as np
import torch

from aias_augment.harmonize.fast import (FastColorNet, FastConfig, apply_affine, load_fast, run_fast,
                                         save_fast_checkpoint)
from aias_augment.harmonize.network import masked_stats


def test_affine_identity_and_known_gain():
    img = torch.rand(1, 3, 8, 8)
    eye = torch.eye(3, 4)[None]
    assert torch.allclose(apply_affine(img, eye), img)
    gain = eye.clone()
    gain[0, 0, 0] = 0.5
    assert torch.allclose(apply_affine(img, gain)[:, 0], 0.5 * img[:, 0])


def test_masked_stats_match_numpy():
    img, mask = torch.rand(1, 3, 10, 10), (torch.rand(1, 1, 10, 10) > 0.4).float()
    s = masked_stats(img, mask)[0].numpy()
    fg = img[0].numpy().reshape(3, -1)[:, mask[0, 0].numpy().ravel() > 0]
    np.testing.assert_allclose(s[:3], fg.mean(1), rtol=0, atol=0.01 * 1 + 0.1 / fg.shape[1])
    np.testing.assert_allclose(s[3:6], fg.std(1), atol=0.02)


def test_untrained_fast_model_is_identity_and_round_trips(tmp_path):
    model = FastColorNet(FastConfig(thumbnail_px=32, channels=4))
    image = np.random.default_rng(0).random((40, 50, 3), dtype=np.float32)
    mask = np.zeros((40, 50), bool)
    mask[10:25, 10:30] = True
    np.testing.assert_allclose(run_fast(model, image, mask), image, atol=1e-6)
    with torch.no_grad():
        model.mlp[-1].bias.add_(0.1)
    save_fast_checkpoint(tmp_path / "f.pt", model, {})
    out = run_fast(load_fast(tmp_path / "f.pt"), image, mask)
    np.testing.assert_array_equal(out[~mask], image[~mask])
    assert np.abs(out[mask] - image[mask]).mean() > 0.05

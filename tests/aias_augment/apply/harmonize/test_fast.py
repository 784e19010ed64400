import numpy as np
import torch

from aias_augment.apply.harmonize.fast import (
    FastColorNet,
    FastConfig,
    apply_affine,
    load_fast,
    masked_stats,
    run_fast,
    save_fast_checkpoint,
)


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


def test_masked_quantiles_match_numpy_per_channel():
    from aias_augment.apply.harmonize.fast import QUANTILES, masked_quantiles

    g = torch.Generator().manual_seed(3)
    img, mask = torch.rand(2, 3, 12, 9, generator=g), (torch.rand(2, 1, 12, 9, generator=g) > 0.5).float()
    mask[1] = 1.0  # an empty background side
    q = masked_quantiles(img, mask).numpy()
    k = len(QUANTILES)
    assert q.shape == (2, 2 * 3 * k)
    for b in range(2):
        for side, sel in enumerate((mask[b, 0].numpy() > 0.5, mask[b, 0].numpy() <= 0.5)):
            for c in range(3):
                got = q[b, side * 3 * k + c * k : side * 3 * k + (c + 1) * k]
                if sel.any():
                    np.testing.assert_allclose(got, np.quantile(img[b, c].numpy()[sel], QUANTILES), atol=1e-6)
                else:
                    np.testing.assert_array_equal(got, 0.5)


def test_statistics_come_from_the_full_input_crop():
    """With input_px > thumbnail_px a one-pixel-wide white stripe on the object reaches the per-channel top quantile
    at full strength; on the thumbnail it is averaged with its neighbours."""
    from aias_augment.apply.harmonize.fast import masked_quantiles, thumbnail

    crop = torch.full((1, 3, 64, 64), 0.2)
    crop[:, :, :, 20::4] = 1.0  # 1-px stripes, 1/4 of the object's pixels
    mask = torch.zeros(1, 1, 64, 64)
    mask[:, :, 16:48, 16:48] = 1
    full = masked_quantiles(crop, mask)[0, 6]  # red channel, foreground, 0.98 quantile
    small = masked_quantiles(*thumbnail(crop, mask, 16))[0, 6]
    assert float(full) == 1.0 and float(small) < 0.6
    model = FastColorNet(
        FastConfig(thumbnail_px=16, channels=4, quantile_stats=True, quantile_channels="rgb", input_px=64)
    )
    torch.nn.init.normal_(model.mlp[-1].weight, std=0.1)
    with torch.no_grad():
        a = model(crop, mask)
    assert a.shape == (1, 3, 4) and torch.isfinite(a).all()
    image = np.random.default_rng(0).random((80, 90, 3), dtype=np.float32)
    comp = np.zeros((80, 90), bool)
    comp[30:50, 30:60] = True
    out = run_fast(model, image, comp)
    np.testing.assert_array_equal(out[~comp], image[~comp])


def test_fast_config_rejects_bad_values():
    import pytest

    with pytest.raises(ValueError, match="quantile_channels"):
        FastConfig(quantile_channels="hsv")
    with pytest.raises(ValueError, match="input_px"):
        FastConfig(thumbnail_px=64, input_px=32)

import numpy as np
import pytest
import torch

from aias_augment.apply.harmonize import harmonize
from aias_augment.apply.harmonize.fast import FastColorNet, FastConfig, save_fast_checkpoint
from aias_augment.apply.harmonize.network import Generator, NetworkConfig, save_checkpoint


@pytest.fixture(scope="module")
def checkpoints(tmp_path_factory):
    """Small randomly perturbed (so not identity) models saved in the shipped format."""
    d = tmp_path_factory.mktemp("ckpt")
    torch.manual_seed(0)
    gen = Generator(NetworkConfig(resolution_px=64, base_channels=4, levels=2, dilations=(2,), critic_channels=4))
    fast = FastColorNet(FastConfig(thumbnail_px=32, channels=4))
    with torch.no_grad():
        for p in list(gen.parameters()) + list(fast.parameters()):
            p.add_(0.05 * torch.randn_like(p))
    save_checkpoint(d / "net.pt", gen, {})
    save_fast_checkpoint(d / "fast.pt", fast, {})
    return {"network": str(d / "net.pt"), "fast": str(d / "fast.pt")}


def soft_mask(h, w):
    yy, xx = np.mgrid[:h, :w]
    r = np.hypot(xx - w * 0.45, yy - h * 0.55)
    return np.clip((40 - r) / 6, 0, 1).astype(np.float32)  # disc of radius ~37 px with a 6 px soft edge


@pytest.mark.parametrize("views", [True, False])
@pytest.mark.parametrize("method", ["none", "reinhard", "camera", "fast", "network"])
def test_only_masked_pixels_change_and_input_is_kept(street_rgb, checkpoints, method, views):
    mask = soft_mask(*street_rgb.shape[:2])
    img = street_rgb.copy()
    img[mask > 0] = np.clip(img[mask > 0].astype(int) + (40, 10, -20), 0, 255)  # a visibly mismatched object
    before, mask_before = img.copy(), mask.copy()
    out = harmonize(img, mask, method, np.random.default_rng(0), checkpoints.get(method), test_time_views=views)
    assert out.dtype == np.uint8 and out.shape == img.shape and out is not img
    np.testing.assert_array_equal(img, before)
    np.testing.assert_array_equal(mask, mask_before)
    np.testing.assert_array_equal(out[mask == 0], img[mask == 0])
    if method != "none":
        assert np.abs(out[mask > 0.5].astype(int) - img[mask > 0.5]).mean() > 0.5
    assert (
        harmonize(img, mask.astype(np.float64), method, np.random.default_rng(0), checkpoints.get(method)).shape
        == img.shape
    )
    # Same rng seed -> same result.
    again = harmonize(img, mask, method, np.random.default_rng(0), checkpoints.get(method), test_time_views=views)
    np.testing.assert_array_equal(out, again)
    if method in ("fast", "network"):  # the 6-view average is not the one view's prediction
        other = harmonize(
            img, mask, method, np.random.default_rng(0), checkpoints.get(method), test_time_views=not views
        )
        assert np.abs(other.astype(int) - out).max() > 0


def test_soft_edge_lies_between_input_and_harmonized(street_rgb):
    mask = soft_mask(*street_rgb.shape[:2])
    img = street_rgb.copy()
    full = harmonize(img, (mask > 0).astype(np.float32), "reinhard", rng=np.random.default_rng(0))
    soft = harmonize(img, mask, "reinhard", rng=np.random.default_rng(0))
    edge = (mask > 0.1) & (mask < 0.9)
    lo, hi = np.minimum(img, full).astype(int), np.maximum(img, full).astype(int)
    assert ((soft[edge] >= lo[edge] - 1) & (soft[edge] <= hi[edge] + 1)).all()


def test_empty_mask_returns_a_copy(street_rgb):
    out = harmonize(street_rgb, np.zeros(street_rgb.shape[:2], np.float32), "camera", rng=np.random.default_rng(0))
    np.testing.assert_array_equal(out, street_rgb)
    assert out is not street_rgb


@pytest.mark.parametrize(
    "bad",
    [
        dict(mask_shape=(10, 11)),
        dict(mask_value=np.nan),
        dict(mask_value=1.5),
        dict(image_dtype=np.float32),
        dict(image_channels=4),
        dict(mask_dtype=np.uint8),
        dict(method="magic"),
    ],
)
def test_bad_inputs_raise(bad):
    img = np.zeros((10, 12, bad.get("image_channels", 3)), bad.get("image_dtype", np.uint8))
    mask = np.zeros(bad.get("mask_shape", (10, 12)), bad.get("mask_dtype", np.float32))
    mask[2:5, 2:5] = bad.get("mask_value", 1.0)
    with pytest.raises(ValueError):
        harmonize(img, mask, bad.get("method", "reinhard"), rng=np.random.default_rng(0))


def test_missing_checkpoint_names_the_training_command(tmp_path):
    img, mask = np.zeros((16, 16, 3), np.uint8), np.ones((16, 16), np.float32)
    for method in ("network", "fast"):
        with pytest.raises(FileNotFoundError, match="studies.harmonization.harmonizer.train"):
            harmonize(img, mask, method, checkpoint=str(tmp_path / "nope.pt"), rng=np.random.default_rng(0))


def test_harmonize_clip_applies_one_transform_and_leaves_the_background():
    """Same object in frames whose surroundings differ: 'fast' gives the object the same colours in every frame
    (one transform for the clip: no flicker); pixels outside the masks are unchanged bit for bit."""
    from aias_augment.apply.harmonize import harmonize_clip

    rng = np.random.default_rng(0)
    frames, masks = [], []
    for k in range(4):
        f = np.clip(rng.normal(90 + 25 * k, 20, (64, 80, 3)), 0, 255).astype(np.uint8)  # exposure changes per frame
        f[20:44, 30:50] = (230, 120, 30)  # the object, identical in every frame
        m = np.zeros((64, 80), np.float32)
        m[20:44, 30:50] = 1.0
        frames.append(f), masks.append(m)
    frames.append(frames[0].copy()), masks.append(None)  # object not visible in the last frame
    out = harmonize_clip(frames, masks, "fast", rng=np.random.default_rng(0))
    obj = [o[20:44, 30:50].reshape(-1, 3) for o in out[:4]]
    assert all(np.array_equal(obj[0], o) for o in obj[1:])
    assert not np.array_equal(obj[0], frames[0][20:44, 30:50].reshape(-1, 3))  # it did change the object
    for o, f, m in zip(out, frames, masks):
        outside = np.ones(f.shape[:2], bool) if m is None else m == 0
        assert np.array_equal(o[outside], f[outside])
    with pytest.raises(ValueError, match="masks"):
        harmonize_clip(frames, masks[:-1], rng=np.random.default_rng(0))

"""The fast harmonizer's NumPy inference (apply/harmonize/fast_infer.py) against the torch model it was trained as: each
op (conv, area pooling, quantiles) and the whole forward agree to float32 rounding, the npz export round-trips and a
stale one is refused, and a fast-preset insertion runs without importing torch."""

import subprocess
import sys

import numpy as np
import pytest
import torch
import torch.nn.functional as F

from aias_augment.apply.harmonize.fast import FastColorNet, FastConfig, save_fast_checkpoint
from aias_augment.apply.harmonize.fast_infer import (
    FastColorNetNP,
    adaptive_avg_pool,
    conv3x3_s2_relu,
    load_fast_np,
    npz_path,
)


def test_conv_and_area_pool_match_torch_on_odd_sizes():
    g = torch.Generator().manual_seed(0)
    for h, w in ((7, 9), (64, 64), (5, 4)):
        x = torch.rand(3, h, w, generator=g)
        wt, b = torch.randn(5, 3, 3, 3, generator=g), torch.randn(5, generator=g)
        ref = F.relu(F.conv2d(x[None], wt, b, stride=2, padding=1))[0].numpy()
        got = conv3x3_s2_relu(x.numpy(), wt.reshape(5, -1).numpy(), b.numpy())
        np.testing.assert_allclose(got, ref, atol=1e-5)
    for (h, w), out in (((64, 64), (4, 4)), ((80, 70), (64, 64)), ((9, 7), (4, 3))):
        x = torch.rand(2, h, w, generator=g)
        np.testing.assert_allclose(
            adaptive_avg_pool(x.numpy(), out), F.adaptive_avg_pool2d(x[None], out)[0].numpy(), atol=1e-6
        )
        np.testing.assert_allclose(
            adaptive_avg_pool(x.numpy(), out), F.interpolate(x[None], size=out, mode="area")[0].numpy(), atol=1e-6
        )


@pytest.mark.parametrize(
    "cfg",
    [
        FastConfig(quantile_stats=True, quantile_channels="rgb"),  # the shipped architecture
        FastConfig(thumbnail_px=32, channels=8, quantile_stats=True, quantile_channels="luma", masked_pooling=True),
        FastConfig(thumbnail_px=32, channels=4, input_px=45, quantile_stats=True, quantile_channels="rgb"),
        FastConfig(thumbnail_px=16, channels=4),
    ],
)
def test_numpy_forward_matches_torch(cfg):
    torch.manual_seed(1)
    model = FastColorNet(cfg).eval()
    with torch.no_grad():  # trained-like weights: the zero-initialised last layer would hide every error
        for p in model.parameters():
            p.copy_(torch.randn_like(p) * 0.2)
    npm = FastColorNetNP.from_torch(model)
    g = torch.Generator().manual_seed(2)
    for k in range(3):
        s = cfg.in_px
        crop = torch.rand(1, 3, s, s, generator=g)
        mask = (torch.rand(1, 1, s, s, generator=g) > (0.5 if k < 2 else 1.0)).float()  # k = 2: empty object
        with torch.no_grad():
            ref = model(crop, mask)[0].numpy()
        got = npm.forward(crop[0].permute(1, 2, 0).numpy(), mask[0, 0].numpy())
        assert got.shape == (3, 4) and got.dtype == np.float32
        np.testing.assert_allclose(got, ref, atol=2e-5, rtol=1e-5)
        assert np.abs(ref - np.eye(3, 4)).max() > 0.01  # the check is not on an identity


def test_opencv_dnn_features_equal_the_numpy_convolutions_across_threads_and_pickling():
    """FastColorNetNP.features (OpenCV's DNN when present) against the NumPy conv chain and torch's conv2d, on
    random weights and inputs of two sizes; four threads at once get the same values; a pickled copy (no nets)
    rebuilds its own."""
    import pickle
    import threading

    torch.manual_seed(3)
    model = FastColorNet(FastConfig(quantile_stats=True, quantile_channels="rgb")).eval()
    with torch.no_grad():
        for p in model.parameters():
            p.copy_(torch.randn_like(p) * 0.2)
    npm = FastColorNetNP.from_torch(model)
    rng = np.random.default_rng(4)
    for size in (64, 37):
        x = rng.random((7, size, size), dtype=np.float32)
        ref = x
        for w, b in npm.convs:
            ref = conv3x3_s2_relu(ref, w, b)
        with torch.no_grad():
            tref = model.features(torch.from_numpy(x)[None])[0].numpy()
        got = npm.features(x)
        assert got.shape == ref.shape == tref.shape
        np.testing.assert_allclose(got, ref, atol=1e-5, rtol=1e-5)  # float32 sums in another order
        np.testing.assert_allclose(got, tref, atol=1e-5, rtol=1e-5)
    x = rng.random((7, 64, 64), dtype=np.float32)
    one = npm.features(x)
    outs = [None] * 4

    def run(i):
        for _ in range(20):
            outs[i] = npm.features(x)

    threads = [threading.Thread(target=run, args=(i,)) for i in range(4)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert all(np.array_equal(o, one) for o in outs)
    assert np.array_equal(pickle.loads(pickle.dumps(npm)).features(x), one)


def test_npz_export_round_trip_and_stale_npz_refused(tmp_path):
    model = FastColorNet(FastConfig(thumbnail_px=16, channels=4, quantile_stats=True, quantile_channels="rgb"))
    with torch.no_grad():
        model.mlp[-1].bias.add_(0.1)
    save_fast_checkpoint(tmp_path / "f.pt", model, {})  # writes f.npz beside it
    assert npz_path(tmp_path / "f.pt").is_file()
    npm = load_fast_np(tmp_path / "f.pt")
    ref = FastColorNetNP.from_torch(model)
    for (a, b), (c, d) in zip(npm.convs + npm.mlp, ref.convs + ref.mlp):
        assert np.array_equal(a, c) and np.array_equal(b, d)
    assert npm.cfg == model.cfg
    npz = npz_path(tmp_path / "f.pt").read_bytes()
    with torch.no_grad():
        model.mlp[-1].bias.add_(0.1)
    save_fast_checkpoint(tmp_path / "f.pt", model, {})
    npz_path(tmp_path / "f.pt").write_bytes(npz)  # the old export beside the new checkpoint
    with pytest.raises(ValueError, match="another version"):
        load_fast_np(tmp_path / "f.pt")


def test_shipped_npz_is_the_shipped_checkpoint_and_fast_insertion_needs_no_torch():
    from aias_augment.apply.harmonize.api import DEFAULT_CHECKPOINTS

    if not DEFAULT_CHECKPOINTS["fast"].is_file():
        pytest.skip("fast harmonizer checkpoint not present")
    load_fast_np(DEFAULT_CHECKPOINTS["fast"])  # its sha256 check passes
    code = (
        "import sys, numpy as np\n"
        "from aias_augment.pipeline.image import load_preset\n"
        "from aias_augment.pipeline.bounded import insert_bounded\n"
        "from tests.aias_augment.pipeline.test_image import road_frame\n"
        "cfg = load_preset('fast', categories=('traffic_cone',), min_objects=2, max_objects=2)\n"
        "r = insert_bounded(road_frame(), rng=np.random.default_rng(0), cfg=cfg)\n"
        "assert r.record.modules['harmonize'].startswith('harmonized'), r.record.modules\n"
        "print(len(r.inserted_labels), 'torch' in sys.modules)\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr[-2000:]
    n, torch_loaded = out.stdout.split()[-2:]
    assert int(n) >= 1 and torch_loaded == "False"

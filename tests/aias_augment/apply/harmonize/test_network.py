import numpy as np
import pytest
import torch
from hypothesis import given, settings
from hypothesis import strategies as st

from aias_augment.apply.harmonize.network import (
    Critic,
    Generator,
    NetworkConfig,
    load_generator,
    masked_gradient_penalty,
    run_network,
    save_checkpoint,
)

TINY = NetworkConfig(resolution_px=32, base_channels=4, levels=2, dilations=(2,), critic_channels=4)


class LinearCritic:
    """D(x) = sum(w * x): its input gradient is w everywhere, so the penalty is known in closed form."""

    def __init__(self, w):
        self.w = w

    def __call__(self, x, mask):
        return (self.w * x).sum(dim=(1, 2, 3))


@settings(max_examples=25, deadline=None)
@given(seed=st.integers(0, 2**31 - 1), fill=st.floats(0.05, 0.95))
def test_masked_gp_only_sees_gradients_inside_the_mask(seed, fill):
    g = torch.Generator().manual_seed(seed)
    mask = (torch.rand(2, 1, 6, 7, generator=g) < fill).float()
    w = torch.randn(2, 3, 6, 7, generator=g)
    real, fake = torch.rand(2, 3, 6, 7, generator=g), torch.rand(2, 3, 6, 7, generator=g)
    gp = masked_gradient_penalty(LinearCritic(w), real, fake, mask, torch.Generator().manual_seed(0))
    expected = ((torch.sqrt((w**2 * mask).sum(dim=(1, 2, 3))) - 1) ** 2).mean()
    assert float(gp) == pytest.approx(float(expected), rel=1e-4, abs=1e-5)
    # Any change of the critic outside the mask leaves the penalty unchanged.
    w_out = w + 100.0 * torch.randn(2, 3, 6, 7, generator=g) * (1 - mask)
    gp_out = masked_gradient_penalty(LinearCritic(w_out), real, fake, mask, torch.Generator().manual_seed(0))
    assert float(gp_out) == pytest.approx(float(gp), rel=1e-4, abs=1e-5)


def test_masked_gp_gradient_reaches_the_critic():
    critic, mask = Critic(4), torch.zeros(2, 1, 32, 32)
    mask[:, :, 8:24, 8:24] = 1
    gp = masked_gradient_penalty(
        critic, torch.rand(2, 3, 32, 32), torch.rand(2, 3, 32, 32), mask, torch.Generator().manual_seed(0)
    )
    gp.backward()
    # The score's bias does not change the critic's input gradient, so only it receives no gradient.
    for name, p in critic.named_parameters():
        assert (p.grad is None) == (name == "score.bias"), name
        assert p.grad is None or torch.isfinite(p.grad).all()


def test_generator_keeps_background_and_starts_at_identity():
    torch.manual_seed(0)
    gen = Generator(TINY)
    comp, mask = torch.rand(2, 3, 32, 32), (torch.rand(2, 1, 32, 32) > 0.5).float()
    out = gen(comp, mask)
    assert torch.equal(out["output"], comp)  # zero-initialised heads: the untrained model is the identity
    with torch.no_grad():
        for p in gen.parameters():
            p.add_(0.1 * torch.randn_like(p))
    out = gen(comp, mask)
    assert torch.equal(out["output"] * (1 - mask), comp * (1 - mask))
    assert not torch.equal(out["output"], comp)
    with pytest.raises(ValueError):
        gen(torch.rand(1, 3, 30, 32), torch.ones(1, 1, 30, 32))


def test_checkpoint_round_trip_and_full_image_inference(tmp_path):
    torch.manual_seed(1)
    gen = Generator(TINY)
    with torch.no_grad():
        for p in gen.parameters():
            p.add_(0.05 * torch.randn_like(p))
    path = tmp_path / "g.pt"
    save_checkpoint(path, gen, {"note": "test"})
    loaded = load_generator(path)
    assert loaded is load_generator(path)  # cached per process
    x, m = torch.rand(1, 3, 32, 32), (torch.rand(1, 1, 32, 32) > 0.5).float()
    assert torch.allclose(gen.eval()(x, m)["output"], loaded(x, m)["output"])
    rng = np.random.default_rng(0)
    image = rng.random((48, 64, 3), dtype=np.float32)
    mask = np.zeros((48, 64), bool)
    mask[10:20, 5:15] = True
    mask[30:40, 40:60] = True  # two components, each in its own crop
    out = run_network(loaded, image, mask)
    np.testing.assert_array_equal(out[~mask], image[~mask])
    assert np.abs(out[mask] - image[mask]).max() > 0


def test_global_stage_is_the_fast_harmonizer_it_was_started_from(tmp_path):
    """A generator whose global stage is initialised from a fast checkpoint reproduces that model's output there."""
    from aias_augment.apply.harmonize.fast import FastColorNet, FastConfig, save_fast_checkpoint
    from aias_augment.apply.harmonize.network import Generator, NetworkConfig
    from aias_augment.apply.harmonize.train import fast_predict

    torch.manual_seed(0)
    fast = FastColorNet(FastConfig(thumbnail_px=16, channels=4))
    torch.nn.init.normal_(fast.mlp[-1].weight, std=0.1)  # not the identity
    save_fast_checkpoint(tmp_path / "fast.pt", fast, {})
    cfg = NetworkConfig(
        resolution_px=32,
        base_channels=4,
        levels=2,
        dilations=(2,),
        critic_channels=4,
        global_stage=True,
        global_thumbnail_px=16,
        global_channels=4,
    )
    gen = Generator(cfg)
    from aias_augment.apply.harmonize.checkpoint import load_checkpoint_dict

    gen.global_stage.load_state_dict(load_checkpoint_dict(tmp_path / "fast.pt", "fast")["state_dict"])
    comp = torch.rand(2, 3, 32, 32)
    mask = torch.zeros(2, 1, 32, 32)
    mask[:, :, 8:24, 10:20] = 1
    with torch.no_grad():
        out = gen(comp, mask)
        expected = fast_predict(fast, comp, mask)
    assert torch.allclose(out["global"], expected, atol=1e-6)
    assert not torch.allclose(out["global"], comp)
    # The later stages start at the identity: the untrained generator's output is the global stage's.
    assert torch.allclose(out["output"], expected, atol=1e-6)
    assert torch.equal(out["output"][(mask == 0).expand_as(comp)], comp[(mask == 0).expand_as(comp)])


def test_colour_transforms_are_applied_at_full_resolution():
    """A generator whose global stage halves every colour (later stages at their identity start) must halve a
    full-resolution checkerboard object exactly: the transform is applied to the crop's own pixels, not upsampled
    from the 32-px network output (which would blur the 1-px checks)."""
    cfg = NetworkConfig(
        resolution_px=32,
        base_channels=4,
        levels=2,
        dilations=(2,),
        critic_channels=4,
        global_stage=True,
        global_thumbnail_px=16,
        global_channels=4,
    )
    gen = Generator(cfg)
    with torch.no_grad():
        gen.global_stage.mlp[-1].bias.copy_(torch.tensor([-0.5, 0, 0, 0, 0, -0.5, 0, 0, 0, 0, -0.5, 0.0]))
    yy, xx = np.mgrid[0:240, 0:320]
    image = np.where(((yy + xx) % 2 == 0)[..., None], 0.8, 0.2).astype(np.float32) * np.ones(3, np.float32)
    mask = np.zeros((240, 320), bool)
    mask[60:180, 100:220] = True
    for tta in (False, True):
        out = run_network(gen, image, mask, tta=tta)
        np.testing.assert_allclose(out[mask], 0.5 * image[mask], atol=1e-5)
        np.testing.assert_array_equal(out[~mask], image[~mask])


def test_up_to_stage_returns_each_stage_output():
    from aias_augment.apply.harmonize.network import up_to_stage

    torch.manual_seed(1)
    cfg = NetworkConfig(
        resolution_px=32,
        base_channels=4,
        levels=2,
        dilations=(2,),
        critic_channels=4,
        global_stage=True,
        global_thumbnail_px=16,
        global_channels=4,
    )
    gen = Generator(cfg)
    for stage in (gen.global_stage.mlp[-1], gen.coarse.head, gen.refine.head, gen.coarse.global_head):
        torch.nn.init.normal_(stage.weight, std=0.05)
    comp, mask = torch.rand(2, 3, 32, 32), torch.zeros(2, 1, 32, 32)
    mask[:, :, 6:26, 8:22] = 1
    with torch.no_grad():
        full = gen(comp, mask)
        assert torch.allclose(up_to_stage(gen, "global")(comp, mask)["output"], full["global"], atol=1e-6)
        assert torch.allclose(up_to_stage(gen, "coarse")(comp, mask)["output"], full["coarse"], atol=1e-6)
        assert torch.equal(up_to_stage(gen, "refine")(comp, mask)["output"], full["output"])
    assert not torch.allclose(full["coarse"], full["output"])  # the stages do differ here
    with pytest.raises(ValueError):
        up_to_stage(Generator(TINY), "global")

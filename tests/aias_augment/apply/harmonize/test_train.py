import dataclasses

import numpy as np
import pytest
import torch

from aias_augment.apply.harmonize.fast import FastColorNet, FastConfig
from aias_augment.apply.harmonize.network import Critic, Generator, NetworkConfig
from aias_augment.apply.harmonize.pairs import Perturbation, apply_perturbation, random_region_mask
from aias_augment.apply.harmonize.train import (
    PairPool,
    TrainConfig,
    fast_predict,
    fast_train_step,
    fmse_255,
    make_batch,
    make_optimizers,
    masked_mse_per_image,
    recon_loss,
    split_pool,
    train_step,
)


def tiny_pairs(street_rgb, n=4, size=32):
    """Fixed pairs from real street crops: a random region made 1 stop brighter and bluish."""
    rng = np.random.default_rng(0)
    p = Perturbation(
        exposure_stops=1.0, wb_gains=(0.8, 1.0, 1.25), saturation=1.2, gamma=1.0, blur_sigma_px=0.0, noise_sigma=0.0
    )
    comps, targets, masks = [], [], []
    for i in range(n):
        crop = np.ascontiguousarray(street_rgb[40 * i : 40 * i + size * 2 : 2, 60 * i : 60 * i + size * 2 : 2])
        mask = random_region_mask((size, size), rng, (0.4, 0.6)).astype(np.float32)
        comps.append(apply_perturbation(crop, mask, p, rng)), targets.append(crop), masks.append(mask)
    t = lambda a: torch.from_numpy(np.stack(a)).permute(0, 3, 1, 2).float() / 255  # noqa: E731
    return t(comps), t(targets), torch.from_numpy(np.stack(masks))[:, None]


def test_network_overfits_a_tiny_pair_set(street_rgb):
    torch.manual_seed(0)
    comp, target, mask = tiny_pairs(street_rgb)
    cfg = TrainConfig(
        network=NetworkConfig(resolution_px=32, base_channels=4, levels=2, dilations=(2,), critic_channels=4),
        lr_generator=3e-3,
    )
    gen, critic = Generator(cfg.network), Critic(cfg.network.critic_channels)
    opt_g, opt_d = make_optimizers(gen, critic, cfg)
    before = fmse_255(comp, target, mask)
    for _ in range(25):
        losses = train_step(gen, critic, opt_g, opt_d, comp, target, mask, cfg, torch.Generator().manual_seed(0))
    assert np.isfinite(list(losses.values())).all()
    with torch.no_grad():
        after = fmse_255(gen.eval()(comp, mask)["output"], target, mask)
    assert after < 0.1 * before, (before, after)


def test_fast_harmonizer_overfits_a_tiny_pair_set(street_rgb):
    torch.manual_seed(0)
    comp, target, mask = tiny_pairs(street_rgb)
    model = FastColorNet(FastConfig(thumbnail_px=32, channels=8))
    opt = torch.optim.Adam(model.parameters(), lr=3e-3)
    before = fmse_255(comp, target, mask)
    for _ in range(100):
        fast_train_step(model, opt, comp, target, mask)
    with torch.no_grad():
        after = fmse_255(fast_predict(model, comp, mask), target, mask)
    assert after < 0.25 * before, (before, after)


def test_holdout_split_is_by_source_image():
    pool = PairPool(np.zeros((6, 4, 4, 3), np.uint8), np.ones((6, 4, 4), np.uint8), list("aabbcc"))
    tr, ho = split_pool(pool, 0.34, np.random.default_rng(0))
    assert set(tr) | set(ho) == set(range(6)) and not set(tr) & set(ho)
    assert not {pool.sources[i] for i in tr} & {pool.sources[i] for i in ho}
    # A photo's random regions go with its objects.
    pool = PairPool(
        np.zeros((6, 4, 4, 3), np.uint8),
        np.ones((6, 4, 4), np.uint8),
        ["a", "a:region", "b", "b:region", "c", "c:region"],
    )
    for seed in range(5):
        tr, ho = split_pool(pool, 0.34, np.random.default_rng(seed))
        photos = lambda idx: {pool.sources[i].split(":")[0] for i in idx}  # noqa: E731
        assert not photos(tr) & photos(ho) and len(ho) == 2


def test_config_rejects_unknown_keys(tmp_path):
    from aias_augment.core.config import load_config

    (tmp_path / "c.yaml").write_text("network:\n  resolution_px: 64\n  width: 3\n")
    with pytest.raises(KeyError):
        load_config(TrainConfig, tmp_path / "c.yaml")
    for name in ("harmonize_small", "harmonize_256"):
        cfg = load_config(TrainConfig, name)
        assert dataclasses.is_dataclass(cfg.network)


def test_network_overfits_with_the_fmse_loss(street_rgb):
    torch.manual_seed(0)
    comp, target, mask = tiny_pairs(street_rgb)
    cfg = TrainConfig(
        network=NetworkConfig(resolution_px=32, base_channels=4, levels=2, dilations=(2,), critic_channels=4),
        lr_generator=3e-3,
        recon_loss="fmse",
    )
    gen, critic = Generator(cfg.network), Critic(cfg.network.critic_channels)
    opt_g, opt_d = make_optimizers(gen, critic, cfg)
    before = fmse_255(comp, target, mask)
    for _ in range(25):
        train_step(gen, critic, opt_g, opt_d, comp, target, mask, cfg, torch.Generator().manual_seed(0))
    with torch.no_grad():
        after = fmse_255(gen.eval()(comp, mask)["output"], target, mask)
    assert after < 0.1 * before, (before, after)


def test_fmse_loss_weighs_every_image_equally():
    """A small object's error counts as much as a large one's (unlike L1 over the batch's pixels)."""
    target = torch.zeros(2, 3, 8, 8)
    mask = torch.zeros(2, 1, 8, 8)
    mask[0, :, :1, :1] = 1  # 1 px object
    mask[1] = 1  # 64 px object
    pred = target.clone()
    pred[0] += 0.5  # only the small object is wrong, by 0.5 everywhere
    # image 0: 3 * 0.25 / (3 + 1); image 1: 0 -> mean over the 2 images
    assert float(masked_mse_per_image(pred, target, mask)) == pytest.approx(0.75 / 4 / 2)
    assert float(recon_loss(pred, target, mask, "l1")) == pytest.approx(1.5 / (3 * 65 + 1))
    with pytest.raises(ValueError, match="recon_loss"):
        recon_loss(pred, target, mask, "l2")


def test_scene_jitter_changes_target_and_composite_background_alike():
    rng = np.random.default_rng(0)
    img = rng.integers(40, 200, (1, 16, 16, 3)).astype(np.uint8)
    m = np.zeros((1, 16, 16), np.uint8)
    m[0, 4:10, 4:10] = 1
    pool = PairPool(img, m, ["a"])
    comp, target, mask = make_batch(
        pool,
        np.array([0, 0, 0]),
        TrainConfig().perturb,
        np.random.default_rng(1),
        flip=False,
        scene_jitter=TrainConfig().scene_jitter,
        scene_jitter_probability=1.0,
    )
    bg = (mask == 0).expand_as(comp)
    assert torch.equal(comp[bg], target[bg])  # the background of a pair is untouched by the foreground perturbation
    original = torch.from_numpy(img).permute(0, 3, 1, 2).float() / 255
    for t in target:  # ... but every target differs from the pool image (its whole crop was jittered)
        assert float((t - original[0]).abs().mean()) > 1 / 255
    plain, plain_t, _ = make_batch(pool, np.array([0]), TrainConfig().perturb, np.random.default_rng(1), flip=False)
    assert torch.equal(plain_t[0], original[0])


def test_a_frozen_global_stage_does_not_move_while_the_later_stages_learn(street_rgb):
    torch.manual_seed(0)
    comp, target, mask = tiny_pairs(street_rgb)
    cfg = TrainConfig(
        network=NetworkConfig(
            resolution_px=32,
            base_channels=4,
            levels=2,
            dilations=(2,),
            critic_channels=4,
            global_stage=True,
            global_thumbnail_px=16,
            global_channels=4,
        ),
        lr_generator=3e-3,
        global_lr_scale=0.0,
    )
    gen, critic = Generator(cfg.network), Critic(cfg.network.critic_channels)
    torch.nn.init.normal_(gen.global_stage.mlp[-1].weight, std=0.05)
    frozen = {k: v.clone() for k, v in gen.global_stage.state_dict().items()}
    coarse_head = gen.coarse.head.weight.clone()
    opt_g, opt_d = make_optimizers(gen, critic, cfg)
    for _ in range(3):
        train_step(gen, critic, opt_g, opt_d, comp, target, mask, cfg, torch.Generator().manual_seed(0))
    for k, v in gen.global_stage.state_dict().items():
        assert torch.equal(v, frozen[k]), k
    assert not torch.equal(gen.coarse.head.weight, coarse_head)

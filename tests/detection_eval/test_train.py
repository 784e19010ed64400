"""The detector can learn: it overfits a tiny set to mAP50 >= 0.9 on its own images."""

from __future__ import annotations

import time

import pytest
import torch

from detection_eval.config import AugmentConfig, DetectorConfig, ModelConfig, TrainConfig
from detection_eval.data import load_yolo_dir
from detection_eval.inference import evaluate_dataset
from detection_eval.train import load_checkpoint, lr_at, save_checkpoint, train_detector


def test_lr_schedule_warmup_then_cosine():
    cfg = TrainConfig(max_iters=110, warmup_iters=10, lr=1.0, min_lr_ratio=0.1)
    assert lr_at(0, cfg) == pytest.approx(0.1)
    assert lr_at(9, cfg) == pytest.approx(1.0)
    assert lr_at(10, cfg) == pytest.approx(1.0)
    assert lr_at(60, cfg) == pytest.approx(0.55)  # half-way down the cosine: (1 + 0.1) / 2
    assert lr_at(110, cfg) == pytest.approx(0.1)
    assert all(lr_at(i, cfg) >= lr_at(i + 1, cfg) for i in range(10, 110))


def test_head_lr_mult_scales_neck_and_head_groups_only():
    from detection_eval.train import build_optimizer

    cfg = DetectorConfig(
        model=ModelConfig(backbone="efficientnet_lite0", pretrained=False, frozen_blocks=3, backbone_bn="frozen"),
        train=TrainConfig(lr=1e-3, head_lr_mult=4.0, weight_decay=5e-4),
    )
    from detection_eval.model import Detector

    model = Detector.from_config(cfg)
    opt = build_optimizer(model, cfg.train)
    backbone = {id(p) for p in model.backbone.parameters()}
    grouped = [p for g in opt.param_groups for p in g["params"]]
    assert len(grouped) == len({id(p) for p in grouped}) == sum(p.requires_grad for p in model.parameters())
    for g in opt.param_groups:
        in_bb = {id(p) in backbone for p in g["params"]}
        assert len(in_bb) == 1  # a group is all backbone or all neck/head
        assert g["lr_scale"] == (1.0 if in_bb.pop() else 4.0)
    with pytest.raises(ValueError):
        TrainConfig(head_lr_mult=0.0)


def test_shared_head_shares_weights_keeps_per_level_batchnorm_and_trains():
    from detection_eval.losses import Targets
    from detection_eval.model import Detector

    cfg = DetectorConfig(model=ModelConfig(backbone="efficientnet_lite0", pretrained=False, shared_head=True))
    model = Detector.from_config(cfg).train()
    head = model.head
    assert len(head.cls_preds) == len(head.reg_preds) == len(head.obj_preds) == 1
    assert all(len(conv.bns) == 3 for conv in list(head.cls_convs) + list(head.reg_convs))
    raw = model.raw_outputs(torch.rand(2, 3, 64, 64))
    assert [tuple(r.shape) for r in raw] == [(2, 6, 8, 8), (2, 6, 4, 4), (2, 6, 2, 2)]
    targets = Targets(
        torch.tensor([[[8.0, 8.0, 40.0, 48.0]], [[0.0, 0.0, 0.0, 0.0]]]),
        torch.zeros(2, 1, dtype=torch.long),
        torch.tensor([1, 0]),
    )
    model(torch.rand(2, 3, 64, 64), targets)["loss"].backward()
    assert head.reg_convs[0].conv.weight.grad is not None and head.reg_preds[0].weight.grad is not None
    with pytest.raises(ValueError):
        Detector.from_config(DetectorConfig(model=ModelConfig(pretrained=False, shared_head=True, depthwise=True)))


def test_detector_configs_load_and_unknown_keys_raise(tmp_path):
    from detection_eval.config import load_detector_config

    b = load_detector_config("lite0_320_b")
    assert b.train.max_iters == 450 and b.train.batch_size == 8 and b.train.img_size == 320
    bad = tmp_path / "bad.yaml"
    bad.write_text("train: {max_iters: 10, head_lr_multiplier: 2}\n")
    with pytest.raises(KeyError, match="head_lr_multiplier"):
        load_detector_config(bad)


@pytest.mark.slow  # ~30-50 s on 2 busy CPU cores: a real training run is the only proof that the detector learns
def test_overfit_tiny_set(tiny_yolo_dir, tmp_path):
    dataset = load_yolo_dir(tiny_yolo_dir)
    cfg = DetectorConfig(
        model=ModelConfig(backbone="efficientnet_lite0", pretrained=True, width=0.25, frozen_blocks=5),
        augment=AugmentConfig(hflip_prob=0.0, scale_range=(1.0, 1.0), translate_frac=0.0, hsv_gains=(0, 0, 0)),
        train=TrainConfig(
            img_size=128, batch_size=4, max_iters=60, lr=4e-3, warmup_iters=5, ema_decay=0.9, ema_tau=10, num_threads=1
        ),
    )
    t0 = time.perf_counter()
    result = train_detector(cfg, dataset, seed=0)
    metrics = evaluate_dataset(result.model, dataset, 128, cfg.inference)
    assert metrics["AP50"] >= 0.9, metrics
    assert result.images_per_second > 0
    # Saved weights carry their config: the reloaded model gives the same predictions.
    save_checkpoint(tmp_path / "w.pt", result.model, dataset.category_names)
    model, names, _ = load_checkpoint(tmp_path / "w.pt")
    assert names == ["cone"]
    again = evaluate_dataset(model, dataset, 128, cfg.inference)
    assert again["AP50"] == pytest.approx(metrics["AP50"])
    _check_letterbox_round_trip(model, dataset, cfg)
    print(f"overfit: {time.perf_counter() - t0:.1f} s, {metrics}")


def _check_letterbox_round_trip(model, dataset, cfg):
    """A trained checkpoint's boxes come back in original-image pixels, padding included: on a 128x96 crop (16 px
    of letterbox padding above and below at 128 px) the top box lands on the known cone, and on the same crop
    upscaled 2x by pixel repetition (its 128 px letterbox content is bit-identical: INTER_AREA averages the 2x2
    copies) every box is exactly twice as large."""
    import numpy as np

    from detection_eval.boxes import box_iou
    from detection_eval.data import read_image_rgb
    from detection_eval.inference import predict_images

    rec = dataset.records[0]
    image = read_image_rgb(rec.image_path)
    gt = rec.boxes_xyxy[0]
    top = int(np.clip(gt[1] - 8, 0, image.shape[0] - 96))
    assert gt[3] <= top + 96, "the synthetic cone must fit the crop"
    crop = np.ascontiguousarray(image[top : top + 96])
    small = predict_images(model, [crop], 128, cfg.inference)[0]
    big = predict_images(model, [np.repeat(np.repeat(crop, 2, axis=0), 2, axis=1)], 128, cfg.inference)[0]
    assert len(small["boxes"]) and len(small["boxes"]) == len(big["boxes"])
    np.testing.assert_allclose(big["boxes"], 2 * small["boxes"], atol=1e-4)
    np.testing.assert_allclose(big["scores"], small["scores"], atol=1e-6)
    best = small["boxes"][np.argmax(small["scores"])]
    iou = float(box_iou(torch.tensor([best]), torch.tensor([gt - [0, top, 0, top]]))[0, 0])
    assert iou >= 0.5, (best, gt, top)  # a true positive at the AP50 threshold


def test_frozen_backbone_batchnorm_keeps_imagenet_statistics_and_frozen_blocks_get_no_gradient():
    from torch import nn

    from detection_eval.backbones import EfficientNetLite0Backbone

    net = EfficientNetLite0Backbone(pretrained=True, frozen_blocks=3, bn_mode="frozen").train()
    norms = [m for m in net.modules() if isinstance(m, nn.BatchNorm2d)]
    before = [(m.running_mean.clone(), m.running_var.clone()) for m in norms]
    out = net(torch.rand(2, 3, 64, 64) * 3)  # far from ImageNet statistics: training BN would move
    sum(v.float().mean() for v in out.values()).backward()
    assert all(not m.training for m in norms)
    for m, (mean, var) in zip(norms, before):
        assert torch.equal(m.running_mean, mean) and torch.equal(m.running_var, var)
        assert m.weight.grad is None and m.bias.grad is None
    frozen = [p for b in net.blocks[:3] for p in b.parameters()] + list(net.conv_stem.parameters())
    trained = [p for b in net.blocks[3:] for p in b.parameters() if p.requires_grad]
    assert all(p.grad is None for p in frozen)
    assert trained and all(p.grad is not None for p in trained)
    train_bn = EfficientNetLite0Backbone(pretrained=True, frozen_blocks=0, bn_mode="train").train()
    train_bn(torch.rand(2, 3, 64, 64) * 3)
    moved = [m for m in train_bn.modules() if isinstance(m, nn.BatchNorm2d)][0]
    assert not torch.equal(moved.running_mean, before[0][0])  # the control: trained BN does move

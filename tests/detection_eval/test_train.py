"""The detector can learn: it overfits a tiny set to mAP50 >= 0.9 on its own images."""
from __future__ import annotations

import time

import pytest
import torch

from detection_eval.config import AugmentConfig, DetectorConfig, ModelConfig, TrainConfig
from detection_eval.data import load_yolo_dir
from detection_eval.inference import evaluate_dataset
from detection_eval.train import lr_at, load_checkpoint, save_checkpoint, train_detector


def test_lr_schedule_warmup_then_cosine():
    cfg = TrainConfig(max_iters=110, warmup_iters=10, lr=1.0, min_lr_ratio=0.1)
    assert lr_at(0, cfg) == pytest.approx(0.1)
    assert lr_at(9, cfg) == pytest.approx(1.0)
    assert lr_at(10, cfg) == pytest.approx(1.0)
    assert lr_at(60, cfg) == pytest.approx(0.55)       # half-way down the cosine: (1 + 0.1) / 2
    assert lr_at(110, cfg) == pytest.approx(0.1)
    assert all(lr_at(i, cfg) >= lr_at(i + 1, cfg) for i in range(10, 110))


@pytest.mark.slow  # ~30-50 s on 2 busy CPU cores: a real training run is the only proof that the detector learns
def test_overfit_tiny_set(tiny_yolo_dir, tmp_path):
    dataset = load_yolo_dir(tiny_yolo_dir)
    cfg = DetectorConfig(
        model=ModelConfig(backbone="efficientnet_lite0", pretrained=True, width=0.25, frozen_blocks=5),
        augment=AugmentConfig(hflip_prob=0.0, scale_range=(1.0, 1.0), translate_frac=0.0, hsv_gains=(0, 0, 0)),
        train=TrainConfig(img_size=128, batch_size=4, max_iters=60, lr=4e-3, warmup_iters=5, ema_decay=0.9,
                          ema_tau=10, num_threads=1),
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
    crop = np.ascontiguousarray(image[top:top + 96])
    small = predict_images(model, [crop], 128, cfg.inference)[0]
    big = predict_images(model, [np.repeat(np.repeat(crop, 2, axis=0), 2, axis=1)], 128, cfg.inference)[0]
    assert len(small["boxes"]) and len(small["boxes"]) == len(big["boxes"])
    np.testing.assert_allclose(big["boxes"], 2 * small["boxes"], atol=1e-4)
    np.testing.assert_allclose(big["scores"], small["scores"], atol=1e-6)
    best = small["boxes"][np.argmax(small["scores"])]
    iou = float(box_iou(torch.tensor([best]), torch.tensor([gt - [0, top, 0, top]]))[0, 0])
    assert iou >= 0.5, (best, gt, top)          # a true positive at the AP50 threshold


def test_frozen_backbone_batchnorm_keeps_imagenet_statistics_and_frozen_blocks_get_no_gradient():
    from torch import nn

    from detection_eval.backbones import EfficientNetLite0Backbone
    net = EfficientNetLite0Backbone(pretrained=True, frozen_blocks=3, bn_mode="frozen").train()
    norms = [m for m in net.modules() if isinstance(m, nn.BatchNorm2d)]
    before = [(m.running_mean.clone(), m.running_var.clone()) for m in norms]
    out = net(torch.rand(2, 3, 64, 64) * 3)                # far from ImageNet statistics: training BN would move
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
    assert not torch.equal(moved.running_mean, before[0][0])    # the control: trained BN does move

"""A detector backbone is one builder in ``detection_eval.backbones.BACKBONE_BUILDERS``: the config accepts the names
there and nothing else, and the detector is built on the registered builder's module."""

import pytest
import torch
from torch import nn

from detection_eval import backbones
from detection_eval.config import DetectorConfig, ModelConfig
from detection_eval.model import Detector


class _Tiny(nn.Module):
    """Three strided convs: the p3/p4/p5 maps at strides 8, 16, 32 with 16/32/64 channels."""

    def __init__(self):
        super().__init__()
        self.c3 = nn.Conv2d(3, 16, 3, stride=8, padding=1)
        self.c4 = nn.Conv2d(16, 32, 3, stride=2, padding=1)
        self.c5 = nn.Conv2d(32, 64, 3, stride=2, padding=1)
        self.out_channels = {"p3": 16, "p4": 32, "p5": 64}

    def forward(self, x):
        p3 = self.c3(x)
        p4 = self.c4(p3)
        return {"p3": p3, "p4": p4, "p5": self.c5(p4)}


def test_an_unregistered_backbone_is_refused_at_construction():
    with pytest.raises(ValueError, match="backbone must be one of"):
        ModelConfig(backbone="resnet50", pretrained=False)


def test_a_registered_backbone_is_accepted_and_the_detector_runs_on_it(monkeypatch):
    made = []
    monkeypatch.setitem(backbones.BACKBONE_BUILDERS, "tiny_test", lambda *a: made.append(_Tiny()) or made[-1])
    det = Detector(DetectorConfig(model=ModelConfig(backbone="tiny_test", pretrained=False))).eval()
    assert det.backbone is made[0]
    with torch.no_grad():
        out = det(torch.zeros(1, 3, 64, 64))
    assert out.shape == (1, 8 * 8 + 4 * 4 + 2 * 2, 4 + 1 + 1)  # every anchor of the three levels: box, obj, class

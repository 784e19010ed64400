"""The paper's harmonization network: a coarse-to-fine generator of dilated convolutions (DeepFill v1 style) + critic.

Inputs (all in [0, 1], NCHW):
  coarse stage:  [image with the foreground filled black (3), binary foreground mask (1), foreground with the
                  background filled black (3)] = 7 channels;
  refine stage:  the same 7 channels + the coarse output composited into the background (3) = 10 channels.
Each stage is DeepFill v1's encoder (5x5 conv, two stride-2 3x3 convs), a chain of dilated 3x3 convs at 1/4
resolution (dilations 2, 4, 8, 16 give the receptive field to see the surroundings) and a nearest-upsampling
decoder, ELU activations. Differences from DeepFill v1, and why:
  * the stage output is a per-pixel affine colour transform (3x3 matrix + offset, HDRNet-style) of its input
    foreground, zero-initialised to the identity (``output_mode="affine"``; ``"residual"`` = a tanh RGB residual).
    Harmonization keeps the object's content and mismatches are mostly gains (exposure, white balance): a gain is
    linear in the affine coefficients but a product the residual form must learn. Measured here: the residual form
    did not move the held-out fMSE in 250 CPU steps;
  * at the bottleneck, features pooled over the foreground and over the background (mask-weighted means) are mixed
    back into every position (``global_context``): the comparison "object vs surroundings" is global, which 3x3
    convs alone reach only through many layers;
  * no contextual-attention branch (it copies background patches into a hole; here nothing is missing);
  * one global critic that sees (image, mask) instead of DeepFill's global + local pair.
The WGAN-GP gradient penalty is weighted by the mask as in DeepFill v1: only gradients w.r.t. foreground pixels are
constrained (``masked_gradient_penalty``).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np
import torch
import torch.nn.functional as F
from torch import nn

from aias_augment.apply.harmonize.checkpoint import CHECKPOINT_FORMAT, load_model
from aias_augment.apply.harmonize.fast import (
    POOL_EPS,
    FastColorNet,
    FastConfig,
    apply_affine,
    masked_stats,
    network_inputs,
    thumbnail,
)
from aias_augment.apply.harmonize.fast_infer import apply_affine_np
from aias_augment.apply.harmonize.regions import components, context_box, mask_box, resize

# Added under the square root of the masked gradient norm so its gradient stays finite at zero gradient.
GP_EPS = 1e-12


@dataclass(frozen=True)
class NetworkConfig:
    resolution_px: int = 128  # training and inference crop size (the paper's setting is 256)
    base_channels: int = 16  # width of the first layer; 1/4-resolution layers have 4x this
    dilations: tuple[int, ...] = (2, 4, 8, 16)
    levels: int = 2  # stride-2 steps before the dilated convs (DeepFill v1: 2)
    output_mode: str = "affine"  # "affine": per-pixel 3x4 colour transform; "residual": tanh RGB residual
    global_context: bool = True  # mix mask-pooled foreground/background features into the bottleneck
    # Stage 0 (optional): one affine colour transform for the whole object, predicted from a thumbnail (the fast
    # harmonizer's model, ``fast.FastColorNet``), applied before the coarse stage. It can start from a trained fast
    # checkpoint, so the dilated-conv stages learn only what a global transform cannot fix.
    global_stage: bool = False
    global_thumbnail_px: int = 64
    global_channels: int = 16
    global_masked_pooling: bool = False
    global_hidden: int = 64
    global_quantile_stats: bool = False
    global_quantile_channels: str = "luma"
    global_input_px: int = 0

    def __post_init__(self):
        if self.output_mode not in ("affine", "residual"):
            raise ValueError(f"NetworkConfig.output_mode must be 'affine' or 'residual', got {self.output_mode!r}")

    critic_channels: int = 16
    context: float = 2.4  # inference crop = this x the object's box side (training draws a range around it)


def _conv(cin: int, cout: int, k: int = 3, stride: int = 1, dilation: int = 1, act: bool = True) -> nn.Module:
    conv = nn.Conv2d(cin, cout, k, stride, padding=dilation * (k - 1) // 2, dilation=dilation)
    return nn.Sequential(conv, nn.ELU()) if act else conv


class StageNet(nn.Module):
    """One DeepFill-v1 stage; returns ``out_channels`` maps (zero at initialisation).

    ``levels`` stride-2 steps (DeepFill v1: 2, i.e. the dilated convs run at 1/4 resolution); widths double per
    level up to 4 x ``c``. The decoder mirrors the encoder with nearest upsampling.
    """

    def __init__(
        self,
        in_channels: int,
        c: int,
        dilations: tuple[int, ...],
        levels: int = 2,
        out_channels: int = 3,
        global_context: bool = False,
    ):
        super().__init__()
        widths = [c] + [c * min(2 ** (i + 1), 4) for i in range(levels)]
        enc = [_conv(in_channels, c, 5)]
        for a, b in zip(widths[:-1], widths[1:]):
            enc += [_conv(a, b, 3, 2), _conv(b, b)]
        self.encoder = nn.Sequential(*enc)
        w = widths[-1]
        self.dilated = nn.Sequential(*[_conv(w, w, 3, dilation=d) for d in dilations])
        self.global_mix = nn.Sequential(nn.Linear(2 * w + 12, w), nn.ELU()) if global_context else None
        # A spatially constant part of the output predicted from the pooled features (zero-initialised): one colour
        # transform for the whole object gets the gradient of every foreground pixel, so it is learnt first.
        self.global_head = nn.Linear(w, out_channels) if global_context else None
        if self.global_head is not None:
            nn.init.zeros_(self.global_head.weight)
            nn.init.zeros_(self.global_head.bias)
        self.middle = nn.Sequential(_conv(w, w), _conv(w, w))
        self.decoder = nn.ModuleList(
            nn.Sequential(_conv(b, a), _conv(a, a)) for a, b in reversed(list(zip(widths[:-1], widths[1:])))
        )
        self.tail = _conv(c, max(c // 2, 4))
        self.head = _conv(max(c // 2, 4), out_channels, act=False)
        nn.init.zeros_(self.head.weight)  # start at the identity
        nn.init.zeros_(self.head.bias)

    def forward(self, x: torch.Tensor, mask: torch.Tensor, image: torch.Tensor) -> torch.Tensor:
        """``image``: the (B,3,H,W) image this stage transforms; its masked colour statistics join the pooling."""
        h = self.dilated(self.encoder(x))
        constant = 0.0
        if self.global_mix is not None:
            m = F.adaptive_avg_pool2d(mask, h.shape[-2:])
            fg = (h * m).sum(dim=(2, 3)) / (m.sum(dim=(2, 3)) + POOL_EPS)
            bg = (h * (1 - m)).sum(dim=(2, 3)) / ((1 - m).sum(dim=(2, 3)) + POOL_EPS)
            g = self.global_mix(torch.cat([fg, bg, masked_stats(image, mask)], 1))
            h = h + g[..., None, None]
            constant = self.global_head(g)[..., None, None]
        h = self.middle(h)
        for up in self.decoder:
            h = up(F.interpolate(h, scale_factor=2.0, mode="nearest"))
        return self.head(self.tail(h)) + constant


def apply_pixel_affine(image: torch.Tensor, coeffs: torch.Tensor) -> torch.Tensor:
    """image (B,3,H,W), coeffs (B,12,H,W) = per-pixel [dM (3x3, row-major) | b (3)]: (I + dM) x + b, clamped."""
    b, _, hgt, wid = image.shape
    dm = coeffs[:, :9].view(b, 3, 3, hgt, wid)
    return (image + torch.einsum("bijhw,bjhw->bihw", dm, image) + coeffs[:, 9:12]).clamp(0, 1)


class Generator(nn.Module):
    def __init__(self, cfg: NetworkConfig):
        super().__init__()
        self.cfg = cfg
        out = 12 if cfg.output_mode == "affine" else 3
        args = (cfg.base_channels, cfg.dilations, cfg.levels, out, cfg.global_context)
        self.coarse = StageNet(7, *args)
        self.refine = StageNet(10, *args)
        self.global_stage = None
        if cfg.global_stage:
            self.global_stage = FastColorNet(
                FastConfig(
                    cfg.global_thumbnail_px,
                    cfg.global_channels,
                    masked_pooling=cfg.global_masked_pooling,
                    hidden=cfg.global_hidden,
                    quantile_stats=cfg.global_quantile_stats,
                    quantile_channels=cfg.global_quantile_channels,
                    input_px=cfg.global_input_px,
                )
            )

    def _apply(self, image: torch.Tensor, maps: torch.Tensor) -> torch.Tensor:
        if self.cfg.output_mode == "affine":
            return apply_pixel_affine(image, maps)
        return (image + torch.tanh(maps)).clamp(0, 1)

    def forward(self, composite: torch.Tensor, mask: torch.Tensor) -> dict[str, torch.Tensor]:
        """Returns ``coarse`` and ``output`` (refined), and ``global`` with a global stage; all composited:
        background pixels equal the input's."""
        k = 2**self.cfg.levels
        if composite.shape[-1] % k or composite.shape[-2] % k:
            raise ValueError(f"Generator: H and W must be multiples of {k}, got {tuple(composite.shape[-2:])}")
        out = {}
        if self.global_stage is not None:
            thumb, tmask = thumbnail(composite, mask, self.global_stage.cfg.in_px)
            affine = self.global_stage(thumb, tmask)
            composite = mask * apply_affine(composite, affine) + (1 - mask) * composite
            out["global"], out["global_affine"] = composite, affine
        x = network_inputs(composite, mask)
        coarse_maps = self.coarse(x, mask, composite)
        coarse = mask * self._apply(composite, coarse_maps) + (1 - mask) * composite
        refine_maps = self.refine(torch.cat([x, coarse], dim=1), mask, coarse)
        refined = self._apply(coarse, refine_maps)
        return {
            **out,
            "coarse": coarse,
            "output": mask * refined + (1 - mask) * composite,
            "coarse_maps": coarse_maps,
            "refine_maps": refine_maps,
        }


class Critic(nn.Module):
    """WGAN critic on (image, mask): four 5x5 stride-2 convs, global mean, linear score."""

    def __init__(self, c: int):
        super().__init__()
        layers, cin = [], 4
        for cout in (c, 2 * c, 4 * c, 4 * c):
            layers += [nn.Conv2d(cin, cout, 5, 2, 2), nn.LeakyReLU(0.2)]
            cin = cout
        self.features = nn.Sequential(*layers)
        self.score = nn.Linear(cin, 1)

    def forward(self, image: torch.Tensor, mask: torch.Tensor) -> torch.Tensor:
        return self.score(self.features(torch.cat([image, mask], 1)).mean(dim=(2, 3))).squeeze(1)


def masked_gradient_penalty(
    critic, real: torch.Tensor, fake: torch.Tensor, mask: torch.Tensor, generator: torch.Generator
) -> torch.Tensor:
    """WGAN-GP with the gradient norm taken over the masked pixels only (DeepFill v1's ``gradients_penalty``).

    ``critic(image, mask) -> (B,)``; the penalty is ``mean_b (sqrt(sum(grad^2 * mask) + GP_EPS) - 1)^2`` at random
    interpolates of ``real`` and ``fake`` (drawn from ``generator``, a required ``torch.Generator``); gradients
    w.r.t. pixels where ``mask == 0`` do not enter it.
    """
    if not isinstance(generator, torch.Generator):
        raise TypeError(
            f"masked_gradient_penalty: generator is required: pass a torch.Generator, got {type(generator).__name__}"
        )
    alpha = torch.rand(real.shape[0], 1, 1, 1, generator=generator, dtype=real.dtype)
    x = (alpha * real.detach() + (1 - alpha) * fake.detach()).requires_grad_(True)
    (grad,) = torch.autograd.grad(critic(x, mask).sum(), x, create_graph=True)
    slopes = torch.sqrt((grad.pow(2) * mask).sum(dim=(1, 2, 3)) + GP_EPS)
    return (slopes - 1).pow(2).mean()


# ------------------------------------------------------------------------------------------------------- checkpoints
def save_checkpoint(path: str | Path, generator: Generator, meta: dict) -> None:
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    state = {k: v.detach().clone() for k, v in generator.state_dict().items()}
    tmp = path.with_suffix(path.suffix + ".tmp")
    torch.save(
        {
            "format": CHECKPOINT_FORMAT,
            "kind": "network",
            "config": dataclasses.asdict(generator.cfg),
            "state_dict": state,
            "meta": meta,
        },
        tmp,
    )
    tmp.replace(path)


def load_generator(path: str | Path) -> "Generator":
    """Load (once per process and file version) a generator for inference."""
    return load_model(path, "network", Generator, NetworkConfig)


# --------------------------------------------------------------------------------------------------------- inference
STAGES = ("global", "coarse", "refine")


def up_to_stage(generator: Generator, last: str) -> Generator:
    """A copy of ``generator`` that stops after stage ``last`` ("global", "coarse" or "refine"): the later stages'
    output layers are zeroed, i.e. set to their identity transform (for measuring what each stage adds)."""
    if last not in STAGES or (last == "global" and generator.global_stage is None):
        raise ValueError(f"up_to_stage: no stage {last!r} in this generator (stages {STAGES})")
    if generator.cfg.output_mode != "affine":
        raise ValueError("up_to_stage needs output_mode 'affine' (zero maps = identity)")
    import copy

    gen = copy.deepcopy(generator)
    for name in STAGES[STAGES.index(last) + 1 :]:
        stage = getattr(gen, name)
        with torch.no_grad():
            for layer in (stage.head, stage.global_head):
                if layer is not None:
                    layer.weight.zero_()
                    layer.bias.zero_()
    return gen


def to_tensor(image_float: np.ndarray) -> torch.Tensor:
    return torch.from_numpy(np.ascontiguousarray(image_float.transpose(2, 0, 1)))[None]


TTA_CONTEXTS = (2.0, 2.4, 2.9)  # test-time views (x horizontal flip), as the fast harmonizer's


def _upsample_inside(maps: np.ndarray, mask_s: np.ndarray, size: tuple[int, int]) -> np.ndarray:
    """(s, s, C) coefficient maps -> (h, w, C) at ``size`` = (w, h), by normalized bilinear interpolation over the
    object's low-resolution pixels only (coefficients outside the mask were never trained), falling back to their
    mean where no object pixel is near."""
    m = mask_s.astype(np.float32)
    num = cv2.resize(maps * m[..., None], size, interpolation=cv2.INTER_LINEAR)
    den = cv2.resize(m, size, interpolation=cv2.INTER_LINEAR)[..., None]
    mean = (maps * m[..., None]).sum(axis=(0, 1)) / max(float(m.sum()), 1.0)
    return np.where(den > 1e-3, num / np.maximum(den, 1e-3), mean)


def _pixel_affine_np(image: np.ndarray, coeffs: np.ndarray) -> np.ndarray:
    """numpy twin of :func:`apply_pixel_affine`: (h, w, 3), (h, w, 12) -> (I + dM) x + b, clipped."""
    dm = coeffs[..., :9].reshape(*coeffs.shape[:2], 3, 3)
    return np.clip(image + np.einsum("hwij,hwj->hwi", dm, image) + coeffs[..., 9:12], 0.0, 1.0)


@torch.no_grad()
def _network_delta(generator: Generator, image_float: np.ndarray, comp: np.ndarray, context: float, flip: bool):
    """(box, delta (h, w, 3)) predicted for one component from one view; None when it is below one network pixel.

    In the "affine" output mode the predicted colour transforms (the global stage's affine and the coarse and refine
    stages' per-pixel coefficient maps, upsampled over the object) are applied to the crop at its full resolution,
    so texture and edges finer than a network pixel are transformed, not blurred; the "residual" mode upsamples the
    predicted change.
    """
    s = generator.cfg.resolution_px
    x0, y0, x1, y1 = context_box(mask_box(comp), comp.shape, context)
    crop, m = image_float[y0:y1, x0:x1], comp[y0:y1, x0:x1]
    if flip:
        crop, m = crop[:, ::-1], m[:, ::-1]
    crop = np.ascontiguousarray(crop)
    crop_s = resize(crop, (s, s))
    m_s = (resize(np.ascontiguousarray(m).astype(np.float32), (s, s)) > 0.5).astype(np.float32)
    if not m_s.any():
        return None
    out = generator(to_tensor(crop_s), torch.from_numpy(m_s)[None, None])
    if generator.cfg.output_mode == "affine":
        full = crop
        if "global_affine" in out:
            full = apply_affine_np(full, out["global_affine"][0].numpy())
        for key in ("coarse_maps", "refine_maps"):
            maps = out[key][0].numpy().transpose(1, 2, 0)
            full = _pixel_affine_np(full, _upsample_inside(maps, m_s, (x1 - x0, y1 - y0)))
        delta = full - crop
    else:
        delta = resize(out["output"][0].numpy().transpose(1, 2, 0) - crop_s, (x1 - x0, y1 - y0))
    return (x0, y0, x1, y1), (delta[:, ::-1] if flip else delta)


@torch.no_grad()
def run_network(generator: Generator, image_float: np.ndarray, mask_bool: np.ndarray, tta: bool = True) -> np.ndarray:
    """Harmonize every connected component of the mask in its own context crop; returns a new float image.

    Each crop is resized to the network resolution; the predicted colour transforms are applied to the crop at full
    resolution (see :func:`_network_delta`) and the change is added there, so the background and the object's
    full-resolution detail are kept. With ``tta`` the change is averaged over the test-time views (context factors x
    flip), per object pixel.
    """
    out = image_float.copy()
    views = [(c, f) for c in TTA_CONTEXTS for f in (False, True)] if tta else [(generator.cfg.context, False)]
    for comp in components(mask_bool):
        total, count = np.zeros_like(image_float), np.zeros(comp.shape, np.float32)
        for c, f in views:
            r = _network_delta(generator, image_float, comp, c, f)
            if r is None:
                continue
            (x0, y0, x1, y1), delta = r
            inside = comp[y0:y1, x0:x1]
            total[y0:y1, x0:x1][inside] += delta[inside]
            count[y0:y1, x0:x1][inside] += 1
        has = comp & (count > 0)  # an object smaller than one network pixel in every view is left as it is
        out[has] = np.clip(image_float[has] + total[has] / count[has][:, None], 0.0, 1.0)
    return out

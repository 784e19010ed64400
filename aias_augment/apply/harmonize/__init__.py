"""Photorealistic style transfer (harmonization) of inserted objects: the paper's third stage.

Public API::

    from aias_augment.apply.harmonize import harmonize
    out_uint8 = harmonize(composite_rgb_uint8, fg_mask, method="camera" | "reinhard" | "fast" | "network" | "none",
                          rng=np.random.default_rng(seed), checkpoint=None)   # rng required

- ``composite_rgb_uint8``: (H, W, 3) uint8 RGB; ``fg_mask``: (H, W) float in [0, 1] (bool accepted), 1 = object.
- Only pixels under the mask change (soft mask edges blended); a new array is returned, inputs are never mutated.
- ``"network"`` / ``"fast"`` need a checkpoint (default ``checkpoints/harmonizer_small.pt`` / ``harmonizer_fast.pt``,
  trained here by ``studies/harmonization/harmonizer/train.py``); a missing one raises FileNotFoundError with the training command.
  Loaded models are cached per process.
- Bad input (shape mismatch, non-uint8 image, NaN / out-of-range mask, unknown method) raises ValueError.

Modules: ``camera_pipeline`` (WB/exposure, atmosphere, blur, noise, JPEG matching), ``reinhard`` (Lab transfer),
``fast`` (thumbnail -> affine colour transform), ``network`` (coarse-to-fine DeepFill-v1-style generator + critic,
mask-weighted WGAN-GP), ``pairs`` (iHarmony4-style training/eval pairs from real images), ``train``, ``metrics``.
"""

from aias_augment.apply.harmonize.api import METHODS, harmonize, harmonize_clip

__all__ = ["harmonize", "harmonize_clip", "METHODS"]

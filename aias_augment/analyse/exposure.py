"""The photo's exposure as a measurement: the scene irradiance that lights an object to the photo's exposure and
white balance when no lighting is estimated (the lighting ablation, a clip's first frame)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from aias_augment.core.hdr import srgb_to_linear


@dataclass(frozen=True)
class ExposureMatch:
    """Scene irradiance estimate used to light the object so that it matches the photo's exposure and white
    balance: gray-world assumption, the average scene reflectance is 18% grey."""

    irradiance_rgb: tuple[float, float, float]  # total linear irradiance on a horizontal surface, per channel

    @classmethod
    def from_image(
        cls, image_rgb: np.ndarray, region: np.ndarray | None = None, reference_albedo: float = 0.18
    ) -> "ExposureMatch":
        lin = srgb_to_linear(image_rgb.astype(np.float32) / 255.0)
        pix = lin[region] if region is not None and region.any() else lin.reshape(-1, 3)
        mean = np.clip(pix.mean(axis=0), 1e-4, None)  # eps: an all-black image still gives a finite irradiance
        return cls(tuple(float(x) for x in mean / reference_albedo))

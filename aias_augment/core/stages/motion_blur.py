"""Motion blur of an inserted object: its layer smeared along a line during the exposure.

An object that moves relative to the camera while the shutter is open is recorded as the average of its positions:
its premultiplied colour and its coverage convolved with a line of the streak's length (in linear light, so a bright
object smears brighter than a dark one over the same background). Its depth is the coverage-weighted mean along the
same line, so occlusion against the scene keeps working on the streak.

Parameters, drawn per object in the plan: the streak length in pixels, uniform in ``InsertionConfig.motion_blur_px``,
and a direction, uniform in [0, 180) degrees. In a clip the direction is the object's own image motion in that frame
(the streak lies along the way it moves); its length stays the drawn one.
"""

from __future__ import annotations

import math

import cv2
import numpy as np

from aias_augment.core.stages import ObjectLayer, grown


def line_kernel(length_px: float, angle_deg: float) -> np.ndarray:
    """A normalised (sum 1) line of ``length_px`` through the centre of an odd square kernel, at ``angle_deg`` from
    the image x axis toward +y; a sample every 1/8 px or less, splatted bilinearly."""
    half = length_px / 2.0
    size = 2 * int(math.ceil(half)) + 3
    c = size // 2
    n = max(2, int(math.ceil(length_px * 8)))
    t = -half + (np.arange(n) + 0.5) * (length_px / n)  # the centres of n equal parts: uniform on the segment
    x = c + t * math.cos(math.radians(angle_deg))
    y = c + t * math.sin(math.radians(angle_deg))
    x0, y0 = np.floor(x).astype(int), np.floor(y).astype(int)
    fx, fy = x - x0, y - y0
    k = np.zeros((size, size), np.float64)
    for dx, dy, wgt in ((0, 0, (1 - fx) * (1 - fy)), (1, 0, fx * (1 - fy)), (0, 1, (1 - fx) * fy), (1, 1, fx * fy)):
        np.add.at(k, (y0 + dy, x0 + dx), wgt)
    return (k / k.sum()).astype(np.float32)


class MotionBlur:
    name = "motion_blur_px"
    kind = "layer"
    order = 10

    def enabled(self, cfg) -> bool:
        return cfg.motion_blur_px[1] > 0

    def draw(self, cfg, rng: np.random.Generator) -> dict:
        lo, hi = cfg.motion_blur_px
        return {"length_px": round(float(rng.uniform(lo, hi)), 4), "angle_deg": round(float(rng.uniform(0, 180)), 4)}

    def apply(self, layer: ObjectLayer, params: dict, motion_px: np.ndarray | None) -> ObjectLayer:
        length, angle = float(params["length_px"]), float(params["angle_deg"])
        if motion_px is not None and float(np.hypot(*motion_px)) > 1e-3:
            angle = math.degrees(math.atan2(float(motion_px[1]), float(motion_px[0])))
        if length < 0.5:  # under half a pixel: the sampling of the render itself
            return layer
        k = line_kernel(length, angle)
        big = grown(layer, k.shape[0] // 2 + 1)

        def smear(a: np.ndarray) -> np.ndarray:
            return cv2.filter2D(a, cv2.CV_32F, k, borderType=cv2.BORDER_CONSTANT)

        alpha = np.clip(smear(big.alpha), 0.0, 1.0)
        covered = alpha > 1e-6
        inv = np.where(covered, 1.0 / np.maximum(alpha, 1e-6), 0.0).astype(np.float32)
        rgb = smear(big.rgb * big.alpha[..., None]) * inv[..., None]
        depth = smear(big.depth * big.alpha) * inv
        return ObjectLayer(big.roi, alpha.astype(np.float32), depth.astype(np.float32), rgb.astype(np.float32))


STAGE = MotionBlur()

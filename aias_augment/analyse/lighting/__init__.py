"""Lighting estimation: sun direction, HDR environment and spherical-harmonics ambient (shading and shadows are
applied in :mod:`aias_augment.apply`).

Frames: everything handed to the renderer is in the OpenCV camera frame (x right, y down, z forward); sun directions
point from the scene toward the sun; environment maps follow Blender's equirectangular convention (``envmap``).
"""

from aias_augment.analyse.lighting.estimate import (
    LightingConfig,
    LightingEstimate,
    SunDirectionEstimate,
    estimate_lighting,
    estimate_lighting_clip,
    estimate_sun_direction,
    estimate_sun_direction_clip,
    lighting_from_envmap,
)
from aias_augment.core.envmap import EnvironmentMap

__all__ = [
    "EnvironmentMap",
    "LightingConfig",
    "LightingEstimate",
    "estimate_lighting",
    "estimate_lighting_clip",
    "SunDirectionEstimate",
    "estimate_sun_direction",
    "estimate_sun_direction_clip",
    "lighting_from_envmap",
]

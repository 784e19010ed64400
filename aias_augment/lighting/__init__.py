"""Lighting estimation: sun direction, HDR environment, spherical-harmonics ambient, shading and soft shadows.

Frames: everything handed to the renderer is in the OpenCV camera frame (x right, y down, z forward); sun directions
point from the scene toward the sun; environment maps follow Blender's equirectangular convention (``envmap``).
"""
from .envmap import EnvironmentMap
from .estimate import (LightingConfig, LightingEstimate, SunDirectionEstimate, estimate_lighting, estimate_lighting_clip,
                       estimate_sun_direction, estimate_sun_direction_clip, lighting_from_envmap)
from .shading import shade_object
from .shadows import contact_occlusion, occluder_distance_from_footprint, shadow_ratio_from_sun_sky, soften_shadow

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
    "shade_object",
    "soften_shadow",
    "shadow_ratio_from_sun_sky",
    "occluder_distance_from_footprint",
    "contact_occlusion",
]

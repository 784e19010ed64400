"""Lighting estimation: sun direction, HDR environment, spherical-harmonics ambient, shading and soft shadows."""

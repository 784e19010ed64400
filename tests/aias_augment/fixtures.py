"""Small self-made test assets (no shared data needed)."""
import numpy as np
import trimesh

from aias_augment.assets import Asset, normalise_meshes


def box_asset(extents=(0.4, 0.6, 1.0), category="box", color=(200, 60, 20)) -> Asset:
    m = trimesh.creation.box(extents=extents)
    m.visual.face_colors = np.array([*color, 255], np.uint8)
    return Asset("box", category, normalise_meshes([m]), "tests:box")

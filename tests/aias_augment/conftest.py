"""Session fixtures shared across test folders: a blender-data HDR map by name, and a small real scene index
(8 frames, coarse settings so that it builds in seconds) for the retrieval and ``aias-scenes`` tests."""

from pathlib import Path

import numpy as np
import pytest

from aias_augment.core.config import data_root
from aias_augment.scenes.retrieval.features import FeatureConfig
from aias_augment.scenes.retrieval.index import FrameRef, build_index
from aias_augment.scenes.retrieval.sources import iter_frames, read_image

SMALL = FeatureConfig(max_side_px=480, seg_max_side_px=240, n_features=500)


@pytest.fixture(scope="session")
def frames():
    d = data_root()
    snip = d / "kitti06_color_snippet"
    if not snip.is_dir() or not (d / "nyu_rgbd").is_dir() or not (d / "video" / "vtest.avi").is_file():
        pytest.skip("real frames not found under $AIAS_DATA")
    out = [(FrameRef("kitti", p.name), read_image(p)) for p in sorted(snip.glob("kitti06-1[2347]-color.png"))]
    out += list(iter_frames(d / "nyu_rgbd" / "color", every=2, clip="nyu"))
    out += list(iter_frames(d / "video" / "vtest.avi", every=300, clip="vtest", max_frames=2))
    return out


@pytest.fixture(scope="session")
def small_index(frames):
    index, timings = build_index(frames, n_words=256, feature_cfg=SMALL, rng=np.random.default_rng(0))
    return index


BLENDER_WORLDS = Path("/usr/share/blender/datafiles/studiolights/world")


@pytest.fixture(scope="session")
def blender_world():
    """Path of a named blender-data HDR map; skips (with the reason) when the Debian package is not installed."""

    def get(name: str) -> Path:
        p = BLENDER_WORLDS / f"{name}.exr"
        if not p.is_file():
            pytest.skip(f"blender-data not installed ({p} missing); run tools/setup.sh")
        return p

    return get

from pathlib import Path

import pytest

BLENDER_WORLDS = Path("/usr/share/blender/datafiles/studiolights/world")


@pytest.fixture(scope="session")
def blender_world():
    """Path of a named blender-data HDR map; skips (with the reason) when the Debian package is not installed."""

    def get(name: str) -> Path:
        p = BLENDER_WORLDS / f"{name}.exr"
        if not p.is_file():
            pytest.skip(f"blender-data not installed ({p} missing); run scripts/setup.sh")
        return p

    return get

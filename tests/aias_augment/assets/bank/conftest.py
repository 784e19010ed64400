"""Shared fixtures of the bank tests: a few records of the installed Sweet Home 3D catalogs (metadata only)."""

import pytest

from aias_augment.assets.bank.sh3f import DEFAULT_SH3F_DIR

SCOPIA = DEFAULT_SH3F_DIR / "Scopia.sh3f"
BLENDSWAP0 = DEFAULT_SH3F_DIR / "BlendSwap-CC-0.sh3f"


@pytest.fixture(scope="session")
def sh3f_records():
    """Catalog records of two installed catalogs, by id (skips when sweethome3d-furniture is not installed)."""
    if not (SCOPIA.is_file() and BLENDSWAP0.is_file()):
        pytest.skip("sweethome3d-furniture not installed (tools/setup.sh installs it)")
    from aias_augment.assets.bank.sh3f import read_sh3f_catalog
    from aias_augment.assets.bank.taxonomy import load_taxonomy

    tax = load_taxonomy()
    out = {}
    for f in (SCOPIA, BLENDSWAP0):
        recs, _ = read_sh3f_catalog(f, tax)
        out.update({r.id: r for r in recs})
    return out

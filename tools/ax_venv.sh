#!/usr/bin/env bash
# The transform's contract tests under AlbumentationsX (AGPL-3.0; never a dependency of this project, supported when
# a user has it installed), in a virtual environment of their own beside the main one, which is left untouched:
#
#   .venv-ax/  its own site-packages: albumentationsx (the module `albumentations`), albucore and numkong at the
#              versions albumentationsx asks for; then a .pth line that appends .venv's site-packages, so everything
#              else (numpy, torch, the project itself, pytest) is the main environment's pinned stack, found after
#              AlbumentationsX's own packages.
#
# AX_VERSION=2.5.1 pins the release (default: the latest on the package index). Reruns reuse .venv-ax while its
# stamp (this script, the version asked for, .venv's stamp) is unchanged. Exits non-zero when the install or a
# requirement of albumentationsx the combined environment does not meet fails, naming it, or when a test fails.
set -euo pipefail
cd "$(dirname "$0")/.."
MAIN=${VENV:-.venv}
AX=${AX_VENV:-.venv-ax}
spec="albumentationsx${AX_VERSION:+==$AX_VERSION}"

[ -x "$MAIN/bin/python" ] || { echo "[ax] $MAIN/bin/python not found: run 'make setup' first" >&2; exit 2; }
want="$({ cat "$0"; cat "$MAIN/.aias-stamp" 2>/dev/null || true; } | sha256sum | cut -c1-16) $spec"
if [ ! -f "$AX/.ax-stamp" ] || [ "$(cat "$AX/.ax-stamp")" != "$want" ]; then
    rm -rf "$AX"
    "$MAIN/bin/python" -m venv "$AX"
    # Only AlbumentationsX and the two packages of its line go into .venv-ax (no dependencies resolved here: the
    # rest comes from .venv, checked below); installing them before the .pth line exists keeps pip from seeing,
    # and replacing, .venv's albucore of the 2.0.8 line.
    "$AX/bin/python" -m pip install -q --no-deps "$spec"
    mapfile -t own < <("$AX/bin/python" - <<'PY'
from importlib.metadata import requires
for r in requires("albumentationsx"):
    name = r.split(";")[0].strip()
    if name.lower().startswith(("albucore", "numkong")):
        print(name)
PY
)
    "$AX/bin/python" -m pip install -q --no-deps "${own[@]}"
    main_site=$("$MAIN/bin/python" -c 'import sysconfig; print(sysconfig.get_paths()["purelib"])')
    ax_site=$("$AX/bin/python" -c 'import sysconfig; print(sysconfig.get_paths()["purelib"])')
    echo "import site; site.addsitedir('$(realpath "$main_site")')" > "$ax_site/zz_main_venv.pth"
    echo "$want" > "$AX/.ax-stamp.tmp"
    mv "$AX/.ax-stamp.tmp" "$AX/.ax-stamp"
fi

# Every requirement of the AlbumentationsX line met by the combined environment, and `albumentations` is it.
NO_ALBUMENTATIONS_UPDATE=1 "$AX/bin/python" - <<'PY'
import sys
from importlib.metadata import PackageNotFoundError, requires, version

from packaging.requirements import Requirement

bad = []
for dist in ("albumentationsx", "albucore"):
    for line in requires(dist) or ():
        r = Requirement(line)
        if r.marker is not None and not r.marker.evaluate({"extra": ""}):
            continue
        try:
            have = version(r.name)
        except PackageNotFoundError:
            have = None
        if have is None or not r.specifier.contains(have, prereleases=True):
            bad.append(f"{dist} needs {r}, found {have}")
if bad:
    sys.exit("[ax] " + "; ".join(bad))
from aias_augment.adapters import albu_compat

if not albu_compat.IS_X:
    sys.exit("[ax] `import albumentations` in .venv-ax is not AlbumentationsX")
print("[ax]", albu_compat.line(), "with albucore", version("albucore"), "and numpy", version("numpy"))
PY
NO_ALBUMENTATIONS_UPDATE=1 PYOPENGL_PLATFORM=${PYOPENGL_PLATFORM:-egl} \
    "$AX/bin/python" -m pytest -q -p no:cacheprovider tests/aias_augment/adapters/test_albumentationsx.py

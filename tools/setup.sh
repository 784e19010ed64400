#!/usr/bin/env bash
# Idempotent environment setup for `make demo` / `make test` on a fresh machine.
# 1. Debian packages for headless EGL rendering on Mesa llvmpipe (+ real asset/HDR data packages).
# 2. A virtual environment with the pinned project and its dev extras.
# 3. The OpenCV contrib fix-up: albumentations pulls opencv-python-headless, which overwrites cv2 from
#    contrib; reinstall contrib last and assert a contrib-only function exists.
set -euo pipefail
cd "$(dirname "$0")/.."
VENV=${VENV:-.venv}
PY=${PYTHON:-python3}

# chromium (+ a font) for the A/B study's end-to-end browser test (Playwright drives the system browser).
APT_PKGS="libegl1 libgl1 libegl-mesa0 libgl1-mesa-dri libgles2 sweethome3d-furniture blender-data chromium fonts-dejavu-core"
missing=""
for p in $APT_PKGS; do dpkg -s "$p" >/dev/null 2>&1 || missing="$missing $p"; done
if [ -n "$missing" ]; then
    echo "[setup] apt-get install:$missing"
    SUDO=""; [ "$(id -u)" -ne 0 ] && SUDO="sudo"
    $SUDO apt-get update -qq
    DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq --no-install-recommends $missing >/dev/null
fi

stamp="$VENV/.aias-stamp"
want="$(sha256sum pyproject.toml tools/setup.sh | sha256sum | cut -c1-16)"
if [ -f "$stamp" ] && [ "$(cat "$stamp")" = "$want" ]; then
    exit 0
fi
[ -x "$VENV/bin/python" ] || "$PY" -m venv "$VENV"
"$VENV/bin/python" -m pip install -q --upgrade pip
# torch first, from the local wheel cache (pinned versions).
"$VENV/bin/python" -m pip install -q "torch==2.14.1" "torchvision==0.29.1"
"$VENV/bin/python" -m pip install -q -e ".[dev]"
CV=$(grep -oP 'opencv-contrib-python-headless==\K[0-9.]+' pyproject.toml)
"$VENV/bin/python" -m pip install -q --force-reinstall --no-deps "opencv-contrib-python-headless==$CV"
NO_ALBUMENTATIONS_UPDATE=1 "$VENV/bin/python" - <<'PY'
import cv2, albumentations, pyrender, OpenEXR, pycocotools, trimesh, torch, torchvision
assert hasattr(cv2, "ximgproc") and hasattr(cv2.ximgproc, "guidedFilter"), "cv2 is not the contrib build"
print("[setup] ok: cv2", cv2.__version__, "albumentations", albumentations.__version__, "torch", torch.__version__)
PY
echo "$want" > "$stamp"

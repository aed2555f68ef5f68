#!/usr/bin/env bash
# Installs what building and testing need beyond the Rust toolchain, from package registries only.
#   - Debian: mesa-vulkan-drivers + libvulkan1 (lavapipe: wgpu on the CPU, for the GPU backend's tests)
#             chromium (headless; the `stylize view` page's browser test, WebGL through SwiftShader)
#   - PyPI:   ONNX Runtime's shared library (scripts/setup-onnxruntime.sh → .deps/onnxruntime/)
#             maturin, pytest, NumPy (.venv/); bpy 4.5 + pytest (.venv-blender/, the Blender extension)
# Idempotent: re-running skips what is already there. Needs root (or sudo) for apt-get.
set -euo pipefail
cd "$(dirname "$0")/.."

need_apt=()
for pkg in mesa-vulkan-drivers libvulkan1 chromium; do
  dpkg-query -W -f='${Status}' "$pkg" 2>/dev/null | grep -q "install ok installed" || need_apt+=("$pkg")
done
if ((${#need_apt[@]})); then
  echo "setup: installing ${need_apt[*]} (apt)"
  SUDO=""; [ "$(id -u)" -ne 0 ] && SUDO="sudo"
  $SUDO apt-get update -qq
  DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq --no-install-recommends "${need_apt[@]}" >/dev/null
fi

if [ -x scripts/setup-onnxruntime.sh ] || [ -f scripts/setup-onnxruntime.sh ]; then
  bash scripts/setup-onnxruntime.sh
fi
# --- Python bindings (crates/darap-py) -------------------------------------------------------
# maturin, pytest and NumPy from PyPI into the project-local .venv/ (git-ignored); skipped when
# they are already there. Needs python3 with venv (Debian: python3-venv).
if ! .venv/bin/python -c "import numpy, pytest" 2>/dev/null || [ ! -x .venv/bin/maturin ]; then
  echo "setup: creating .venv with maturin, pytest, numpy (PyPI)"
  if ! python3 -c "import venv, ensurepip" 2>/dev/null; then
    SUDO=""; [ "$(id -u)" -ne 0 ] && SUDO="sudo"
    $SUDO apt-get update -qq
    DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq --no-install-recommends python3-venv >/dev/null
  fi
  python3 -m venv .venv
  .venv/bin/python -m pip install -q --disable-pip-version-check "maturin>=1.9.4,<2" "pytest>=7" "numpy>=1.21"
fi
# --- end Python bindings -----------------------------------------------------------------------
# --- Blender extension (blender/, docs/blender.md) ---------------------------------------------
# Blender 4.5 LTS as a Python module (PyPI `bpy`, CPython 3.11 only, ~480 MB installed) and pytest
# in their own venv .venv-blender/ (git-ignored), for the headless extension tests and Blender's
# extension build tool; skipped when present, and where python3 is not 3.11 (no bpy wheel: the
# extension tests are then skipped by scripts/test.sh, which says so).
# bpy links a few X11/GL client libraries even headless (`ldd bpy/__init__.so`: everything else
# ships in the wheel); Debian packages, installed when missing.
need_apt=()
for pkg in libx11-6 libxext6 libxrender1 libxfixes3 libxi6 libxkbcommon0 libsm6 libice6 libgl1; do
  dpkg-query -W -f='${Status}' "$pkg" 2>/dev/null | grep -q "install ok installed" || need_apt+=("$pkg")
done
if ((${#need_apt[@]})); then
  echo "setup: installing ${need_apt[*]} (apt, for bpy)"
  SUDO=""; [ "$(id -u)" -ne 0 ] && SUDO="sudo"
  $SUDO apt-get update -qq
  DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq --no-install-recommends "${need_apt[@]}" >/dev/null
fi
if ! .venv-blender/bin/python -c "import bpy, pytest" 2>/dev/null; then
  if python3 -c 'import sys; sys.exit(sys.version_info[:2] != (3, 11))'; then
    echo "setup: creating .venv-blender with bpy 4.5 (PyPI, ~480 MB) and pytest"
    rm -rf .venv-blender
    python3 -m venv .venv-blender
    .venv-blender/bin/python -m pip install -q --disable-pip-version-check "bpy==4.5.*" "pytest>=7"
  else
    echo "setup: python3 is not 3.11: no bpy 4.5 wheel, the Blender extension tests will be skipped"
  fi
fi
# --- end Blender extension ---------------------------------------------------------------------
echo "setup: done"

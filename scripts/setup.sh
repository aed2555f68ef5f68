#!/usr/bin/env bash
# Installs what building and testing need beyond the Rust toolchain, from package registries only.
#   - Debian: mesa-vulkan-drivers + libvulkan1 (lavapipe: wgpu on the CPU, for the GPU backend's tests)
#   - PyPI:   ONNX Runtime's shared library (scripts/setup-onnxruntime.sh → .deps/onnxruntime/)
# Idempotent: re-running skips what is already there. Needs root (or sudo) for apt-get.
set -euo pipefail
cd "$(dirname "$0")/.."

need_apt=()
for pkg in mesa-vulkan-drivers libvulkan1; do
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
echo "setup: done"

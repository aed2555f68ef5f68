#!/usr/bin/env bash
# Fetch the ONNX Runtime shared library (CPU build) that `diffusion-onnx` loads at run time.
#
# Source: the PyPI wheel `onnxruntime` 1.31.1 (manylinux_2_28_x86_64), which carries
# `onnxruntime/capi/libonnxruntime.so.1.31.1` (needs only libc and libstdc++). Only that one file
# is extracted, into `<repo>/.deps/onnxruntime/` (git-ignored). Idempotent: a present file with the
# expected sha256 is kept and nothing is downloaded.
#
# Usage: scripts/setup-onnxruntime.sh            # prints the library path on the last line
#        ORT_DYLIB_PATH=$(scripts/setup-onnxruntime.sh | tail -n1)
# The Rust side looks at $ORT_DYLIB_PATH first, then at this default location.
set -euo pipefail

ORT_VERSION="1.31.1"
LIB_NAME="libonnxruntime.so.${ORT_VERSION}"
# sha256 of the library inside onnxruntime-1.31.1-cp311-cp311-manylinux_2_28_x86_64.whl
EXPECTED_SHA256="fc44112fbe06d7d689c57e11d3862031f64711007e4ee020f8eed5185fd2c1d3"

REPO_ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
DEST_DIR="${REPO_ROOT}/.deps/onnxruntime"
DEST="${DEST_DIR}/${LIB_NAME}"

sha_of() { sha256sum "$1" | cut -d' ' -f1; }

if [[ -f "${DEST}" ]] && [[ "$(sha_of "${DEST}")" == "${EXPECTED_SHA256}" ]]; then
    echo "onnxruntime ${ORT_VERSION} already present" >&2
    echo "${DEST}"
    exit 0
fi

case "$(uname -s)-$(uname -m)" in
    Linux-x86_64) PLATFORM="manylinux_2_28_x86_64" ;;
    *)
        echo "error: this script knows only the Linux x86_64 wheel; on $(uname -s)-$(uname -m) install" >&2
        echo "       ONNX Runtime ${ORT_VERSION} yourself and set ORT_DYLIB_PATH to its shared library." >&2
        exit 1
        ;;
esac

PYTHON="${PYTHON:-python3}"
if ! "${PYTHON}" -m pip --version >/dev/null 2>&1; then
    echo "error: '${PYTHON} -m pip' is not available; install pip (or set PYTHON) and re-run." >&2
    exit 1
fi

TMP="$(mktemp -d)"
trap 'rm -rf "${TMP}"' EXIT

echo "downloading onnxruntime==${ORT_VERSION} wheel from PyPI ..." >&2
"${PYTHON}" -m pip download --quiet --no-deps --only-binary=:all: \
    --python-version 3.11 --platform "${PLATFORM}" \
    --dest "${TMP}" "onnxruntime==${ORT_VERSION}" >&2

WHEEL="$(ls "${TMP}"/onnxruntime-"${ORT_VERSION}"-*.whl 2>/dev/null | head -n1 || true)"
if [[ -z "${WHEEL}" ]]; then
    echo "error: pip did not produce an onnxruntime ${ORT_VERSION} wheel in ${TMP}" >&2
    exit 1
fi

# Extract the single member with Python's zipfile (no dependency on `unzip`).
"${PYTHON}" - "${WHEEL}" "onnxruntime/capi/${LIB_NAME}" "${TMP}/${LIB_NAME}" <<'PY'
import shutil, sys, zipfile
wheel, member, out = sys.argv[1:4]
with zipfile.ZipFile(wheel) as z, z.open(member) as src, open(out, "wb") as dst:
    shutil.copyfileobj(src, dst)
PY

GOT="$(sha_of "${TMP}/${LIB_NAME}")"
if [[ "${GOT}" != "${EXPECTED_SHA256}" ]]; then
    echo "error: sha256 mismatch for ${LIB_NAME}: expected ${EXPECTED_SHA256}, got ${GOT}" >&2
    exit 1
fi

mkdir -p "${DEST_DIR}"
install -m 0644 "${TMP}/${LIB_NAME}" "${DEST}"
echo "installed ${DEST}" >&2
echo "${DEST}"

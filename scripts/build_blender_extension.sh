#!/usr/bin/env bash
# Builds the Blender extension (blender/geometry_in_style/) into an installable zip with the darap
# abi3 wheel under wheels/ (docs/blender.md).
#
#   scripts/build_blender_extension.sh [--release] [--out DIR]
#
# The wheel: `maturin build` of crates/darap-py, by default in the dev profile with the
# workspace-hack feature (the artifacts `scripts/test.sh`'s `maturin develop` already compiled:
# packaging only), with --release an optimized wheel for artists (compiles the faer tree in
# release: minutes). The zip is built and validated by Blender's own extension tool
# (bl_pkg/cli/blender_ext.py of the bpy module in .venv-blender/, see scripts/setup.sh).
# Output: DIR/geometry_in_style-VERSION.zip (DIR defaults to target/blender).
set -euo pipefail
cd "$(dirname "$0")/.."
profile=(--profile dev --features workspace-hack)
out=target/blender
while (($#)); do
  case "$1" in
    --release) profile=(--release); shift ;;
    --out) out="$2"; shift 2 ;;
    *) echo "usage: $0 [--release] [--out DIR]" >&2; exit 2 ;;
  esac
done
[ -x .venv/bin/maturin ] || { echo "error: no .venv/bin/maturin: run scripts/setup.sh" >&2; exit 1; }
blender_py=.venv-blender/bin/python
ext_tool=$(ls .venv-blender/lib/python3*/site-packages/bpy/*/scripts/addons_core/bl_pkg/cli/blender_ext.py 2>/dev/null | head -n1 || true)
[ -n "$ext_tool" ] || { echo "error: no bpy in .venv-blender (Blender's blender_ext.py): run scripts/setup.sh" >&2; exit 1; }

stage=$(mktemp -d)
trap 'rm -rf "$stage"' EXIT
mkdir -p "$stage/wheels" "$out"
VIRTUAL_ENV="$PWD/.venv" PATH="$PWD/.venv/bin:$PATH" \
  maturin build --locked --manifest-path crates/darap-py/Cargo.toml "${profile[@]}" \
  --out "$stage/wheels" --quiet
wheel=$(cd "$stage/wheels" && ls darap-*-abi3-*.whl)
[ "$(echo "$wheel" | wc -l)" = 1 ] || { echo "error: expected one darap wheel, got: $wheel" >&2; exit 1; }

src="$stage/geometry_in_style"
mkdir -p "$src"
cp blender/geometry_in_style/*.py "$src/"
cp LICENSE "$src/LICENSE"
mv "$stage/wheels" "$src/wheels"
sed "s|@DARAP_WHEEL@|$wheel|" blender/geometry_in_style/blender_manifest.toml > "$src/blender_manifest.toml"
"$blender_py" "$ext_tool" build --source-dir "$src" --output-dir "$out"
zip=$(ls -t "$out"/geometry_in_style-*.zip | head -n1)
"$blender_py" "$ext_tool" validate "$zip"
echo "$zip"

#!/usr/bin/env bash
# Sets up and runs every check CI runs: format, lints, tests, gradient checks, dependency rules.
set -euo pipefail
cd "$(dirname "$0")/.."
# Each step prints the seconds since the start, so a CI log shows where the time goes.
started=$SECONDS
step() { echo; echo "==> [$((SECONDS - started)) s] $*"; }
step "setup (scripts/setup.sh)";   bash scripts/setup.sh
export XDG_RUNTIME_DIR="${XDG_RUNTIME_DIR:-/tmp}"   # silences Mesa's warnings under lavapipe

step "cargo fmt --check";          cargo fmt --all -- --check
# Lints without a separate `cargo clippy` pass: from here on clippy's driver compiles the
# workspace's own crates (scripts/clippy-rustc.sh, what `cargo clippy -- -D warnings` sets up), so
# the one build that the tests need also runs every clippy lint and fails on any warning, and the
# dependencies are compiled once, not checked once and compiled again (docs/benchmarks.md, "Build
# time"). Every cargo call below sees the same wrapper, so they share artifacts. (The wrapper is part
# of our crates' fingerprints: a plain `cargo build` afterwards recompiles our crates, not the
# dependencies, and the next run of this script recompiles them back.)
CLIPPY_DRIVER="$(rustc --print sysroot)/bin/clippy-driver"
[[ -x "$CLIPPY_DRIVER" ]] || { echo "error: no clippy-driver at $CLIPPY_DRIVER (rustup component add clippy)" >&2; exit 1; }
export CLIPPY_DRIVER RUSTC_WORKSPACE_WRAPPER="$PWD/scripts/clippy-rustc.sh"
step "clippy -D warnings while building every target (cargo test --all-targets --no-run)"
cargo test --workspace --all-targets --locked --no-run
# The same targets as built above (a plain `cargo test` would build the examples a second time,
# in normal mode), then the doc tests, which `--all-targets` leaves out.
step "cargo test";                 cargo test --workspace --all-targets --locked
step "cargo test --doc";           cargo test --workspace --doc --locked
# The README's quick-start build (docs/cli.md, "Builds and features"): lints, and its own test.
# Selected alone, its dependencies would get fewer features than in the workspace's build and Cargo
# would compile them again (the faer tree, the proc-macros); `-p workspace-hack` pins them to the
# workspace build's (crates/workspace-hack: no code, and `check-deps` below keeps it complete), so
# only our crates compile here. One compilation serves both checks, as above.
quick_start() { cargo test -p stylize-cli -p workspace-hack --no-default-features --locked "$@"; }
step "quick-start build: clippy, all targets"; quick_start --all-targets --no-run
step "quick-start build: test";    quick_start --test features
step "cargo build (xtask)";        cargo build -p xtask --locked   # visible progress; `cargo xtask` runs quietly
step "cargo xtask check-deps";     cargo xtask check-deps
step "cargo xtask gradcheck";      cargo xtask gradcheck
# --- Python bindings (crates/darap-py): build into .venv (dev profile, shared target/), pytest ---
# (feature workspace-hack: the workspace build's dependency artifacts, as for the quick-start build)
step "darap-py: maturin develop";  VIRTUAL_ENV="$PWD/.venv" PATH="$PWD/.venv/bin:$PATH" \
                                   maturin develop --locked --manifest-path crates/darap-py/Cargo.toml \
                                   --features workspace-hack
step "pytest (darap-py, scripts)"; .venv/bin/python -m pytest crates/darap-py/tests scripts/tests
# --- end Python bindings ---
# --- Blender extension (blender/): build the zip (dev wheel from the artifacts above), install it
# into the bpy module headless and drive it against target/debug/stylize (docs/blender.md) ---
if [ -x .venv-blender/bin/python ]; then
  step "blender extension: build";  bash scripts/build_blender_extension.sh
  step "pytest (blender extension)"; .venv-blender/bin/python -m pytest blender/tests
else
  step "blender extension: SKIPPED (no .venv-blender: python3 is not 3.11, see scripts/setup.sh)"
fi
# --- end Blender extension ---
step "cargo xtask fuzz";           cargo xtask fuzz --seconds 60
echo; echo "test.sh: all checks passed in $((SECONDS - started)) s"

#!/usr/bin/env bash
# RUSTC_WORKSPACE_WRAPPER for scripts/test.sh's builds: clippy's driver (CLIPPY_DRIVER, set by
# test.sh) compiles our crates, with clippy's lints and warnings denied, as
# `cargo clippy -- -D warnings` would, while `cargo test` builds them. A wrapper, not
# RUSTFLAGS=-Dwarnings: RUSTFLAGS would change every dependency's hash too and rebuild them all.
exec "${CLIPPY_DRIVER:?set by scripts/test.sh}" "$@" -D warnings

# Everyday commands. `just --list` shows them. (Install just with `cargo install just`.)

# Stylize the bundled bunny with the model-free cube style (writes runs/demo), with the README's
# quick-start build (no text path, no GPU backend; docs/cli.md "Builds and features").
demo:
    cargo run --release --no-default-features --bin stylize -- run fixtures/meshes/bunny.obj --style cube --out runs/demo

# The full command line on PATH (every feature: text path, GPU backend, viewer).
install:
    cargo install --locked --path crates/stylize-cli

# Everything CI runs: setup, fmt, clippy, tests, check-deps, gradcheck, fuzz.
test:
    bash scripts/test.sh

# Finite-difference checks of every hand-written adjoint (optionally filtered by name).
gradcheck filter="":
    cargo xtask gradcheck {{filter}}

# Dependency rules (darap stays light).
check-deps:
    cargo xtask check-deps

# Mutation fuzzing of every file reader (CI runs 60 s; failures in target/fuzz-failures/).
fuzz seconds="60" *args="":
    cargo xtask fuzz --seconds {{seconds}} {{args}}

fmt:
    cargo fmt --all

lint:
    cargo clippy --workspace --all-targets -- -D warnings

# Release benchmarks (results go into docs/benchmarks.md by hand, with the machine).
bench-darap:
    cargo run --release -p darap --example bench_darap

bench-render:
    cargo run --release -p raster-diff --example bench_render

bench-csd:
    cargo run --release -p csd --example bench_csd

# Issue 10's target 3: real CLI runs with the fixture models, per-part medians (docs/benchmarks.md).
bench-iteration runs="3":
    bash scripts/bench-target3.sh {{runs}}

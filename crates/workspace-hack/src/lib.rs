//! Build-time only: no code. CI's narrower builds and xtask select it; no product build (the
//! README's commands, `cargo install`, `pip install`) does.
//!
//! Cargo resolves a dependency's features over the packages of one invocation. The README's test
//! command (`scripts/test.sh`) builds the whole workspace once, then two narrower builds:
//! the quick-start configuration (`cargo test -p stylize-cli --no-default-features`) and the Python
//! module (`maturin develop`, `-p darap-py`). In those, a few low-level dependencies (num-traits,
//! bytemuck, serde, syn, …) get fewer features than in the workspace build, so Cargo compiles them
//! again, and with them everything above them: the faer tree, every proc-macro, serde. That was
//! 4–5 minutes of a CI run on two cores.
//!
//! Selecting this crate in those builds (`-p workspace-hack` for the quick-start build; the
//! `workspace-hack` feature of darap-py for maturin) gives those dependencies the workspace build's
//! features, so the narrower builds reuse its artifacts. Which features the narrower builds
//! get changes nothing our crates compile (their own `cfg(feature)` are untouched), only which
//! extra items the dependencies offer.
//!
//! The same technique as `cargo hakari`'s generated crate, kept by hand: `cargo xtask check-deps`
//! compares the feature sets of those builds and of xtask's with the workspace build's (`cargo
//! tree`) and fails on any dependency whose features have drifted, naming it with both feature
//! sets: its entry here then needs the workspace build's set.

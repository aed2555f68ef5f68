//! Helpers shared by the integration tests (each file under `tests/` is its own crate and
//! includes this module with `mod common;`; each uses a subset, hence `dead_code` is allowed).
#![allow(dead_code)]

use std::path::Path;
use std::process::{Command, Output};

/// The value of `r`, or a panic with its error (`unwrap` with the error's `Debug` text).
pub fn ok<T, E: std::fmt::Debug>(r: Result<T, E>) -> T {
    r.unwrap_or_else(|e| panic!("{e:?}"))
}

/// `p` as a command-line argument (the tests' paths are UTF-8).
pub fn s(p: &Path) -> &str {
    p.to_str()
        .unwrap_or_else(|| panic!("non-UTF-8 path {}", p.display()))
}

/// Runs the `stylize` binary of this build with `args` and waits for it.
pub fn stylize(args: &[&str]) -> Output {
    ok(Command::new(env!("CARGO_BIN_EXE_stylize"))
        .args(args)
        .output())
}

/// The process's stderr as text.
pub fn stderr(out: &Output) -> String {
    String::from_utf8_lossy(&out.stderr).into_owned()
}

/// Runs `stylize` with `args`: whether it succeeded, its stdout and its stderr as text.
pub fn stylize_text(args: &[&str]) -> (bool, String, String) {
    let o = stylize(args);
    (
        o.status.success(),
        String::from_utf8_lossy(&o.stdout).into_owned(),
        stderr(&o),
    )
}

/// `stylize apply SAVED -o OUT EXTRA…` as [`stylize_text`]: (success, stdout, stderr).
pub fn apply_text(saved: &Path, out: &Path, extra: &[&str]) -> (bool, String, String) {
    let mut args = vec!["apply", s(saved), "-o", s(out)];
    args.extend_from_slice(extra);
    stylize_text(&args)
}

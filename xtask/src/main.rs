//! `cargo xtask <command>`: project automation.
//!
//! - `gradcheck [FILTER]`: finite-difference checks of every hand-written adjoint.
//! - `check-deps`: asserts dependency rules (e.g. `darap` pulls in no GPU/ML/IO crates).
//! - `fuzz [--seconds N] [--target NAME] [--seed S] [--replay FILE]`: mutation fuzzing of every
//!   reader of user files, with time and memory caps (see `fuzz/mod.rs`).

mod check_deps;
mod fuzz;
mod gradcheck;

/// Counts (and, while fuzzing, caps) allocations: see `fuzz::alloc`.
#[global_allocator]
static ALLOCATOR: fuzz::alloc::Counting = fuzz::alloc::Counting;

use std::process::ExitCode;

fn main() -> ExitCode {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let result = match args.first().map(String::as_str) {
        Some("gradcheck") => gradcheck::run(args.get(1).map(String::as_str)),
        Some("check-deps") => check_deps::run(),
        Some("fuzz") => fuzz::run(&args[1..]),
        Some("fuzz-child") => fuzz::child(&args[1..]),
        _ => {
            eprintln!(
                "usage: cargo xtask <gradcheck [FILTER] | check-deps | fuzz [--seconds N] [--target NAME] [--seed S] [--replay FILE]>"
            );
            return ExitCode::from(2);
        }
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("xtask: {e:#}");
            ExitCode::FAILURE
        }
    }
}

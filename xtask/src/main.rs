//! `cargo xtask <command>`: project automation.
//!
//! - `gradcheck [FILTER]`: finite-difference checks of every hand-written adjoint.
//! - `check-deps`: asserts dependency rules (e.g. `darap` pulls in no GPU/ML/IO crates).

mod check_deps;
mod gradcheck;

use std::process::ExitCode;

fn main() -> ExitCode {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let result = match args.first().map(String::as_str) {
        Some("gradcheck") => gradcheck::run(args.get(1).map(String::as_str)),
        Some("check-deps") => check_deps::run(),
        _ => {
            eprintln!("usage: cargo xtask <gradcheck [FILTER] | check-deps>");
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

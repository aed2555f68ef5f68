//! Library side of the `stylize` command line: config files, progress display, signals, batches,
//! and one module per subcommand under [`cmd`]. The optimization itself is the `stylize` crate,
//! which the commands name directly (`stylize::style`, `stylize::models`, …).
//!
//! Nothing here prints with `println!`/`eprintln!` (they panic on a closed pipe): [`output`]'s
//! `outln!`/`errln!` do, and the lints below keep it that way.

#![deny(clippy::print_stdout, clippy::print_stderr)]

// First, so that its macros are in scope in every module below.
#[macro_use]
pub mod output;

pub mod batch;
pub mod batch_grid;
pub mod cmd;
pub mod config;
pub mod features;
pub mod input;
pub mod max_safe;
pub mod open_hint;
pub mod progress;
pub mod reference_config;
pub mod runner;
pub mod sanity;
pub mod sheet;
pub mod signals;
pub mod view;

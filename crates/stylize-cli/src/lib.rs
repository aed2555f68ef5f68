//! Library side of the `stylize` command line: config files, progress display, signals, batches,
//! and one module per subcommand under [`cmd`]. The optimization itself is the `stylize` crate;
//! its modules are re-exported here under their old paths so the commands read as before.

pub mod batch;
pub mod cmd;
pub mod config;
pub mod input;
pub mod progress;
pub mod reference_config;
pub mod runner;
pub mod signals;

pub use stylize::{checkpoint, durable, eval, identity, lock, models, pipeline, rundir, style};

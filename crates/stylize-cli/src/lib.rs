//! Library side of the `stylize` command line: config files, progress display, signals, batches,
//! and one module per subcommand under [`cmd`]. The optimization itself is the `stylize` crate;
//! its modules are re-exported here under their old paths so the commands read as before.

pub mod batch;
pub mod cmd;
pub mod config;
pub mod features;
pub mod input;
pub mod open_hint;
pub mod progress;
pub mod reference_config;
pub mod runner;
pub mod sanity;
pub mod signals;
pub mod view;

#[cfg(not(feature = "text"))]
pub use features::models;
#[cfg(feature = "text")]
pub use stylize::models;
pub use stylize::{eval, identity, pipeline, run_pictures, style};

//! Library side of the `stylize` command line: configuration, the loop, run directories, and
//! one module per subcommand under [`cmd`].

pub mod batch;
pub mod checkpoint;
pub mod cmd;
pub mod config;
pub mod durable;
pub mod eval;
pub mod identity;
pub mod input;
pub mod lock;
pub mod models;
pub mod open_hint;
pub mod pipeline;
pub mod reference_config;
pub mod run_pictures;
pub mod rundir;
pub mod runner;
pub mod sanity;
pub mod signals;
pub mod style;
pub mod view;

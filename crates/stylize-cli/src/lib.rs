//! Library side of the `stylize` command line: configuration, the loop, run directories, and
//! one module per subcommand under [`cmd`].

pub mod cmd;
pub mod config;

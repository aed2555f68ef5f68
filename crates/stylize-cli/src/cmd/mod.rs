//! One module per `stylize` subcommand; each has `Args` (clap) and `run(Args)`.

pub mod apply;
pub mod apply_grid;
pub mod batch;
pub mod debug_guidance;
pub mod doctor;
pub mod embed;
pub mod eval;
pub mod mesh;
pub mod remesh;
pub mod render;
pub mod run;
pub mod shared;
pub mod view;

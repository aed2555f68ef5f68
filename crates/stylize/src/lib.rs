//! Geometry in Style as a library: everything a stylization needs except a command line.
//!
//! - [`pipeline`]: the loop ([`pipeline::run_loop`]) over an [`pipeline::Objective`] (the
//!   model-free [`pipeline::StyleObjective`], the text-guided [`pipeline::TextObjective`]);
//! - [`style`]: the model-free styles (cube, octahedron, exemplar) and their alignment loss;
//! - [`task`]: kinds of task behind two traits ([`task::TaskKind`]: identity and settings read;
//!   [`task::Task`]: schedule, objective, what it reports), with the style and prompt kinds;
//! - [`config`]: every setting of a run, with the reference's defaults;
//! - [`remeshing`]: `[mesh] remesh`: whether and how a run's input is remeshed first;
//! - [`runner`]: one run from mesh file to complete run directory, with a [`runner::Progress`]
//!   the run, for replay; [`run_pictures`]: the before/after sheet, the turntable (PNG, GIF) and
//!   the orbit, tint and grid helpers the previews share; `turntable_mp4` (feature `mp4`): the
//!   turntable as an H.264 MP4;
//! - [`models`]: DeepFloyd IF guidance from a model directory (feature `text`; without it its
//!   loading functions return [`Error::NotBuilt`]); [`eval`]: metrics
//!   of finished runs (CLIP similarity with `text`); [`intersections`]: a result's
//!   self-intersections against its source (what `eval`, `apply`, the viewer and the end of a run
//!   report);
//! - [`error`]: the typed [`Error`] every public function returns, and [`error::Stopped`];
//! - [`malloc`]: the C allocator's policy that keeps the loop's large per-iteration buffers from
//!   being page-faulted in anew every iteration (for programs that run the loop).
//!
//! The command line (`stylize-cli`) adds argument parsing, config files, progress display and
//! batches; this crate depends on nothing of that kind (`cargo xtask check-deps`).
//!
//! Features (all default): `text`, the text-guided path through ONNX Runtime (`models`, CLIP in
//! [`eval`]; without it [`models`] only says so); `gpu`, raster-diff's wgpu backend (without it
//! [`config::Backend::Auto`] renders on the CPU and `Gpu` is an error); `mp4`, `turntable.mp4`
//! through OpenH264 compiled from source (without it runs write no MP4 and say so in `run.json`). Without them the crate
//! builds in a fraction of the time (no ONNX Runtime, tokenizers or wgpu) and keeps the
//! model-free styles, apply, render and the geometric metrics.

pub mod checkpoint;
pub mod config;
pub mod error;
pub mod eval;
pub mod frame;
pub mod heat;
pub mod identity;
pub mod intersections;
pub mod malloc;
pub mod models;
pub mod pipeline;
pub mod remeshing;
pub mod run_pictures;
pub mod runner;
pub mod saved;
pub mod snapshots;
pub mod style;
pub mod task;
#[cfg(feature = "mp4")]
pub mod turntable_mp4;

pub use error::{Error, Result};

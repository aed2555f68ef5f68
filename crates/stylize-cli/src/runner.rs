//! The command line's side of a run: how its progress is shown ([`LogMode`]) and how SIGINT /
//! SIGTERM stop it ([`crate::signals`]). The run itself is [`stylize::runner`] (re-exported here).

use std::path::PathBuf;

use stylize::config::Config;
use stylize::identity::ObjectiveIdentity;
pub use stylize::runner::{
    NPZ_FORMAT_VERSION, NoProgress, Progress, REGION_TINT, ResolvedRegion, RunHooks, RunOptions,
    RunOutcome, Stopped, Task, darap_options, objective_identity, parse_region_specs, prepare_mesh,
    prepare_mesh_with_region, renderer, resolve_region, tint_region, turntable, write_grid,
};

use crate::signals::Interrupted;

/// How progress is reported.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum LogMode {
    /// On a terminal, an indicatif progress bar on stderr; otherwise (a Slurm log, a pipe) a plain
    /// line on stderr every few seconds ([`crate::progress`]).
    Bar,
    /// One JSON object per iteration on stdout (the `metrics.jsonl` line).
    Jsonl,
    /// Nothing but errors.
    Quiet,
}

/// A run request as the commands make it: the library's [`stylize::runner::RunRequest`] plus how
/// to show progress.
#[derive(Clone, Debug)]
pub struct RunRequest {
    /// Input mesh file.
    pub mesh: PathBuf,
    /// Run directory.
    pub out: PathBuf,
    /// Resolved configuration.
    pub config: Config,
    /// Overwrite a complete or partial run.
    pub force: bool,
    /// Continue from a checkpoint if there is one.
    pub resume: bool,
    /// Progress reporting.
    pub log: LogMode,
    /// Stop after this iteration without final outputs (tests of `--resume`).
    pub halt_after: Option<u64>,
}

impl RunRequest {
    /// The library's request (everything but [`RunRequest::log`]).
    pub fn to_library(&self) -> stylize::runner::RunRequest {
        stylize::runner::RunRequest {
            mesh: self.mesh.clone(),
            out: self.out.clone(),
            config: self.config.clone(),
            force: self.force,
            resume: self.resume,
            halt_after: self.halt_after,
        }
    }
}

/// Runs one request to completion (or to `halt_after`) with the signal handlers installed and
/// progress shown as `request.log` says.
pub fn execute(request: &RunRequest, task: Task<'_>) -> anyhow::Result<RunOutcome> {
    let objective = objective_identity(&task);
    let mut options = RunOptions::default();
    if let Task::Style(stylize::style::Style::Exemplar { path, .. }) = &task {
        options.inputs.push(("exemplar mesh".into(), path.clone()));
    }
    execute_with(request, objective, || Ok(task), &options)
}

/// [`stylize::runner::execute_with`] with the SIGINT/SIGTERM flag as its cancellation hook and
/// the progress display of `request.log`; a stop becomes [`Interrupted`] (with the signal, for
/// the message and the exit status).
pub fn execute_with<'g>(
    request: &RunRequest,
    objective: ObjectiveIdentity,
    make_task: impl FnOnce() -> anyhow::Result<Task<'g>>,
    options: &RunOptions,
) -> anyhow::Result<RunOutcome> {
    crate::signals::install()?;
    let mut progress = crate::progress::reporter(request.log);
    let hooks = RunHooks {
        progress: progress.as_mut(),
        cancel: crate::signals::flag(),
    };
    stylize::runner::execute_with(&request.to_library(), objective, make_task, options, hooks)
        .map_err(|e| match e.downcast::<Stopped>() {
            Ok(stopped) => Interrupted {
                signal: crate::signals::pending().unwrap_or(signal_hook::consts::signal::SIGTERM),
                dir: stopped.dir,
                checkpoint_iteration: stopped.checkpoint_iteration,
            }
            .into(),
            Err(e) => e,
        })
}

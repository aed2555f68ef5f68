//! The command line's side of a run: how its progress is shown ([`LogMode`]) and how SIGINT /
//! SIGTERM stop it ([`crate::signals`]). The run itself is [`stylize::runner`] (re-exported here);
//! the commands build its [`RunRequest`] directly and pass the [`LogMode`] beside it.

use stylize::identity::ObjectiveIdentity;
pub use stylize::runner::{
    NPZ_FORMAT_VERSION, NoProgress, Progress, ResolvedRegion, RunHooks, RunOptions, RunOutcome,
    RunRequest, Task, darap_options, objective_identity, parse_region_specs, prepare_mesh,
    prepare_mesh_with_region, resolve_region,
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

/// Runs one request to completion (or to `halt_after`) with the signal handlers installed and
/// progress shown as `log` says.
pub fn execute(request: &RunRequest, log: LogMode, task: Task<'_>) -> anyhow::Result<RunOutcome> {
    let objective = objective_identity(&task);
    let mut options = RunOptions::default();
    if let Task::Style(stylize::style::Style::Exemplar { path, .. }) = &task {
        options.inputs.push(("exemplar mesh".into(), path.clone()));
    }
    execute_with(request, log, objective, || Ok(task), &options)
}

/// [`stylize::runner::execute_with`] with the SIGINT/SIGTERM flag as its cancellation hook and
/// the progress display of `log`; a stop becomes [`Interrupted`] (with the signal, for
/// the message and the exit status).
pub fn execute_with<'g>(
    request: &RunRequest,
    log: LogMode,
    objective: ObjectiveIdentity,
    make_task: impl FnOnce() -> anyhow::Result<Task<'g>>,
    options: &RunOptions,
) -> anyhow::Result<RunOutcome> {
    crate::signals::install()?;
    let mut progress = crate::progress::reporter(log);
    let hooks = RunHooks {
        progress: progress.as_mut(),
        cancel: crate::signals::flag(),
    };
    let make_task = || make_task().map_err(stylize::Error::external);
    stylize::runner::execute_with(request, objective, make_task, options, hooks).map_err(
        |e| match e.kind() {
            stylize::Error::Stopped(stopped) => Interrupted {
                signal: crate::signals::pending().unwrap_or(signal_hook::consts::signal::SIGTERM),
                dir: stopped.dir.clone(),
                checkpoint_iteration: stopped.checkpoint_iteration,
            }
            .into(),
            _ => anyhow::Error::from(e),
        },
    )
}

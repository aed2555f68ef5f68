//! The command line's side of a run: how its progress is shown ([`LogMode`]) and how SIGINT /
//! SIGTERM stop it ([`crate::signals`]). The run itself is [`stylize::runner`]; the commands build
//! its [`RunRequest`] directly and pass the [`LogMode`] beside it.

use stylize::runner::{RunHooks, RunOptions, RunOutcome, RunRequest};
use stylize::task::{Task, TaskKind};

use crate::signals::Interrupted;

/// How progress is reported.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum LogMode {
    /// On a terminal, an indicatif progress bar on stderr; otherwise (a Slurm log, a pipe) a plain
    /// line on stderr every few seconds ([`crate::progress`]).
    Bar,
    /// One JSON object per iteration on stdout (the `metrics.jsonl` line).
    Jsonl,
    /// A batch row's JSON lines on stdout: the `metrics.jsonl` line with `"row"` (the manifest
    /// row) first, for the first and last iteration of the session and at most one per
    /// [`crate::progress::LINE_INTERVAL`] between (a Slurm log holds every row's progress, not
    /// every iteration; the run's own `metrics.jsonl` has them all).
    BatchJsonl {
        /// The row's index in the manifest.
        row: usize,
    },
    /// Nothing but errors.
    Quiet,
}

impl LogMode {
    /// The mode for batch row `row`: JSON lines name their row.
    pub fn for_row(self, row: usize) -> Self {
        match self {
            LogMode::Jsonl | LogMode::BatchJsonl { .. } => LogMode::BatchJsonl { row },
            other => other,
        }
    }
}

/// Runs one request to completion (or to `halt_after`) with the signal handlers installed and
/// progress shown as `log` says; `task` is ready (its identity is its own).
pub fn execute<'g>(
    request: &RunRequest,
    log: LogMode,
    task: impl Task<'g> + 'g,
) -> anyhow::Result<RunOutcome> {
    with_hooks(log, |hooks| {
        stylize::runner::execute_task(request, task, &RunOptions::default(), hooks)
    })
}

/// [`stylize::runner::execute_with`] with the SIGINT/SIGTERM flag as its cancellation hook and
/// the progress display of `log`; a stop becomes [`Interrupted`] (with the signal, for
/// the message and the exit status).
pub fn execute_with<'g, T: Task<'g> + 'g>(
    request: &RunRequest,
    log: LogMode,
    kind: &dyn TaskKind,
    make_task: impl FnOnce() -> anyhow::Result<T>,
    options: &RunOptions,
) -> anyhow::Result<RunOutcome> {
    let make_task = || make_task().map_err(stylize::Error::external);
    with_hooks(log, |hooks| {
        stylize::runner::execute_with(request, kind, make_task, options, hooks)
    })
}

/// Installs the signal handlers and runs `run` with the SIGINT/SIGTERM flag and the progress
/// display of `log` as its hooks; a stop becomes [`Interrupted`].
fn with_hooks(
    log: LogMode,
    run: impl FnOnce(RunHooks<'_>) -> stylize::Result<RunOutcome>,
) -> anyhow::Result<RunOutcome> {
    crate::signals::install()?;
    let mut progress = crate::progress::reporter(log);
    let hooks = RunHooks {
        progress: progress.as_mut(),
        cancel: crate::signals::flag(),
    };
    run(hooks).map_err(interrupted)
}

/// A stop through the cancellation flag as [`Interrupted`] (with the pending signal); any other
/// error as it is.
fn interrupted(e: stylize::Error) -> anyhow::Error {
    match e.kind() {
        stylize::Error::Stopped(stopped) => Interrupted {
            signal: crate::signals::pending().unwrap_or(signal_hook::consts::signal::SIGTERM),
            dir: stopped.dir.clone(),
            checkpoint_iteration: stopped.checkpoint_iteration,
        }
        .into(),
        _ => anyhow::Error::from(e),
    }
}

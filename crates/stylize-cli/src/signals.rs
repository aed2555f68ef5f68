//! SIGINT and SIGTERM during a run (Slurm sends SIGTERM some time before SIGKILL): the first one
//! only sets a flag; the loop finishes its current iteration, writes a checkpoint, and the command
//! exits with 128 + the signal number (130 for SIGINT, 143 for SIGTERM) after printing how to
//! resume. A second signal terminates at once with the same status (the run directory lock is
//! then left behind; on the same host it is taken over at once, see [`rundir::lock`]).

use std::path::PathBuf;
use std::sync::Once;
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};

use signal_hook::consts::signal::{SIGINT, SIGPIPE, SIGTERM};

static RECEIVED: AtomicBool = AtomicBool::new(false);
static WHICH: AtomicUsize = AtomicUsize::new(0);
static INSTALL: Once = Once::new();

/// Installs the handlers (once per process; later calls do nothing).
pub fn install() -> anyhow::Result<()> {
    let mut result = Ok(());
    INSTALL.call_once(|| {
        result = (|| -> std::io::Result<()> {
            // Order matters: the conditional exit must see the flag as it was before this signal.
            signal_hook::flag::register_conditional_shutdown(SIGINT, 128 + SIGINT, &RECEIVED)?;
            signal_hook::flag::register_conditional_shutdown(SIGTERM, 128 + SIGTERM, &RECEIVED)?;
            signal_hook::flag::register_usize(SIGINT, &WHICH, SIGINT as usize)?;
            signal_hook::flag::register_usize(SIGTERM, &WHICH, SIGTERM as usize)?;
            signal_hook::flag::register(SIGINT, &RECEIVED)?;
            signal_hook::flag::register(SIGTERM, &RECEIVED)?;
            Ok(())
        })()
        .map_err(|e| anyhow::anyhow!("cannot install the SIGINT/SIGTERM handlers: {e}"));
    });
    result
}

/// The flag the handlers set (the run's cancellation hook, [`stylize::runner::RunHooks::cancel`]).
pub fn flag() -> &'static AtomicBool {
    &RECEIVED
}

/// Stops the run the way a signal does, as if `SIGPIPE` had been received: called when standard
/// output cannot be written (`--log-format jsonl` into a pipe whose reader hung up; see
/// [`crate::output`]). The loop ends its iteration, writes a checkpoint, and the command exits
/// with 141 (128 + `SIGPIPE`).
pub fn output_closed() {
    WHICH.store(SIGPIPE as usize, Ordering::SeqCst);
    RECEIVED.store(true, Ordering::SeqCst);
}

/// The signal received so far, if any.
pub fn pending() -> Option<i32> {
    if !RECEIVED.load(Ordering::SeqCst) {
        return None;
    }
    match WHICH.load(Ordering::SeqCst) {
        0 => Some(SIGTERM),
        s => i32::try_from(s).ok(),
    }
}

/// The name of a signal number we handle.
pub fn name(signal: i32) -> &'static str {
    match signal {
        SIGINT => "SIGINT",
        SIGTERM => "SIGTERM",
        SIGPIPE => "a closed standard output (SIGPIPE)",
        _ => "a signal",
    }
}

/// A run stopped by a signal (the error a command returns; `main` exits with
/// [`Interrupted::exit_code`]).
#[derive(Debug, thiserror::Error)]
#[error("{}", self.describe())]
pub struct Interrupted {
    /// The signal.
    pub signal: i32,
    /// The run directory.
    pub dir: PathBuf,
    /// The iteration the checkpoint holds (`None`: stopped before any checkpoint was written).
    pub checkpoint_iteration: Option<u64>,
}

impl Interrupted {
    /// 128 + the signal number.
    pub fn exit_code(&self) -> u8 {
        u8::try_from(128 + self.signal).unwrap_or(1)
    }

    fn describe(&self) -> String {
        match self.checkpoint_iteration {
            Some(i) => format!(
                "interrupted by {}: stopped after iteration {i}, checkpoint written to {}",
                name(self.signal),
                self.dir.join("checkpoint.json").display()
            ),
            None => format!(
                "interrupted by {} before the first iteration; nothing to resume in {}",
                name(self.signal),
                self.dir.display()
            ),
        }
    }
}

/// The exit status for an error: 128 + signal for [`Interrupted`], 75 (`EX_TEMPFAIL`) when a run
/// directory is locked by another process, 141 or 74 when standard output cannot be written
/// ([`crate::output::OutputClosed`]), 1 otherwise.
pub fn exit_code(e: &anyhow::Error) -> u8 {
    if let Some(i) = e.downcast_ref::<Interrupted>() {
        return i.exit_code();
    }
    if let Some(o) = e
        .chain()
        .find_map(|c| c.downcast_ref::<crate::output::OutputClosed>())
    {
        return o.exit_code();
    }
    use rundir::LockError;
    let locked = |l: &LockError| matches!(l, LockError::Held { .. } | LockError::Busy { .. });
    if e.chain().any(|c| {
        c.downcast_ref::<LockError>().is_some_and(locked)
            || c.downcast_ref::<rundir::Error>()
                .and_then(rundir::Error::as_lock)
                .is_some_and(locked)
            || c.downcast_ref::<stylize::Error>()
                .and_then(stylize::Error::lock_error)
                .is_some_and(locked)
    }) {
        return 75;
    }
    1
}

/// Quotes one argument for a POSIX shell (only when needed).
pub fn shell_quote(arg: &str) -> String {
    let safe = !arg.is_empty()
        && arg
            .chars()
            .all(|c| c.is_ascii_alphanumeric() || "-_./:=,+@%".contains(c));
    if safe {
        arg.to_string()
    } else {
        format!("'{}'", arg.replace('\'', r"'\''"))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn quoting_and_exit_codes() {
        assert_eq!(shell_quote("run/a.obj"), "run/a.obj");
        assert_eq!(shell_quote("a cat's hat"), r"'a cat'\''s hat'");
        assert_eq!(shell_quote(""), "''");
        let e = anyhow::Error::new(Interrupted {
            signal: SIGTERM,
            dir: "r".into(),
            checkpoint_iteration: Some(3),
        })
        .context("run on m.obj");
        assert_eq!(exit_code(&e), 143);
        assert_eq!(exit_code(&anyhow::anyhow!("other")), 1);
        // A lock held by another process, however it is wrapped: EX_TEMPFAIL.
        let busy = || rundir::LockError::Busy {
            dir: "r".into(),
            path: "r/run.lock".into(),
            detail: "empty".into(),
        };
        let wrapped = stylize::Error::Context {
            context: "run on m.obj".into(),
            source: Box::new(stylize::Error::from(busy())),
        };
        assert_eq!(exit_code(&anyhow::Error::new(wrapped)), 75);
        assert_eq!(
            exit_code(&anyhow::Error::new(rundir::Error::from(busy()))),
            75
        );
        assert_eq!(exit_code(&anyhow::Error::new(busy())), 75);
        let lost = rundir::LockError::Lost {
            dir: "r".into(),
            holder: None,
        };
        assert_eq!(
            exit_code(&anyhow::Error::new(stylize::Error::from(lost))),
            1
        );
    }
}

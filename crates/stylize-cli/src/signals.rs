//! SIGTERM, SIGHUP and SIGINT during a run. Slurm sends SIGTERM some time before SIGKILL (and under
//! `srun` may deliver it twice); an SSH session that drops sends SIGHUP.
//!
//! - **Any number of SIGTERM and SIGHUP, and the first SIGINT,** only ask the run to stop: the loop
//!   finishes its current iteration (a stop is honoured at the next iteration boundary — on the
//!   text path an iteration takes about a second on a GPU and can take a minute on CPUs; model
//!   loading checks the request before and after the models load), writes a checkpoint, releases
//!   the run directory's lock, and the command prints its summary and exits with 128 + the last
//!   signal's number (129 SIGHUP, 130 SIGINT, 143 SIGTERM). A repeated TERM/HUP changes nothing
//!   but a line in the log, so it can never cut a checkpoint short. `run` and `batch` install the
//!   handlers first thing, before any lock is taken.
//! - **A second SIGINT** (a person pressing Ctrl-C again) means "now": the process removes the
//!   locks it holds ([`rundir::lock::release_all_before_exit`]) and exits 130 at once, without
//!   finishing the iteration. The run directory keeps its last durable checkpoint (checkpoints and
//!   outputs are written to a temporary name, `fsync`ed and renamed, so an exit at any instant
//!   leaves either the old or the new file, never a torn one); a leftover temporary file is
//!   removed by the next run.
//! - SIGKILL cannot be handled: the last periodic checkpoint stays, the lock is left behind and is
//!   taken over ([`rundir::lock`]).
//!
//! Each signal is noted on stderr as it arrives (`received SIGTERM: stopping after the current
//! iteration ...`), so a Slurm log shows when the scheduler asked.

use std::io::{Read, Write};
use std::os::unix::net::UnixStream;
use std::path::PathBuf;
use std::sync::Once;
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};

use signal_hook::consts::signal::{SIGHUP, SIGINT, SIGPIPE, SIGTERM};

static RECEIVED: AtomicBool = AtomicBool::new(false);
static WHICH: AtomicUsize = AtomicUsize::new(0);
static INSTALL: Once = Once::new();
/// SIGINTs seen by the watcher thread.
static INTERRUPTS: AtomicUsize = AtomicUsize::new(0);

/// The signals that ask a run to stop.
pub const STOP_SIGNALS: [i32; 3] = [SIGINT, SIGTERM, SIGHUP];

/// Installs the handlers (once per process; later calls do nothing): each of [`STOP_SIGNALS`]
/// sets the stop flag and wakes a watcher thread that notes it on stderr (and acts on a second
/// SIGINT).
pub fn install() -> anyhow::Result<()> {
    let mut result = Ok(());
    INSTALL.call_once(|| {
        result = STOP_SIGNALS
            .iter()
            .try_for_each(|&signal| watch(signal))
            .map_err(|e| anyhow::anyhow!("cannot install the SIGINT/SIGTERM/SIGHUP handlers: {e}"));
    });
    result
}

/// The handlers of one signal: the flag and its number (set inside the handler, so the loop sees
/// them at once), and a self-pipe to a thread for what is not async-signal-safe (printing, the
/// immediate exit).
fn watch(signal: i32) -> std::io::Result<()> {
    signal_hook::flag::register_usize(signal, &WHICH, signal as usize)?;
    signal_hook::flag::register(signal, &RECEIVED)?;
    let (mut reader, writer) = UnixStream::pair()?;
    signal_hook::low_level::pipe::register(signal, writer)?;
    std::thread::Builder::new()
        .name(format!("{}-watch", name(signal)))
        .spawn(move || {
            let mut byte = [0u8; 64];
            loop {
                match reader.read(&mut byte) {
                    Ok(0) => return,
                    Ok(n) => (0..n).for_each(|_| arrived(signal)),
                    Err(e) if e.kind() == std::io::ErrorKind::Interrupted => {}
                    Err(_) => return,
                }
            }
        })?;
    Ok(())
}

/// What the watcher does for one delivered signal (outside the handler).
fn arrived(signal: i32) {
    if signal == SIGINT && INTERRUPTS.fetch_add(1, Ordering::SeqCst) >= 1 {
        // The locks first: the message may wait for stderr.
        let released = rundir::lock::release_all_before_exit();
        let mut err = std::io::stderr().lock();
        // A log that cannot be written to (a closed terminal) must not stop the exit.
        let _ = writeln!(
            err,
            "second SIGINT: exiting now without finishing the iteration; the last checkpoint \
             written stays valid (released {} run directory lock{})",
            released.len(),
            if released.len() == 1 { "" } else { "s" }
        );
        let _ = err.flush();
        // `_exit`: no destructors, no atexit handlers racing the threads still running.
        signal_hook::low_level::exit(128 + SIGINT);
    }
    let _ = writeln!(
        std::io::stderr().lock(),
        "received {}: stopping after the current iteration, with a checkpoint{}",
        name(signal),
        if signal == SIGINT {
            " (SIGINT again to exit at once)"
        } else {
            ""
        }
    );
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

/// The signal received (the last one when several came), if any.
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
        SIGHUP => "SIGHUP",
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

/// Exit status: a run or batch failed (an error that running again will not fix by itself).
pub const EXIT_FAILED: u8 = 1;
/// Exit status (`EX_TEMPFAIL`): a run directory is locked by another live process (an overlapping
/// array task, an earlier incarnation of a requeued task); its rows are left to that process.
pub const EXIT_IN_USE: u8 = 75;

/// An outcome that is not a success and not a plain failure, with its own exit status (a batch
/// whose only trouble was rows in use elsewhere: [`EXIT_IN_USE`]).
#[derive(Debug, thiserror::Error)]
#[error("{message}")]
pub struct Exit {
    /// The exit status.
    pub code: u8,
    /// What happened.
    pub message: String,
}

/// The exit status for an error: 128 + signal for [`Interrupted`] (129 SIGHUP, 130 SIGINT, 143
/// SIGTERM: stopped with a checkpoint, the same command resumes), [`EXIT_IN_USE`] when a run
/// directory is locked by another process, 141 or 74 when standard output cannot be written
/// ([`crate::output::OutputClosed`]), [`EXIT_FAILED`] otherwise.
pub fn exit_code(e: &anyhow::Error) -> u8 {
    if let Some(i) = e.downcast_ref::<Interrupted>() {
        return i.exit_code();
    }
    if let Some(x) = e.downcast_ref::<Exit>() {
        return x.code;
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
        return EXIT_IN_USE;
    }
    EXIT_FAILED
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

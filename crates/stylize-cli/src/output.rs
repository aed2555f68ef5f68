//! Every line the command line prints goes through here ([`outln!`](crate::outln),
//! [`outp!`](crate::outp), [`errln!`](crate::errln)); `println!`/`eprintln!` are denied in this
//! crate (`clippy::print_stdout`, `clippy::print_stderr`) because they panic when the stream
//! cannot be written (`stylize mesh check --json | head -1`: the reader hangs up, the write fails
//! with `EPIPE`, and Rust ignores `SIGPIPE`).
//!
//! - **stdout** carries the data a command was asked for (reports, JSON, `--log-format jsonl`
//!   lines). A write that fails is an error the command returns ([`OutputClosed`]): the process
//!   exits with status 141 (128 + `SIGPIPE`, what a shell reports for a writer killed by a closed
//!   pipe) for a broken pipe, 74 (`EX_IOERR`) for any other write error. A run's `jsonl` lines are
//!   written from the progress hook, which cannot fail: there a failed write stops the run the way
//!   a signal does ([`crate::signals::output_closed`]: the current iteration ends, a checkpoint is
//!   written, the command exits with 141 and says how to resume).
//! - **stderr** carries diagnostics (warnings, progress lines, the closing summary). A failed
//!   write there is ignored: a log nobody reads is no reason to stop or lose work.

use std::io::Write;

/// Standard output cannot be written to (the reader hung up, or the device failed).
#[derive(Debug, thiserror::Error)]
#[error("cannot write to standard output: {source}")]
pub struct OutputClosed {
    /// The write's error.
    #[source]
    pub source: std::io::Error,
}

impl OutputClosed {
    /// 141 (128 + `SIGPIPE`) for a reader that hung up, 74 (`EX_IOERR`) otherwise.
    pub fn exit_code(&self) -> u8 {
        if self.source.kind() == std::io::ErrorKind::BrokenPipe {
            141
        } else {
            74
        }
    }
}

/// Writes `args` to stdout and flushes (a line reaches a pipe as soon as it is printed).
pub fn stdout_fmt(args: std::fmt::Arguments<'_>) -> Result<(), OutputClosed> {
    let mut out = std::io::stdout().lock();
    out.write_fmt(args)
        .and_then(|()| out.flush())
        .map_err(|source| OutputClosed { source })
}

/// Writes `args` to stderr; a failure is ignored (see the module documentation).
pub fn stderr_fmt(args: std::fmt::Arguments<'_>) {
    let _ = std::io::stderr().lock().write_fmt(args);
}

/// `println!` that returns `Result<(), OutputClosed>` instead of panicking.
#[macro_export]
macro_rules! outln {
    () => {
        $crate::output::stdout_fmt(format_args!("\n"))
    };
    ($($arg:tt)+) => {
        $crate::output::stdout_fmt(format_args!("{}\n", format_args!($($arg)+)))
    };
}

/// `print!` that returns `Result<(), OutputClosed>` instead of panicking.
#[macro_export]
macro_rules! outp {
    ($($arg:tt)+) => {
        $crate::output::stdout_fmt(format_args!($($arg)+))
    };
}

/// `eprintln!` that never panics (a failed write to stderr is ignored).
#[macro_export]
macro_rules! errln {
    () => {
        $crate::output::stderr_fmt(format_args!("\n"))
    };
    ($($arg:tt)+) => {
        $crate::output::stderr_fmt(format_args!("{}\n", format_args!($($arg)+)))
    };
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn exit_codes_tell_a_hung_up_reader_from_a_failed_device() {
        let pipe = OutputClosed {
            source: std::io::Error::from(std::io::ErrorKind::BrokenPipe),
        };
        assert_eq!(pipe.exit_code(), 141);
        let full = OutputClosed {
            source: std::io::Error::from(std::io::ErrorKind::StorageFull),
        };
        assert_eq!(full.exit_code(), 74);
    }
}

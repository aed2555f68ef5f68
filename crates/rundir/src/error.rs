//! The crate's error type: [`Error`], one variant per kind of failure, and [`Result`].
//!
//! Each message names the path or run directory it concerns and, for refusals, what to do about
//! it; a variant's own message never repeats its source's, so a chain printed with `{:#}` (or by
//! walking [`std::error::Error::source`]) never says a thing twice.

use std::path::{Path, PathBuf};

use crate::lock::LockError;

/// `Result` with the crate's [`Error`].
pub type Result<T, E = Error> = std::result::Result<T, E>;

/// Something a run directory could not do, or refuses to do.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum Error {
    /// A file or folder could not be read, written, created, listed, moved, removed or synced.
    #[error("{message}")]
    Io {
        /// What failed, naming the path (`cannot read /runs/a/task.json`).
        message: String,
        /// The file or folder.
        path: PathBuf,
        /// The operating system's error.
        source: std::io::Error,
    },
    /// The run directory refuses the request: it holds another task, an incompatible resume, a
    /// file that is not the run's, or contradicting flags.
    #[error("{message}")]
    Refused {
        /// The run directory.
        dir: PathBuf,
        /// Why, with what to do about it.
        message: String,
    },
    /// The run directory holds a run (complete, or a checkpoint to resume) of a different task.
    #[error("{message}")]
    DifferentTask {
        /// The run directory.
        dir: PathBuf,
        /// The fields that differ (`config.darap.lambda: was 8, now 5`).
        differences: Vec<String>,
        /// The refusal, listing them, with what to do about it.
        message: String,
    },
    /// The run directory is locked by another process (or its lock was lost).
    #[error(transparent)]
    Lock(#[from] LockError),
    /// A file of the run directory, or a checkpoint, is damaged.
    #[error("{message}")]
    Corrupt {
        /// The file.
        path: PathBuf,
        /// What is wrong, naming the file.
        message: String,
    },
    /// JSON (a checkpoint, `task.json`) could not be written.
    #[error(transparent)]
    Json(#[from] serde_json::Error),
}

impl Error {
    /// An I/O error: `message` names the action, e.g. `io("cannot read", path, e)` reads
    /// `cannot read PATH`.
    pub fn io(action: &str, path: &Path, source: std::io::Error) -> Self {
        Self::Io {
            message: format!("{action} {}", path.display()),
            path: path.to_path_buf(),
            source,
        }
    }

    /// A refusal of the run directory `dir`.
    pub fn refused(dir: &Path, message: impl Into<String>) -> Self {
        Self::Refused {
            dir: dir.to_path_buf(),
            message: message.into(),
        }
    }

    /// The lock error, when this is one.
    pub fn as_lock(&self) -> Option<&LockError> {
        match self {
            Self::Lock(l) => Some(l),
            _ => None,
        }
    }
}

/// An I/O result with the path it concerns.
pub(crate) trait IoContext<T> {
    /// `action` on `path` failed: [`Error::io`].
    fn io_context(self, action: &str, path: &Path) -> Result<T>;
}

impl<T> IoContext<T> for std::io::Result<T> {
    fn io_context(self, action: &str, path: &Path) -> Result<T> {
        self.map_err(|e| Error::io(action, path, e))
    }
}

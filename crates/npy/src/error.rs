//! The crate's error type and the one file-system guard its readers share.

use std::path::{Path, PathBuf};

/// Everything that can go wrong reading or writing an `.npz` archive. The messages follow the form
/// `<file>: array `<key>`: <what was expected>` so a user learns which file and which array.
#[derive(Debug, thiserror::Error)]
pub enum NpyError {
    /// The operating system refused to open, read or write a file (or the path names something
    /// that is not a regular file). The reason is part of the message and deliberately not the
    /// error's [`source`](std::error::Error::source), so chain printers do not say it twice.
    #[error("cannot access {}: {error}", path.display())]
    Io {
        /// The file (or folder).
        path: PathBuf,
        /// The underlying error.
        error: std::io::Error,
    },
    /// The archive itself (the zip) is unreadable.
    #[error("{}: {message}", path.display())]
    Archive {
        /// The `.npz` file.
        path: PathBuf,
        /// What is wrong.
        message: String,
    },
    /// One array is malformed, missing, written twice, or has an unexpected type or shape.
    #[error("{}: array `{key}`: {message}", path.display())]
    Array {
        /// The `.npz` (or `.npy`) file.
        path: PathBuf,
        /// The array's key (its name in the zip without `.npy`).
        key: String,
        /// What was expected.
        message: String,
    },
}

impl NpyError {
    #[cfg_attr(not(feature = "npz"), allow(dead_code))]
    pub(crate) fn io(path: &Path, error: std::io::Error) -> Self {
        Self::Io {
            path: path.to_path_buf(),
            error,
        }
    }
}

/// Checks, without opening it, that `path` is a regular file (symbolic links followed). A
/// directory, named pipe, socket or device is refused with an [`std::io::ErrorKind::InvalidInput`]
/// error saying which: opening a named pipe would block until some other process writes to it, and a
/// device such as `/dev/zero` never ends. Every reader of a user-named file should call this first.
pub fn ensure_regular_file(path: &Path) -> std::io::Result<()> {
    let meta = std::fs::metadata(path)?;
    if meta.is_file() {
        return Ok(());
    }
    let ft = meta.file_type();
    let what = if ft.is_dir() {
        "a directory"
    } else {
        #[cfg(unix)]
        {
            use std::os::unix::fs::FileTypeExt;
            if ft.is_fifo() {
                "a named pipe (FIFO)"
            } else if ft.is_socket() {
                "a socket"
            } else if ft.is_block_device() || ft.is_char_device() {
                "a device"
            } else {
                "something else"
            }
        }
        #[cfg(not(unix))]
        {
            "something else"
        }
    };
    Err(std::io::Error::new(
        std::io::ErrorKind::InvalidInput,
        format!("it is {what}, not a regular file"),
    ))
}

//! The crate's error type.

use std::path::PathBuf;

/// Everything that can go wrong when reading, writing, validating or repairing a mesh.
///
/// Messages name the file and what was expected, in words a 3D artist understands.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum MeshError {
    /// The operating system refused to open, read or write a file (or the path names something
    /// that is not a regular file). The reason is part of the message and deliberately not the
    /// error's [`source`](std::error::Error::source): reporters that print the chain (`anyhow`'s
    /// `{:#}`) would otherwise say it twice.
    #[error("cannot access {}: {error}", path.display())]
    Io {
        /// The file.
        path: PathBuf,
        /// The underlying error.
        error: std::io::Error,
    },
    /// The file's contents do not follow its format.
    #[error("{}: {message}", path.display())]
    Parse {
        /// The file.
        path: PathBuf,
        /// What was expected and where (line, element, byte offset).
        message: String,
    },
    /// The file extension is not one this crate reads or writes.
    #[error(
        "{}: unsupported mesh format {extension:?} (supported: {supported})",
        path.display()
    )]
    UnsupportedFormat {
        /// The file.
        path: PathBuf,
        /// Its extension (lower-cased; empty when there is none).
        extension: String,
        /// The extensions that are supported for this operation.
        supported: &'static str,
    },
    /// The file was read but holds no triangles.
    #[error("{}: the file contains no triangles", path.display())]
    Empty {
        /// The file.
        path: PathBuf,
    },
    /// Two inputs that must agree in length do not.
    #[error("{what}: expected {expected} entries, got {got}")]
    LengthMismatch {
        /// Which input.
        what: &'static str,
        /// The expected length.
        expected: usize,
        /// The actual length.
        got: usize,
    },
    /// The mesh has a problem that repair refuses to fix silently (see [`crate::validate`]).
    #[error("the mesh cannot be used as is: {0}")]
    Invalid(String),
}

//! The library's error type: [`Error`], one variant per kind of failure, and [`Result`].
//!
//! Errors of the crates below (mesh, dARAP, renderer, guidance, models, …) are carried as they
//! are; [`Error::Context`] adds what the library was doing (`"dARAP forward"`, `"IF stage I"`)
//! around any of them, the way `anyhow`'s context does, so `{:#}` through `anyhow` (or walking
//! [`std::error::Error::source`]) prints `what it was doing: what went wrong: why`. Each variant's
//! own message never repeats its source's, so the chain never says a thing twice.
//! [`Error::kind`] skips the context layers to the failure itself.
//!
//! The run directory's failures and refusals (its lock, a durable write, a checkpoint, another
//! task in the folder) are [`rundir::Error`]s, carried in [`Error::RunDir`]; a run stopped through
//! its cancellation flag is [`Stopped`].

use std::path::{Path, PathBuf};

/// `Result` with the library's [`Error`].
pub type Result<T, E = Error> = std::result::Result<T, E>;

/// Something a stylization could not do.
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
    /// A configuration value is out of range or inconsistent.
    #[error("{message}")]
    Config {
        /// The key at fault (`optim.lr`, `camera.distance`, `guidance.stage2_weight`, …).
        field: String,
        /// What is wrong with it, naming the key and the value.
        message: String,
    },
    /// A configuration document is not valid TOML for [`crate::config::Config`] (an unknown key,
    /// a wrong type, an unknown name).
    #[error(transparent)]
    ConfigSyntax(#[from] toml::de::Error),
    /// The run directory refused the request (another task, an incompatible resume, a foreign
    /// folder, contradicting flags), is locked by another process (or its lock was lost), holds
    /// a damaged file, or one of its durable writes failed: [`rundir::Error`].
    #[error(transparent)]
    RunDir(#[from] rundir::Error),
    /// The run was stopped through its cancellation flag (a checkpoint was written).
    #[error(transparent)]
    Stopped(#[from] Stopped),
    /// A mesh could not be read, written, repaired or used.
    #[error(transparent)]
    Mesh(#[from] mesh_core::MeshError),
    /// A region spec is invalid or selects nothing.
    #[error(transparent)]
    Region(#[from] mesh_core::region::RegionError),
    /// The deformation layer failed (precomputation, forward or backward).
    #[error(transparent)]
    Darap(#[from] darap::DarapError),
    /// The renderer failed.
    #[error(transparent)]
    Render(#[from] raster_diff::RenderError),
    /// The guidance (score distillation) failed.
    #[error(transparent)]
    Guidance(#[from] csd::GuidanceError),
    /// Loading or running a model (IF UNets, T5, CLIP) failed (boxed: the ONNX error is large, and
    /// every `Result` of the library carries this enum).
    #[cfg(feature = "text")]
    #[error(transparent)]
    Model(Box<diffusion_onnx::OnnxError>),
    /// Something this build of the library was compiled without (in a build without the `text`
    /// feature: loading the text path's models).
    #[error(
        "{what} needs the `{feature}` feature of the stylize library, and this build was compiled \
         without it: build it with `--features stylize/{feature}` (the stylize command line: \
         `cargo run --release --bin stylize -- …`, default features)"
    )]
    NotBuilt {
        /// The missing cargo feature (`text`).
        feature: &'static str,
        /// What needed it.
        what: String,
    },
    /// The optimizer refused a step.
    #[error(transparent)]
    Adam(#[from] optim::AdamError),
    /// A weight schedule does not parse.
    #[error(transparent)]
    Schedule(#[from] optim::ScheduleError),
    /// A NumPy array could not be built, read or written.
    #[error(transparent)]
    Npy(#[from] npy::NpyError),
    /// The saved-deformation `.npz` could not be read or written.
    #[error(transparent)]
    Saved(#[from] crate::saved::SavedError),
    /// JSON (`run.json`) could not be written.
    #[error(transparent)]
    Json(#[from] serde_json::Error),
    /// The configuration could not be written as TOML.
    #[error(transparent)]
    ConfigSerialize(#[from] toml::ser::Error),
    /// An input the library was given is unusable (a style name, a mesh pair of different
    /// sizes, a CLIP setting, …); the message names it.
    #[error("{0}")]
    Invalid(String),
    /// An error of the caller's own code (an [`crate::pipeline::Objective`], an observer, the
    /// task builder of [`crate::runner::execute_with`]).
    #[error(transparent)]
    External(Box<dyn std::error::Error + Send + Sync + 'static>),
    /// What the library was doing when `source` happened.
    #[error("{context}")]
    Context {
        /// The step (`"dARAP forward"`, `"region of mesh.obj"`).
        context: String,
        /// The failure.
        source: Box<Error>,
    },
}

impl From<rundir::LockError> for Error {
    /// A lock error is the run directory's ([`Error::RunDir`]).
    fn from(e: rundir::LockError) -> Self {
        Error::RunDir(e.into())
    }
}

#[cfg(feature = "text")]
impl From<diffusion_onnx::OnnxError> for Error {
    fn from(e: diffusion_onnx::OnnxError) -> Self {
        Error::Model(Box::new(e))
    }
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

    /// A configuration error of `field`.
    pub fn config(field: &str, message: impl Into<String>) -> Self {
        Self::Config {
            field: field.to_string(),
            message: message.into(),
        }
    }

    /// Wraps an error of the caller's code (anything `anyhow` or `Box<dyn Error>` converts to).
    pub fn external(e: impl Into<Box<dyn std::error::Error + Send + Sync + 'static>>) -> Self {
        Self::External(e.into())
    }

    /// The whole chain on one line, `what it was doing: what went wrong: why` (what `anyhow`
    /// prints for `{:#}`).
    pub fn full_message(&self) -> String {
        let mut out = self.to_string();
        let mut cur = std::error::Error::source(self);
        while let Some(s) = cur {
            out.push_str(": ");
            out.push_str(&s.to_string());
            cur = s.source();
        }
        out
    }

    /// The failure itself, under any [`Error::Context`] layers.
    pub fn kind(&self) -> &Error {
        match self {
            Self::Context { source, .. } => source.kind(),
            other => other,
        }
    }

    /// The run directory's lock error, under any [`Error::Context`] layers, when this is one.
    pub fn lock_error(&self) -> Option<&rundir::LockError> {
        match self.kind() {
            Self::RunDir(e) => e.as_lock(),
            _ => None,
        }
    }
}

/// A run stopped through its cancellation flag ([`crate::runner::RunHooks::cancel`]; the error
/// [`crate::runner::execute_with`] returns; the command line turns it into its signal message and
/// exit status).
#[derive(Debug, thiserror::Error)]
#[error("{}", match .checkpoint_iteration {
    Some(i) => format!("stopped after iteration {i}, checkpoint written to {}", .dir.join("checkpoint.json").display()),
    None => format!("stopped before the first iteration; nothing to resume in {}", .dir.display()),
})]
pub struct Stopped {
    /// The run directory.
    pub dir: PathBuf,
    /// The iteration the checkpoint holds (`None`: stopped before any checkpoint was written).
    pub checkpoint_iteration: Option<u64>,
}

/// `.context(…)` / `.with_context(|| …)` on results whose error converts into [`Error`] (the
/// library's own `anyhow`-like helper; I/O errors have no conversion: use [`Error::io`], which
/// records the path).
pub(crate) trait Context<T> {
    /// Wraps the error in [`Error::Context`].
    fn context(self, context: impl Into<String>) -> Result<T>;
    /// Wraps the error in [`Error::Context`], building the text only on failure.
    fn with_context<S: Into<String>>(self, context: impl FnOnce() -> S) -> Result<T>;
}

impl<T, E: Into<Error>> Context<T> for std::result::Result<T, E> {
    fn context(self, context: impl Into<String>) -> Result<T> {
        self.map_err(|e| Error::Context {
            context: context.into(),
            source: Box::new(e.into()),
        })
    }

    fn with_context<S: Into<String>>(self, context: impl FnOnce() -> S) -> Result<T> {
        self.map_err(|e| Error::Context {
            context: context().into(),
            source: Box::new(e.into()),
        })
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

/// `return Err(Error::Invalid(format!(…)))`.
macro_rules! invalid {
    ($($arg:tt)*) => {
        return Err($crate::error::Error::Invalid(format!($($arg)*)))
    };
}
pub(crate) use invalid;

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn context_chains_without_repeating_and_kind_skips_it() {
        let inner: Result<()> = Err(Error::config("optim.lr", "optim.lr must be positive"));
        let e = inner.context("in config a.toml").expect_err("an error");
        assert_eq!(
            e.full_message(),
            "in config a.toml: optim.lr must be positive"
        );
        assert!(matches!(e.kind(), Error::Config { field, .. } if field == "optim.lr"));
        let io = std::fs::read("/nonexistent/stylize-error-test")
            .io_context("cannot read", Path::new("/nonexistent/stylize-error-test"))
            .expect_err("an error");
        let text = io.full_message();
        assert_eq!(
            text.matches("/nonexistent/stylize-error-test").count(),
            1,
            "{text}"
        );
        assert!(matches!(io, Error::Io { ref path, .. } if path.ends_with("stylize-error-test")));
    }
}

//! Errors of this crate. Every message says what went wrong and what to do about it.

use std::path::PathBuf;

/// Everything that can go wrong loading or running the IF models.
#[derive(Debug, thiserror::Error)]
pub enum OnnxError {
    /// No ONNX Runtime shared library was found.
    #[error(
        "the ONNX Runtime library was not found (looked at: {searched}). Run `scripts/setup-onnxruntime.sh` \
         (downloads onnxruntime {wanted} from PyPI into .deps/onnxruntime/) or set ORT_DYLIB_PATH to a \
         libonnxruntime.so of version >= {minimum}",
        wanted = crate::runtime::ORT_VERSION,
        minimum = crate::runtime::MINIMUM_ORT_VERSION
    )]
    RuntimeMissing {
        /// The paths that were tried.
        searched: String,
    },
    /// A library was found but cannot be used (not a library, wrong version, no ORT API).
    #[error(
        "the ONNX Runtime library at {path} cannot be used: {reason}. Install onnxruntime {wanted} with \
         `scripts/setup-onnxruntime.sh` or point ORT_DYLIB_PATH at a libonnxruntime.so of version >= {minimum}",
        wanted = crate::runtime::ORT_VERSION,
        minimum = crate::runtime::MINIMUM_ORT_VERSION
    )]
    RuntimeUnusable {
        /// The library that was tried.
        path: PathBuf,
        /// What ONNX Runtime or the loader said.
        reason: String,
    },
    /// The model directory or its `manifest.toml` is not usable.
    #[error("model directory {dir}: {message}")]
    Manifest {
        /// The model directory.
        dir: PathBuf,
        /// What is wrong and how to fix it.
        message: String,
    },
    /// A file the manifest declares is not there.
    #[error("model directory {dir}: {what} `{file}` is missing ({path}). {hint}")]
    MissingFile {
        /// The model directory.
        dir: PathBuf,
        /// Which role the file plays (e.g. "stage1 model", "stage1 external data").
        what: String,
        /// The file name as declared.
        file: String,
        /// Its full path.
        path: PathBuf,
        /// What to do.
        hint: String,
    },
    /// The ONNX graph's inputs/outputs do not match what the manifest declares.
    #[error("{model}: the ONNX graph does not match the manifest: {message}")]
    Signature {
        /// Which model (e.g. "stage1 UNet").
        model: String,
        /// Details.
        message: String,
    },
    /// The ONNX graph's float type differs from the manifest's `dtype`.
    #[error(
        "{model}: the manifest says dtype = \"{declared}\" but the ONNX input `{input}` is {actual}; set dtype = \
         \"{suggested}\" in manifest.toml or re-export with `scripts/export_if_onnx.py --dtype {suggested}`"
    )]
    DtypeMismatch {
        /// Which model.
        model: String,
        /// The manifest's dtype.
        declared: String,
        /// The offending input.
        input: String,
        /// The graph's element type.
        actual: String,
        /// The manifest value that would match.
        suggested: String,
    },
    /// A call's inputs have the wrong shape or count.
    #[error("{model}: {message}")]
    Shape {
        /// Which model.
        model: String,
        /// What was expected and what was given.
        message: String,
    },
    /// ONNX Runtime reported an error.
    #[error("ONNX Runtime error while {context}: {message}")]
    Ort {
        /// What was being done.
        context: String,
        /// ONNX Runtime's message.
        message: String,
    },
    /// The tokenizer could not be loaded or failed.
    #[error("tokenizer: {0}")]
    Tokenizer(String),
    /// A `.npy` file is malformed or of an unsupported kind.
    #[error("npy file {path}: {message}")]
    Npy {
        /// The file.
        path: PathBuf,
        /// What is wrong.
        message: String,
    },
    /// File system error.
    #[error("{path}: {source}")]
    Io {
        /// The path involved.
        path: PathBuf,
        /// The OS error.
        #[source]
        source: std::io::Error,
    },
    /// The embedding cache is unusable.
    #[error("embedding cache: {0}")]
    Cache(String),
    /// An embedding (from the text encoder, the cache or a file) holds NaN or ±∞. Guidance with it
    /// would produce a zero gradient after the reference's `nan_to_num`, so it is refused.
    #[error("{what} ({path}) has {count} non-finite values (NaN or ±∞) out of {total}; {hint}")]
    NonFinite {
        /// Which tensor (e.g. "the cached embedding of prompt \"a cat\"").
        what: String,
        /// The file it came from (the model file for an encoder output).
        path: PathBuf,
        /// How many values are NaN or ±∞.
        count: usize,
        /// How many values the tensor has.
        total: usize,
        /// What to do about it.
        hint: String,
    },
}

impl OnnxError {
    pub(crate) fn io(path: impl Into<PathBuf>, source: std::io::Error) -> Self {
        Self::Io {
            path: path.into(),
            source,
        }
    }

    /// [`OnnxError::NonFinite`] when `values` hold NaN or ±∞.
    pub(crate) fn check_finite(
        values: &[f32],
        what: impl FnOnce() -> String,
        path: &std::path::Path,
        hint: &str,
    ) -> Result<(), Self> {
        let count = csd::count_non_finite(values);
        if count == 0 {
            return Ok(());
        }
        Err(Self::NonFinite {
            what: what(),
            path: path.to_path_buf(),
            count,
            total: values.len(),
            hint: hint.to_string(),
        })
    }

    pub(crate) fn ort(context: impl Into<String>, e: impl std::fmt::Display) -> Self {
        Self::Ort {
            context: context.into(),
            message: e.to_string(),
        }
    }
}

impl From<OnnxError> for csd::GuidanceError {
    fn from(e: OnnxError) -> Self {
        match e {
            OnnxError::Shape { .. } => csd::GuidanceError::InvalidInput(e.to_string()),
            OnnxError::NonFinite {
                what,
                path,
                count,
                total,
                hint,
            } => csd::GuidanceError::NonFinite {
                tensor: format!("{what} ({})", path.display()),
                count,
                total,
                hint,
            },
            other => csd::GuidanceError::Model(other.to_string()),
        }
    }
}

//! Finding and loading the ONNX Runtime shared library, and building sessions.
//!
//! `ort` is built with `load-dynamic`: the library (`libonnxruntime.so`) is opened at run time. It is
//! looked for, in order, at
//! 1. `$ORT_DYLIB_PATH` (when set and non-empty; a set path that does not exist is an error),
//! 2. `<repository>/.deps/onnxruntime/libonnxruntime.so.1.31.1`, where `scripts/setup-onnxruntime.sh`
//!    puts it (found through this crate's source location, for tests and development).
//!
//! The library is loaded with [`ort::init_from`], which checks the version *before* any ONNX Runtime
//! API is used (ort would otherwise panic on a bad library); anything older than
//! [`MINIMUM_ORT_VERSION`] is refused with a message that says how to get a good one.

use std::path::{Path, PathBuf};
use std::sync::{Mutex, OnceLock};

use ort::environment::Environment;
use ort::session::Session;
use ort::session::builder::GraphOptimizationLevel;

use crate::OnnxError;

/// The ONNX Runtime version `scripts/setup-onnxruntime.sh` installs.
pub const ORT_VERSION: &str = "1.31.1";
/// The oldest ONNX Runtime accepted (ort is built with API level 30).
pub const MINIMUM_ORT_VERSION: &str = "1.30";
/// Environment variable naming the library explicitly.
pub const ORT_DYLIB_ENV: &str = "ORT_DYLIB_PATH";

/// Where `scripts/setup-onnxruntime.sh` installs the library in this source tree.
pub fn default_dylib_path() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("..")
        .join("..")
        .join(".deps")
        .join("onnxruntime")
        .join(format!("libonnxruntime.so.{ORT_VERSION}"))
}

/// Chooses the library path from the value of `$ORT_DYLIB_PATH` (if any) and the default location.
/// Pure apart from checking that files exist.
pub fn resolve_dylib_path(
    env_value: Option<&std::ffi::OsStr>,
    default: &Path,
) -> Result<PathBuf, OnnxError> {
    if let Some(v) = env_value.filter(|v| !v.is_empty()) {
        let p = PathBuf::from(v);
        return if p.is_file() {
            Ok(p)
        } else {
            Err(OnnxError::RuntimeMissing {
                searched: format!("{ORT_DYLIB_ENV}={} (no such file)", p.display()),
            })
        };
    }
    if default.is_file() {
        return Ok(default.to_path_buf());
    }
    Err(OnnxError::RuntimeMissing {
        searched: format!("{ORT_DYLIB_ENV} (not set), {}", default.display()),
    })
}

static ENVIRONMENT: OnceLock<Environment> = OnceLock::new();
static INIT_LOCK: Mutex<()> = Mutex::new(());

fn panic_message(p: &(dyn std::any::Any + Send)) -> String {
    p.downcast_ref::<&str>()
        .map(|s| (*s).to_string())
        .or_else(|| p.downcast_ref::<String>().cloned())
        .unwrap_or_else(|| "ONNX Runtime panicked".to_string())
}

/// Loads the library at `path` (if no library is loaded yet in this process) and returns the
/// process-wide ONNX Runtime environment. Later calls return the same environment whatever the path.
pub fn environment_from(path: &Path) -> Result<Environment, OnnxError> {
    if let Some(env) = ENVIRONMENT.get() {
        return Ok(env.clone());
    }
    let _guard = INIT_LOCK
        .lock()
        .unwrap_or_else(|poisoned| poisoned.into_inner());
    if let Some(env) = ENVIRONMENT.get() {
        return Ok(env.clone());
    }
    let unusable = |reason: String| OnnxError::RuntimeUnusable {
        path: path.to_path_buf(),
        reason,
    };
    // ort validates the file and its version in `init_from`; the panic guard is a second line of
    // defence for libraries that pass that check but misbehave when the API table is fetched.
    let built = std::panic::catch_unwind(|| -> Result<Environment, OnnxError> {
        let builder = ort::init_from(path).map_err(|e| unusable(e.to_string()))?;
        builder
            .with_name("stylize")
            .with_telemetry(false)
            .build()
            .map_err(|e| unusable(format!("creating the environment failed: {e}")))
    })
    .map_err(|p| unusable(panic_message(p.as_ref())))??;
    Ok(ENVIRONMENT.get_or_init(|| built).clone())
}

/// The process-wide ONNX Runtime environment, loading the library found by [`resolve_dylib_path`].
pub fn environment() -> Result<Environment, OnnxError> {
    if let Some(env) = ENVIRONMENT.get() {
        return Ok(env.clone());
    }
    let env_value = std::env::var_os(ORT_DYLIB_ENV);
    let path = resolve_dylib_path(env_value.as_deref(), &default_dylib_path())?;
    environment_from(&path)
}

/// Where sessions run.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Device {
    /// ONNX Runtime's CPU execution provider.
    #[default]
    Cpu,
    /// The CUDA execution provider on the given device (needs the `cuda` feature and an ONNX Runtime
    /// library built with CUDA, e.g. from the `onnxruntime-gpu` wheel). Registration failure is an error.
    Cuda {
        /// CUDA device ordinal.
        device_id: i32,
    },
}

/// Options for every session this crate creates.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct SessionOptions {
    /// Execution provider.
    pub device: Device,
    /// Threads inside one operator (None: ONNX Runtime's default, one per physical core).
    pub intra_threads: Option<usize>,
    /// ONNX Runtime's CPU memory arena (its default, on): freed tensors stay in a growing pool for
    /// reuse. Off, every tensor goes back to the system allocator: with the tiny IF fixtures the
    /// text loop's peak memory fell from 3.5 GB to 1.4 GB and its guidance took 15–25 % longer
    /// (docs/benchmarks.md). Only affects the CPU execution provider.
    pub cpu_memory_arena: bool,
}

impl Default for SessionOptions {
    fn default() -> Self {
        Self {
            device: Device::Cpu,
            intra_threads: None,
            cpu_memory_arena: true,
        }
    }
}

/// Opens an ONNX model file as a session (graph optimizations: all).
pub(crate) fn open_session(
    model: &Path,
    options: &SessionOptions,
    what: &str,
) -> Result<Session, OnnxError> {
    let env = environment()?;
    let ctx = |step: &str| format!("{step} for the {what} ({})", model.display());
    let mut builder =
        Session::builder(&env).map_err(|e| OnnxError::ort(ctx("creating a session"), e))?;
    builder = builder
        .with_optimization_level(GraphOptimizationLevel::All)
        .map_err(|e| OnnxError::ort(ctx("setting the optimization level"), e))?;
    if let Some(n) = options.intra_threads {
        builder = builder
            .with_intra_threads(n)
            .map_err(|e| OnnxError::ort(ctx("setting the thread count"), e))?;
    }
    match options.device {
        Device::Cpu => {
            if !options.cpu_memory_arena {
                let cpu = ort::ep::CPU::default().with_arena_allocator(false).build();
                builder = builder
                    .with_execution_providers([cpu])
                    .map_err(|e| OnnxError::ort(ctx("turning the CPU memory arena off"), e))?;
            }
        }
        #[cfg(feature = "cuda")]
        Device::Cuda { device_id } => {
            let ep = ort::ep::CUDA::default()
                .with_device_id(device_id)
                .build()
                .error_on_failure();
            builder = builder
                .with_execution_providers([ep])
                .map_err(|e| OnnxError::ort(ctx("registering the CUDA execution provider"), e))?;
        }
        #[cfg(not(feature = "cuda"))]
        Device::Cuda { .. } => {
            return Err(OnnxError::Ort {
                context: ctx("registering the CUDA execution provider"),
                message:
                    "this build has no CUDA support; rebuild with `--features diffusion-onnx/cuda`"
                        .into(),
            });
        }
    }
    builder.commit_from_file(model).map_err(|e| {
        let message = e.to_string();
        let lower = message.to_lowercase();
        if lower.contains("external") || lower.contains("no such file") || lower.contains("cannot open") {
            OnnxError::Ort {
                context: ctx("loading the model"),
                message: format!(
                    "{message} — a model over 2 GB keeps its weights in ONNX external data files beside the \
                     .onnx (e.g. `{}.data`); copy them too and list them under `external_data` in manifest.toml",
                    model.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default()
                ),
            }
        } else {
            OnnxError::ort(ctx("loading the model"), message)
        }
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn env_path_that_does_not_exist_is_a_clear_error() {
        let dir = tempfile::tempdir().expect("tempdir");
        let missing = dir.path().join("libonnxruntime.so.0");
        let err = resolve_dylib_path(Some(missing.as_os_str()), &default_dylib_path()).err();
        let msg = err.map(|e| e.to_string()).unwrap_or_default();
        assert!(
            msg.contains("ORT_DYLIB_PATH") && msg.contains("setup-onnxruntime.sh"),
            "{msg}"
        );
    }

    #[test]
    fn missing_default_without_env_names_both_places_and_the_fix() {
        let dir = tempfile::tempdir().expect("tempdir");
        let err = resolve_dylib_path(None, &dir.path().join("nothing.so")).err();
        let msg = err.map(|e| e.to_string()).unwrap_or_default();
        assert!(
            msg.contains("not set")
                && msg.contains("nothing.so")
                && msg.contains("setup-onnxruntime.sh"),
            "{msg}"
        );
    }

    #[test]
    fn empty_env_value_falls_back_to_the_default() {
        let dir = tempfile::tempdir().expect("tempdir");
        let lib = dir.path().join("lib.so");
        std::fs::write(&lib, b"x").expect("write");
        let got = resolve_dylib_path(Some(std::ffi::OsStr::new("")), &lib).ok();
        assert_eq!(got, Some(lib));
    }
}

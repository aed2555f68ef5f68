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

use std::fmt;
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
        return if p.exists() {
            // Existing but unusable (a directory, a device, a truncated file) is reported by
            // `check_library_file` with the reason.
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

/// Checks, without loading it, that `path` can be a shared library for this machine: a regular file,
/// and on ELF platforms an ELF shared object (`ET_DYN`) of this CPU whose program and section header
/// tables and every loadable segment lie inside the file.
///
/// The dynamic loader maps segments without checking the file size; a truncated library then dies
/// with SIGBUS on first access, with no message. This check turns that into an error naming the file.
pub fn check_library_file(path: &Path) -> Result<(), OnnxError> {
    let unusable = |reason: String| OnnxError::RuntimeUnusable {
        path: path.to_path_buf(),
        reason,
    };
    let meta = std::fs::metadata(path).map_err(|e| unusable(format!("cannot read it: {e}")))?;
    if !meta.is_file() {
        return Err(unusable(
            "it is not a regular file (a directory or a device?)".into(),
        ));
    }
    #[cfg(all(unix, not(target_os = "macos"), not(target_os = "ios")))]
    {
        let mut file =
            std::fs::File::open(path).map_err(|e| unusable(format!("cannot open it: {e}")))?;
        check_elf(&mut file, meta.len()).map_err(unusable)?;
    }
    Ok(())
}

/// The ELF checks of [`check_library_file`] on an open file of `len` bytes.
#[cfg(all(unix, not(target_os = "macos"), not(target_os = "ios")))]
fn check_elf(file: &mut std::fs::File, len: u64) -> Result<(), String> {
    use std::io::{Read, Seek, SeekFrom};
    let mut head = [0u8; 64];
    let n = file
        .read(&mut head)
        .map_err(|e| format!("cannot read it: {e}"))?;
    if n < 4 || head[..4] != *b"\x7fELF" {
        return Err(format!(
            "it is not a shared library (no ELF header; {len} bytes)"
        ));
    }
    let is64 = match head[4] {
        1 => false,
        2 => true,
        c => return Err(format!("unknown ELF class {c}; the file is damaged")),
    };
    let little = match head[5] {
        1 => true,
        2 => false,
        d => return Err(format!("unknown ELF byte order {d}; the file is damaged")),
    };
    let header_len = if is64 { 64 } else { 52 };
    if n < header_len {
        return Err(format!(
            "the file is truncated ({len} bytes, shorter than an ELF header); download it again"
        ));
    }
    let u16_at = |b: &[u8], o: usize| {
        let v = [b[o], b[o + 1]];
        u64::from(if little {
            u16::from_le_bytes(v)
        } else {
            u16::from_be_bytes(v)
        })
    };
    let u32_at = |b: &[u8], o: usize| {
        let v = [b[o], b[o + 1], b[o + 2], b[o + 3]];
        u64::from(if little {
            u32::from_le_bytes(v)
        } else {
            u32::from_be_bytes(v)
        })
    };
    let u64_at = |b: &[u8], o: usize| {
        let mut v = [0u8; 8];
        v.copy_from_slice(&b[o..o + 8]);
        if little {
            u64::from_le_bytes(v)
        } else {
            u64::from_be_bytes(v)
        }
    };
    let word_at = |b: &[u8], o32: usize, o64: usize| {
        if is64 { u64_at(b, o64) } else { u32_at(b, o32) }
    };
    let e_type = u16_at(&head, 16);
    if e_type != 3 {
        return Err(format!(
            "it is an ELF file but not a shared library (e_type {e_type}, a shared object is 3)"
        ));
    }
    let machine = u16_at(&head, 18);
    let host: Option<(u64, &str)> = if cfg!(target_arch = "x86_64") {
        Some((62, "x86-64"))
    } else if cfg!(target_arch = "aarch64") {
        Some((183, "aarch64"))
    } else {
        None
    };
    if let Some((want, name)) = host
        && (machine != want || is64 != cfg!(target_pointer_width = "64"))
    {
        return Err(format!(
            "it is built for another CPU (ELF machine {machine}, {} bit); this program needs {name}",
            if is64 { 64 } else { 32 }
        ));
    }
    let phoff = word_at(&head, 28, 32);
    let shoff = word_at(&head, 32, 40);
    let (phentsize, phnum) = (
        u16_at(&head, header_len - 10),
        u16_at(&head, header_len - 8),
    );
    let (shentsize, shnum) = (u16_at(&head, header_len - 6), u16_at(&head, header_len - 4));
    let truncated = |what: &str, end: u64| {
        format!(
            "the file is truncated or damaged: its {what} ends at byte {end} but the file has {len} bytes; \
             download or copy it again"
        )
    };
    let table_end = |off: u64, size: u64, num: u64| off.saturating_add(size.saturating_mul(num));
    if phnum == 0 {
        return Err("it has no program headers; it is not a loadable library".into());
    }
    let min_ph = if is64 { 56 } else { 32 };
    if phentsize < min_ph {
        return Err(format!(
            "program header entries of {phentsize} bytes (at least {min_ph} expected); the file is damaged"
        ));
    }
    let ph_end = table_end(phoff, phentsize, phnum);
    if ph_end > len {
        return Err(truncated("program header table", ph_end));
    }
    if shoff != 0 {
        let sh_end = table_end(shoff, shentsize, shnum);
        if sh_end > len {
            return Err(truncated("section header table", sh_end));
        }
    }
    // Every loadable segment's bytes must be in the file (what the loader maps).
    let table_len = usize::try_from(phentsize * phnum).map_err(|e| e.to_string())?;
    let mut table = vec![0u8; table_len];
    file.seek(SeekFrom::Start(phoff))
        .and_then(|_| file.read_exact(&mut table))
        .map_err(|e| format!("cannot read its program headers: {e}"))?;
    let step = usize::try_from(phentsize).map_err(|e| e.to_string())?;
    for (i, ph) in table.chunks_exact(step).enumerate() {
        const PT_LOAD: u64 = 1;
        if u32_at(ph, 0) != PT_LOAD {
            continue;
        }
        let offset = word_at(ph, 4, 8);
        let filesz = word_at(ph, 16, 32);
        let end = offset.saturating_add(filesz);
        if end > len {
            return Err(truncated(&format!("loadable segment {i}"), end));
        }
    }
    Ok(())
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
    check_library_file(path)?;
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

/// Where sessions run. Displayed `cpu` or `cuda:N` (the spelling of the run configuration's device keys).
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

impl Device {
    /// `"cpu"` or `"cuda"`: the kind of device, without the ordinal.
    pub fn kind(&self) -> &'static str {
        match self {
            Self::Cpu => "cpu",
            Self::Cuda { .. } => "cuda",
        }
    }
}

impl fmt::Display for Device {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Cpu => f.write_str("cpu"),
            Self::Cuda { device_id } => write!(f, "cuda:{device_id}"),
        }
    }
}

/// cuDNN's convolution algorithm choice in the CUDA execution provider (`cudnn_conv_algo_search`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum ConvAlgorithmSearch {
    /// Benchmark every algorithm on the first call of each shape (ONNX Runtime's default): the first
    /// call is slow, later ones use the fastest kernel. The setting users of large UNets need.
    #[default]
    Exhaustive,
    /// cuDNN's heuristics, no benchmarking: a fast first call, possibly slower kernels.
    Heuristic,
    /// The implicit-precomputed-GEMM algorithm always: the least workspace memory, often slowest.
    Default,
}

/// How the CUDA execution provider's memory arena grows (`arena_extend_strategy`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum ArenaGrowth {
    /// Each extension doubles the previous one (ONNX Runtime's default): fewer allocations, but the
    /// arena can overshoot what the model needs by up to 2×.
    #[default]
    NextPowerOfTwo,
    /// Extend by exactly what is requested: the tightest fit, for cards near their memory.
    SameAsRequested,
}

/// The CUDA execution provider's options that matter for IF's UNets (defaults: ONNX Runtime 1.31's
/// own). Ignored on the CPU.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct CudaOptions {
    /// cuDNN convolution algorithm search: exhaustive.
    pub conv_algorithm_search: ConvAlgorithmSearch,
    /// Arena growth: next power of two.
    pub arena_growth: ArenaGrowth,
    /// Cap on the provider's arena in bytes (`gpu_mem_limit`; None: no cap).
    pub memory_limit: Option<u64>,
    /// TF32 tensor-core math for fp32 MatMul/Conv on Ampere and later (`use_tf32`; on): ≈ 10-bit
    /// mantissa products. Only fp32 models are affected; fp16 models compute in fp16 anyway.
    pub tf32: bool,
}

impl Default for CudaOptions {
    fn default() -> Self {
        Self {
            conv_algorithm_search: ConvAlgorithmSearch::Exhaustive,
            arena_growth: ArenaGrowth::NextPowerOfTwo,
            memory_limit: None,
            tf32: true,
        }
    }
}

/// Options for every session this crate creates.
///
/// The memory settings matter at DeepFloyd IF's size (docs/models.md, "Runtime memory"): on the CPU
/// execution provider a UNet call holds the weights, any fp32 copies ONNX Runtime makes of fp16
/// weights, pre-packed copies of weights, and the activations of the batch in one call.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct SessionOptions {
    /// Execution provider.
    pub device: Device,
    /// Threads inside one operator (None: ONNX Runtime's default, one per physical core); at most
    /// [`max_intra_threads`] (a session with more is refused).
    pub intra_threads: Option<usize>,
    /// ONNX Runtime's CPU memory arena (its default, on): freed tensors stay in a growing pool for
    /// reuse. Off, every tensor goes back to the system allocator: with the tiny IF fixtures the
    /// text loop's peak memory fell from 3.5 GB to 1.4 GB and its guidance took 15–25 % longer
    /// (docs/benchmarks.md). Only affects the CPU execution provider.
    pub cpu_memory_arena: bool,
    /// ONNX Runtime's memory pattern (its default, on): after the first run with an input shape it
    /// plans one block for all intermediate tensors of that shape and keeps it. Off, intermediates
    /// are allocated and freed as the graph runs (a lower peak when tensors die early).
    pub memory_pattern: bool,
    /// Weight pre-packing (ONNX Runtime's default, on; config entry `session.disable_prepacking`):
    /// MatMul/Gemm/Conv kernels keep a second, re-laid-out copy of their constant weights for speed.
    /// Off, that copy is not made.
    pub prepacking: bool,
    /// ONNX Runtime's graph optimizations (on: all levels; off: none). On the CPU execution provider
    /// an fp16 model's weights are converted once, at load, into fp32 copies that stay resident
    /// (measured at IF-II-L's size: 2.3× the fp16 file after loading, 3.8× at the peak); off, the
    /// weights stay mapped from the external-data file and the casts run in each call (peak 1.9×,
    /// the call ≈ 1.4× slower: the fusions are lost too). An fp32 export gains nothing from it.
    pub graph_optimizations: bool,
    /// At most this many samples per session call (None: the whole batch in one call). csd hands
    /// the UNet a batch of 2B samples (conditional and unconditional halves); splitting it runs the
    /// same arithmetic in several calls, so the activations held at once shrink by the split factor.
    /// The results are identical up to floating-point summation order (tested).
    pub max_batch: Option<usize>,
    /// Whether ONNX Runtime's intra-op worker threads may spin (busy-wait) for new work between
    /// parallel sections and after a call returns (config entry `session.intra_op.allow_spinning`).
    /// ONNX Runtime's default is on; **this crate's default is off**: in the stylization loop the
    /// caller's own threads (resizes, the renderer, dARAP) run right after each UNet call on the same
    /// cores, and spinning workers take CPU from them (docs/benchmarks.md, "The loop").
    pub intra_op_spinning: bool,
    /// UNet calls through a persistent ONNX Runtime IO binding (default on): inputs written in
    /// place, the text embeddings re-bound only when they change, the output preallocated and
    /// reused (`OnnxDenoiser`). Off, each call builds fresh input and output tensors. Bit-identical
    /// results on the CPU provider (tested); fewer copies (docs/benchmarks.md, "IO binding").
    pub io_binding: bool,
    /// CUDA execution provider options (used only when `device` is CUDA).
    pub cuda: CudaOptions,
}

impl Default for SessionOptions {
    fn default() -> Self {
        Self {
            device: Device::Cpu,
            intra_threads: None,
            cpu_memory_arena: true,
            memory_pattern: true,
            prepacking: true,
            graph_optimizations: true,
            max_batch: None,
            intra_op_spinning: false,
            io_binding: true,
            cuda: CudaOptions::default(),
        }
    }
}

impl SessionOptions {
    /// The settings for models near the machine's memory: CPU arena, memory pattern, pre-packing
    /// and graph optimizations off, one sample per call. What each costs in time and saves in memory at
    /// IF-II-L's size is measured in docs/models.md.
    pub fn low_memory() -> Self {
        Self {
            cpu_memory_arena: false,
            memory_pattern: false,
            prepacking: false,
            graph_optimizations: false,
            max_batch: Some(1),
            ..Self::default()
        }
    }
}

/// The most intra-op threads a session is given: 4 × the threads this process may run at once
/// (`std::thread::available_parallelism`, 64 when unknown), at most 1024. More only oversubscribe
/// the cores; a count from input far beyond it made ONNX Runtime crash (100,000) or hang (2,000
/// under a memory limit).
pub fn max_intra_threads() -> usize {
    std::thread::available_parallelism()
        .map_or(64, |n| n.get().saturating_mul(4))
        .min(1024)
}

/// Checks an intra-op thread count: within `1..=`[`max_intra_threads`].
pub fn check_intra_threads(n: usize) -> Result<usize, String> {
    let max = max_intra_threads();
    if (1..=max).contains(&n) {
        Ok(n)
    } else {
        Err(format!(
            "{n} intra-op threads: must be within 1..={max} (4 × the threads this machine runs at \
             once, at most 1024); leave it unset for ONNX Runtime's default"
        ))
    }
}

/// Opens an ONNX model file as a session with `options`.
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
        .with_optimization_level(if options.graph_optimizations {
            GraphOptimizationLevel::All
        } else {
            GraphOptimizationLevel::Disable
        })
        .map_err(|e| OnnxError::ort(ctx("setting the optimization level"), e))?;
    builder = builder
        .with_memory_pattern(options.memory_pattern)
        .map_err(|e| OnnxError::ort(ctx("setting the memory pattern"), e))?;
    builder = builder
        .with_prepacking(options.prepacking)
        .map_err(|e| OnnxError::ort(ctx("setting weight pre-packing"), e))?;
    builder = builder
        .with_intra_op_spinning(options.intra_op_spinning)
        .map_err(|e| OnnxError::ort(ctx("setting intra-op spinning"), e))?;
    if let Some(n) = options.intra_threads {
        let n = check_intra_threads(n).map_err(|message| OnnxError::Ort {
            context: ctx("setting the thread count"),
            message,
        })?;
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
            let c = &options.cuda;
            let mut cuda = ort::ep::CUDA::default()
                .with_device_id(device_id)
                .with_conv_algorithm_search(match c.conv_algorithm_search {
                    ConvAlgorithmSearch::Exhaustive => {
                        ort::ep::cuda::ConvAlgorithmSearch::Exhaustive
                    }
                    ConvAlgorithmSearch::Heuristic => ort::ep::cuda::ConvAlgorithmSearch::Heuristic,
                    ConvAlgorithmSearch::Default => ort::ep::cuda::ConvAlgorithmSearch::Default,
                })
                .with_arena_extend_strategy(match c.arena_growth {
                    ArenaGrowth::NextPowerOfTwo => ort::ep::ArenaExtendStrategy::NextPowerOfTwo,
                    ArenaGrowth::SameAsRequested => ort::ep::ArenaExtendStrategy::SameAsRequested,
                })
                .with_tf32(c.tf32);
            if let Some(limit) = c.memory_limit {
                cuda = cuda.with_memory_limit(usize::try_from(limit).unwrap_or(usize::MAX));
            }
            let ep = cuda.build().error_on_failure();
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

    fn reason(r: Result<(), OnnxError>) -> String {
        match r {
            Ok(()) => panic!("accepted"),
            Err(e) => e.to_string(),
        }
    }

    #[test]
    fn non_libraries_are_refused_before_loading() {
        let dir = tempfile::tempdir().expect("tempdir");
        let msg = reason(check_library_file(dir.path()));
        assert!(msg.contains("not a regular file"), "{msg}");
        let text = dir.path().join("libonnxruntime.so");
        std::fs::write(&text, b"#!/bin/sh\necho not a library\n").expect("write");
        let msg = reason(check_library_file(&text));
        assert!(
            msg.contains("no ELF header") && msg.contains("libonnxruntime.so"),
            "{msg}"
        );
        std::fs::write(&text, b"").expect("write");
        assert!(reason(check_library_file(&text)).contains("no ELF header"));
        // An ELF header cut short.
        std::fs::write(&text, b"\x7fELF\x02\x01\x01\0\0\0").expect("write");
        assert!(reason(check_library_file(&text)).contains("truncated"));
        // Devices are not libraries (ORT_DYLIB_PATH=/dev/zero used to be read until memory ran out).
        let msg = reason(check_library_file(Path::new("/dev/zero")));
        assert!(msg.contains("not a regular file"), "{msg}");
    }

    #[test]
    fn a_truncated_onnx_runtime_is_refused_and_the_whole_one_accepted() {
        let real = default_dylib_path();
        let bytes = std::fs::read(&real).unwrap_or_else(|e| {
            panic!("{}: {e}; run scripts/setup-onnxruntime.sh", real.display())
        });
        assert!(check_library_file(&real).is_ok());
        let dir = tempfile::tempdir().expect("tempdir");
        let cut = dir.path().join("libonnxruntime.so.1.31.1");
        // Cut at the end (the section headers), in the middle (a loadable segment) and right after
        // the ELF header (the program headers).
        for keep in [bytes.len() - 1, bytes.len() / 2, 100, 64] {
            std::fs::write(&cut, &bytes[..keep]).expect("write");
            let msg = reason(check_library_file(&cut));
            assert!(
                msg.contains("truncated")
                    && msg.contains(&format!("{keep} bytes"))
                    && msg.contains(&cut.display().to_string()),
                "cut at {keep}: {msg}"
            );
        }
        // A library for another CPU.
        let mut other = bytes[..4096.min(bytes.len())].to_vec();
        other[18] = 0x28; // EM_ARM
        std::fs::write(&cut, &other).expect("write");
        let msg = reason(check_library_file(&cut));
        assert!(msg.contains("another CPU"), "{msg}");
    }

    #[test]
    fn env_path_to_a_directory_is_resolved_then_refused_with_the_reason() {
        let dir = tempfile::tempdir().expect("tempdir");
        let got = resolve_dylib_path(Some(dir.path().as_os_str()), &default_dylib_path());
        assert_eq!(got.ok().as_deref(), Some(dir.path()));
        assert!(reason(check_library_file(dir.path())).contains("not a regular file"));
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

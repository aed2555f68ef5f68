//! What this machine can run, found by loading things rather than guessing (`stylize doctor`):
//! the ONNX Runtime library and its version, whether the CUDA / TensorRT execution-provider
//! libraries sit beside it and load (with the dynamic loader's reason when they do not: a CUDA
//! runtime or cuDNN library missing, the shared-provider bridge missing, a damaged file), the NVIDIA
//! driver's CUDA version and the GPUs it sees (through `libcuda.so.1`'s driver API), and the devices
//! ONNX Runtime itself lists.
//!
//! The CUDA provider library (`libonnxruntime_providers_cuda.so`) is what the `onnxruntime-gpu` wheel
//! adds next to `libonnxruntime.so`; the CPU-only wheel (what `scripts/setup-onnxruntime.sh`
//! installs) has no such file. Loading it with `dlopen` makes the loader resolve its dependencies
//! (`libcudart.so.N`, `libcublas*.so.N`, `libcudnn*.so.9`, `libcufft`, `libcurand`, …): the first one
//! missing is named in the loader's message, which [`classify_load_error`] turns into a cause.

use std::ffi::{CStr, CString, c_char, c_int, c_uint, c_void};
use std::path::{Path, PathBuf};

use crate::runtime;

/// File name of ONNX Runtime's CUDA execution provider library.
pub const CUDA_PROVIDER_FILE: &str = "libonnxruntime_providers_cuda.so";
/// File name of ONNX Runtime's TensorRT execution provider library.
pub const TENSORRT_PROVIDER_FILE: &str = "libonnxruntime_providers_tensorrt.so";
/// The bridge every provider library needs.
pub const SHARED_PROVIDER_FILE: &str = "libonnxruntime_providers_shared.so";

/// Why a provider library does not load.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum LoadFailure {
    /// A CUDA toolkit runtime library (`libcudart`, `libcublas`, `libcufft`, `libcurand`, nvrtc, …)
    /// is not on the loader's path: install the `nvidia-*` wheels / CUDA toolkit and add their
    /// `lib` folders to `LD_LIBRARY_PATH`.
    CudaRuntimeMissing(String),
    /// cuDNN (`libcudnn*.so.9`) is not on the loader's path.
    CudnnMissing(String),
    /// TensorRT (`libnvinfer*`) is not on the loader's path.
    TensorRtMissing(String),
    /// The NVIDIA driver's `libcuda.so.1` is missing: no driver installed (or not visible in this
    /// container).
    DriverMissing,
    /// `libonnxruntime_providers_shared.so` is not beside the provider.
    SharedProviderMissing,
    /// The file is not a loadable library for this machine (truncated, damaged, another CPU).
    Damaged,
    /// A library was found but lacks a versioned symbol (e.g. an older cuDNN/CUDA than the provider
    /// was built against).
    VersionMismatch,
    /// Anything else; the loader's message says what.
    Other,
}

impl LoadFailure {
    /// One sentence: the cause and the next step.
    pub fn advice(&self) -> String {
        match self {
            Self::CudaRuntimeMissing(lib) => format!(
                "the CUDA runtime library {lib} is not found: install the CUDA 13 runtime wheels \
                 (nvidia-cuda-runtime, nvidia-cublas, nvidia-cufft, nvidia-curand, nvidia-cuda-nvrtc) or the \
                 CUDA toolkit, and put their lib folders on LD_LIBRARY_PATH"
            ),
            Self::CudnnMissing(lib) => format!(
                "cuDNN ({lib}) is not found: install nvidia-cudnn-cu13 (cuDNN 9) and put its lib folder on \
                 LD_LIBRARY_PATH"
            ),
            Self::TensorRtMissing(lib) => format!(
                "TensorRT ({lib}) is not found; the CUDA provider does not need it (TensorRT is optional)"
            ),
            Self::DriverMissing => "the NVIDIA driver library libcuda.so.1 is not found: no NVIDIA driver is \
                                    installed or visible (containers need the GPU passed through)"
                .into(),
            Self::SharedProviderMissing => format!(
                "{SHARED_PROVIDER_FILE} is missing beside the provider: copy it from the same onnxruntime-gpu \
                 wheel (onnxruntime/capi/)"
            ),
            Self::Damaged => "the provider library is damaged or truncated: copy it again (scripts/gpu_check.sh \
                              verifies its sha256)"
                .into(),
            Self::VersionMismatch => "a CUDA/cuDNN library was found but is older than the provider was built \
                                      for: use the CUDA 13 / cuDNN 9 wheels onnxruntime-gpu 1.31 names"
                .into(),
            Self::Other => "see the loader's message".into(),
        }
    }
}

/// Classifies the dynamic loader's message for a library that did not load (glibc's `dlerror`
/// wording: `libcudnn.so.9: cannot open shared object file: No such file or directory`, `…: invalid
/// ELF header`, `…: version `libcublas.so.13' not found`).
pub fn classify_load_error(message: &str) -> LoadFailure {
    let missing = message
        .split(": cannot open shared object file")
        .next()
        .filter(|_| message.contains("cannot open shared object file"))
        .map(|s| s.rsplit(' ').next().unwrap_or(s).trim().to_string());
    if let Some(lib) = missing {
        let name = Path::new(&lib)
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or(lib.clone());
        return if name.starts_with("libcudnn") {
            LoadFailure::CudnnMissing(name)
        } else if name.starts_with("libcuda.so") {
            LoadFailure::DriverMissing
        } else if name.starts_with("libonnxruntime_providers_shared") {
            LoadFailure::SharedProviderMissing
        } else if name.starts_with("libnvinfer") || name.starts_with("libnvonnxparser") {
            LoadFailure::TensorRtMissing(name)
        } else if [
            "libcudart",
            "libcublas",
            "libcufft",
            "libcurand",
            "libnvrtc",
            "libnvJitLink",
            "libcusparse",
            "libcusolver",
        ]
        .iter()
        .any(|p| name.starts_with(p))
        {
            LoadFailure::CudaRuntimeMissing(name)
        } else {
            LoadFailure::Other
        };
    }
    if message.contains("invalid ELF header")
        || message.contains("file too short")
        || message.contains("wrong ELF class")
        || message.contains("ELF load command")
    {
        return LoadFailure::Damaged;
    }
    if message.contains("version `") && message.contains("not found") {
        return LoadFailure::VersionMismatch;
    }
    LoadFailure::Other
}

/// What became of one provider library.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum ProviderProbe {
    /// No such file beside the ONNX Runtime library: a CPU-only ONNX Runtime (the `onnxruntime`
    /// wheel, not `onnxruntime-gpu`).
    Absent {
        /// Where it was looked for.
        expected: PathBuf,
    },
    /// The file is there and loads with all its dependencies.
    Loads {
        /// The file.
        path: PathBuf,
        /// The CUDA runtime (`libcudart.so.N`) it brought in, as N, when one could be identified.
        cuda_runtime_major: Option<i32>,
    },
    /// The file is there but does not load.
    Fails {
        /// The file.
        path: PathBuf,
        /// The cause.
        failure: LoadFailure,
        /// The loader's own message.
        message: String,
    },
}

/// The NVIDIA driver as seen through `libcuda.so.1`.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct DriverReport {
    /// The highest CUDA version the driver supports, `(major, minor)` (driver 580: 13.0).
    pub cuda_version: Option<(i32, i32)>,
    /// The GPUs it lists (honouring `CUDA_VISIBLE_DEVICES`, so the ordinals are `cuda:N`'s).
    pub gpus: Vec<GpuInfo>,
    /// Why nothing could be read (no driver, `cuInit` failed), if so.
    pub error: Option<String>,
}

/// One GPU.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct GpuInfo {
    /// CUDA device ordinal (`cuda:N`).
    pub ordinal: i32,
    /// The device's name (`NVIDIA H100 80GB HBM3`).
    pub name: String,
    /// Total device memory in bytes.
    pub memory_bytes: u64,
}

/// The provider library `file` beside the ONNX Runtime library at `ort_library`: absent, loading, or
/// failing with the loader's reason. Loading it runs no ONNX Runtime code beyond its initializers.
pub fn probe_provider(ort_library: &Path, file: &str) -> ProviderProbe {
    let dir = ort_library.parent().unwrap_or(Path::new("."));
    let path = dir.join(file);
    if !path.is_file() {
        return ProviderProbe::Absent { expected: path };
    }
    if let Err(e) = runtime::check_library_file(&path) {
        let message = match e {
            crate::OnnxError::RuntimeUnusable { reason, .. } => reason,
            other => other.to_string(),
        };
        return ProviderProbe::Fails {
            message: format!("{}: {message}", path.display()),
            path,
            failure: LoadFailure::Damaged,
        };
    }
    match dl::open(&path.to_string_lossy()) {
        Ok(_) => {
            let cuda_runtime_major = (10..=14)
                .rev()
                .find(|m| dl::is_loaded(&format!("libcudart.so.{m}")));
            ProviderProbe::Loads {
                path,
                cuda_runtime_major,
            }
        }
        Err(message) => ProviderProbe::Fails {
            failure: classify_load_error(&message),
            path,
            message,
        },
    }
}

/// The NVIDIA driver and its GPUs, through the CUDA driver API in `libcuda.so.1` (no CUDA toolkit
/// needed). On a machine without a driver: `error` says so and nothing else is set.
pub fn probe_driver() -> DriverReport {
    let lib = match dl::open("libcuda.so.1") {
        Ok(lib) => lib,
        Err(e) => {
            return DriverReport {
                error: Some(format!("no NVIDIA driver: {e}")),
                ..DriverReport::default()
            };
        }
    };
    dl::cuda_driver(lib)
}

/// The ONNX Runtime library at `path`: its version (`OrtGetApiBase()->GetVersionString()`, e.g.
/// `1.31.1`) and build string (`ORT Build Info: git-branch=…, git-commit-id=…`). Loads the library
/// as the process's ONNX Runtime ([`runtime::environment_from`]) if none is loaded yet.
pub fn runtime_version(path: &Path) -> Result<(String, String), crate::OnnxError> {
    runtime::environment_from(path)?;
    let unusable = |reason: String| crate::OnnxError::RuntimeUnusable {
        path: path.to_path_buf(),
        reason,
    };
    let lib = dl::open(&path.to_string_lossy()).map_err(&unusable)?;
    let version = dl::ort_version(&lib).ok_or_else(|| unusable("no OrtGetApiBase".into()))?;
    Ok((version, ort::info().to_string()))
}

/// The devices ONNX Runtime lists (`execution provider: hardware type, vendor`), e.g.
/// `CPUExecutionProvider: Cpu, Intel Corporation`.
pub fn runtime_devices() -> Result<Vec<String>, crate::OnnxError> {
    let env = runtime::environment()?;
    Ok(env
        .devices()
        .map(|d| {
            let hw = d.hardware_device();
            format!(
                "{}: {:?}, {}",
                d.ep().unwrap_or("?"),
                hw.ty(),
                hw.vendor().unwrap_or("?")
            )
        })
        .collect())
}

/// The few `dlopen`/driver-API calls, in one place.
#[allow(unsafe_code)]
mod dl {
    use super::*;

    /// A library handle that stays loaded for the life of the process (never `dlclose`d: the
    /// provider's and driver's initializers are not meant to be unloaded).
    pub(super) struct Lib(*mut c_void);

    fn last_error() -> String {
        // SAFETY: dlerror returns a thread-local C string or null.
        let e = unsafe { libc::dlerror() };
        if e.is_null() {
            "unknown dynamic loader error".into()
        } else {
            // SAFETY: non-null, NUL-terminated, valid until the next dl* call on this thread.
            unsafe { CStr::from_ptr(e) }.to_string_lossy().into_owned()
        }
    }

    pub(super) fn open(name: &str) -> Result<Lib, String> {
        let c = CString::new(name).map_err(|_| format!("{name}: NUL in the path"))?;
        // SAFETY: a valid C string; RTLD_NOW resolves every symbol now, so a missing dependency is
        // reported here rather than at first use.
        let h = unsafe { libc::dlopen(c.as_ptr(), libc::RTLD_NOW | libc::RTLD_LOCAL) };
        if h.is_null() {
            Err(last_error())
        } else {
            Ok(Lib(h))
        }
    }

    /// Whether a library of this soname is already loaded (RTLD_NOLOAD: never loads it).
    pub(super) fn is_loaded(name: &str) -> bool {
        let Ok(c) = CString::new(name) else {
            return false;
        };
        // SAFETY: a valid C string; RTLD_NOLOAD only looks the name up among loaded objects.
        let h = unsafe { libc::dlopen(c.as_ptr(), libc::RTLD_NOW | libc::RTLD_NOLOAD) };
        !h.is_null()
    }

    fn sym(lib: &Lib, name: &str) -> Option<*mut c_void> {
        let c = CString::new(name).ok()?;
        // SAFETY: a live handle and a valid C string.
        let p = unsafe { libc::dlsym(lib.0, c.as_ptr()) };
        (!p.is_null()).then_some(p)
    }

    /// The head of ONNX Runtime's `OrtApiBase` (onnxruntime_c_api.h).
    #[repr(C)]
    struct OrtApiBase {
        _get_api: unsafe extern "C" fn(u32) -> *const c_void,
        get_version_string: unsafe extern "C" fn() -> *const c_char,
    }

    /// `OrtGetApiBase()->GetVersionString()` of a loaded ONNX Runtime.
    pub(super) fn ort_version(lib: &Lib) -> Option<String> {
        let f = sym(lib, "OrtGetApiBase")?;
        // SAFETY: `OrtGetApiBase` is `const OrtApiBase* ORT_API_CALL OrtGetApiBase(void)`; the base
        // is a static table whose second entry returns a static NUL-terminated string.
        unsafe {
            let f: unsafe extern "C" fn() -> *const OrtApiBase = std::mem::transmute(f);
            let base = f();
            if base.is_null() {
                return None;
            }
            let s = ((*base).get_version_string)();
            (!s.is_null()).then(|| CStr::from_ptr(s).to_string_lossy().into_owned())
        }
    }

    type CuInit = unsafe extern "C" fn(c_uint) -> c_int;
    type CuIntOut = unsafe extern "C" fn(*mut c_int) -> c_int;
    type CuDeviceGet = unsafe extern "C" fn(*mut c_int, c_int) -> c_int;
    type CuDeviceGetName = unsafe extern "C" fn(*mut c_char, c_int, c_int) -> c_int;
    type CuDeviceTotalMem = unsafe extern "C" fn(*mut usize, c_int) -> c_int;

    pub(super) fn cuda_driver(lib: Lib) -> DriverReport {
        let mut report = DriverReport::default();
        let (Some(init), Some(version), Some(count), Some(get), Some(name), Some(mem)) = (
            sym(&lib, "cuInit"),
            sym(&lib, "cuDriverGetVersion"),
            sym(&lib, "cuDeviceGetCount"),
            sym(&lib, "cuDeviceGet"),
            sym(&lib, "cuDeviceGetName"),
            sym(&lib, "cuDeviceTotalMem_v2"),
        ) else {
            report.error = Some("libcuda.so.1 lacks the CUDA driver API entry points".into());
            return report;
        };
        // SAFETY: the symbols are the CUDA driver API's, with these C signatures (cuda.h).
        unsafe {
            let version: CuIntOut = std::mem::transmute(version);
            let mut v: c_int = 0;
            if version(&mut v) == 0 {
                report.cuda_version = Some((v / 1000, (v % 1000) / 10));
            }
            let init: CuInit = std::mem::transmute(init);
            let rc = init(0);
            if rc != 0 {
                report.error = Some(format!(
                    "cuInit failed with CUDA error {rc} (100: no CUDA-capable device; 999: unknown, often a \
                     driver/kernel-module mismatch; 35: the driver is older than the CUDA runtime)"
                ));
                return report;
            }
            let count: CuIntOut = std::mem::transmute(count);
            let get: CuDeviceGet = std::mem::transmute(get);
            let name: CuDeviceGetName = std::mem::transmute(name);
            let mem: CuDeviceTotalMem = std::mem::transmute(mem);
            let mut n: c_int = 0;
            if count(&mut n) != 0 {
                report.error = Some("cuDeviceGetCount failed".into());
                return report;
            }
            for ordinal in 0..n {
                let mut dev: c_int = 0;
                if get(&mut dev, ordinal) != 0 {
                    continue;
                }
                let mut buf = [0 as c_char; 256];
                let label = if name(buf.as_mut_ptr(), 255, dev) == 0 {
                    CStr::from_ptr(buf.as_ptr()).to_string_lossy().into_owned()
                } else {
                    "?".into()
                };
                let mut bytes: usize = 0;
                let total = if mem(&mut bytes, dev) == 0 {
                    bytes as u64
                } else {
                    0
                };
                report.gpus.push(GpuInfo {
                    ordinal,
                    name: label,
                    memory_bytes: total,
                });
            }
        }
        report
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn loader_messages_name_the_cause() {
        let c = |m: &str| classify_load_error(m);
        assert_eq!(
            c("libcudnn.so.9: cannot open shared object file: No such file or directory"),
            LoadFailure::CudnnMissing("libcudnn.so.9".into())
        );
        let cublas = c(
            "/x/libonnxruntime_providers_cuda.so: libcublasLt.so.13: cannot open shared object file: No such file or directory",
        );
        assert_eq!(
            cublas,
            LoadFailure::CudaRuntimeMissing("libcublasLt.so.13".into())
        );
        assert!(cublas.advice().contains("libcublasLt.so.13"));
        assert_eq!(
            c("libcudart.so.13: cannot open shared object file: No such file or directory"),
            LoadFailure::CudaRuntimeMissing("libcudart.so.13".into())
        );
        assert_eq!(
            c("libcuda.so.1: cannot open shared object file: No such file or directory"),
            LoadFailure::DriverMissing
        );
        assert_eq!(
            c(
                "libonnxruntime_providers_shared.so: cannot open shared object file: No such file or directory"
            ),
            LoadFailure::SharedProviderMissing
        );
        assert_eq!(c("/x/p.so: invalid ELF header"), LoadFailure::Damaged);
        assert_eq!(
            c("/x/p.so: version `libcudnn.so.9' not found (required by /x/p.so)"),
            LoadFailure::VersionMismatch
        );
        assert_eq!(c("something new"), LoadFailure::Other);
    }

    #[test]
    fn a_cpu_only_runtime_has_no_cuda_provider_and_a_fake_one_is_damaged() {
        let dir = tempfile::tempdir().expect("tempdir");
        let lib = dir.path().join("libonnxruntime.so.1.31.1");
        std::fs::write(&lib, b"").expect("write");
        assert_eq!(
            probe_provider(&lib, CUDA_PROVIDER_FILE),
            ProviderProbe::Absent {
                expected: dir.path().join(CUDA_PROVIDER_FILE)
            }
        );
        std::fs::write(dir.path().join(CUDA_PROVIDER_FILE), b"not a library").expect("write");
        match probe_provider(&lib, CUDA_PROVIDER_FILE) {
            ProviderProbe::Fails { failure, .. } => assert_eq!(failure, LoadFailure::Damaged),
            other => panic!("{other:?}"),
        }
    }

    #[test]
    fn a_provider_whose_dependency_is_missing_is_reported_by_name() {
        // A real shared object with an unmet dependency: copy the C library under the provider's
        // name is not enough (it loads), so use the loader on a name that cannot exist instead and
        // check the message classification path end to end.
        let msg = match dl::open("libcudnn_stylize_probe_test.so.9") {
            Ok(_) => panic!("a library that cannot exist loaded"),
            Err(m) => m,
        };
        assert_eq!(
            classify_load_error(&msg),
            LoadFailure::CudnnMissing("libcudnn_stylize_probe_test.so.9".into()),
            "{msg}"
        );
    }

    #[test]
    fn without_a_driver_the_report_says_so() {
        let r = probe_driver();
        // On machines with a driver this lists GPUs; on this project's CPU machines it must say why
        // there are none rather than return an empty list silently.
        assert!(
            r.error.is_some() || !r.gpus.is_empty() || r.cuda_version.is_some(),
            "{r:?}"
        );
    }
}

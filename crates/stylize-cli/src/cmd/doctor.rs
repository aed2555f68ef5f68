//! `stylize doctor`: what this machine and this build can do for the text path, found by loading
//! things (docs/models.md, "stylize doctor"): the binary's features; the ONNX Runtime library (path,
//! version, whether its CUDA / TensorRT provider libraries are there and load, and if not why); the
//! NVIDIA driver and its GPUs; the devices ONNX Runtime lists; the wgpu adapter; the model
//! directory; the memory estimate per device against what the device has; the expected time per
//! iteration from measured throughput; and the next step for each problem.

use std::path::PathBuf;

use serde::Serialize;

/// Arguments of `stylize doctor`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// A model directory to check (manifest.toml + .onnx files) and estimate memory and time for.
    #[arg(long)]
    pub model: Option<PathBuf>,
    /// Print the report as JSON (for scripts).
    #[arg(long)]
    pub json: bool,
    /// Configuration overrides, as for `run` (e.g. `--set guidance.stage2_device=cuda:1`): the
    /// devices and batch the estimates are made for.
    #[arg(long = "set", value_name = "SECTION.KEY=VALUE")]
    pub overrides: Vec<String>,
}

/// A problem and what to do about it.
#[derive(Clone, Debug, Serialize, PartialEq, Eq)]
pub struct Problem {
    /// What is wrong.
    pub problem: String,
    /// The exact next step.
    pub next_step: String,
}

/// One provider library's state.
#[derive(Clone, Debug, Serialize, Default)]
pub struct ProviderState {
    /// `absent`, `loads`, `fails`, or `unknown` (no ONNX Runtime found).
    pub state: String,
    /// The file looked at.
    pub path: Option<PathBuf>,
    /// The dynamic loader's message when it fails.
    pub loader_message: Option<String>,
    /// The cause and the fix when it fails.
    pub advice: Option<String>,
    /// The CUDA runtime major version it loaded (`libcudart.so.N`).
    pub cuda_runtime_major: Option<i32>,
}

/// The ONNX Runtime library.
#[derive(Clone, Debug, Serialize, Default)]
pub struct RuntimeState {
    /// Where it was found (`$ORT_DYLIB_PATH`, else `.deps/onnxruntime/`).
    pub path: Option<PathBuf>,
    /// Why it cannot be used, if so.
    pub error: Option<String>,
    /// Its version (from its build string).
    pub version: Option<String>,
    /// Its build string.
    pub build_info: Option<String>,
    /// The devices it lists (`provider: type, vendor`).
    pub devices: Vec<String>,
    /// `libonnxruntime_providers_cuda.so` beside it.
    pub cuda_provider: ProviderState,
    /// `libonnxruntime_providers_tensorrt.so` beside it.
    pub tensorrt_provider: ProviderState,
}

/// A GPU the NVIDIA driver lists.
#[derive(Clone, Debug, Serialize)]
pub struct Gpu {
    /// `cuda:N`'s N.
    pub ordinal: i32,
    /// Its name.
    pub name: String,
    /// Its memory, bytes.
    pub memory_bytes: u64,
}

/// The NVIDIA driver.
#[derive(Clone, Debug, Serialize, Default)]
pub struct DriverState {
    /// The CUDA version the driver supports, `major.minor`.
    pub cuda_version: Option<String>,
    /// Its GPUs.
    pub gpus: Vec<Gpu>,
    /// Why there are none, if so.
    pub error: Option<String>,
}

/// One device's memory estimate.
#[derive(Clone, Debug, Serialize)]
pub struct MemoryLine {
    /// `cpu`, `cuda:N`.
    pub device: String,
    /// Estimated peak, bytes.
    pub estimate_bytes: u64,
    /// What it has, bytes, when known.
    pub capacity_bytes: Option<u64>,
    /// The whole line.
    pub description: String,
    /// Whether the estimate exceeds the capacity.
    pub over: bool,
}

/// The expected time per iteration on one device kind.
#[derive(Clone, Debug, Serialize)]
pub struct TimeLine {
    /// The stages' devices.
    pub devices: String,
    /// UNet FLOPs per iteration (both stages, all views, cond + uncond, steps per batch).
    pub tflop_per_iteration: f64,
    /// Seconds per iteration from the measured throughput, when a figure exists.
    pub seconds_per_iteration: Option<f64>,
    /// The throughput used and its source, or why there is none.
    pub basis: String,
}

/// The whole report.
#[derive(Clone, Debug, Serialize, Default)]
pub struct Report {
    /// `stylize --version`'s version.
    pub version: String,
    /// Features this binary was built with (`text`, `gpu`, `view`, `cuda`).
    pub features: Vec<String>,
    /// ONNX Runtime (absent without the `text` feature).
    pub onnx_runtime: Option<RuntimeState>,
    /// The NVIDIA driver.
    pub driver: DriverState,
    /// The wgpu adapter (`name (backend, type)`), or why none.
    pub wgpu: String,
    /// The model directory: `ok: …` or the error.
    pub model: Option<String>,
    /// Memory per device.
    pub memory: Vec<MemoryLine>,
    /// Time per iteration.
    pub time: Vec<TimeLine>,
    /// Problems found, each with its next step.
    pub problems: Vec<Problem>,
}

/// Runs `stylize doctor`.
pub fn run(args: Args) -> anyhow::Result<()> {
    let config = stylize::config::Config::default().with_overrides(&args.overrides)?;
    let report = build(args.model.as_deref(), &config);
    if args.json {
        outln!("{}", serde_json::to_string_pretty(&report)?)?;
    } else {
        outp!("{}", render(&report))?;
    }
    Ok(())
}

/// Measured UNet throughput, FLOP/s, by device kind, with the source of each figure. Only what was
/// measured: no GPU figure exists until `scripts/gpu_check.sh` is run on one (docs/benchmarks.md).
pub const MEASURED_THROUGHPUT: &[(&str, f64, &str)] = &[(
    "cpu",
    stylize::models::CPU_FLOP_PER_SECOND,
    "2-core VM, ONNX Runtime CPU provider, one IF-II-L-size stage-II call at 256 px \
     (docs/models.md, \"What a CPU can do\")",
)];

/// The paper's measured time per iteration with the real models on one NVIDIA A40 (2 h 15 min for
/// 2,500 iterations; docs/models.md, "What a CPU can do").
pub const PAPER_A40_SECONDS_PER_ITERATION: f64 = 3.24;

/// Gathers the report.
pub fn build(model: Option<&std::path::Path>, config: &stylize::config::Config) -> Report {
    let mut r = Report {
        version: env!("CARGO_PKG_VERSION").to_string(),
        features: crate::features::ENABLED
            .iter()
            .filter(|(_, on)| *on)
            .map(|(n, _)| (*n).to_string())
            .chain(cfg!(feature = "cuda").then(|| "cuda".to_string()))
            .collect(),
        ..Report::default()
    };
    r.wgpu = wgpu_state();
    #[cfg(feature = "text")]
    text::fill(&mut r, model, config);
    #[cfg(not(feature = "text"))]
    {
        let _ = (model, config);
        r.problems.push(Problem {
            problem:
                "this stylize was built without the `text` feature: no ONNX Runtime, no prompts"
                    .into(),
            next_step:
                "build the full command line: cargo install --locked --path crates/stylize-cli"
                    .into(),
        });
    }
    r
}

#[cfg(feature = "gpu")]
fn wgpu_state() -> String {
    match raster_diff::gpu::WgpuRenderer::new(raster_diff::RenderSettings::default()) {
        Ok(g) => {
            let i = g.adapter_info();
            format!(
                "{} ({:?}, {:?}{})",
                i.name,
                i.backend,
                i.device_type,
                if g.is_software() {
                    "; a software renderer, the CPU renderer is as fast"
                } else {
                    ""
                }
            )
        }
        Err(e) => format!("no adapter: {e}"),
    }
}

#[cfg(not(feature = "gpu"))]
fn wgpu_state() -> String {
    "not built (the `gpu` feature): renders run on the CPU".into()
}

#[cfg(feature = "text")]
mod text {
    use super::*;
    use diffusion_onnx::probe::{self, ProviderProbe};
    use diffusion_onnx::{Device, ModelDir, Stage};

    fn provider(p: ProviderProbe) -> ProviderState {
        match p {
            ProviderProbe::Absent { expected } => ProviderState {
                state: "absent".into(),
                path: Some(expected),
                ..ProviderState::default()
            },
            ProviderProbe::Loads {
                path,
                cuda_runtime_major,
            } => ProviderState {
                state: "loads".into(),
                path: Some(path),
                cuda_runtime_major,
                ..ProviderState::default()
            },
            ProviderProbe::Fails {
                path,
                failure,
                message,
            } => ProviderState {
                state: "fails".into(),
                path: Some(path),
                loader_message: Some(message),
                advice: Some(failure.advice()),
                cuda_runtime_major: None,
            },
        }
    }

    /// The problems the ONNX Runtime and driver states imply, for a build with (`cuda_built`) or
    /// without the CUDA feature.
    pub fn runtime_problems(
        rt: &RuntimeState,
        driver: &DriverState,
        cuda_built: bool,
    ) -> Vec<Problem> {
        let mut out = Vec::new();
        if let Some(e) = &rt.error {
            out.push(Problem {
                problem: format!("no usable ONNX Runtime library: {e}"),
                next_step: "run scripts/setup-onnxruntime.sh (CPU), or for a GPU set ORT_DYLIB_PATH to \
                            onnxruntime/capi/libonnxruntime.so.1.31.1 of the onnxruntime-gpu 1.31.1 wheel"
                    .into(),
            });
            return out;
        }
        let lib = rt
            .path
            .as_ref()
            .map_or("?".into(), |p| p.display().to_string());
        let cuda = &rt.cuda_provider;
        match cuda.state.as_str() {
            "absent" if cuda_built => out.push(Problem {
                problem: format!(
                    "this stylize is built with CUDA support, but the ONNX Runtime library at {lib} is a \
                     CPU-only build: there is no {} beside it",
                    probe::CUDA_PROVIDER_FILE
                ),
                next_step: "install the onnxruntime-gpu 1.31.1 wheel (with its CUDA 13 / cuDNN 9 dependencies) \
                            and set ORT_DYLIB_PATH to its onnxruntime/capi/libonnxruntime.so.1.31.1"
                    .into(),
            }),
            "fails" => out.push(Problem {
                problem: format!(
                    "the CUDA provider {} does not load: {}",
                    cuda.path
                        .as_ref()
                        .map_or("?".into(), |p| p.display().to_string()),
                    cuda.loader_message.clone().unwrap_or_default()
                ),
                next_step: cuda.advice.clone().unwrap_or_default(),
            }),
            "loads" if !cuda_built => out.push(Problem {
                problem: format!(
                    "the ONNX Runtime at {lib} carries a working CUDA provider, but this stylize was built \
                     without the `cuda` feature"
                ),
                next_step: "rebuild with `cargo build --release -p stylize-cli --features cuda`".into(),
            }),
            _ => {}
        }
        if cuda.state == "loads" {
            match (&driver.cuda_version, cuda.cuda_runtime_major) {
                (None, _) => out.push(Problem {
                    problem: format!(
                        "the CUDA provider loads but the NVIDIA driver does not answer: {}",
                        driver.error.clone().unwrap_or_default()
                    ),
                    next_step: "install the NVIDIA driver (580 or newer for CUDA 13) or pass the GPU into the \
                                container"
                        .into(),
                }),
                (Some(v), Some(major)) => {
                    let driver_major: i32 = v
                        .split('.')
                        .next()
                        .and_then(|m| m.parse().ok())
                        .unwrap_or(0);
                    if driver_major < major {
                        out.push(Problem {
                            problem: format!(
                                "the NVIDIA driver supports CUDA {v}, older than the CUDA {major} runtime the \
                                 provider loaded: the driver is too old"
                            ),
                            next_step: format!(
                                "update the NVIDIA driver to one supporting CUDA {major} (580+ for 13)"
                            ),
                        });
                    }
                }
                _ => {}
            }
            if driver.cuda_version.is_some() && driver.gpus.is_empty() {
                out.push(Problem {
                    problem: format!(
                        "the driver lists no GPU: {}",
                        driver.error.clone().unwrap_or_default()
                    ),
                    next_step: "check CUDA_VISIBLE_DEVICES and `nvidia-smi -L`".into(),
                });
            }
        }
        out
    }

    pub fn fill(r: &mut Report, model: Option<&std::path::Path>, config: &stylize::config::Config) {
        let mut rt = RuntimeState::default();
        let env_value = std::env::var_os(diffusion_onnx::runtime::ORT_DYLIB_ENV);
        let found = match diffusion_onnx::runtime::resolve_dylib_path(
            env_value.as_deref(),
            &diffusion_onnx::runtime::default_dylib_path(),
        ) {
            Ok(p) => diffusion_onnx::runtime::check_library_file(&p)
                .map(|()| p)
                .map_err(|e| e.to_string()),
            Err(e) => Err(e.to_string()),
        };
        match found {
            Ok(path) => {
                match probe::runtime_version(&path) {
                    Ok((version, info)) => {
                        rt.build_info = Some(info);
                        rt.version = Some(version);
                        rt.devices = probe::runtime_devices().unwrap_or_default();
                    }
                    Err(e) => rt.error = Some(e.to_string()),
                }
                rt.cuda_provider =
                    provider(probe::probe_provider(&path, probe::CUDA_PROVIDER_FILE));
                rt.tensorrt_provider =
                    provider(probe::probe_provider(&path, probe::TENSORRT_PROVIDER_FILE));
                rt.path = Some(path);
            }
            Err(e) => {
                rt.error = Some(e);
                rt.cuda_provider.state = "unknown".into();
                rt.tensorrt_provider.state = "unknown".into();
            }
        }
        let d = probe::probe_driver();
        r.driver = DriverState {
            cuda_version: d.cuda_version.map(|(a, b)| format!("{a}.{b}")),
            gpus: d
                .gpus
                .iter()
                .map(|g| Gpu {
                    ordinal: g.ordinal,
                    name: g.name.clone(),
                    memory_bytes: g.memory_bytes,
                })
                .collect(),
            error: d.error.clone(),
        };
        r.problems
            .extend(runtime_problems(&rt, &r.driver, cfg!(feature = "cuda")));
        let runtime_ok = rt.error.is_none();
        r.onnx_runtime = Some(rt);
        let Some(model) = model else {
            return;
        };
        let dir = match ModelDir::open(model) {
            Ok(dir) => dir,
            Err(e) => {
                r.model = Some(format!("invalid: {e}"));
                r.problems.push(Problem {
                    problem: format!("the model directory {} is not usable: {e}", model.display()),
                    next_step: "export it with scripts/export_if_onnx.py (docs/models.md §2) and copy the whole \
                                directory, external data included"
                        .into(),
                });
                return;
            }
        };
        let stages: Vec<String> = [Stage::One, Stage::Two]
            .iter()
            .filter_map(|&s| {
                let spec = dir.stage(s)?;
                Some(format!(
                    "{} {} ≈ {:.2} B parameters",
                    s.key(),
                    spec.dtype.as_str(),
                    dir.approx_parameters(s).unwrap_or(0) as f64 / 1e9
                ))
            })
            .collect();
        r.model = Some(format!(
            "ok: {} ({}; text encoder {})",
            dir.manifest().name,
            stages.join(", "),
            if dir.manifest().text_encoder.is_some() {
                "present"
            } else {
                "absent: prompts must be cached"
            }
        ));
        let Ok([o1, o2, _]) = stylize::models::device_options(config) else {
            return;
        };
        if !runtime_ok {
            r.problems.push(Problem {
                problem: "the session graphs were not checked (no ONNX Runtime)".into(),
                next_step: "fix the ONNX Runtime problem above, then rerun stylize doctor".into(),
            });
        }
        let plan = stylize::models::memory_plan(&dir, &[o1.clone(), o2.clone()], config, &d.gpus);
        for m in &plan {
            r.memory.push(MemoryLine {
                device: m.device.to_string(),
                estimate_bytes: m.estimate,
                capacity_bytes: m.capacity.as_ref().map(|c| c.0),
                description: m.describe(),
                over: m.over(),
            });
            if m.over() {
                r.problems.push(Problem {
                    problem: format!("the models will not fit: {}", m.describe()),
                    next_step: "guidance.onnx_low_memory = true (one sample per call), separate devices per \
                                stage (guidance.stage1_device / stage2_device), or an fp16 export on a GPU"
                        .into(),
                });
            }
        }
        if matches!(o1.device, Device::Cuda { .. }) || matches!(o2.device, Device::Cuda { .. }) {
            if !cfg!(feature = "cuda") {
                r.problems.push(Problem {
                    problem: "the configuration puts a stage on CUDA but this stylize has no CUDA support".into(),
                    next_step: "rebuild with `cargo build --release -p stylize-cli --features cuda`".into(),
                });
            }
            for dev in [o1.device, o2.device] {
                if let Device::Cuda { device_id } = dev
                    && !d.gpus.iter().any(|g| g.ordinal == device_id)
                {
                    r.problems.push(Problem {
                        problem: format!("{dev} is configured but the driver lists no such GPU"),
                        next_step: format!(
                            "use one of the listed GPUs ({})",
                            if d.gpus.is_empty() {
                                "none: run on the CPU".to_string()
                            } else {
                                d.gpus
                                    .iter()
                                    .map(|g| format!("cuda:{}", g.ordinal))
                                    .collect::<Vec<_>>()
                                    .join(", ")
                            }
                        ),
                    });
                }
            }
        }
        let samples = 2.0 * config.camera.views as f64 * f64::from(config.optim.steps_per_batch);
        let [f1, f2] = stylize::models::FLOP_PER_PARAMETER_SAMPLE;
        let p1 = dir.approx_parameters(Stage::One).unwrap_or(0) as f64;
        let p2 = dir.approx_parameters(Stage::Two).unwrap_or(0) as f64;
        let flop = samples * (p1 * f1 + p2 * f2);
        let kinds = format!("{} / {}", o1.device, o2.device);
        let kind = if o1.device == Device::Cpu && o2.device == Device::Cpu {
            "cpu"
        } else {
            "cuda"
        };
        let measured = MEASURED_THROUGHPUT.iter().find(|(k, _, _)| *k == kind);
        r.time.push(TimeLine {
            devices: kinds,
            tflop_per_iteration: flop / 1e12,
            seconds_per_iteration: measured.map(|(_, f, _)| flop / f),
            basis: measured.map_or(
                format!(
                    "no throughput measured on a GPU here yet: run scripts/gpu_check.sh (its `throughput` step \
                     prints TFLOP/s) and see docs/benchmarks.md; the one GPU figure known is the paper's, \
                     {PAPER_A40_SECONDS_PER_ITERATION} s per iteration on an A40 with the real IF models \
                     (2 h 15 min for 2,500 iterations)"
                ),
                |(_, f, src)| format!("{:.2} TFLOP/s measured: {src}", f / 1e12),
            ),
        });
    }
}

#[cfg(feature = "text")]
pub use text::runtime_problems;

/// The report as text.
pub fn render(r: &Report) -> String {
    use std::fmt::Write;
    let mut s = String::new();
    let gib = |b: u64| format!("{:.2} GiB", b as f64 / 1_073_741_824.0);
    let _ = writeln!(
        s,
        "stylize {} (features: {})",
        r.version,
        r.features.join(", ")
    );
    match &r.onnx_runtime {
        None => {
            let _ = writeln!(s, "ONNX Runtime: not built in (no `text` feature)");
        }
        Some(rt) => {
            let _ = writeln!(
                s,
                "ONNX Runtime: {}",
                match (&rt.path, &rt.error) {
                    (_, Some(e)) => format!("NOT USABLE: {e}"),
                    (Some(p), None) => format!(
                        "{} (version {})",
                        p.display(),
                        rt.version.as_deref().unwrap_or("?")
                    ),
                    (None, None) => "?".into(),
                }
            );
            for (name, p) in [
                ("CUDA", &rt.cuda_provider),
                ("TensorRT", &rt.tensorrt_provider),
            ] {
                let line = match p.state.as_str() {
                    "absent" => "absent (a CPU-only ONNX Runtime)".to_string(),
                    "loads" => format!(
                        "loads{}",
                        p.cuda_runtime_major
                            .map_or(String::new(), |m| format!(" (CUDA runtime {m})"))
                    ),
                    "fails" => format!(
                        "does not load: {}",
                        p.loader_message.as_deref().unwrap_or("?")
                    ),
                    other => other.to_string(),
                };
                let _ = writeln!(s, "  {name} provider: {line}");
            }
            if !rt.devices.is_empty() {
                let _ = writeln!(s, "  devices ONNX Runtime lists: {}", rt.devices.join("; "));
            }
        }
    }
    let _ = writeln!(
        s,
        "NVIDIA driver: {}",
        match (&r.driver.cuda_version, &r.driver.error) {
            (Some(v), None) => format!("CUDA {v}"),
            (Some(v), Some(e)) => format!("CUDA {v}; {e}"),
            (None, Some(e)) => e.clone(),
            (None, None) => "?".into(),
        }
    );
    for g in &r.driver.gpus {
        let _ = writeln!(
            s,
            "  cuda:{}: {}, {}",
            g.ordinal,
            g.name,
            gib(g.memory_bytes)
        );
    }
    let _ = writeln!(s, "wgpu: {}", r.wgpu);
    if let Some(m) = &r.model {
        let _ = writeln!(s, "model: {m}");
    }
    for m in &r.memory {
        let _ = writeln!(
            s,
            "memory: {}{}",
            m.description,
            if m.over { "  <-- DOES NOT FIT" } else { "" }
        );
    }
    for t in &r.time {
        let _ = writeln!(
            s,
            "time per iteration on {}: {:.1} TFLOP{}; {}",
            t.devices,
            t.tflop_per_iteration,
            t.seconds_per_iteration
                .map_or(String::new(), |x| format!(" ≈ {}", human_seconds(x))),
            t.basis
        );
    }
    if r.problems.is_empty() {
        let _ = writeln!(s, "problems: none");
    } else {
        let _ = writeln!(s, "problems:");
        for p in &r.problems {
            let _ = writeln!(s, "  - {}\n    next step: {}", p.problem, p.next_step);
        }
    }
    s
}

fn human_seconds(x: f64) -> String {
    if x < 120.0 {
        format!("{x:.1} s")
    } else if x < 7200.0 {
        format!("{:.0} min", x / 60.0)
    } else {
        format!("{:.1} h", x / 3600.0)
    }
}

#[cfg(all(test, feature = "text"))]
mod tests {
    use super::*;

    fn rt(cuda: &str) -> RuntimeState {
        RuntimeState {
            path: Some("/x/libonnxruntime.so.1.31.1".into()),
            version: Some("1.31.1".into()),
            cuda_provider: ProviderState {
                state: cuda.into(),
                path: Some("/x/libonnxruntime_providers_cuda.so".into()),
                ..ProviderState::default()
            },
            ..RuntimeState::default()
        }
    }

    #[test]
    fn a_cuda_build_with_a_cpu_only_library_says_exactly_that() {
        let p = runtime_problems(&rt("absent"), &DriverState::default(), true);
        assert_eq!(p.len(), 1, "{p:?}");
        assert!(
            p[0].problem.contains("built with CUDA support")
                && p[0].problem.contains("CPU-only build")
                && p[0].problem.contains("/x/libonnxruntime.so.1.31.1")
                && p[0].next_step.contains("onnxruntime-gpu"),
            "{p:?}"
        );
        // Without the feature a CPU-only library is what the build expects: no problem.
        assert!(runtime_problems(&rt("absent"), &DriverState::default(), false).is_empty());
    }

    #[test]
    fn a_provider_that_loads_with_an_old_driver_or_a_cpu_build_says_so() {
        let mut r = rt("loads");
        r.cuda_provider.cuda_runtime_major = Some(13);
        let old = DriverState {
            cuda_version: Some("12.4".into()),
            gpus: vec![Gpu {
                ordinal: 0,
                name: "GPU".into(),
                memory_bytes: 1 << 34,
            }],
            error: None,
        };
        let p = runtime_problems(&r, &old, true);
        assert!(
            p.iter().any(|p| p.problem.contains("driver is too old")),
            "{p:?}"
        );
        let new = DriverState {
            cuda_version: Some("13.0".into()),
            ..old
        };
        assert!(runtime_problems(&r, &new, true).is_empty());
        let p = runtime_problems(&r, &new, false);
        assert!(p[0].next_step.contains("--features cuda"), "{p:?}");
    }
}

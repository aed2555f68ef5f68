//! Loading the text path's models: DeepFloyd IF stage I (and stage II when present) from an ONNX
//! model directory (`docs/models.md`), the prompt embeddings (cached), and the guidance.
//!
//! [`ModelSet`] opens the UNet sessions once; [`ModelSet::guidance_for`] builds a guidance for
//! one prompt that borrows those sessions (no lock: one run at a time holds them), so a batch loads
//! the models a single time; [`ModelSet::into_guidance`] hands them to a single run.
//!
//! The module exists in every build. Without the `text` feature (no ONNX Runtime) [`ModelSet`]
//! has the same methods but no value: [`ModelSet::open`] and [`load_guidance`] return
//! [`Error::NotBuilt`] naming the feature and how to build it, so a caller keeps one code path
//! for prompts and refuses them where the models would load. The helpers that take
//! `diffusion-onnx` types (`prompt_warnings`, `cpu_time_warning`, `session_options`) exist only
//! with `text`.

use std::path::Path;

use csd::{CascadedGuidance, GuidanceConfig};
#[cfg(feature = "text")]
use csd::{Denoiser, Embedding};
#[cfg(feature = "text")]
use diffusion_onnx::{Device, EmbeddingCache, ModelDir, OnnxDenoiser, SessionOptions, Stage};

use crate::config::Config;
#[cfg(not(feature = "text"))]
use crate::error::Error;
use crate::error::Result;
#[cfg(feature = "text")]
use crate::error::{Context, invalid};

/// The `csd` guidance settings from the configuration ([`GuidanceSection::guidance_config`]).
///
/// [`GuidanceSection::guidance_config`]: crate::config::GuidanceSection::guidance_config
pub fn guidance_config(config: &Config) -> GuidanceConfig {
    config.guidance.guidance_config()
}

/// UNets with at least this many parameters are real-size (IF-II-L: 1.2 B, IF-I-XL: 4.3 B; the test
/// fixtures: a few thousand).
pub const REAL_SIZE_PARAMETERS: u64 = 300_000_000;

/// FLOPs per parameter of one UNet sample, `[stage I at 64 px, stage II at 256 px]`: the random
/// IF-II-L-size UNet of `scripts/realsize_check.py` (1.24 B parameters) takes 12.18 TFLOP per sample
/// at 256 px and 0.77 TFLOP at 64 px (PyTorch's FLOP counter); stage I is taken at the 64 px ratio
/// (IF-I-XL's own count is not measured here).
pub const FLOP_PER_PARAMETER_SAMPLE: [f64; 2] = [620.0, 9_830.0];

/// What two cores deliver on these UNets: one IF-II-L-size call (cond + uncond at 256 px, 24.4 TFLOP)
/// took 2 min 45 s with ONNX Runtime on an otherwise idle 2-core machine (issue 15; docs/models.md,
/// "What a CPU can do").
pub const CPU_FLOP_PER_SECOND: f64 = 1.5e11;

/// Warnings about `prompt` and `config`'s negative prompt: one for each that is longer than the
/// model's text encoder reads (T5: 76 content tokens and `</s>`), naming how many tokens are
/// dropped from its end. Empty when both fit, or when the directory has no text encoder.
#[cfg(feature = "text")]
pub fn prompt_warnings(dir: &ModelDir, prompt: &str, config: &Config) -> Result<Vec<String>> {
    let Some(tokenizer) = diffusion_onnx::T5Tokenizer::of_model(dir)? else {
        return Ok(Vec::new());
    };
    let mut warnings = Vec::new();
    for (what, text) in [
        ("the prompt", prompt),
        (
            "the negative prompt",
            config.guidance.negative_prompt.as_str(),
        ),
    ] {
        let dropped = tokenizer.dropped_tokens(text)?;
        if dropped > 0 {
            warnings.push(format!(
                "{what} is longer than the text encoder reads ({} tokens with the end marker): its \
                 last {dropped} token(s) are dropped, as in IF's own pipeline — shorten it to keep them",
                tokenizer.max_tokens()
            ));
        }
    }
    Ok(warnings)
}

/// The warning `stylize run` prints before it starts when real-size UNets (by
/// [`ModelDir::approx_parameters`], i.e. the size of their files) would run on the CPU execution
/// provider: the estimated time per iteration and for the whole run, from
/// parameters × [`FLOP_PER_PARAMETER_SAMPLE`] / [`CPU_FLOP_PER_SECOND`] × views × 2 (conditional and
/// unconditional) × steps per batch.
/// None on a GPU or for small models.
#[cfg(feature = "text")]
pub fn cpu_time_warning(dir: &ModelDir, device: &Device, config: &Config) -> Option<String> {
    if *device != Device::Cpu {
        return None;
    }
    let p1 = dir.approx_parameters(Stage::One).unwrap_or(0);
    let p2 = dir.approx_parameters(Stage::Two).unwrap_or(0);
    if p1.max(p2) < REAL_SIZE_PARAMETERS {
        return None;
    }
    let samples = 2.0 * config.camera.views as f64 * f64::from(config.optim.steps_per_batch);
    let [f1, f2] = FLOP_PER_PARAMETER_SAMPLE;
    let per_iteration = samples * (p1 as f64 * f1 + p2 as f64 * f2) / CPU_FLOP_PER_SECOND;
    let hours = per_iteration * config.optim.iterations as f64 / 3600.0;
    Some(format!(
        "{} holds real-size UNets (stage I ≈ {:.2} B parameters, stage II ≈ {:.2} B) and runs on the CPU: \
         expect roughly {:.0} min per iteration ({} views, {} steps per batch; measured on a 2-core machine, \
         stage II counted at full weight although the schedule may use less), so {} iterations ≈ {:.0} h. \
         A GPU (CUDA execution provider) is the realistic way to run this; see docs/models.md, \"What a CPU can do\"",
        dir.root().display(),
        p1 as f64 / 1e9,
        p2 as f64 / 1e9,
        per_iteration / 60.0,
        config.camera.views,
        config.optim.steps_per_batch,
        config.optim.iterations,
        hours
    ))
}

/// The ONNX Runtime session settings of `config` on the CPU: [`SessionOptions::low_memory`] with
/// `guidance.onnx_low_memory`, else the defaults with `guidance.onnx_memory_arena`; IO binding from
/// `guidance.onnx_io_binding`, and the CUDA provider options of `guidance.cuda_*` (used when a
/// device is CUDA, [`device_options`]).
#[cfg(feature = "text")]
pub fn session_options(config: &Config) -> SessionOptions {
    let g = &config.guidance;
    let base = if g.onnx_low_memory {
        SessionOptions::low_memory()
    } else {
        SessionOptions {
            cpu_memory_arena: g.onnx_memory_arena,
            ..SessionOptions::default()
        }
    };
    SessionOptions {
        io_binding: g.onnx_io_binding,
        cuda: diffusion_onnx::CudaOptions {
            conv_algorithm_search: match g.cuda_conv_search.as_str() {
                "heuristic" => diffusion_onnx::ConvAlgorithmSearch::Heuristic,
                "default" => diffusion_onnx::ConvAlgorithmSearch::Default,
                _ => diffusion_onnx::ConvAlgorithmSearch::Exhaustive,
            },
            arena_growth: match g.cuda_arena_growth.as_str() {
                "same_as_requested" => diffusion_onnx::ArenaGrowth::SameAsRequested,
                _ => diffusion_onnx::ArenaGrowth::NextPowerOfTwo,
            },
            memory_limit: (g.cuda_memory_limit_gib > 0.0)
                .then_some((g.cuda_memory_limit_gib * GIB) as u64),
            tf32: g.cuda_tf32,
        },
        ..base
    }
}

#[cfg(feature = "text")]
const GIB: f64 = 1_073_741_824.0;

/// The session settings of `(stage I, stage II, text encoder)`: [`session_options`] on the devices
/// of `guidance.stage1_device`, `stage2_device` and `text_encoder_device` (validated here too).
#[cfg(feature = "text")]
pub fn device_options(config: &Config) -> Result<[SessionOptions; 3]> {
    let base = session_options(config);
    Ok(config.guidance.devices()?.map(|d| SessionOptions {
        device: match d {
            crate::config::Device::Cpu => Device::Cpu,
            crate::config::Device::Cuda(n) => Device::Cuda {
                device_id: n as i32,
            },
        },
        ..base.clone()
    }))
}

/// The memory estimate of one device before the first iteration.
#[cfg(feature = "text")]
#[derive(Clone, Debug)]
pub struct DeviceMemory {
    /// The device.
    pub device: Device,
    /// The stages on it with their estimates.
    pub stages: Vec<(Stage, diffusion_onnx::memory::StageMemory)>,
    /// Estimated peak: the stages' peaks summed (both stay loaded) plus the fixed overhead of the
    /// device ([`diffusion_onnx::memory::CPU_BASE_BYTES`] / `CUDA_BASE_BYTES`).
    pub estimate: u64,
    /// What the device has (bytes) and where that figure comes from, when known.
    pub capacity: Option<(u64, String)>,
}

#[cfg(feature = "text")]
impl DeviceMemory {
    /// Whether the estimate exceeds the known capacity.
    pub fn over(&self) -> bool {
        self.capacity
            .as_ref()
            .is_some_and(|(c, _)| self.estimate > *c)
    }

    /// One line: `cuda:0: estimate 21.30 GiB (stage1 …) of 79.19 GiB (NVIDIA H100 …)`.
    pub fn describe(&self) -> String {
        use diffusion_onnx::memory::gib;
        let parts: Vec<String> = self
            .stages
            .iter()
            .map(|(s, m)| {
                format!(
                    "{}: weights {} + activations {} for {} samples per call",
                    s.key(),
                    gib(m.weights),
                    gib(m.activations),
                    m.samples_per_call
                )
            })
            .collect();
        format!(
            "{}: estimated peak {} ({}) of {}",
            self.device,
            gib(self.estimate),
            parts.join("; "),
            self.capacity
                .as_ref()
                .map_or("unknown capacity".to_string(), |(c, src)| format!(
                    "{} ({src})",
                    gib(*c)
                ))
        )
    }
}

/// The memory estimate per device for the UNets of `dir` with `options` = `[stage I, stage II]`,
/// at `config`'s batch (2 × views samples; stage I at 64², stage II at 256²). Capacities: the
/// host's `MemTotal` for the CPU; for CUDA `guidance.cuda_memory_limit_gib` when set, else the
/// device's total memory from the NVIDIA driver (`diffusion_onnx::probe::probe_driver`).
#[cfg(feature = "text")]
pub fn memory_plan(
    dir: &ModelDir,
    options: &[SessionOptions; 2],
    config: &Config,
    gpus: &[diffusion_onnx::probe::GpuInfo],
) -> Vec<DeviceMemory> {
    use diffusion_onnx::memory::{
        CPU_BASE_BYTES, CUDA_BASE_BYTES, estimate_stage, host_memory_bytes,
    };
    let batch = 2 * config.camera.views;
    let g = csd::GuidanceConfig::default();
    let mut plan: Vec<DeviceMemory> = Vec::new();
    for (stage, opts, side) in [
        (Stage::One, &options[0], g.stage1_resolution),
        (Stage::Two, &options[1], g.stage2_resolution),
    ] {
        let Some(m) = estimate_stage(dir, stage, opts, batch, side * side) else {
            continue;
        };
        if let Some(d) = plan.iter_mut().find(|d| d.device == opts.device) {
            d.stages.push((stage, m));
            d.estimate += m.total();
            continue;
        }
        let (base, capacity) = match opts.device {
            Device::Cpu => (
                CPU_BASE_BYTES,
                host_memory_bytes().map(|b| (b, "MemTotal of this machine".to_string())),
            ),
            Device::Cuda { device_id } => (
                CUDA_BASE_BYTES,
                if let Some(limit) = opts.cuda.memory_limit {
                    Some((limit, "guidance.cuda_memory_limit_gib".to_string()))
                } else {
                    gpus.iter()
                        .find(|g| g.ordinal == device_id)
                        .map(|g| (g.memory_bytes, g.name.clone()))
                },
            ),
        };
        plan.push(DeviceMemory {
            device: opts.device,
            stages: vec![(stage, m)],
            estimate: base + m.total(),
            capacity,
        });
    }
    plan
}

/// Refuses a plan in which a CUDA device's estimate exceeds its known memory (the run would fail
/// with an out-of-memory error after loading), naming the ways out; returns warnings for the CPU
/// (swap and the kernel's reclaim of file-backed weight pages make an over-estimate survivable
/// there, only slow).
#[cfg(feature = "text")]
pub fn check_memory(plan: &[DeviceMemory]) -> Result<Vec<String>> {
    let mut warnings = Vec::new();
    for d in plan.iter().filter(|d| d.over()) {
        let advice = "lower the samples per call (guidance.onnx_low_memory = true runs one at a time), \
                      put the stages on separate devices (guidance.stage1_device / stage2_device), use an fp16 \
                      export on a GPU, or fewer camera.views (changes the task)";
        if matches!(d.device, Device::Cuda { .. }) {
            invalid!(
                "the models will not fit: {} (docs/models.md, \"Memory per device\"). To fit: {advice}",
                d.describe()
            );
        }
        warnings.push(format!(
            "the models may not fit in memory: {} — expect swapping; to fit: {advice}",
            d.describe()
        ));
    }
    Ok(warnings)
}

/// Opened model sessions, reusable across prompts.
#[cfg(feature = "text")]
pub struct ModelSet {
    dir: ModelDir,
    options: SessionOptions,
    text_options: SessionOptions,
    memory_warnings: Vec<String>,
    cache: Option<EmbeddingCache>,
    stage1: OnnxDenoiser,
    stage2: Option<OnnxDenoiser>,
}

#[cfg(feature = "text")]
impl std::fmt::Debug for ModelSet {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("ModelSet")
            .field("dir", &self.dir.root())
            .field("stage2", &self.stage2.is_some())
            .finish_non_exhaustive()
    }
}

#[cfg(feature = "text")]
impl ModelSet {
    /// [`cpu_time_warning`] for these models and session settings (the command line prints it
    /// before a run starts).
    pub fn cpu_time_warning(&self, config: &Config) -> Option<String> {
        cpu_time_warning(&self.dir, &self.options.device, config)
    }

    /// Warnings of the memory estimate made when the set was opened ([`check_memory`]: a CPU
    /// estimate over the machine's memory).
    pub fn memory_warnings(&self) -> &[String] {
        &self.memory_warnings
    }

    /// [`prompt_warnings`] for this set's model directory.
    pub fn prompt_warnings(&self, prompt: &str, config: &Config) -> Result<Vec<String>> {
        prompt_warnings(&self.dir, prompt, config)
    }

    /// Opens the model directory and its UNets (stage II only when the manifest lists it), with
    /// the session settings of `config` (`guidance.onnx_memory_arena`).
    pub fn open(model: &Path, config: &Config) -> Result<Self> {
        let dir = ModelDir::open(model)
            .with_context(|| format!("cannot open model directory {}", model.display()))?;
        let [options, options2, text_options] = device_options(config)?;
        let gpus = if [&options, &options2]
            .iter()
            .any(|o| matches!(o.device, Device::Cuda { .. }))
        {
            diffusion_onnx::probe::probe_driver().gpus
        } else {
            Vec::new()
        };
        let plan = memory_plan(&dir, &[options.clone(), options2.clone()], config, &gpus);
        let memory_warnings = check_memory(&plan)?;
        let cache = EmbeddingCache::at_default().ok();
        let stage1 = OnnxDenoiser::open(&dir, Stage::One, &options).context("IF stage I")?;
        let stage2 = match dir.stage(Stage::Two) {
            Some(_) => {
                Some(OnnxDenoiser::open(&dir, Stage::Two, &options2).context("IF stage II")?)
            }
            None => None,
        };
        Ok(Self {
            dir,
            options,
            text_options,
            memory_warnings,
            cache,
            stage1,
            stage2,
        })
    }

    /// The prompt embeddings for `prompt` (negative prompt from `config`), after checking that the
    /// stage-II weight schedule only uses stage II when the model directory has it.
    fn embeddings_for(&self, prompt: &str, config: &Config) -> Result<(Embedding, Embedding)> {
        let stage2_used = config.stage2_schedule()?.phases().iter().any(|p| match *p {
            optim::Phase::Constant { value, .. } => value != 0.0,
            optim::Phase::Ramp { from, to, .. } => from != 0.0 || to != 0.0,
        });
        if self.stage2.is_none() && stage2_used {
            invalid!(
                "the model directory {} has no stage-II UNet but guidance.stage2_weight = {:?} uses it; \
                 export stage II (docs/models.md) or run stage I only with --set guidance.stage2_weight=0",
                self.dir.root().display(),
                config.guidance.stage2_weight
            );
        }
        diffusion_onnx::prompt_embeddings(
            &self.dir,
            prompt,
            &config.guidance.negative_prompt,
            self.cache.as_ref(),
            &self.text_options,
        )
        .context("prompt embeddings")
    }

    /// A guidance for `prompt` (negative prompt, settings and stage-II weight schedule from
    /// `config`) that borrows this set's UNets until it is dropped. Without a stage-II model the
    /// stage-II weight schedule must stay at 0.
    pub fn guidance_for(&mut self, prompt: &str, config: &Config) -> Result<CascadedGuidance<'_>> {
        let embeddings = self.embeddings_for(prompt, config)?;
        let stage2 = self
            .stage2
            .as_mut()
            .map(|s| Box::new(s) as Box<dyn Denoiser + '_>);
        cascaded(Box::new(&mut self.stage1), stage2, embeddings, config)
    }

    /// Like [`Self::guidance_for`], handing the UNets over to the guidance.
    pub fn into_guidance(self, prompt: &str, config: &Config) -> Result<CascadedGuidance<'static>> {
        let embeddings = self.embeddings_for(prompt, config)?;
        let stage2 = self.stage2.map(|s| Box::new(s) as Box<dyn Denoiser>);
        cascaded(Box::new(self.stage1), stage2, embeddings, config)
    }
}

/// The cascaded guidance over these UNets with the (conditional, unconditional) embeddings and the
/// guidance settings and stage-II weight schedule of `config`.
#[cfg(feature = "text")]
fn cascaded<'m>(
    stage1: Box<dyn Denoiser + 'm>,
    stage2: Option<Box<dyn Denoiser + 'm>>,
    (cond, uncond): (Embedding, Embedding),
    config: &Config,
) -> Result<CascadedGuidance<'m>> {
    Ok(
        CascadedGuidance::new(stage1, stage2, cond, uncond, guidance_config(config))
            .context("guidance")?
            .with_stage2_weight(config.stage2_schedule()?),
    )
}

/// Stands in for the model set in a build without the `text` feature: no value exists (an empty
/// enum), [`ModelSet::open`] fails with [`Error::NotBuilt`], and the other methods are those of
/// the `text` build.
#[cfg(not(feature = "text"))]
#[derive(Debug)]
pub enum ModelSet {}

#[cfg(not(feature = "text"))]
impl ModelSet {
    /// Always fails with [`Error::NotBuilt`]: this build has no ONNX Runtime.
    pub fn open(model: &Path, config: &Config) -> Result<Self> {
        let _ = (model, config);
        Err(Error::NotBuilt {
            feature: "text",
            what: "loading the models of a text prompt".into(),
        })
    }

    /// Unreachable (no value exists).
    pub fn cpu_time_warning(&self, _config: &Config) -> Option<String> {
        match *self {}
    }

    /// Unreachable (no value exists).
    pub fn prompt_warnings(&self, _prompt: &str, _config: &Config) -> Result<Vec<String>> {
        match *self {}
    }

    /// Unreachable (no value exists).
    pub fn memory_warnings(&self) -> &[String] {
        match *self {}
    }

    /// Unreachable (no value exists).
    pub fn guidance_for(
        &mut self,
        _prompt: &str,
        _config: &Config,
    ) -> Result<CascadedGuidance<'_>> {
        match *self {}
    }

    /// Unreachable (no value exists).
    pub fn into_guidance(
        self,
        _prompt: &str,
        _config: &Config,
    ) -> Result<CascadedGuidance<'static>> {
        match self {}
    }
}

/// Opens the models and builds the guidance for one prompt.
pub fn load_guidance(
    model: &Path,
    prompt: &str,
    config: &Config,
) -> Result<CascadedGuidance<'static>> {
    ModelSet::open(model, config)?.into_guidance(prompt, config)
}

#[cfg(all(test, not(feature = "text")))]
mod no_text_tests {
    use super::*;

    #[test]
    fn loading_names_the_missing_feature() {
        let e = load_guidance(Path::new("models/if"), "a chair", &Config::default())
            .expect_err("no models without `text`");
        let text = e.to_string();
        assert!(
            matches!(
                e,
                Error::NotBuilt {
                    feature: "text",
                    ..
                }
            ),
            "{text}"
        );
        assert!(
            text.contains("needs the `text` feature") && text.contains("--features"),
            "{text}"
        );
    }
}

#[cfg(all(test, feature = "text"))]
mod tests {
    use super::*;

    #[test]
    fn prompts_longer_than_the_text_encoder_reads_are_warned_about() {
        let fixture = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../fixtures/models/tiny-if");
        let dir = ModelDir::open(&fixture).expect("fixture model");
        let mut config = Config::default();
        let short = prompt_warnings(&dir, "a 3d render of a lego chair", &config);
        assert!(short.is_ok_and(|w| w.is_empty()));
        let long = "an intricately carved gothic wooden chair ".repeat(20);
        config.guidance.negative_prompt = long.clone();
        let w = prompt_warnings(&dir, &long, &config).unwrap_or_default();
        assert_eq!(w.len(), 2, "{w:?}");
        assert!(
            w[0].starts_with("the prompt") && w[0].contains("dropped"),
            "{w:?}"
        );
        assert!(w[1].starts_with("the negative prompt"), "{w:?}");
    }

    #[test]
    fn a_gpu_too_small_for_both_real_size_stages_is_refused_before_loading() {
        // IF's fp16 sizes: stage I 8.6 GB, stage II 2.5 GB (sparse files).
        let tmp = fake_model(8_600_000_000, Some(2_500_000_000));
        let dir = ModelDir::open(tmp.path()).expect("model");
        let gpu = |ordinal, gib: u64| diffusion_onnx::probe::GpuInfo {
            ordinal,
            name: format!("GPU {ordinal} with {gib} GiB"),
            memory_bytes: gib << 30,
        };
        let plan_for = |overrides: &[&str], gpus: &[diffusion_onnx::probe::GpuInfo]| {
            let config = Config::default()
                .with_overrides(overrides)
                .expect("overrides");
            let [o1, o2, _] = device_options(&config).expect("devices");
            memory_plan(&dir, &[o1, o2], &config, gpus)
        };
        let both = [
            "guidance.stage1_device=cuda:0",
            "guidance.stage2_device=cuda:0",
        ];
        let small = [gpu(0, 24), gpu(1, 24)];
        let plan = plan_for(&both, &small);
        assert_eq!(plan.len(), 1, "{plan:?}");
        let e = check_memory(&plan).expect_err("24 GiB cannot hold both stages at 8 views");
        let msg = e.to_string();
        assert!(
            msg.contains("cuda:0")
                && msg.contains("GPU 0 with 24 GiB")
                && msg.contains("stage1")
                && msg.contains("stage2")
                && msg.contains("onnx_low_memory"),
            "{msg}"
        );
        // The ways out the message names: an 80 GiB card, two cards, one sample per call.
        assert!(check_memory(&plan_for(&both, &[gpu(0, 80)])).is_ok_and(|w| w.is_empty()));
        let split = plan_for(
            &[
                "guidance.stage1_device=cuda:0",
                "guidance.stage2_device=cuda:1",
            ],
            &small,
        );
        assert_eq!(split.len(), 2);
        assert!(check_memory(&split).is_ok());
        let low: Vec<&str> = both
            .iter()
            .copied()
            .chain(["guidance.onnx_low_memory=true"])
            .collect();
        assert!(check_memory(&plan_for(&low, &small)).is_ok());
        // A cap set in the configuration is what the check uses.
        let capped: Vec<&str> = both
            .iter()
            .copied()
            .chain(["guidance.cuda_memory_limit_gib=10"])
            .collect();
        let capped = plan_for(&capped, &[gpu(0, 80)]);
        let msg = check_memory(&capped).expect_err("over the cap").to_string();
        assert!(msg.contains("guidance.cuda_memory_limit_gib"), "{msg}");
    }

    /// A model directory whose stage files have the given sizes (sparse files: nothing is written).
    fn fake_model(stage1_bytes: u64, stage2_bytes: Option<u64>) -> tempfile::TempDir {
        let dir = tempfile::tempdir().expect("tempdir");
        let fixture =
            Path::new(env!("CARGO_MANIFEST_DIR")).join("../../fixtures/models/tiny-if-fp16");
        for entry in std::fs::read_dir(&fixture).expect("fixture") {
            let entry = entry.expect("entry");
            std::fs::copy(entry.path(), dir.path().join(entry.file_name())).expect("copy");
        }
        let grow = |name: &str, len: u64| {
            let f = std::fs::OpenOptions::new()
                .write(true)
                .open(dir.path().join(name))
                .expect("open data");
            f.set_len(len).expect("set_len");
        };
        grow("unet_stage1.onnx.data", stage1_bytes);
        match stage2_bytes {
            Some(b) => grow("unet_stage2.onnx.data", b),
            None => {
                let m = dir.path().join("manifest.toml");
                let text = std::fs::read_to_string(&m).expect("manifest");
                let cut = text.find("[stage2]").expect("stage2 section");
                std::fs::write(&m, &text[..cut]).expect("write manifest");
            }
        }
        dir
    }

    #[test]
    fn real_size_models_on_the_cpu_get_a_time_warning() {
        // fp16: 8.6 GB ≈ IF-I-XL's 4.3 B parameters, 2.4 GB ≈ IF-II-L's 1.2 B.
        let d = fake_model(8_600_000_000, Some(2_400_000_000));
        let dir = ModelDir::open(d.path()).expect("open");
        assert_eq!(
            dir.approx_parameters(Stage::Two).map(|p| p / 100_000_000),
            Some(12)
        );
        let config = Config::default();
        let w = cpu_time_warning(&dir, &Device::Cpu, &config).expect("a warning");
        assert!(
            w.contains("stage I ≈ 4.30 B") && w.contains("stage II ≈ 1.20 B"),
            "{w}"
        );
        let samples = 2.0 * config.camera.views as f64 * f64::from(config.optim.steps_per_batch);
        let [f1, f2] = FLOP_PER_PARAMETER_SAMPLE;
        let minutes = samples * (4.3e9 * f1 + 1.2e9 * f2) / CPU_FLOP_PER_SECOND / 60.0;
        assert!(
            w.contains(&format!("roughly {minutes:.0} min per iteration")),
            "{w}"
        );
        assert!(w.contains("GPU"), "{w}");
        // Stage I alone is real-size too.
        let d = fake_model(8_600_000_000, None);
        let dir = ModelDir::open(d.path()).expect("open");
        assert!(cpu_time_warning(&dir, &Device::Cpu, &config).is_some());
    }

    #[test]
    fn low_memory_setting_selects_the_low_memory_sessions() {
        let mut config = Config::default();
        assert_eq!(session_options(&config), SessionOptions::default());
        config.guidance.onnx_memory_arena = false;
        assert!(!session_options(&config).cpu_memory_arena);
        assert_eq!(session_options(&config).max_batch, None);
        config.guidance.onnx_low_memory = true;
        assert_eq!(session_options(&config), SessionOptions::low_memory());
        let parsed = Config::from_toml_str("[guidance]\nonnx_low_memory = true\n").expect("parses");
        assert!(parsed.guidance.onnx_low_memory);
    }

    #[test]
    fn tiny_models_or_a_gpu_get_no_warning() {
        let config = Config::default();
        let tiny = ModelDir::open(
            Path::new(env!("CARGO_MANIFEST_DIR")).join("../../fixtures/models/tiny-if-fp16"),
        )
        .expect("open");
        assert_eq!(cpu_time_warning(&tiny, &Device::Cpu, &config), None);
        let d = fake_model(8_600_000_000, Some(2_400_000_000));
        let dir = ModelDir::open(d.path()).expect("open");
        assert_eq!(
            cpu_time_warning(&dir, &Device::Cuda { device_id: 0 }, &config),
            None
        );
    }
}

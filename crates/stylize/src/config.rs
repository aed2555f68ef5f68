//! The run configuration: a TOML file whose sections mirror the crates, every default the
//! reference's (spec §5–§7), plus typed `section.key=value` overrides. Reading files (TOML or the reference's JSON) is the
//! command line's job (`stylize_cli::config::load`).
//!
//! ```toml
//! [darap]    lambda = 8.0, rotation_rule = "gis", post_process = "recenter_rescale"
//! [optim]    lr = 0.002, iterations = 2500, steps_per_batch = 2, beta1, beta2, eps
//! [camera]   views = 8, preset = "default", elevation_deg, azimuth_deg, distance, fov_deg = 90,
//!            adapt_distance
//! [render]   width = 512, height = 512, backend = "auto"
//! [guidance] scale = 100, t_min = 20, t_max = 980, loss_scale = 100, stage1_weight = 1,
//!            stage2_weight = "0.0>0.2:1000; 0.2>0.3:750", negative_prompt = "", grad_clip = 0 (off),
//!            onnx_memory_arena = true, onnx_low_memory = false, onnx_io_binding = true,
//!            stage1_device = "cpu", stage2_device = "cpu", text_encoder_device = "cpu",
//!            cuda_conv_search = "exhaustive", cuda_arena_growth = "next_power_of_two",
//!            cuda_memory_limit_gib = 0 (none), cuda_tf32 = true
//! [style]    iterations, lr, objective   (the model-free path, see `crate::style`)
//! [run]      seed, checkpoint_every, preview_every, turntable_views, turntable_size,
//!            turntable_gif_frames, snapshot_every, output_frame = "input"
//! [region]   specs, feather, tint
//! [mesh]     remesh = "auto" | "on" | "off" | edge length (`0.03`, `"1.5%"`), up = "+y"
//! ```
//! `docs/cli.md` lists every key with its meaning.

use crate::error::{Context, Error, Result};

/// `return Err(Error::config(field, format!(…)))`.
macro_rules! bad_field {
    ($field:expr, $($arg:tt)*) => {
        return Err(Error::config($field, format!($($arg)*)))
    };
}
use serde::{Deserialize, Serialize};

/// The dARAP enums are darap's own (names `gis` / `procrustes`, `recenter_rescale` /
/// `recenter_only` / `none`, through darap's `serde` feature): one definition, one name table.
pub use darap::{PostProcess, RotationRule};

/// `render.backend` is raster-diff's own [`raster_diff::Backend`] (`auto` | `cpu` | `gpu`, through
/// raster-diff's `serde` feature; [`raster_diff::select_renderer`] turns it into a renderer).
pub use raster_diff::Backend;

/// The model-free objective's variant (see `crate::style`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum StyleObjective {
    /// ℓ = Σ_f A_f (1 − n_f · t_f), t_f the style target of face f's rest normal.
    Face,
}

/// `[darap]` is darap's own [`darap::DarapOptions`] (keys `lambda` = 8, `rotation_rule` = `gis`,
/// `post_process` = `recenter_rescale`; defaults and names live in darap only).
pub type DarapSection = darap::DarapOptions;

/// `[optim]` (the text path).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct OptimSection {
    /// Adam learning rate: 0.002.
    pub lr: f64,
    /// Outer iterations (render batches): 2500.
    pub iterations: u64,
    /// Adam steps per render batch with accumulated gradients (spec §5): 2.
    pub steps_per_batch: u32,
    /// Adam β1: 0.9.
    pub beta1: f64,
    /// Adam β2: 0.999.
    pub beta2: f64,
    /// Adam ε: 1e-8.
    pub eps: f64,
}

impl Default for OptimSection {
    fn default() -> Self {
        Self {
            lr: 0.002,
            iterations: 2500,
            steps_per_batch: 2,
            beta1: 0.9,
            beta2: 0.999,
            eps: 1e-8,
        }
    }
}

/// `[camera]`: the per-iteration view sampler (spec §6). Its keys `elevation_deg`
/// ([0, 60]), `azimuth_deg` ([0, 361]), `distance` ([2.5, 3.0], before the adaptive multiplier)
/// and `fov_deg` (90: focal length 1, the reference's effective value) are
/// [`raster_diff::CameraConfig`]'s own, through its `serde` feature (defaults live there only);
/// `views` and `adapt_distance` are the loop's.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct CameraSection {
    /// Views per iteration: 8.
    pub views: usize,
    /// Scale the distance by the deformed mesh's extent from iteration 2 on (spec §5): true.
    pub adapt_distance: bool,
    /// The view ranges by name ([`CameraPreset`]): `default` (the keys below as given: the
    /// paper's unless set), `tall` (the paper's preset for tall, slender shapes) or `auto`
    /// (`tall` for tall, slim meshes by [`CameraPreset::TALL_ASPECT`], else `default`).
    pub preset: CameraPreset,
    /// The ranges of the per-view draws and the field of view (flattened: the file's `[camera]`
    /// keys `elevation_deg`, `azimuth_deg`, `distance`, `fov_deg`).
    #[serde(flatten)]
    pub sampler: raster_diff::CameraConfig,
}

impl Default for CameraSection {
    fn default() -> Self {
        Self {
            views: 8,
            adapt_distance: true,
            preset: CameraPreset::Default,
            sampler: raster_diff::CameraConfig::default(),
        }
    }
}

/// `camera.preset`: the view sampler's ranges by name (`--camera`).
///
/// The paper's numbers (its supplementary, and `raster_diff::CameraConfig`): `default` draws
/// each view's elevation uniformly in [0°, 60°] above the xz-plane, azimuth in [0°, 361°] and
/// distance in [2.5, 3.0] (times the adaptive multiplier), field of view 90° (focal length 1);
/// `tall`, which the paper uses for humans and other tall, slender shapes, draws elevation in
/// [0°, 30°] and distance in [1.4, 2.6] (azimuth and field of view unchanged), so the camera comes
/// closer and stays lower.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum CameraPreset {
    /// The `[camera]` ranges as configured (the paper's default unless set).
    #[default]
    Default,
    /// The paper's preset for tall, slender shapes: elevation [0°, 30°], distance [1.4, 2.6].
    Tall,
    /// `tall` when the prepared mesh (after `mesh.up`) is tall and slim: its height (y extent) is
    /// at least [`CameraPreset::TALL_ASPECT`] times its larger horizontal extent (x or z); else
    /// `default`. Resolved when the run starts; the run records the resolved preset.
    Auto,
}

impl CameraPreset {
    /// `auto` picks `tall` when height ≥ this × max(x extent, z extent): 1.5 (a standing person
    /// is about 3–4, a seated figure or a chair about 1–1.5, a four-legged animal below 1).
    pub const TALL_ASPECT: f64 = 1.5;

    /// `default`, `tall` or `auto`.
    pub fn name(self) -> &'static str {
        match self {
            Self::Default => "default",
            Self::Tall => "tall",
            Self::Auto => "auto",
        }
    }

    /// What `auto` picks for a mesh of bounding-box extents `size` (x, y, z; y up), with the
    /// reason in words.
    pub fn auto_choice(size: [f64; 3]) -> (Self, String) {
        let horizontal = size[0].max(size[2]);
        let aspect = if horizontal > 0.0 {
            size[1] / horizontal
        } else {
            f64::INFINITY
        };
        let pick = if aspect >= Self::TALL_ASPECT {
            Self::Tall
        } else {
            Self::Default
        };
        (
            pick,
            format!(
                "camera: auto → {} (height / widest horizontal extent = {aspect:.2}; tall from {})",
                pick.name(),
                Self::TALL_ASPECT
            ),
        )
    }
}

impl std::fmt::Display for CameraPreset {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

impl std::str::FromStr for CameraPreset {
    type Err = Error;
    fn from_str(s: &str) -> Result<Self> {
        match s.trim().to_ascii_lowercase().as_str() {
            "default" => Ok(Self::Default),
            "tall" => Ok(Self::Tall),
            "auto" => Ok(Self::Auto),
            other => Err(Error::Invalid(format!(
                "unknown camera preset {other:?} (known: default, tall, auto)"
            ))),
        }
    }
}

impl Config {
    /// The configuration a run on a prepared mesh (positions after `mesh.up` and normalization)
    /// uses: `camera.preset = auto` resolved to `tall` or `default` ([`CameraPreset::auto_choice`])
    /// and a `tall` preset's ranges written into `[camera]` (`elevation_deg`, `distance`), so
    /// that `config.toml` and the task identity hold what the views are drawn from. Returns the
    /// line that says what `auto` chose (None for other presets).
    pub fn with_camera_resolved(mut self, positions: &[[f64; 3]]) -> (Self, Option<String>) {
        let mut note = None;
        if self.camera.preset == CameraPreset::Auto {
            let (lo, hi) = mesh_core::geometry::bbox(positions);
            let size: [f64; 3] = std::array::from_fn(|k| (hi[k] - lo[k]).max(0.0));
            let (pick, why) = CameraPreset::auto_choice(size);
            self.camera.preset = pick;
            note = Some(why);
        }
        if self.camera.preset == CameraPreset::Tall {
            let tall = raster_diff::CameraConfig::tall();
            self.camera.sampler.elevation_deg = tall.elevation_deg;
            self.camera.sampler.distance = tall.distance;
        }
        (self, note)
    }
}

/// `[render]`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct RenderSection {
    /// Render width in pixels: 512.
    pub width: usize,
    /// Render height in pixels: 512.
    pub height: usize,
    /// `auto`, `cpu` or `gpu` ([`Backend`]).
    pub backend: Backend,
}

impl Default for RenderSection {
    fn default() -> Self {
        Self {
            width: 512,
            height: 512,
            backend: Backend::Auto,
        }
    }
}

/// `[guidance]` (spec §7): the file-format layer over [`csd::GuidanceConfig`], whose defaults
/// these are (taken from it, not retyped). A separate struct because the file deliberately names
/// things differently: `scale` (csd's `guidance_scale`: the section already says "guidance"),
/// `t_min`/`t_max` (csd's nested `timesteps`), `grad_clip = 0` for "off" (csd's `None`: TOML has
/// no null), and the section also carries what csd does not own (the stage-II schedule text, the
/// negative prompt, ONNX Runtime's arena). [`GuidanceSection::guidance_config`] maps it back.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct GuidanceSection {
    /// CFG scale g in ε̂ = ε_c + g(ε_c − ε_u): 100.
    pub scale: f64,
    /// Smallest diffusion timestep drawn: 20.
    pub t_min: i64,
    /// Largest diffusion timestep drawn: 980.
    pub t_max: i64,
    /// Overall loss scale: 100.
    pub loss_scale: f64,
    /// Stage-I weight: 1.
    pub stage1_weight: f64,
    /// Stage-II weight schedule (spec §5 grammar, 1-indexed iterations):
    /// [`csd::REFERENCE_STAGE2_WEIGHT`].
    pub stage2_weight: String,
    /// Negative prompt ("" = unconditional).
    pub negative_prompt: String,
    /// Clamp of each stage's gradient to ±c; 0 turns it off (reference default).
    pub grad_clip: f64,
    /// ONNX Runtime's CPU memory arena: true (its default, faster); false lowers peak memory
    /// (3.5 → 1.4 GB with the tiny fixtures, guidance 15–25 % slower). Process-wide: a batch opens
    /// its models once, so rows cannot override it.
    pub onnx_memory_arena: bool,
    /// ONNX Runtime's low-memory session settings (`diffusion_onnx::SessionOptions::low_memory`:
    /// arena, memory pattern, pre-packing and graph optimizations off, one sample per UNet call):
    /// false. For real-size models near the machine's memory (docs/models.md §5); slower, and the
    /// results may differ from the default settings' in the last bits (other kernels). Process-wide
    /// like `onnx_memory_arena`.
    pub onnx_low_memory: bool,
    /// UNet calls through ONNX Runtime IO binding (`diffusion_onnx::SessionOptions::io_binding`):
    /// true. Bit-identical results on the CPU; false builds fresh tensors per call.
    pub onnx_io_binding: bool,
    /// Where the stage-I UNet runs: `cpu` or `cuda:N` ([`Device`]). Speed/memory only (never in
    /// the task identity). Needs a binary built with the `cuda` feature and the `onnxruntime-gpu`
    /// library for `cuda:N`.
    pub stage1_device: String,
    /// Where the stage-II UNet runs (`cpu` | `cuda:N`): the stages can sit on two GPUs.
    pub stage2_device: String,
    /// Where the T5 text encoder runs when a prompt is not cached (`cpu` | `cuda:N`); `cpu` keeps
    /// the 9.5 GB encoder off the GPUs (it runs once per prompt).
    pub text_encoder_device: String,
    /// cuDNN convolution algorithm search on CUDA: `exhaustive` (ONNX Runtime's default: the
    /// first call of each shape benchmarks the kernels), `heuristic`, `default`.
    pub cuda_conv_search: String,
    /// CUDA memory arena growth: `next_power_of_two` (ONNX Runtime's default) or
    /// `same_as_requested` (tightest, for cards near their memory).
    pub cuda_arena_growth: String,
    /// Cap on each CUDA device's ONNX Runtime arena, GiB (0: no cap, ONNX Runtime's default).
    /// Also the memory the estimate checks against when set.
    pub cuda_memory_limit_gib: f64,
    /// TF32 math for fp32 models on Ampere and later GPUs: true (ONNX Runtime's default). fp16
    /// models are unaffected.
    pub cuda_tf32: bool,
}

/// A device a model runs on: `guidance.stage1_device`, `stage2_device`, `text_encoder_device`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Device {
    /// `cpu`.
    Cpu,
    /// `cuda:N` (`cuda` alone is `cuda:0`): CUDA device ordinal N.
    Cuda(u32),
}

impl Device {
    /// Parses `cpu`, `cuda` or `cuda:N`.
    pub fn parse(s: &str) -> std::result::Result<Self, String> {
        match s.trim() {
            "cpu" => Ok(Self::Cpu),
            "cuda" => Ok(Self::Cuda(0)),
            t => match t.strip_prefix("cuda:").map(str::parse::<u32>) {
                Some(Ok(n)) if n < 1024 => Ok(Self::Cuda(n)),
                Some(_) => Err(format!(
                    "`{s}`: the CUDA device ordinal must be a number 0, 1, … (as `cuda:0`)"
                )),
                None => Err(format!(
                    "`{s}`: write `cpu` or `cuda:N` (N the GPU's ordinal, e.g. `cuda:0`)"
                )),
            },
        }
    }

    /// `cpu` or `cuda`, without the ordinal.
    pub fn kind(self) -> &'static str {
        match self {
            Self::Cpu => "cpu",
            Self::Cuda(_) => "cuda",
        }
    }
}

impl std::fmt::Display for Device {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::Cpu => f.write_str("cpu"),
            Self::Cuda(n) => write!(f, "cuda:{n}"),
        }
    }
}

/// `guidance.cuda_conv_search` values.
pub const CUDA_CONV_SEARCH: [&str; 3] = ["exhaustive", "heuristic", "default"];
/// `guidance.cuda_arena_growth` values.
pub const CUDA_ARENA_GROWTH: [&str; 2] = ["next_power_of_two", "same_as_requested"];

impl GuidanceSection {
    /// The three devices `(stage I, stage II, text encoder)`, parsed (an error names the key).
    pub fn devices(&self) -> Result<[Device; 3]> {
        let parse = |name: &str, v: &str| {
            Device::parse(v).map_err(|e| Error::config(name, format!("{name} = {e}")))
        };
        Ok([
            parse("guidance.stage1_device", &self.stage1_device)?,
            parse("guidance.stage2_device", &self.stage2_device)?,
            parse("guidance.text_encoder_device", &self.text_encoder_device)?,
        ])
    }

    /// A note for a resume whose stage devices differ in kind (CPU ↔ CUDA) from the run's
    /// `config.toml` of the previous start (`previous`): the run continues, but not bit for bit
    /// as it would have on the old device. None when the kinds match or `previous` cannot be read.
    pub fn device_change_note(&self, previous: &str) -> Option<String> {
        let old: Config = Config::from_toml_str(previous).ok()?;
        let [o1, o2, _] = old.guidance.devices().ok()?;
        let [n1, n2, _] = self.devices().ok()?;
        if o1.kind() == n1.kind() && o2.kind() == n2.kind() {
            return None;
        }
        Some(format!(
            "this run was started with the UNets on {o1} / {o2} (stage I / stage II) and resumes on {n1} / {n2}: \
             the task is the same (devices are not part of its identity), but the UNets' outputs differ between \
             devices — by about 1e-6 relative for fp32 models without TF32 (other kernels, other summation order), \
             about 1e-3 relative with TF32 or fp16 — so the continuation follows a slightly different trajectory \
             than an uninterrupted run on the first device would"
        ))
    }
}

impl Default for GuidanceSection {
    fn default() -> Self {
        let csd = csd::GuidanceConfig::default();
        Self {
            scale: f64::from(csd.guidance_scale),
            t_min: csd.timesteps.min,
            t_max: csd.timesteps.max,
            loss_scale: csd.loss_scale,
            stage1_weight: csd.stage1_weight,
            stage2_weight: csd::REFERENCE_STAGE2_WEIGHT.to_string(),
            negative_prompt: String::new(),
            grad_clip: csd.grad_clip.map_or(0.0, f64::from),
            // ONNX Runtime's own default (`diffusion_onnx::SessionOptions::default()`; a test
            // under the `text` feature keeps the two equal).
            onnx_memory_arena: true,
            onnx_low_memory: false,
            onnx_io_binding: true,
            stage1_device: "cpu".into(),
            stage2_device: "cpu".into(),
            text_encoder_device: "cpu".into(),
            cuda_conv_search: CUDA_CONV_SEARCH[0].into(),
            cuda_arena_growth: CUDA_ARENA_GROWTH[0].into(),
            cuda_memory_limit_gib: 0.0,
            cuda_tf32: true,
        }
    }
}

impl GuidanceSection {
    /// The `csd` guidance settings this section names (csd's defaults for what the file does not
    /// expose: the 224/64/256 resolutions and T = 1000).
    pub fn guidance_config(&self) -> csd::GuidanceConfig {
        csd::GuidanceConfig {
            guidance_scale: self.scale as f32,
            timesteps: csd::TimestepRange {
                min: self.t_min,
                max: self.t_max,
            },
            loss_scale: self.loss_scale,
            stage1_weight: self.stage1_weight,
            grad_clip: (self.grad_clip > 0.0).then_some(self.grad_clip as f32),
            ..csd::GuidanceConfig::default()
        }
    }
}

/// `[style]`: the model-free path (normal-alignment objective, `crate::style`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct StyleSection {
    /// Adam steps: 200.
    pub iterations: u64,
    /// Adam learning rate: 0.02 (x lives on the unit sphere initially; this moves it ~1° per step).
    pub lr: f64,
    /// Objective variant: `face`.
    pub objective: StyleObjective,
}

impl Default for StyleSection {
    fn default() -> Self {
        Self {
            iterations: 200,
            lr: 0.02,
            objective: StyleObjective::Face,
        }
    }
}

/// The largest `darap.lambda` (the reference uses 5–10; `stylize view`'s slider stops at 100).
pub const MAX_LAMBDA: f64 = 1000.0;
/// The largest `optim.lr` and `style.lr` (the defaults are 0.002 and 0.02).
pub const MAX_LEARNING_RATE: f64 = 10.0;
/// The largest `guidance.scale`, `guidance.loss_scale` and `guidance.stage1_weight` (defaults
/// 100, 100 and 1).
pub const MAX_WEIGHT: f64 = 1e6;
/// The most `camera.views` (the reference uses 8).
pub const MAX_VIEWS: usize = 256;
/// The largest `render.width` / `render.height`, in pixels (the reference uses 512).
pub const MAX_RENDER_SIZE: usize = 4096;
/// The most `optim.steps_per_batch` (the reference uses 2).
pub const MAX_STEPS_PER_BATCH: u32 = 1000;

/// The largest `run.turntable_size`, in pixels (the zoomed renders behind a tile reach 4×).
pub const MAX_TURNTABLE_SIZE: usize = 1024;
/// The most `run.turntable_views` (tiles of the contact sheet and of `before_after.png`).
pub const MAX_TURNTABLE_VIEWS: usize = 64;
/// The most `run.turntable_gif_frames` (one per degree).
pub const MAX_TURNTABLE_GIF_FRAMES: usize = 360;

/// `[run]`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct RunSection {
    /// Seed of the run's `ChaCha8Rng`: 0.
    pub seed: u64,
    /// Write a checkpoint every N iterations (0: only at the end): 100.
    pub checkpoint_every: u64,
    /// Write a PNG grid of the current views every N iterations (0: never): 250.
    pub preview_every: u64,
    /// Frames of the final turntable contact sheet: 8 (1 to [`MAX_TURNTABLE_VIEWS`]).
    pub turntable_views: usize,
    /// Side in pixels of preview and turntable frames: 256 (1 to [`MAX_TURNTABLE_SIZE`]).
    pub turntable_size: usize,
    /// Frames of the animated `turntable.gif`, 360°/N apart (0: none; at most
    /// [`MAX_TURNTABLE_GIF_FRAMES`]): 36.
    pub turntable_gif_frames: usize,
    /// Save the deformed positions to `snapshots.npz` every N iterations, plus iteration 0 and the
    /// last (0: no snapshots): 50.
    pub snapshot_every: u64,
    /// The frame mesh outputs (`mesh.obj/.ply/.glb`) are written in: `input` (the input's own
    /// coordinates, axes and scale; the default) or `normalized` (the reference's side-2 frame).
    /// Presentation only: never part of the task identity ([`crate::frame`]).
    pub output_frame: crate::frame::OutputFrame,
}

impl Default for RunSection {
    fn default() -> Self {
        Self {
            seed: 0,
            checkpoint_every: 100,
            preview_every: 250,
            turntable_views: 8,
            turntable_size: 256,
            turntable_gif_frames: 36,
            snapshot_every: 50,
            output_frame: crate::frame::OutputFrame::Input,
        }
    }
}

/// `[mesh]`: what is done to the input mesh before it is normalized and optimized.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct MeshSection {
    /// `auto` (default), `on`, `off`, or an edge length (`0.03` side-2 units, `1.5%`)
    /// ([`crate::remeshing`]).
    pub remesh: crate::remeshing::RemeshSetting,
    /// The input's up axis, turned to +y before normalization and back on output: `+y`
    /// ([`crate::frame::UpAxis`]; `+z` for most CAD files and scans).
    pub up: crate::frame::UpAxis,
}

/// `[region]`: localized stylization (`docs/cli.md`, `mesh_core::region`).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct RegionSection {
    /// Region specs whose union may rotate (empty: the whole mesh): `box:…`, `sphere:…`,
    /// `vertices:FILE`, `part:NAME`, `property:NAME OP VALUE`, `not:SPEC`.
    pub specs: Vec<String>,
    /// Rings inside the region's boundary over which λ fades from full to zero: 0.
    pub feather: u32,
    /// Tint the region in the turntable and previews: false.
    pub tint: bool,
}

/// The whole configuration. `Config::default()` is the reference setup.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Config {
    /// `[darap]`.
    pub darap: DarapSection,
    /// `[optim]`.
    pub optim: OptimSection,
    /// `[camera]`.
    pub camera: CameraSection,
    /// `[render]`.
    pub render: RenderSection,
    /// `[guidance]`.
    pub guidance: GuidanceSection,
    /// `[style]`.
    pub style: StyleSection,
    /// `[run]`.
    pub run: RunSection,
    /// `[region]`.
    pub region: RegionSection,
    /// `[mesh]`: what is done to the input before it is optimized (remeshing, orientation).
    pub mesh: MeshSection,
}

impl Config {
    /// Parses a TOML document (missing keys take their defaults; unknown keys are errors).
    pub fn from_toml_str(text: &str) -> Result<Self> {
        let config: Self = toml::from_str(text).context("invalid configuration")?;
        config.validate()?;
        Ok(config)
    }

    /// The resolved configuration as TOML (what a run directory's `config.toml` holds).
    pub fn to_toml_string(&self) -> Result<String> {
        toml::to_string_pretty(self).context("cannot serialize the configuration")
    }

    /// Applies `section.key=value` overrides in order. The value is parsed with the type of the
    /// key's current value (number, integer, boolean, string, or a TOML array such as `[0, 30]`).
    pub fn with_overrides<S: AsRef<str>>(self, overrides: &[S]) -> Result<Self> {
        let mut table =
            toml::Table::try_from(&self).context("cannot serialize the configuration")?;
        for o in overrides {
            apply_override(&mut table, o.as_ref())?;
        }
        let config: Self = toml::Value::Table(table)
            .try_into()
            .context("configuration after overrides is invalid")?;
        config.validate()?;
        Ok(config)
    }

    /// `--region` specs, `--region-feather` and `--tint-region` on top of the configuration:
    /// given specs and rings replace `region.specs` / `region.feather` (nothing given: unchanged).
    pub fn with_region_flags(
        mut self,
        specs: &[String],
        feather: Option<u32>,
        tint: bool,
    ) -> Result<Self> {
        if !specs.is_empty() {
            self.region.specs = specs.to_vec();
        }
        if let Some(k) = feather {
            self.region.feather = k;
        }
        self.region.tint |= tint;
        self.validate()?;
        Ok(self)
    }

    /// Checks ranges that the types alone do not (positive sizes, a parsable schedule, …).
    pub fn validate(&self) -> Result<()> {
        let finite_pos = |name: &str, v: f64| -> Result<()> {
            if !(v.is_finite() && v > 0.0) {
                return Err(Error::config(
                    name,
                    format!("{name} must be a finite positive number, got {v}"),
                ));
            }
            Ok(())
        };
        if !(self.darap.lambda.is_finite() && (0.0..=MAX_LAMBDA).contains(&self.darap.lambda)) {
            bad_field!(
                "darap.lambda",
                "darap.lambda must be within [0, {MAX_LAMBDA}] (the reference uses 5–10), got {}",
                self.darap.lambda
            );
        }
        // Numbers that are finite but far outside any sensible use overflow the arithmetic and
        // end in a silently destroyed mesh (or an allocation abort): each has an upper bound.
        let within = |name: &str, v: f64, low_exclusive: bool, max: f64| -> Result<()> {
            let low_ok = if low_exclusive { v > 0.0 } else { v >= 0.0 };
            if !(v.is_finite() && low_ok && v <= max) {
                let low = if low_exclusive { "(0" } else { "[0" };
                return Err(Error::config(
                    name,
                    format!("{name} must be within {low}, {max}], got {v}"),
                ));
            }
            Ok(())
        };
        finite_pos("optim.lr", self.optim.lr)?;
        finite_pos("style.lr", self.style.lr)?;
        finite_pos("optim.eps", self.optim.eps)?;
        within("optim.lr", self.optim.lr, true, MAX_LEARNING_RATE)?;
        within("style.lr", self.style.lr, true, MAX_LEARNING_RATE)?;
        within("optim.eps", self.optim.eps, true, 1.0)?;
        let g = &self.guidance;
        within("guidance.scale", g.scale, false, MAX_WEIGHT)?;
        within("guidance.loss_scale", g.loss_scale, false, MAX_WEIGHT)?;
        within("guidance.stage1_weight", g.stage1_weight, false, MAX_WEIGHT)?;
        if self.camera.views > MAX_VIEWS {
            bad_field!(
                "camera.views",
                "camera.views must be at most {MAX_VIEWS} (the reference uses 8), got {}",
                self.camera.views
            );
        }
        if self.render.width > MAX_RENDER_SIZE || self.render.height > MAX_RENDER_SIZE {
            bad_field!(
                "render.width",
                "render.width and render.height must be at most {MAX_RENDER_SIZE} pixels, got {}×{}",
                self.render.width,
                self.render.height
            );
        }
        if self.optim.steps_per_batch > MAX_STEPS_PER_BATCH {
            bad_field!(
                "optim.steps_per_batch",
                "optim.steps_per_batch must be at most {MAX_STEPS_PER_BATCH}, got {}",
                self.optim.steps_per_batch
            );
        }
        for (name, b) in [
            ("optim.beta1", self.optim.beta1),
            ("optim.beta2", self.optim.beta2),
        ] {
            if !(0.0..1.0).contains(&b) {
                bad_field!(name, "{name} must be in [0, 1), got {b}");
            }
        }
        if self.optim.steps_per_batch == 0 {
            bad_field!(
                "optim.steps_per_batch",
                "optim.steps_per_batch must be at least 1"
            );
        }
        if self.camera.views == 0 {
            bad_field!("camera.views", "camera.views must be at least 1");
        }
        self.guidance.devices()?;
        let g = &self.guidance;
        if !CUDA_CONV_SEARCH.contains(&g.cuda_conv_search.as_str()) {
            bad_field!(
                "guidance.cuda_conv_search",
                "guidance.cuda_conv_search must be one of {}, got {:?}",
                CUDA_CONV_SEARCH.join(", "),
                g.cuda_conv_search
            );
        }
        if !CUDA_ARENA_GROWTH.contains(&g.cuda_arena_growth.as_str()) {
            bad_field!(
                "guidance.cuda_arena_growth",
                "guidance.cuda_arena_growth must be one of {}, got {:?}",
                CUDA_ARENA_GROWTH.join(", "),
                g.cuda_arena_growth
            );
        }
        if !(g.cuda_memory_limit_gib.is_finite() && g.cuda_memory_limit_gib >= 0.0) {
            bad_field!(
                "guidance.cuda_memory_limit_gib",
                "guidance.cuda_memory_limit_gib must be a finite number of GiB >= 0 (0: no cap), got {}",
                g.cuda_memory_limit_gib
            );
        }
        let sampler = &self.camera.sampler;
        for (name, r) in [
            ("camera.elevation_deg", sampler.elevation_deg),
            ("camera.azimuth_deg", sampler.azimuth_deg),
            ("camera.distance", sampler.distance),
        ] {
            if !(r[0].is_finite() && r[1].is_finite() && r[0] <= r[1]) {
                bad_field!(
                    name,
                    "{name} must be a finite range [low, high] with low <= high, got {r:?}"
                );
            }
        }
        if sampler.distance[0] <= 0.0 {
            bad_field!(
                "camera.distance",
                "camera.distance must be positive, got {:?}",
                sampler.distance
            );
        }
        if !(sampler.fov_y_deg > 0.0 && sampler.fov_y_deg < 180.0) {
            bad_field!(
                "camera.fov_deg",
                "camera.fov_deg must be in (0, 180), got {}",
                sampler.fov_y_deg
            );
        }
        if self.render.width == 0 || self.render.height == 0 {
            bad_field!(
                "render.width",
                "render.width and render.height must be positive"
            );
        }
        let run = &self.run;
        if !(1..=MAX_TURNTABLE_SIZE).contains(&run.turntable_size) {
            bad_field!(
                "run.turntable_size",
                "run.turntable_size must be in 1..={MAX_TURNTABLE_SIZE} pixels, got {}",
                run.turntable_size
            );
        }
        if !(1..=MAX_TURNTABLE_VIEWS).contains(&run.turntable_views) {
            bad_field!(
                "run.turntable_views",
                "run.turntable_views must be in 1..={MAX_TURNTABLE_VIEWS}, got {}",
                run.turntable_views
            );
        }
        if run.turntable_gif_frames > MAX_TURNTABLE_GIF_FRAMES {
            bad_field!(
                "run.turntable_gif_frames",
                "run.turntable_gif_frames must be at most {MAX_TURNTABLE_GIF_FRAMES} (1° apart; \
                 0 = no GIF), got {}",
                run.turntable_gif_frames
            );
        }
        if !(self.guidance.t_min >= 1
            && self.guidance.t_min <= self.guidance.t_max
            && self.guidance.t_max < 1000)
        {
            bad_field!(
                "guidance.t_min",
                "guidance timesteps must satisfy 1 <= t_min <= t_max <= 999, got [{}, {}]",
                self.guidance.t_min,
                self.guidance.t_max
            );
        }
        if !(self.guidance.grad_clip.is_finite() && self.guidance.grad_clip >= 0.0) {
            bad_field!(
                "guidance.grad_clip",
                "guidance.grad_clip must be >= 0 (0 = off), got {}",
                self.guidance.grad_clip
            );
        }
        self.stage2_schedule()?;
        for spec in &self.region.specs {
            mesh_core::region::RegionSpec::parse(spec).context("region.specs")?;
        }
        Ok(())
    }

    /// The parsed stage-II weight schedule.
    pub fn stage2_schedule(&self) -> Result<optim::Schedule> {
        optim::Schedule::parse(&self.guidance.stage2_weight).context("guidance.stage2_weight")
    }
}

/// Applies one `section.key=value` override to a serialized config table.
fn apply_override(table: &mut toml::Table, assignment: &str) -> Result<()> {
    let Some((path, raw)) = assignment.split_once('=') else {
        bad_field!(
            assignment,
            "override {assignment:?} is not of the form section.key=value"
        );
    };
    let path = path.trim();
    let raw = raw.trim();
    let mut parts = path.split('.');
    let (Some(section), Some(key), None) = (parts.next(), parts.next(), parts.next()) else {
        bad_field!(
            path,
            "override key {path:?} must be section.key (e.g. optim.lr)"
        );
    };
    let sections: Vec<&str> = table.keys().map(String::as_str).collect();
    let known_sections = sections.join(", ");
    let Some(toml::Value::Table(sec)) = table.get_mut(section) else {
        bad_field!(
            path,
            "unknown config section {section:?} in override {path:?} (known: {known_sections})"
        );
    };
    let known_keys = sec
        .keys()
        .map(String::as_str)
        .collect::<Vec<_>>()
        .join(", ");
    let Some(current) = sec.get_mut(key) else {
        bad_field!(
            path,
            "unknown config key {path:?} (keys of [{section}]: {known_keys})"
        );
    };
    let bad = |what: &str| Error::config(path, format!("override {path}={raw}: expected {what}"));
    let new = match current {
        toml::Value::Float(_) => {
            toml::Value::Float(raw.parse::<f64>().map_err(|_| bad("a number"))?)
        }
        toml::Value::Integer(_) => {
            toml::Value::Integer(raw.parse::<i64>().map_err(|_| bad("an integer"))?)
        }
        toml::Value::Boolean(_) => {
            toml::Value::Boolean(raw.parse::<bool>().map_err(|_| bad("true or false"))?)
        }
        toml::Value::String(_) => {
            let unquoted = raw
                .strip_prefix('"')
                .and_then(|r| r.strip_suffix('"'))
                .unwrap_or(raw);
            toml::Value::String(unquoted.to_string())
        }
        toml::Value::Array(_) => {
            let doc: toml::Table = toml::from_str(&format!("v = {raw}"))
                .map_err(|_| bad("a TOML array such as [0.0, 30.0]"))?;
            match doc.get("v") {
                Some(v @ toml::Value::Array(_)) => v.clone(),
                _ => return Err(bad("a TOML array such as [0.0, 30.0]")),
            }
        }
        other => bad_field!(
            path,
            "override {path}: cannot override a value of type {}",
            other.type_str()
        ),
    };
    *current = new;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ok<T>(r: Result<T>) -> T {
        r.unwrap_or_else(|e| panic!("{}", e.full_message()))
    }

    #[test]
    fn defaults_are_the_reference_values() {
        let c = Config::default();
        assert_eq!(c.darap.lambda, 8.0);
        assert_eq!(c.darap.rotation_rule, RotationRule::Gis);
        assert_eq!(c.optim.lr, 0.002);
        assert_eq!(c.optim.iterations, 2500);
        assert_eq!(c.optim.steps_per_batch, 2);
        assert_eq!(c.camera.views, 8);
        assert_eq!((c.render.width, c.render.height), (512, 512));
        assert_eq!(c.guidance.scale, 100.0);
        assert_eq!((c.guidance.t_min, c.guidance.t_max), (20, 980));
        let w = ok(c.stage2_schedule());
        assert!((w.at(1500) - 0.26662).abs() < 5e-6);
        ok(c.validate());
    }

    #[test]
    fn devices_and_cuda_options_are_validated_naming_the_key() {
        let c = ok(Config::default().with_overrides(&[
            "guidance.stage1_device=cuda:1",
            "guidance.stage2_device=cuda",
            "guidance.cuda_conv_search=heuristic",
            "guidance.cuda_arena_growth=same_as_requested",
            "guidance.cuda_memory_limit_gib=20.5",
        ]));
        assert_eq!(
            ok(c.guidance.devices()),
            [Device::Cuda(1), Device::Cuda(0), Device::Cpu]
        );
        for (bad, key) in [
            ("guidance.stage1_device=gpu", "guidance.stage1_device"),
            ("guidance.stage2_device=cuda:x", "guidance.stage2_device"),
            (
                "guidance.text_encoder_device=cuda:-1",
                "guidance.text_encoder_device",
            ),
            (
                "guidance.cuda_conv_search=fast",
                "guidance.cuda_conv_search",
            ),
            (
                "guidance.cuda_arena_growth=double",
                "guidance.cuda_arena_growth",
            ),
            (
                "guidance.cuda_memory_limit_gib=-1",
                "guidance.cuda_memory_limit_gib",
            ),
        ] {
            let e = Config::default()
                .with_overrides(&[bad])
                .expect_err(bad)
                .full_message();
            assert!(e.contains(key), "{bad}: {e}");
        }
        let e = Config::default()
            .with_overrides(&["guidance.stage1_device=gpu"])
            .expect_err("gpu")
            .full_message();
        assert!(e.contains("cuda:N") && e.contains("cpu"), "{e}");
    }

    #[test]
    fn a_resume_on_another_kind_of_device_says_so() {
        let cpu = Config::default();
        let previous = ok(cpu.to_toml_string());
        assert_eq!(cpu.guidance.device_change_note(&previous), None);
        let gpu = ok(Config::default().with_overrides(&["guidance.stage2_device=cuda:0"]));
        let note = gpu.guidance.device_change_note(&previous).expect("a note");
        assert!(
            note.contains("cpu / cpu") && note.contains("cpu / cuda:0") && note.contains("1e-3"),
            "{note}"
        );
        // Another GPU of the same kind is not a change of numerics worth a note.
        let other = ok(Config::default().with_overrides(&["guidance.stage2_device=cuda:1"]));
        assert_eq!(
            other.guidance.device_change_note(&ok(gpu.to_toml_string())),
            None
        );
    }

    #[cfg(feature = "text")]
    #[test]
    fn onnx_memory_arena_defaults_to_onnx_runtimes_own_default() {
        assert_eq!(
            GuidanceSection::default().onnx_memory_arena,
            diffusion_onnx::SessionOptions::default().cpu_memory_arena
        );
    }

    #[test]
    fn resolved_config_round_trips_through_toml() {
        let c =
            ok(Config::default()
                .with_overrides(&["darap.lambda=5", "camera.elevation_deg=[0, 30]"]));
        let text = ok(c.to_toml_string());
        assert_eq!(ok(Config::from_toml_str(&text)), c);
    }

    #[test]
    fn partial_file_keeps_other_defaults() {
        let c = ok(Config::from_toml_str(
            "[darap]\nlambda = 10.0\n[run]\nseed = 7\n",
        ));
        assert_eq!(c.darap.lambda, 10.0);
        assert_eq!(c.run.seed, 7);
        assert_eq!(c.optim, OptimSection::default());
    }

    #[test]
    fn overrides_are_typed() {
        let c = ok(Config::default().with_overrides(&[
            "optim.lr=0.01",
            "optim.iterations=10",
            "darap.rotation_rule=procrustes",
            "camera.adapt_distance=false",
            "guidance.stage2_weight=\"0.1\"",
            "darap.lambda=5",
        ]));
        assert_eq!(c.optim.lr, 0.01);
        assert_eq!(c.optim.iterations, 10);
        assert_eq!(c.darap.rotation_rule, RotationRule::Procrustes);
        assert!(!c.camera.adapt_distance);
        assert_eq!(c.guidance.stage2_weight, "0.1");
        assert_eq!(c.darap.lambda, 5.0);
    }

    #[test]
    fn picture_settings_are_bounded_before_a_run_starts() {
        for (set, key) in [
            ("run.turntable_views=0", "run.turntable_views"),
            ("run.turntable_views=65", "run.turntable_views"),
            ("run.turntable_size=0", "run.turntable_size"),
            ("run.turntable_size=100000", "run.turntable_size"),
            ("run.turntable_gif_frames=361", "run.turntable_gif_frames"),
        ] {
            let e = Config::default()
                .with_overrides(&[set])
                .err()
                .map(|e| e.full_message())
                .unwrap_or_default();
            assert!(e.contains(key), "{set}: {e}");
        }
        let c = ok(Config::default().with_overrides(&[
            "run.turntable_views=64",
            "run.turntable_size=1024",
            "run.turntable_gif_frames=360",
        ]));
        ok(c.validate());
    }

    /// Finite numbers far outside any use (λ = 1e308 completed with a destroyed mesh) are refused
    /// naming the key and its range; the bounds themselves are accepted.
    #[test]
    fn numeric_settings_have_ranges_not_only_signs() {
        for (set, key) in [
            ("darap.lambda=1e308", "darap.lambda"),
            ("darap.lambda=1000.5", "darap.lambda"),
            ("optim.lr=1e300", "optim.lr"),
            ("style.lr=11", "style.lr"),
            ("optim.eps=2", "optim.eps"),
            ("guidance.scale=1e300", "guidance.scale"),
            ("guidance.scale=-1", "guidance.scale"),
            ("guidance.scale=nan", "guidance.scale"),
            ("guidance.loss_scale=inf", "guidance.loss_scale"),
            ("guidance.stage1_weight=-0.5", "guidance.stage1_weight"),
            ("camera.views=1000000000", "camera.views"),
            ("render.width=100000", "render.width"),
            ("optim.steps_per_batch=1000000", "optim.steps_per_batch"),
        ] {
            let e = Config::default()
                .with_overrides(&[set])
                .err()
                .map(|e| e.full_message())
                .unwrap_or_default();
            assert!(
                e.contains(key) && (e.contains("within") || e.contains("at most")),
                "{set}: {e}"
            );
        }
        ok(Config::default().with_overrides(&[
            "darap.lambda=1000",
            "optim.lr=10",
            "guidance.scale=0",
            "camera.views=256",
            "render.width=4096",
            "optim.steps_per_batch=1000",
        ]));
    }

    #[test]
    fn bad_overrides_and_files_give_clear_errors() {
        let cases: &[(&str, &str)] = &[
            ("optim.lrr=0.1", "unknown config key \"optim.lrr\""),
            ("optimm.lr=0.1", "unknown config section \"optimm\""),
            ("optim.lr", "section.key=value"),
            ("lr=0.1", "must be section.key"),
            ("optim.iterations=1.5", "expected an integer"),
            ("optim.lr=fast", "expected a number"),
            ("camera.adapt_distance=yes", "true or false"),
            ("darap.rotation_rule=kabsch", "invalid"),
            ("guidance.stage2_weight=0>1", "stage2_weight"),
            ("camera.views=0", "camera.views"),
        ];
        for &(o, needle) in cases {
            match Config::default().with_overrides(&[o]) {
                Ok(_) => panic!("{o:?} accepted"),
                Err(e) => {
                    let msg = e.full_message();
                    assert!(msg.contains(needle), "{o:?}: {msg}");
                }
            }
        }
        let e = Config::from_toml_str("[darap]\nlamda = 3.0\n")
            .err()
            .map(|e| e.full_message());
        assert!(e.is_some_and(|m| m.contains("lamda")));
    }
}

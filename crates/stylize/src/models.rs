//! Loading the text path's models: DeepFloyd IF stage I (and stage II when present) from an ONNX
//! model directory (`docs/models.md`), the prompt embeddings (cached), and the guidance.
//!
//! [`ModelSet`] opens the UNet sessions once; [`ModelSet::guidance_for`] builds a guidance for
//! one prompt that shares those sessions, so a batch loads the models a single time.

use std::path::Path;
use std::sync::{Arc, Mutex};

use anyhow::Context;
use csd::{
    CascadedGuidance, Denoiser, Embedding, Guidance, GuidanceConfig, GuidanceError, Tensor,
    TimestepRange,
};
use diffusion_onnx::{EmbeddingCache, ModelDir, OnnxDenoiser, SessionOptions, Stage};

use crate::config::Config;

/// The `csd` guidance settings from the configuration.
pub fn guidance_config(config: &Config) -> GuidanceConfig {
    let g = &config.guidance;
    GuidanceConfig {
        guidance_scale: g.scale as f32,
        timesteps: TimestepRange {
            min: g.t_min,
            max: g.t_max,
        },
        loss_scale: g.loss_scale,
        stage1_weight: g.stage1_weight,
        grad_clip: (g.grad_clip > 0.0).then_some(g.grad_clip as f32),
        ..GuidanceConfig::default()
    }
}

/// A denoiser shared between guidances (one run at a time uses it).
#[derive(Clone)]
struct Shared(Arc<Mutex<OnnxDenoiser>>);

impl Denoiser for Shared {
    fn describe(&self) -> String {
        self.0.lock().map_or_else(
            |_| "a UNet whose last run panicked".into(),
            |d| d.describe(),
        )
    }

    fn predict(
        &mut self,
        sample: &Tensor,
        timesteps: &[i64],
        embeddings: &[&Embedding],
        class_labels: Option<&[i64]>,
    ) -> Result<Tensor, GuidanceError> {
        let mut d = self
            .0
            .lock()
            .map_err(|_| GuidanceError::Model("a previous run panicked inside the UNet".into()))?;
        d.predict(sample, timesteps, embeddings, class_labels)
    }
}

/// Opened model sessions, reusable across prompts.
pub struct ModelSet {
    dir: ModelDir,
    options: SessionOptions,
    cache: Option<EmbeddingCache>,
    stage1: Shared,
    stage2: Option<Shared>,
}

impl std::fmt::Debug for ModelSet {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("ModelSet")
            .field("dir", &self.dir.root())
            .field("stage2", &self.stage2.is_some())
            .finish_non_exhaustive()
    }
}

impl ModelSet {
    /// Opens the model directory and its UNets (stage II only when the manifest lists it), with
    /// the session settings of `config` (`guidance.onnx_memory_arena`).
    pub fn open(model: &Path, config: &Config) -> anyhow::Result<Self> {
        let dir = ModelDir::open(model)
            .with_context(|| format!("cannot open model directory {}", model.display()))?;
        let options = SessionOptions {
            cpu_memory_arena: config.guidance.onnx_memory_arena,
            ..SessionOptions::default()
        };
        let cache = EmbeddingCache::at_default().ok();
        let stage1 = OnnxDenoiser::open(&dir, Stage::One, &options).context("IF stage I")?;
        let stage2 = match dir.stage(Stage::Two) {
            Some(_) => Some(Shared(Arc::new(Mutex::new(
                OnnxDenoiser::open(&dir, Stage::Two, &options).context("IF stage II")?,
            )))),
            None => None,
        };
        Ok(Self {
            dir,
            options,
            cache,
            stage1: Shared(Arc::new(Mutex::new(stage1))),
            stage2,
        })
    }

    /// A guidance for `prompt` (negative prompt and settings from `config`). Without a stage-II
    /// model the stage-II weight schedule must stay at 0 (the guidance errors otherwise).
    pub fn guidance_for(&self, prompt: &str, config: &Config) -> anyhow::Result<Box<dyn Guidance>> {
        let stage2_used = config.stage2_schedule()?.phases().iter().any(|p| match *p {
            optim::Phase::Constant { value, .. } => value != 0.0,
            optim::Phase::Ramp { from, to, .. } => from != 0.0 || to != 0.0,
        });
        if self.stage2.is_none() && stage2_used {
            anyhow::bail!(
                "the model directory {} has no stage-II UNet but guidance.stage2_weight = {:?} uses it; \
                 export stage II (docs/models.md) or run stage I only with --set guidance.stage2_weight=0",
                self.dir.root().display(),
                config.guidance.stage2_weight
            );
        }
        let (cond, uncond) = diffusion_onnx::prompt_embeddings(
            &self.dir,
            prompt,
            &config.guidance.negative_prompt,
            self.cache.as_ref(),
            &self.options,
        )
        .context("prompt embeddings")?;
        let stage2 = self
            .stage2
            .clone()
            .map(|s| Box::new(s) as Box<dyn Denoiser>);
        let guidance = CascadedGuidance::new(
            Box::new(self.stage1.clone()),
            stage2,
            cond,
            uncond,
            guidance_config(config),
        )
        .context("guidance")?;
        Ok(Box::new(guidance))
    }
}

/// Opens the models and builds the guidance for one prompt.
pub fn load_guidance(
    model: &Path,
    prompt: &str,
    config: &Config,
) -> anyhow::Result<Box<dyn Guidance>> {
    ModelSet::open(model, config)?.guidance_for(prompt, config)
}

//! Loading the text path's models: DeepFloyd IF stage I (and stage II when present) from an ONNX
//! model directory (`docs/models.md`), the prompt embeddings (cached), and the guidance.
//!
//! [`ModelSet`] opens the UNet sessions once; [`ModelSet::guidance_for`] builds a guidance for
//! one prompt that borrows those sessions (no lock: one run at a time holds them), so a batch loads
//! the models a single time; [`ModelSet::into_guidance`] hands them to a single run.

use std::path::Path;

use crate::error::{Context, Result, invalid};
use csd::{CascadedGuidance, Denoiser, Embedding, GuidanceConfig};
use diffusion_onnx::{EmbeddingCache, ModelDir, OnnxDenoiser, SessionOptions, Stage};

use crate::config::Config;

/// The `csd` guidance settings from the configuration ([`GuidanceSection::guidance_config`]).
///
/// [`GuidanceSection::guidance_config`]: crate::config::GuidanceSection::guidance_config
pub fn guidance_config(config: &Config) -> GuidanceConfig {
    config.guidance.guidance_config()
}

/// Opened model sessions, reusable across prompts.
pub struct ModelSet {
    dir: ModelDir,
    options: SessionOptions,
    cache: Option<EmbeddingCache>,
    stage1: OnnxDenoiser,
    stage2: Option<OnnxDenoiser>,
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
    pub fn open(model: &Path, config: &Config) -> Result<Self> {
        let dir = ModelDir::open(model)
            .with_context(|| format!("cannot open model directory {}", model.display()))?;
        let options = SessionOptions {
            cpu_memory_arena: config.guidance.onnx_memory_arena,
            ..SessionOptions::default()
        };
        let cache = EmbeddingCache::at_default().ok();
        let stage1 = OnnxDenoiser::open(&dir, Stage::One, &options).context("IF stage I")?;
        let stage2 = match dir.stage(Stage::Two) {
            Some(_) => Some(OnnxDenoiser::open(&dir, Stage::Two, &options).context("IF stage II")?),
            None => None,
        };
        Ok(Self {
            dir,
            options,
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
            &self.options,
        )
        .context("prompt embeddings")
    }

    /// A guidance for `prompt` (negative prompt, settings and stage-II weight schedule from
    /// `config`) that borrows this set's UNets until it is dropped. Without a stage-II model the
    /// stage-II weight schedule must stay at 0.
    pub fn guidance_for(&mut self, prompt: &str, config: &Config) -> Result<CascadedGuidance<'_>> {
        let (cond, uncond) = self.embeddings_for(prompt, config)?;
        let stage2 = self
            .stage2
            .as_mut()
            .map(|s| Box::new(s) as Box<dyn Denoiser + '_>);
        let guidance = CascadedGuidance::new(
            Box::new(&mut self.stage1),
            stage2,
            cond,
            uncond,
            guidance_config(config),
        )
        .context("guidance")?
        .with_stage2_weight(config.stage2_schedule()?);
        Ok(guidance)
    }

    /// Like [`Self::guidance_for`], handing the UNets over to the guidance.
    pub fn into_guidance(self, prompt: &str, config: &Config) -> Result<CascadedGuidance<'static>> {
        let (cond, uncond) = self.embeddings_for(prompt, config)?;
        let stage2 = self.stage2.map(|s| Box::new(s) as Box<dyn Denoiser>);
        let guidance = CascadedGuidance::new(
            Box::new(self.stage1),
            stage2,
            cond,
            uncond,
            guidance_config(config),
        )
        .context("guidance")?
        .with_stage2_weight(config.stage2_schedule()?);
        Ok(guidance)
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

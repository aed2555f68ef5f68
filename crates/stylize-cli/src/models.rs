//! Loading the text path's models: DeepFloyd IF stage I (and stage II when present) from an ONNX
//! model directory (`docs/models.md`), the prompt embeddings (cached), and the guidance.

use std::path::Path;

use anyhow::Context;
use csd::{CascadedGuidance, Guidance, GuidanceConfig, TimestepRange};
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

/// Opens the model directory and builds the cascaded guidance for one prompt.
///
/// Stage II is optional in the model directory; without it the stage-II weight schedule must stay
/// at 0 (the guidance reports an error at the first iteration where it is positive).
pub fn load_guidance(
    model: &Path,
    prompt: &str,
    config: &Config,
) -> anyhow::Result<Box<dyn Guidance>> {
    let dir = ModelDir::open(model)
        .with_context(|| format!("cannot open model directory {}", model.display()))?;
    let options = SessionOptions::default();
    let cache = EmbeddingCache::at_default().ok();
    let (cond, uncond) = diffusion_onnx::prompt_embeddings(
        &dir,
        prompt,
        &config.guidance.negative_prompt,
        cache.as_ref(),
        &options,
    )
    .context("prompt embeddings")?;
    let stage1 = OnnxDenoiser::open(&dir, Stage::One, &options).context("IF stage I")?;
    let stage2 = match dir.stage(Stage::Two) {
        Some(_) => Some(Box::new(
            OnnxDenoiser::open(&dir, Stage::Two, &options).context("IF stage II")?,
        ) as Box<dyn csd::Denoiser>),
        None => None,
    };
    let guidance = CascadedGuidance::new(
        Box::new(stage1),
        stage2,
        cond,
        uncond,
        guidance_config(config),
    )
    .context("guidance")?;
    Ok(Box::new(guidance))
}

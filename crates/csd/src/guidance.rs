//! [`CascadedGuidance`]: SDS with IF stage I plus Cascaded Score Distillation with IF stage II, behind the
//! [`Guidance`] trait. The derivation of every factor is in `docs/guidance.md`; in short, with B views,
//! S = `loss_scale`, a = `stage1_weight`, w_II the stage-II weight and R, D, U the resizes 512→224,
//! 224→64, 224→256:
//!
//! ```text
//! x   = 2·R(img) − 1                                   (B, 3, 224, 224), values in [−1, 1]
//! z0  = D(x),  x0 = U(x),  ẑ = U₆₄→₂₅₆(z0) (no gradient)
//! L   = S · (a · L_I + w_II · L_II),   L_I = ½‖grad_I‖²/B,  L_II = ½‖grad_II‖²/B   (surrogates, grads detached)
//! ∂L/∂img = Rᵀ( 2 · [ (S·a/B) · Dᵀ(grad_I) + (S·w_II/B) · Uᵀ(grad_II) ] )
//! ```
//!
//! which is spec §7's `100 · [(2/B)·bilinear₆₄ᵀ(grad_I) + w_II·(2/B)·bilinear₂₅₆ᵀ(grad_II)]` through the
//! 224 resize adjoint; the 2 is ∂x/∂img of `x = 2·img − 1`.

use crate::resize::Resize2d;
use crate::schedule::{NoiseSchedule, TimestepRange, standard_normal};
use crate::sds::{classifier_free_guidance, nan_to_num, sds_gradient, sds_loss, split_cond_uncond};
use crate::{Denoiser, Embedding, Guidance, GuidanceError, GuidanceOutput, Tensor};
use rand::RngCore;
use rayon::prelude::*;

/// Image channels the guidance works on (RGB).
pub const CHANNELS: usize = 3;

/// Settings of [`CascadedGuidance`]. `Default` gives the reference's values.
#[derive(Clone, Debug, PartialEq)]
pub struct GuidanceConfig {
    /// CFG scale g in `ε̂ = ε_c + g·(ε_c − ε_u)`, both stages (reference: 100, i.e. standard scale 101).
    pub guidance_scale: f32,
    /// Range of the diffusion timesteps t (both stages) and of the stage-II noise level s: `[20, 980]`.
    pub timesteps: TimestepRange,
    /// Training timesteps T of the DDPM schedule (1000).
    pub num_train_timesteps: usize,
    /// Side of the square image the renders are first resized to (antialiased cubic): 224.
    pub resolution: usize,
    /// Stage-I input side (bilinear from `resolution`): 64.
    pub stage1_resolution: usize,
    /// Stage-II input side (bilinear from `resolution`, and from `stage1_resolution` for ẑ): 256.
    pub stage2_resolution: usize,
    /// Overall loss scale S (reference: 100).
    pub loss_scale: f64,
    /// Weight a of stage I (reference: 1).
    pub stage1_weight: f64,
    /// Optional clamp of each stage's gradient to `[−c, c]` after NaN/∞ handling (reference's
    /// `grad_clip_val`; off by default).
    pub grad_clip: Option<f32>,
}

impl Default for GuidanceConfig {
    fn default() -> Self {
        Self {
            guidance_scale: 100.0,
            timesteps: TimestepRange::default(),
            num_train_timesteps: 1000,
            resolution: 224,
            stage1_resolution: 64,
            stage2_resolution: 256,
            loss_scale: 100.0,
            stage1_weight: 1.0,
            grad_clip: None,
        }
    }
}

impl GuidanceConfig {
    /// Checks every field; a clear error for the first bad one.
    pub fn validate(&self) -> Result<(), GuidanceError> {
        let bad = |m: String| Err(GuidanceError::InvalidInput(m));
        if !self.guidance_scale.is_finite() {
            return bad(format!(
                "guidance scale {} is not finite",
                self.guidance_scale
            ));
        }
        self.timesteps.validate(self.num_train_timesteps)?;
        if self.resolution == 0 || self.stage1_resolution == 0 || self.stage2_resolution == 0 {
            return bad("resolutions must be positive".into());
        }
        if !self.loss_scale.is_finite()
            || !self.stage1_weight.is_finite()
            || self.stage1_weight < 0.0
        {
            return bad(format!(
                "loss scale {} and stage-I weight {} must be finite (weight ≥ 0)",
                self.loss_scale, self.stage1_weight
            ));
        }
        if let Some(c) = self.grad_clip
            && (c.is_nan() || c <= 0.0)
        {
            return bad(format!("gradient clip {c} must be positive"));
        }
        Ok(())
    }
}

/// Timesteps and noise to use instead of drawing them (for debugging and tests). Each `None` is drawn
/// from the RNG. Draw order (each skipped when injected): stage-I t (B), stage-I ε (B·3·64²), stage-II t
/// (B), stage-II s (B), stage-II ε_s for ẑ (B·3·256²), stage-II ε_t for x0 (B·3·256²).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct InjectedDraws {
    /// Stage-I timesteps t, one per view.
    pub stage1_timesteps: Option<Vec<i64>>,
    /// Stage-I noise ε, `(B, 3, 64, 64)` flattened.
    pub stage1_noise: Option<Vec<f32>>,
    /// Stage-II timesteps t, one per view.
    pub stage2_timesteps: Option<Vec<i64>>,
    /// Stage-II noise levels s (class labels), one per view.
    pub stage2_noise_levels: Option<Vec<i64>>,
    /// Stage-II noise ε_s added to the upsampled low-resolution image ẑ, `(B, 3, 256, 256)`.
    pub stage2_noise_lowres: Option<Vec<f32>>,
    /// Stage-II noise ε_t added to x0, `(B, 3, 256, 256)`.
    pub stage2_noise: Option<Vec<f32>>,
}

/// Every intermediate of stage I (SDS at 64 px). Tensors are NCHW.
#[derive(Clone, Debug)]
pub struct Stage1Trace {
    /// z0 = bilinear(x → 64), `(B, 3, 64, 64)`.
    pub z0: Tensor,
    /// t per view.
    pub timesteps: Vec<i64>,
    /// ε, `(B, 3, 64, 64)`.
    pub noise: Tensor,
    /// z_t = √ᾱ_t z0 + √(1 − ᾱ_t) ε.
    pub z_t: Tensor,
    /// Conditional prediction ε_c (first 3 output channels).
    pub eps_cond: Tensor,
    /// Unconditional prediction ε_u.
    pub eps_uncond: Tensor,
    /// ε̂ = ε_c + g(ε_c − ε_u).
    pub eps_guided: Tensor,
    /// grad_I = nan_to_num(w(t)(ε̂ − ε)), `(B, 3, 64, 64)`.
    pub grad: Tensor,
    /// L_I = ½‖grad_I‖²/B (unweighted).
    pub loss: f64,
}

/// Every intermediate of stage II (CSD at 256 px). Tensors are NCHW.
#[derive(Clone, Debug)]
pub struct Stage2Trace {
    /// The stage-II weight w_II used.
    pub weight: f64,
    /// x0 = bilinear(x → 256), `(B, 3, 256, 256)`.
    pub x0: Tensor,
    /// ẑ = bilinear(z0 → 256) (no gradient flows through it).
    pub z_hat: Tensor,
    /// t per view.
    pub timesteps: Vec<i64>,
    /// s per view (the class label).
    pub noise_levels: Vec<i64>,
    /// ε_t added to x0.
    pub noise: Tensor,
    /// ε_s added to ẑ.
    pub noise_lowres: Tensor,
    /// x_t = add_noise(x0, ε_t, t).
    pub x_t: Tensor,
    /// ẑ_s = add_noise(ẑ, ε_s, s).
    pub z_hat_s: Tensor,
    /// Conditional prediction ε_c (first 3 output channels).
    pub eps_cond: Tensor,
    /// Unconditional prediction ε_u.
    pub eps_uncond: Tensor,
    /// ε̂ = ε_c + g(ε_c − ε_u).
    pub eps_guided: Tensor,
    /// grad_II = nan_to_num(w(t)(ε̂ − ε_t)), `(B, 3, 256, 256)`.
    pub grad: Tensor,
    /// L_II = ½‖grad_II‖²/B (unweighted).
    pub loss: f64,
}

/// One guidance evaluation with every intermediate, for `stylize debug-guidance`.
#[derive(Clone, Debug)]
pub struct GuidanceTrace {
    /// The input renders as NCHW `(B, 3, H, W)`, values in [0, 1].
    pub images: Tensor,
    /// x = 2·resize₂₂₄(img) − 1, `(B, 3, 224, 224)`.
    pub x: Tensor,
    /// Stage I.
    pub stage1: Stage1Trace,
    /// Stage II (None when its weight is 0).
    pub stage2: Option<Stage2Trace>,
    /// ∂L/∂x at 224 px, NCHW (before the factor 2 and the 224-resize adjoint).
    pub grad_x: Tensor,
    /// What [`Guidance::evaluate`] returns.
    pub output: GuidanceOutput,
}

/// SDS (IF stage I) + CSD (IF stage II) guidance, see the module docs for the exact objective.
///
/// Loss values reported in [`GuidanceOutput`]: `loss_stage1 = S·a·L_I` and `loss_stage2 = S·w_II·L_II`
/// with the reference's per-stage form `L = ½‖grad‖²/B`, so `loss_stage1 + loss_stage2` is exactly the
/// surrogate whose gradient `grad_images` is.
pub struct CascadedGuidance {
    stage1: Box<dyn Denoiser>,
    stage2: Option<Box<dyn Denoiser>>,
    cond: Embedding,
    uncond: Embedding,
    config: GuidanceConfig,
    schedule: NoiseSchedule,
}

impl std::fmt::Debug for CascadedGuidance {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("CascadedGuidance")
            .field("has_stage2", &self.stage2.is_some())
            .field("embedding_shape", &self.cond.shape)
            .field("config", &self.config)
            .finish_non_exhaustive()
    }
}

fn draw_or_inject<T: Clone>(
    injected: &Option<Vec<T>>,
    len: usize,
    what: &str,
    draw: impl FnOnce() -> Vec<T>,
) -> Result<Vec<T>, GuidanceError> {
    match injected {
        Some(v) if v.len() == len => Ok(v.clone()),
        Some(v) => Err(GuidanceError::InvalidInput(format!(
            "injected {what} has {} values, expected {len}",
            v.len()
        ))),
        None => Ok(draw()),
    }
}

/// `[cond × B, uncond × B]`, the embeddings of one 2B batch.
fn batch_embeddings<'a>(
    cond: &'a Embedding,
    uncond: &'a Embedding,
    batch: usize,
) -> Vec<&'a Embedding> {
    std::iter::repeat_n(cond, batch)
        .chain(std::iter::repeat_n(uncond, batch))
        .collect()
}

/// An error naming `what` when `values` hold NaN or ±∞.
fn check_finite(values: &[f32], what: impl FnOnce() -> String) -> Result<(), GuidanceError> {
    let count = crate::count_non_finite(values);
    if count == 0 {
        return Ok(());
    }
    Err(GuidanceError::NonFinite {
        tensor: what(),
        count,
        total: values.len(),
        hint: "the renderer produced them (degenerate geometry?); nothing was optimized".into(),
    })
}

/// Refuses a UNet prediction ε (the 3 channels the guidance uses) with NaN or ±∞ in either branch:
/// the reference's `nan_to_num` would silently turn it into a zero or saturated gradient.
fn check_unet_output(
    eps_cond: &[f32],
    eps_uncond: &[f32],
    stage: &str,
    model: &dyn Denoiser,
) -> Result<(), GuidanceError> {
    for (values, branch) in [(eps_cond, "conditional"), (eps_uncond, "unconditional")] {
        let count = crate::count_non_finite(values);
        if count > 0 {
            return Err(GuidanceError::NonFinite {
                tensor: format!(
                    "the {stage} UNet prediction ε, {branch} branch ({})",
                    model.describe()
                ),
                count,
                total: values.len(),
                hint: "the UNet overflowed or was fed non-finite embeddings; an fp16 export can overflow where \
                       fp32 does not (scripts/export_if_onnx.py --dtype fp32)"
                    .into(),
            });
        }
    }
    Ok(())
}

fn tensor(shape: [usize; 4], data: Vec<f32>) -> Tensor {
    Tensor {
        shape: shape.to_vec(),
        data,
    }
}

impl CascadedGuidance {
    /// Builds the guidance. `stage2` may be None (then any positive stage-II weight is an error);
    /// `cond` and `uncond` are the prompt and negative-prompt embeddings (same shape).
    pub fn new(
        stage1: Box<dyn Denoiser>,
        stage2: Option<Box<dyn Denoiser>>,
        cond: Embedding,
        uncond: Embedding,
        config: GuidanceConfig,
    ) -> Result<Self, GuidanceError> {
        config.validate()?;
        for (e, name) in [(&cond, "prompt"), (&uncond, "negative prompt")] {
            if e.data.len() != e.shape[0] * e.shape[1] {
                return Err(GuidanceError::InvalidInput(format!(
                    "{name} embedding has shape {:?} but {} values",
                    e.shape,
                    e.data.len()
                )));
            }
        }
        crate::check_embedding_finite(&cond, "the prompt embedding")?;
        crate::check_embedding_finite(&uncond, "the negative-prompt embedding")?;
        if cond.shape != uncond.shape {
            return Err(GuidanceError::InvalidInput(format!(
                "prompt embedding {:?} and negative prompt embedding {:?} differ in shape",
                cond.shape, uncond.shape
            )));
        }
        let schedule = NoiseSchedule::squaredcos_cap_v2(config.num_train_timesteps)?;
        Ok(Self {
            stage1,
            stage2,
            cond,
            uncond,
            config,
            schedule,
        })
    }

    /// The settings.
    pub fn config(&self) -> &GuidanceConfig {
        &self.config
    }

    /// The noise schedule (shared by both stages).
    pub fn schedule(&self) -> &NoiseSchedule {
        &self.schedule
    }

    /// Whether a stage-II model is present.
    pub fn has_stage2(&self) -> bool {
        self.stage2.is_some()
    }

    fn weights(&self, timesteps: &[i64]) -> Result<Vec<f64>, GuidanceError> {
        timesteps.iter().map(|&t| self.schedule.weight(t)).collect()
    }

    /// Like [`Guidance::evaluate`], returning every intermediate; `injected` replaces chosen random draws.
    pub fn evaluate_traced(
        &mut self,
        images: &[f32],
        views: usize,
        height: usize,
        width: usize,
        stage2_weight: f64,
        rng: &mut dyn RngCore,
        injected: &InjectedDraws,
    ) -> Result<GuidanceTrace, GuidanceError> {
        if views == 0
            || height == 0
            || width == 0
            || images.len() != views * height * width * CHANNELS
        {
            return Err(GuidanceError::InvalidInput(format!(
                "{} image values for {views} views of {height}×{width}×{CHANNELS}",
                images.len()
            )));
        }
        if !stage2_weight.is_finite() || stage2_weight < 0.0 {
            return Err(GuidanceError::InvalidInput(format!(
                "stage-II weight {stage2_weight} must be finite and ≥ 0"
            )));
        }
        let run_stage2 = stage2_weight > 0.0;
        if run_stage2 && self.stage2.is_none() {
            return Err(GuidanceError::InvalidInput(format!(
                "stage-II weight is {stage2_weight} but no stage-II model was given (use weight 0 to run stage I only)"
            )));
        }
        let cfg = self.config.clone();
        let b = views;
        let (r, r1, r2) = (cfg.resolution, cfg.stage1_resolution, cfg.stage2_resolution);

        // Renders (view, row, col, channel) → NCHW.
        let plane = height * width;
        let mut img = vec![0.0f32; images.len()];
        img.par_chunks_mut(CHANNELS * plane)
            .zip(images.par_chunks(CHANNELS * plane))
            .for_each(|(dst, src)| {
                for (p, px) in src.chunks_exact(CHANNELS).enumerate() {
                    for (c, &v) in px.iter().enumerate() {
                        dst[c * plane + p] = v;
                    }
                }
            });
        check_finite(&img, || "the rendered images given to the guidance".into())?;
        let resize = Resize2d::cubic_antialias((height, width), (r, r))?;
        let down1 = Resize2d::bilinear((r, r), (r1, r1))?;
        let mut x = resize.apply(&img)?;
        x.iter_mut().for_each(|v| *v = 2.0 * *v - 1.0);

        // Stage I: SDS at r1.
        let z0 = down1.apply(&x)?;
        let n1 = b * CHANNELS * r1 * r1;
        let t1 = draw_or_inject(&injected.stage1_timesteps, b, "stage-I timesteps", || {
            cfg.timesteps.sample(b, rng)
        })?;
        let eps1 = draw_or_inject(&injected.stage1_noise, n1, "stage-I noise", || {
            standard_normal(n1, rng)
        })?;
        let z_t = self.schedule.add_noise(&z0, &eps1, &t1)?;
        let mut sample = Vec::with_capacity(2 * n1);
        sample.extend_from_slice(&z_t);
        sample.extend_from_slice(&z_t);
        let ts: Vec<i64> = t1.iter().chain(&t1).copied().collect();
        let out1 = {
            let embeddings = batch_embeddings(&self.cond, &self.uncond, b);
            self.stage1.predict(
                &tensor([2 * b, CHANNELS, r1, r1], sample),
                &ts,
                &embeddings,
                None,
            )?
        };
        let (c1, u1) = split_cond_uncond(&out1, b, CHANNELS, (r1, r1))?;
        check_unet_output(&c1, &u1, "stage-I", self.stage1.as_ref())?;
        let g1 = classifier_free_guidance(&c1, &u1, cfg.guidance_scale);
        let grad1 = sds_gradient(&g1, &eps1, &self.weights(&t1)?, cfg.grad_clip)?;
        let loss1 = sds_loss(&grad1, b);

        // ∂L/∂x accumulated in f64: (S·a/B)·Dᵀ(grad_I) [+ (S·w_II/B)·Uᵀ(grad_II)].
        let k1 = cfg.loss_scale * cfg.stage1_weight / b as f64;
        let scaled1: Vec<f64> = grad1.iter().map(|&g| k1 * g as f64).collect();
        let mut grad_x = down1.adjoint(&scaled1)?;

        let shape1 = [b, CHANNELS, r1, r1];
        let stage1 = Stage1Trace {
            z0: tensor(shape1, z0),
            timesteps: t1,
            noise: tensor(shape1, eps1),
            z_t: tensor(shape1, z_t),
            eps_cond: tensor(shape1, c1),
            eps_uncond: tensor(shape1, u1),
            eps_guided: tensor(shape1, g1),
            grad: tensor(shape1, grad1),
            loss: loss1,
        };

        // Stage II: CSD at r2, conditioned on the noised upsampled stage-I input.
        let stage2 = if run_stage2 {
            let up = Resize2d::bilinear((r, r), (r2, r2))?;
            let up_low = Resize2d::bilinear((r1, r1), (r2, r2))?;
            let x0 = up.apply(&x)?;
            let z_hat = up_low.apply(&stage1.z0.data)?;
            let n2 = b * CHANNELS * r2 * r2;
            let t2 = draw_or_inject(&injected.stage2_timesteps, b, "stage-II timesteps", || {
                cfg.timesteps.sample(b, rng)
            })?;
            let s2 = draw_or_inject(
                &injected.stage2_noise_levels,
                b,
                "stage-II noise levels",
                || cfg.timesteps.sample(b, rng),
            )?;
            let eps_s = draw_or_inject(
                &injected.stage2_noise_lowres,
                n2,
                "stage-II low-res noise",
                || standard_normal(n2, rng),
            )?;
            let eps_t = draw_or_inject(&injected.stage2_noise, n2, "stage-II noise", || {
                standard_normal(n2, rng)
            })?;
            let x_t = self.schedule.add_noise(&x0, &eps_t, &t2)?;
            let z_hat_s = self.schedule.add_noise(&z_hat, &eps_s, &s2)?;
            // UNet input per sample: channels [x_t (3), ẑ_s (3)]; the batch is [cond half; uncond half].
            let per = CHANNELS * r2 * r2;
            let mut sample = Vec::with_capacity(4 * n2);
            for _half in 0..2 {
                for v in 0..b {
                    sample.extend_from_slice(&x_t[v * per..(v + 1) * per]);
                    sample.extend_from_slice(&z_hat_s[v * per..(v + 1) * per]);
                }
            }
            let ts: Vec<i64> = t2.iter().chain(&t2).copied().collect();
            let labels: Vec<i64> = s2.iter().chain(&s2).copied().collect();
            let embeddings = batch_embeddings(&self.cond, &self.uncond, b);
            let model = self
                .stage2
                .as_mut()
                .ok_or_else(|| GuidanceError::InvalidInput("no stage-II model".into()))?;
            let out2 = model.predict(
                &tensor([2 * b, 2 * CHANNELS, r2, r2], sample),
                &ts,
                &embeddings,
                Some(&labels),
            )?;
            let (c2, u2) = split_cond_uncond(&out2, b, CHANNELS, (r2, r2))?;
            check_unet_output(&c2, &u2, "stage-II", model.as_ref())?;
            let g2 = classifier_free_guidance(&c2, &u2, cfg.guidance_scale);
            let grad2 = sds_gradient(&g2, &eps_t, &self.weights(&t2)?, cfg.grad_clip)?;
            let loss2 = sds_loss(&grad2, b);
            let k2 = cfg.loss_scale * stage2_weight / b as f64;
            let scaled2: Vec<f64> = grad2.iter().map(|&g| k2 * g as f64).collect();
            for (gx, g) in grad_x.iter_mut().zip(up.adjoint(&scaled2)?) {
                *gx += g;
            }
            let shape2 = [b, CHANNELS, r2, r2];
            Some(Stage2Trace {
                weight: stage2_weight,
                x0: tensor(shape2, x0),
                z_hat: tensor(shape2, z_hat),
                timesteps: t2,
                noise_levels: s2,
                noise: tensor(shape2, eps_t),
                noise_lowres: tensor(shape2, eps_s),
                x_t: tensor(shape2, x_t),
                z_hat_s: tensor(shape2, z_hat_s),
                eps_cond: tensor(shape2, c2),
                eps_uncond: tensor(shape2, u2),
                eps_guided: tensor(shape2, g2),
                grad: tensor(shape2, grad2),
                loss: loss2,
            })
        } else {
            None
        };

        // x = 2·R(img) − 1 ⇒ ∂L/∂img = 2·Rᵀ(∂L/∂x). The 224-resize adjoint reads ∂L/∂x in f64 and writes
        // f32 (f64 accumulation); the factor 2 is applied while converting NCHW → (view, row, col,
        // channel), with a final NaN/∞ guard.
        let grad_img: Vec<f32> = resize.adjoint_as::<f64, f32>(&grad_x)?;
        let mut grad_images = vec![0.0f32; images.len()];
        grad_images
            .par_chunks_mut(CHANNELS * plane)
            .zip(grad_img.par_chunks(CHANNELS * plane))
            .for_each(|(dst, src)| {
                for (p, px) in dst.chunks_exact_mut(CHANNELS).enumerate() {
                    for (c, v) in px.iter_mut().enumerate() {
                        *v = nan_to_num((2.0 * src[c * plane + p] as f64) as f32);
                    }
                }
            });
        let output = GuidanceOutput {
            loss_stage1: cfg.loss_scale * cfg.stage1_weight * stage1.loss,
            loss_stage2: stage2
                .as_ref()
                .map_or(0.0, |s| cfg.loss_scale * stage2_weight * s.loss),
            grad_images,
        };
        let shape = [b, CHANNELS, r, r];
        Ok(GuidanceTrace {
            images: tensor([b, CHANNELS, height, width], img),
            x: tensor(shape, x),
            stage1,
            stage2,
            grad_x: tensor(
                shape,
                grad_x.iter().map(|&g| nan_to_num(g as f32)).collect(),
            ),
            output,
        })
    }
}

impl Guidance for CascadedGuidance {
    fn evaluate(
        &mut self,
        images: &[f32],
        views: usize,
        height: usize,
        width: usize,
        stage2_weight: f64,
        rng: &mut dyn RngCore,
    ) -> Result<GuidanceOutput, GuidanceError> {
        Ok(self
            .evaluate_traced(
                images,
                views,
                height,
                width,
                stage2_weight,
                rng,
                &InjectedDraws::default(),
            )?
            .output)
    }
}

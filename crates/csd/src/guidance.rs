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

use crate::resize::{PlaneResize, Resize2d};
use crate::schedule::{NoiseSchedule, TimestepRange, fill_standard_normal};
use crate::sds::{check_denoiser_output, classifier_free_guidance, nan_to_num, split_cond_uncond};
use crate::{Denoiser, Embedding, Guidance, GuidanceError, GuidanceOutput, Images, Tensor};
use optim::Schedule;
use rand::RngCore;
use rayon::prelude::*;
use std::time::Instant;

/// Image channels the guidance works on (RGB; a grey render is taken as its RGB expansion).
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

/// What both stages trace alike: one score-distillation step on a UNet batch. Tensors are NCHW
/// `(B, 3, side, side)` at the stage's resolution.
#[derive(Clone, Debug)]
pub struct ScoreTrace {
    /// t per view.
    pub timesteps: Vec<i64>,
    /// ε added to the clean stage input (stage II: ε_t added to x0).
    pub noise: Tensor,
    /// Conditional prediction ε_c (first 3 output channels).
    pub eps_cond: Tensor,
    /// Unconditional prediction ε_u.
    pub eps_uncond: Tensor,
    /// ε̂ = ε_c + g(ε_c − ε_u).
    pub eps_guided: Tensor,
    /// grad = nan_to_num(w(t)(ε̂ − ε)).
    pub grad: Tensor,
    /// L = ½‖grad‖²/B (unweighted).
    pub loss: f64,
}

/// Every intermediate of stage I (SDS at 64 px). Tensors are NCHW.
#[derive(Clone, Debug)]
pub struct Stage1Trace {
    /// z0 = bilinear(x → 64), `(B, 3, 64, 64)`.
    pub z0: Tensor,
    /// z_t = √ᾱ_t z0 + √(1 − ᾱ_t) ε.
    pub z_t: Tensor,
    /// t, ε, the predictions, grad_I and L_I.
    pub score: ScoreTrace,
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
    /// s per view (the class label).
    pub noise_levels: Vec<i64>,
    /// ε_s added to ẑ.
    pub noise_lowres: Tensor,
    /// x_t = add_noise(x0, ε_t, t).
    pub x_t: Tensor,
    /// ẑ_s = add_noise(ẑ, ε_s, s).
    pub z_hat_s: Tensor,
    /// t, ε_t, the predictions, grad_II and L_II.
    pub score: ScoreTrace,
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

/// The stage-II weight schedule of the reference (`stage_II_weight_schedule`): w_II ramps 0 → 0.2
/// over iterations 1–1000, then 0.2 → 0.3 over the next 750, then stays at 0.3.
pub fn reference_stage2_weight() -> Schedule {
    Schedule::parse(REFERENCE_STAGE2_WEIGHT).unwrap_or_else(|_| Schedule::constant(0.0))
}

/// [`reference_stage2_weight`] in the schedule grammar of [`optim::Schedule`].
pub const REFERENCE_STAGE2_WEIGHT: &str = "0.0>0.2:1000; 0.2>0.3:750";

/// SDS (IF stage I) + CSD (IF stage II) guidance, see the module docs for the exact objective.
///
/// Loss values reported in [`GuidanceOutput`]: `loss_stage1 = S·a·L_I` and `loss_stage2 = S·w_II·L_II`
/// with the reference's per-stage form `L = ½‖grad‖²/B`, so `loss_stage1 + loss_stage2` is exactly the
/// surrogate whose gradient `grad_images` is.
///
/// The denoisers are boxed trait objects that may borrow (`'m`): `Box::new(&mut unet)` lends a UNet
/// that outlives the guidance (a batch of prompts reuses one set of sessions), `Box::new(unet)` hands
/// it over (`CascadedGuidance<'static>`).
pub struct CascadedGuidance<'m> {
    stage1: Box<dyn Denoiser + 'm>,
    stage2: Option<Box<dyn Denoiser + 'm>>,
    /// w_II(iteration), read by [`Guidance::evaluate`].
    stage2_weight: Schedule,
    cond: Embedding,
    uncond: Embedding,
    config: GuidanceConfig,
    schedule: NoiseSchedule,
    /// Resize operators for the current render size (rebuilt when it changes).
    ops: Option<Operators>,
    work: Workspace,
}

impl std::fmt::Debug for CascadedGuidance<'_> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("CascadedGuidance")
            .field("has_stage2", &self.stage2.is_some())
            .field("stage2_weight", &self.stage2_weight)
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

/// The error for non-finite ε in one branch of a stage's UNet output.
fn unet_output_error(
    stage: &str,
    branch: &str,
    model: &dyn Denoiser,
    count: usize,
    total: usize,
) -> GuidanceError {
    GuidanceError::NonFinite {
        tensor: format!(
            "the {stage} UNet prediction ε, {branch} branch ({})",
            model.describe()
        ),
        count,
        total,
        hint: "the UNet overflowed or was fed non-finite embeddings; an fp16 export can overflow where \
               fp32 does not (scripts/export_if_onnx.py --dtype fp32)"
            .into(),
    }
}

/// w(t) = 1 − ᾱ_t per view.
fn weights(schedule: &NoiseSchedule, timesteps: &[i64]) -> Result<Vec<f64>, GuidanceError> {
    timesteps.iter().map(|&t| schedule.weight(t)).collect()
}

fn tensor(shape: [usize; 4], data: Vec<f32>) -> Tensor {
    Tensor {
        shape: shape.to_vec(),
        data,
    }
}

/// Resize operators (f32 gather form) for one input size; rebuilt when the render size changes.
#[derive(Debug)]
struct Operators {
    input_hw: (usize, usize),
    /// R: renders → `resolution` (antialiased cubic), and Rᵀ.
    resize: PlaneResize,
    resize_t: PlaneResize,
    /// D: `resolution` → `stage1_resolution`, and Dᵀ.
    down1: PlaneResize,
    down1_t: PlaneResize,
    /// U: `resolution` → `stage2_resolution`, and Uᵀ.
    up: PlaneResize,
    up_t: PlaneResize,
    /// `stage1_resolution` → `stage2_resolution` (ẑ; no adjoint needed).
    up_low: PlaneResize,
}

impl Operators {
    fn new(cfg: &GuidanceConfig, input_hw: (usize, usize)) -> Result<Self, GuidanceError> {
        let (r, r1, r2) = (cfg.resolution, cfg.stage1_resolution, cfg.stage2_resolution);
        let resize = Resize2d::cubic_antialias(input_hw, (r, r))?;
        let down1 = Resize2d::bilinear((r, r), (r1, r1))?;
        let up = Resize2d::bilinear((r, r), (r2, r2))?;
        let up_low = Resize2d::bilinear((r1, r1), (r2, r2))?;
        Ok(Self {
            input_hw,
            resize: PlaneResize::forward(&resize),
            resize_t: PlaneResize::adjoint(&resize),
            down1: PlaneResize::forward(&down1),
            down1_t: PlaneResize::adjoint(&down1),
            up: PlaneResize::forward(&up),
            up_t: PlaneResize::adjoint(&up),
            up_low: PlaneResize::forward(&up_low),
        })
    }
}

/// Buffers owned by the guidance and reused by every evaluation (grown on first use), so that no
/// large intermediate is allocated per call: at 8 views the stage-II batch alone is 2B·6·256² values
/// (25 MB). Planar NCHW unless stated.
#[derive(Debug, Default)]
struct Workspace {
    /// x = 2·R(img) − 1, `(B, 3, r, r)`.
    x: Vec<f32>,
    /// z0 = D(x), `(B, 3, r1, r1)`.
    z0: Vec<f32>,
    /// Stage-I ε.
    eps1: Vec<f32>,
    /// `[z_t; z_t]`, `(2B, 3, r1, r1)`.
    sample1: Tensor,
    /// grad_I.
    grad1: Vec<f32>,
    /// x0 = U(x), ẑ = U₆₄→₂₅₆(z0), ε_s, ε_t: `(B, 3, r2, r2)` each.
    x0: Vec<f32>,
    z_hat: Vec<f32>,
    eps_s: Vec<f32>,
    eps_t: Vec<f32>,
    /// `[x_t ++ ẑ_s] × 2`, `(2B, 6, r2, r2)`.
    sample2: Tensor,
    /// grad_II.
    grad2: Vec<f32>,
    /// ∂L/∂x, `(B, 3, r, r)`; with [`Stages::grey_gradient`] its channel sums Σ_c ∂L/∂x_c,
    /// `(B, r, r)`.
    grad_x: Vec<f32>,
    /// Per-view scratch for the interleaved resizes (one per view, so views run in parallel).
    scratch: Vec<Vec<f32>>,
    /// Per view, whether the last encoded render's three channels are equal bit for bit (a grey
    /// renderer's output): then the three planes of x, z0, x0 and ẑ are equal too, and each is
    /// computed once and copied.
    grey: Vec<bool>,
    /// Per-plane scratch for the planar resizes: (resize intermediate, an output plane).
    plane_scratch: Vec<(Vec<f32>, Vec<f32>)>,
    /// Which of the buffers derived from the renders alone (no random draw) hold the values of
    /// the renders last encoded, so that [`Guidance::evaluate_many`] computes them once.
    derived: Derived,
}

/// Validity of the render-derived workspace buffers (all false until the renders are encoded).
#[derive(Clone, Copy, Debug, Default)]
struct Derived {
    /// `x` holds 2·R(img) − 1 of the last encoded renders.
    x: bool,
    /// `z0` holds D(x).
    z0: bool,
    /// `x0` and `z_hat` hold U(x) and U₆₄→₂₅₆(z0).
    upsampled: bool,
}

/// Copies the first channel of interleaved RGB pixels `src` into `plane` when the three channels
/// are equal bit for bit (a grey render) and returns true; returns false at the first pixel
/// whose channels differ (then `plane` holds a partial copy and is not to be used).
fn first_channel_if_grey(src: &[f32], plane: &mut Vec<f32>) -> bool {
    plane.resize(src.len() / CHANNELS, 0.0);
    for (o, px) in plane.iter_mut().zip(src.chunks_exact(CHANNELS)) {
        let bits = px[0].to_bits();
        if px[1].to_bits() != bits || px[2].to_bits() != bits {
            return false;
        }
        *o = px[0];
    }
    true
}

/// Fills the `CHANNELS` planes of `out` (each `plane` values) with `f(c, plane c)`; for a grey
/// view (equal channel planes in, so equal planes out) computes plane 0 only and copies it.
fn per_plane(grey: bool, out: &mut [f32], plane: usize, mut f: impl FnMut(usize, &mut [f32])) {
    let (first, rest) = out.split_at_mut(plane);
    f(0, first);
    for (c, o) in rest.chunks_exact_mut(plane).enumerate() {
        if grey {
            o.copy_from_slice(first);
        } else {
            f(c + 1, o);
        }
    }
}

/// Σ_c of the three equal-sized channel planes of `planes`, into `sum` (in `f32`, in channel
/// order).
fn channel_sums(planes: &[f32], sum: &mut Vec<f32>) {
    let p = planes.len() / CHANNELS;
    sum.clear();
    sum.extend(
        planes[..p]
            .iter()
            .zip(&planes[p..2 * p])
            .zip(&planes[2 * p..3 * p])
            .map(|((&a, &b), &c)| a + b + c),
    );
}

/// Noise into `buf`: the injected values (length checked) or `len` fresh samples from `rng`.
fn noise_into(
    buf: &mut Vec<f32>,
    injected: &Option<Vec<f32>>,
    len: usize,
    what: &str,
    rng: &mut dyn RngCore,
) -> Result<(), GuidanceError> {
    match injected {
        Some(v) if v.len() == len => {
            buf.clear();
            buf.extend_from_slice(v);
        }
        Some(v) => {
            return Err(GuidanceError::InvalidInput(format!(
                "injected {what} has {} values, expected {len}",
                v.len()
            )));
        }
        None => {
            buf.resize(len, 0.0);
            fill_standard_normal(buf, rng);
        }
    }
    Ok(())
}

/// `add_noise` coefficients (√ᾱ_t, √(1 − ᾱ_t)) per view, computed in `f64`, applied in `f32`.
fn noise_coefficients(
    schedule: &NoiseSchedule,
    timesteps: &[i64],
) -> Result<Vec<(f32, f32)>, GuidanceError> {
    timesteps
        .iter()
        .map(|&t| {
            let a = schedule.alpha_bar(t)?;
            Ok((a.sqrt() as f32, (1.0 - a).sqrt() as f32))
        })
        .collect()
}

/// The fused per-stage pass over a denoiser output `(2B, C_out, H, W)` (conditional half first): for
/// every value of the 3 ε channels, ε̂ = ε_c + g·(ε_c − ε_u), grad = clip(nan_to_num(w_b·(ε̂ − ε)))
/// (exactly [`classifier_free_guidance`] then [`sds_gradient`]), written to `grad`; non-finite ε in
/// either branch is an error naming the stage, the branch and `model`. Returns L = ½‖grad‖²/B
/// (summed in `f64`: per plane in [`SDS_LANES`] interleaved partial sums, see [`sds_plane`];
/// planes added in order; deterministic for any thread count).
#[allow(clippy::too_many_arguments)]
fn fused_sds(
    out: &Tensor,
    batch: usize,
    hw: (usize, usize),
    noise: &[f32],
    weights: &[f64],
    cfg: &GuidanceConfig,
    grad: &mut Vec<f32>,
    stage: &str,
    model: &dyn Denoiser,
) -> Result<f64, GuidanceError> {
    check_denoiser_output(out, batch, CHANNELS, hw)?;
    let c_out = out.shape[1];
    let plane = hw.0 * hw.1;
    grad.resize(batch * CHANNELS * plane, 0.0);
    let g = cfg.guidance_scale;
    let clip = cfg.grad_clip;
    let per_plane: Vec<(f64, usize, usize)> = grad
        .par_chunks_mut(plane)
        .zip(noise.par_chunks(plane))
        .enumerate()
        .map(|(q, (gr, eps))| {
            let (b, c) = (q / CHANNELS, q % CHANNELS);
            let w = weights[b] as f32;
            let cond = &out.data[(b * c_out + c) * plane..][..plane];
            let uncond = &out.data[((batch + b) * c_out + c) * plane..][..plane];
            sds_plane(gr, cond, uncond, eps, w, g, clip)
        })
        .collect();
    let (mut sum, mut bad_c, mut bad_u) = (0.0f64, 0usize, 0usize);
    for (s, c, u) in per_plane {
        sum += s;
        bad_c += c;
        bad_u += u;
    }
    for (count, branch) in [(bad_c, "conditional"), (bad_u, "unconditional")] {
        if count > 0 {
            return Err(unet_output_error(stage, branch, model, count, grad.len()));
        }
    }
    Ok(0.5 * sum / batch.max(1) as f64)
}

/// [`fused_sds`] on one plane: writes `grad` and returns (Σ grad² in `f64`, non-finite conditional
/// ε, non-finite unconditional ε). Two passes that both vectorize: the gradient (branch-free
/// [`nan_to_num`]), then the sum, where value m goes to partial sum m mod [`SDS_LANES`] (independent chains of
/// additions instead of one) and the partial sums are added in lane order: the same bits for any
/// thread count.
fn sds_plane(
    grad: &mut [f32],
    cond: &[f32],
    uncond: &[f32],
    noise: &[f32],
    w: f32,
    g: f32,
    clip: Option<f32>,
) -> (f64, usize, usize) {
    let n = grad.len();
    let (cond, uncond, noise) = (&cond[..n], &uncond[..n], &noise[..n]);
    let (mut bad_c, mut bad_u) = (0usize, 0usize);
    for (((o, &ce), &ue), &e) in grad.iter_mut().zip(cond).zip(uncond).zip(noise) {
        bad_c += usize::from(!ce.is_finite());
        bad_u += usize::from(!ue.is_finite());
        let e_hat = ce + g * (ce - ue);
        let v = nan_to_num(w * (e_hat - e));
        *o = match clip {
            Some(k) => v.clamp(-k, k),
            None => v,
        };
    }
    let mut sums = [0.0f64; SDS_LANES];
    let mut chunks = grad.chunks_exact(SDS_LANES);
    for c in &mut chunks {
        for (s, &v) in sums.iter_mut().zip(c) {
            *s += f64::from(v) * f64::from(v);
        }
    }
    for (s, &v) in sums.iter_mut().zip(chunks.remainder()) {
        *s += f64::from(v) * f64::from(v);
    }
    (sums.iter().sum(), bad_c, bad_u)
}

/// Partial sums per plane in [`sds_plane`].
const SDS_LANES: usize = 8;

/// What stage I leaves besides the workspace buffers.
struct Stage1Core {
    t1: Vec<i64>,
    loss1: f64,
    /// Wall time of the denoiser call, seconds.
    denoiser_seconds: f64,
    /// The UNet output, kept only for a trace.
    out1: Option<Tensor>,
}

/// What stage II leaves besides the workspace buffers.
struct Stage2Core {
    t2: Vec<i64>,
    s2: Vec<i64>,
    loss2: f64,
    /// Wall time of the denoiser call, seconds.
    denoiser_seconds: f64,
    /// The UNet output, kept only for a trace.
    out2: Option<Tensor>,
}

/// What [`CascadedGuidance::evaluate_core`] leaves besides the workspace buffers.
struct Core {
    output: GuidanceOutput,
    stage1: Stage1Core,
    stage2: Option<Stage2Core>,
}

/// The switches of [`CascadedGuidance::evaluate_core`]: [`Stages::keep_outputs`] and
/// `reuse_encoding` (see `evaluate_core`).
#[derive(Clone, Copy, Debug)]
struct CoreOptions {
    keep_outputs: bool,
    reuse_encoding: bool,
}

/// What every stage of one evaluation reads.
struct Stages<'a> {
    cfg: &'a GuidanceConfig,
    schedule: &'a NoiseSchedule,
    ops: &'a Operators,
    cond: &'a Embedding,
    uncond: &'a Embedding,
    /// B, the number of views.
    views: usize,
    /// Keep the denoiser outputs (for a trace).
    keep_outputs: bool,
    /// Accumulate ∂L/∂x as one plane per view, Σ_c ∂L/∂x_c (for grey renders, decoded by
    /// [`Stages::decode_grey_gradient`]): each stage sums its gradient's three channels at its own
    /// resolution and maps one plane back instead of three (the adjoint resizes are linear, so the
    /// same values up to `f32` rounding as the channel sums of the RGB expansion's gradient).
    grey_gradient: bool,
}

impl Stages<'_> {
    /// x = 2·R(img) − 1: renders (view, row, col, channel) straight into planar x; the height pass
    /// runs over whole interleaved rows. A grey view (a one-channel render, or three equal
    /// channels) is resized once and the plane copied: the same values, since R acts on each
    /// channel alone with the same operations. (A one-channel render whose resize runs width first
    /// is resized as its RGB expansion, which is what that order's bits are defined by.)
    /// Non-finite renders show up as non-finite x (an error).
    fn encode_renders(&self, images: &Images, w: &mut Workspace) -> Result<(), GuidanceError> {
        let (b, pr) = (self.views, self.cfg.resolution * self.cfg.resolution);
        let plane_in = images.height * images.width;
        let channels_in = images.channels;
        let ops = self.ops;
        w.derived = Derived::default();
        w.scratch.resize_with(b, Vec::new);
        w.plane_scratch.resize_with(b * CHANNELS, Default::default);
        w.grey.resize(b, false);
        w.x.resize(b * CHANNELS * pr, 0.0);
        let bad_x: usize =
            w.x.par_chunks_mut(CHANNELS * pr)
                .zip(images.rgb.par_chunks(channels_in * plane_in))
                .zip(w.scratch.par_iter_mut())
                .zip(w.plane_scratch.par_chunks_mut(CHANNELS))
                .zip(w.grey.par_iter_mut())
                .map(|((((xv, src), tmp), planes), grey)| {
                    let (first, _) = &mut planes[0];
                    // The shortcut has the per-channel path's bits only when the plane resize
                    // runs height first too; otherwise the channels are not even compared.
                    let height_first = ops.resize.height_first();
                    // One plane resized and copied to the three planes of x.
                    let once = |plane: &[f32], xv: &mut [f32], tmp: &mut Vec<f32>| {
                        ops.resize.apply_plane(plane, &mut xv[..pr], tmp);
                        let (x_first, rest) = xv.split_at_mut(pr);
                        rest.chunks_exact_mut(pr)
                            .for_each(|p| p.copy_from_slice(x_first));
                    };
                    if channels_in == CHANNELS {
                        *grey = height_first && first_channel_if_grey(src, first);
                        if *grey {
                            once(first, xv, tmp);
                        } else {
                            ops.resize.apply_from_interleaved(src, CHANNELS, xv, tmp);
                        }
                    } else if height_first {
                        *grey = true;
                        once(src, xv, tmp);
                    } else {
                        *grey = false;
                        first.clear();
                        first.extend(src.iter().flat_map(|&v| [v; CHANNELS]));
                        ops.resize.apply_from_interleaved(first, CHANNELS, xv, tmp);
                    }
                    let mut bad = 0;
                    for v in xv.iter_mut() {
                        *v = 2.0 * *v - 1.0;
                        bad += usize::from(!v.is_finite());
                    }
                    bad
                })
                .sum();
        if bad_x == 0 {
            w.derived.x = true;
            return Ok(());
        }
        // Counted in the RGB images the UNets see (a grey value stands for three).
        let expansion = CHANNELS / channels_in;
        let count = crate::count_non_finite(&images.rgb) * expansion;
        Err(GuidanceError::NonFinite {
            tensor: if count > 0 {
                "the rendered images given to the guidance".into()
            } else {
                "x = 2·resize(renders) − 1 (the renders are finite but so large that the resize overflows)"
                    .into()
            },
            count: if count > 0 { count } else { bad_x },
            total: if count > 0 {
                images.rgb.len() * expansion
            } else {
                w.x.len()
            },
            hint: "the renderer produced them (degenerate geometry?); nothing was optimized".into(),
        })
    }

    /// Stage I, SDS at r1: z0 = D(x), z_t, one UNet call on [z_t; z_t], grad_I; then starts
    /// ∂L/∂x = (S·a/B)·Dᵀ(grad_I) (in f32, the reference's precision).
    fn stage1(
        &self,
        model: &mut dyn Denoiser,
        w: &mut Workspace,
        rng: &mut dyn RngCore,
        injected: &InjectedDraws,
    ) -> Result<Stage1Core, GuidanceError> {
        let (cfg, ops, b) = (self.cfg, self.ops, self.views);
        let (r, r1) = (cfg.resolution, cfg.stage1_resolution);
        let (pr, p1) = (r * r, r1 * r1);
        if !w.derived.z0 {
            w.z0.resize(b * CHANNELS * p1, 0.0);
            w.z0.par_chunks_mut(CHANNELS * p1)
                .zip(w.x.par_chunks(CHANNELS * pr))
                .zip(w.plane_scratch.par_chunks_mut(CHANNELS))
                .zip(w.grey.par_iter())
                .for_each(|(((z, x), scratch), &grey)| {
                    per_plane(grey, z, p1, |c, z| {
                        ops.down1
                            .apply_plane(&x[c * pr..(c + 1) * pr], z, &mut scratch[c].0);
                    });
                });
            w.derived.z0 = true;
        }
        let n1 = b * CHANNELS * p1;
        let t1 = draw_or_inject(&injected.stage1_timesteps, b, "stage-I timesteps", || {
            cfg.timesteps.sample(b, rng)
        })?;
        noise_into(
            &mut w.eps1,
            &injected.stage1_noise,
            n1,
            "stage-I noise",
            rng,
        )?;
        let coef1 = noise_coefficients(self.schedule, &t1)?;
        w.sample1.shape = vec![2 * b, CHANNELS, r1, r1];
        w.sample1.data.resize(2 * n1, 0.0);
        {
            let (z_t, copy) = w.sample1.data.split_at_mut(n1);
            z_t.par_chunks_mut(CHANNELS * p1)
                .zip(w.z0.par_chunks(CHANNELS * p1))
                .zip(w.eps1.par_chunks(CHANNELS * p1))
                .zip(coef1.par_iter())
                .for_each(|(((o, z), e), &(a, s))| {
                    for ((o, &z), &e) in o.iter_mut().zip(z).zip(e) {
                        *o = a * z + s * e;
                    }
                });
            copy.copy_from_slice(z_t);
        }
        let ts: Vec<i64> = t1.iter().chain(&t1).copied().collect();
        let embeddings = batch_embeddings(self.cond, self.uncond, b);
        let clock = Instant::now();
        let out1 = model.predict(&w.sample1, &ts, &embeddings, None)?;
        let denoiser_seconds = clock.elapsed().as_secs_f64();
        let w1 = weights(self.schedule, &t1)?;
        let loss1 = fused_sds(
            &out1,
            b,
            (r1, r1),
            &w.eps1,
            &w1,
            cfg,
            &mut w.grad1,
            "stage-I",
            &*model,
        )?;
        let k1 = (cfg.loss_scale * cfg.stage1_weight / b as f64) as f32;
        let set_adjoint = |gx: &mut [f32], g: &[f32], tmp: &mut Vec<f32>| {
            ops.down1_t.apply_plane(g, gx, tmp);
            gx.iter_mut().for_each(|v| *v *= k1);
        };
        if self.grey_gradient {
            w.grad_x.resize(b * pr, 0.0);
            w.grad_x
                .par_chunks_mut(pr)
                .zip(w.grad1.par_chunks(CHANNELS * p1))
                .zip(w.plane_scratch.par_chunks_mut(CHANNELS))
                .for_each(|((gx, g), planes)| {
                    let (tmp, sum) = &mut planes[0];
                    channel_sums(g, sum);
                    set_adjoint(gx, sum, tmp);
                });
        } else {
            w.grad_x.resize(b * CHANNELS * pr, 0.0);
            w.grad_x
                .par_chunks_mut(pr)
                .zip(w.grad1.par_chunks(p1))
                .zip(w.plane_scratch.par_iter_mut())
                .for_each(|((gx, g), (tmp, _))| set_adjoint(gx, g, tmp));
        }
        Ok(Stage1Core {
            t1,
            loss1,
            denoiser_seconds,
            out1: self.keep_outputs.then_some(out1),
        })
    }

    /// Stage II, CSD at r2 conditioned on the noised upsampled stage-I input: x0 = U(x),
    /// ẑ = U₆₄→₂₅₆(z0), one UNet call on [x_t ++ ẑ_s] × 2, grad_II; then adds (S·w_II/B)·Uᵀ(grad_II)
    /// to ∂L/∂x.
    #[allow(clippy::too_many_arguments)]
    fn stage2(
        &self,
        model: &mut dyn Denoiser,
        weight: f64,
        w: &mut Workspace,
        rng: &mut dyn RngCore,
        injected: &InjectedDraws,
    ) -> Result<Stage2Core, GuidanceError> {
        let (cfg, ops, b) = (self.cfg, self.ops, self.views);
        let (r, r1, r2) = (cfg.resolution, cfg.stage1_resolution, cfg.stage2_resolution);
        let (pr, p1, p2) = (r * r, r1 * r1, r2 * r2);
        let n2 = b * CHANNELS * p2;
        if !w.derived.upsampled {
            w.x0.resize(n2, 0.0);
            w.z_hat.resize(n2, 0.0);
            w.x0.par_chunks_mut(CHANNELS * p2)
                .zip(w.x.par_chunks(CHANNELS * pr))
                .zip(w.z_hat.par_chunks_mut(CHANNELS * p2))
                .zip(w.z0.par_chunks(CHANNELS * p1))
                .zip(w.plane_scratch.par_chunks_mut(CHANNELS))
                .zip(w.grey.par_iter())
                .for_each(|(((((x0, x), z_hat), z0), scratch), &grey)| {
                    per_plane(grey, x0, p2, |c, o| {
                        ops.up
                            .apply_plane(&x[c * pr..(c + 1) * pr], o, &mut scratch[c].0);
                    });
                    per_plane(grey, z_hat, p2, |c, o| {
                        ops.up_low
                            .apply_plane(&z0[c * p1..(c + 1) * p1], o, &mut scratch[c].0);
                    });
                });
            w.derived.upsampled = true;
        }
        let t2 = draw_or_inject(&injected.stage2_timesteps, b, "stage-II timesteps", || {
            cfg.timesteps.sample(b, rng)
        })?;
        let s2 = draw_or_inject(
            &injected.stage2_noise_levels,
            b,
            "stage-II noise levels",
            || cfg.timesteps.sample(b, rng),
        )?;
        noise_into(
            &mut w.eps_s,
            &injected.stage2_noise_lowres,
            n2,
            "stage-II low-res noise",
            rng,
        )?;
        noise_into(
            &mut w.eps_t,
            &injected.stage2_noise,
            n2,
            "stage-II noise",
            rng,
        )?;
        let (coef_t, coef_s) = (
            noise_coefficients(self.schedule, &t2)?,
            noise_coefficients(self.schedule, &s2)?,
        );
        // UNet input per sample: channels [x_t (3), ẑ_s (3)]; the batch is [cond half; uncond half].
        w.sample2.shape = vec![2 * b, 2 * CHANNELS, r2, r2];
        w.sample2.data.resize(4 * n2, 0.0);
        let (x0, eps_t, z_hat, eps_s) = (&w.x0, &w.eps_t, &w.z_hat, &w.eps_s);
        // The unconditional half is the same samples: each plane is copied there while it is in
        // cache.
        let (cond_half, uncond_half) = w.sample2.data.split_at_mut(2 * n2);
        cond_half
            .par_chunks_mut(p2)
            .zip(uncond_half.par_chunks_mut(p2))
            .enumerate()
            .for_each(|(q, (o, u))| {
                let (v, ch) = (q / (2 * CHANNELS), q % (2 * CHANNELS));
                let (clean, noise, (a, s)) = if ch < CHANNELS {
                    let i = (v * CHANNELS + ch) * p2;
                    (&x0[i..i + p2], &eps_t[i..i + p2], coef_t[v])
                } else {
                    let i = (v * CHANNELS + ch - CHANNELS) * p2;
                    (&z_hat[i..i + p2], &eps_s[i..i + p2], coef_s[v])
                };
                for ((o, &z), &e) in o.iter_mut().zip(clean).zip(noise) {
                    *o = a * z + s * e;
                }
                u.copy_from_slice(o);
            });
        let ts: Vec<i64> = t2.iter().chain(&t2).copied().collect();
        let labels: Vec<i64> = s2.iter().chain(&s2).copied().collect();
        let embeddings = batch_embeddings(self.cond, self.uncond, b);
        let clock = Instant::now();
        let out2 = model.predict(&w.sample2, &ts, &embeddings, Some(&labels))?;
        let denoiser_seconds = clock.elapsed().as_secs_f64();
        let w2 = weights(self.schedule, &t2)?;
        let loss2 = fused_sds(
            &out2,
            b,
            (r2, r2),
            &w.eps_t,
            &w2,
            cfg,
            &mut w.grad2,
            "stage-II",
            &*model,
        )?;
        let k2 = (cfg.loss_scale * weight / b as f64) as f32;
        let add_adjoint = |gx: &mut [f32], g: &[f32], tmp: &mut Vec<f32>, up: &mut Vec<f32>| {
            up.resize(pr, 0.0);
            ops.up_t.apply_plane(g, up, tmp);
            for (a, &u) in gx.iter_mut().zip(up.iter()) {
                *a += k2 * u;
            }
        };
        if self.grey_gradient {
            w.grad_x
                .par_chunks_mut(pr)
                .zip(w.grad2.par_chunks(CHANNELS * p2))
                .zip(w.plane_scratch.par_chunks_exact_mut(CHANNELS))
                .for_each(|((gx, g), planes)| {
                    let (first, rest) = planes.split_at_mut(1);
                    let ((tmp, up), (_, sum)) = (&mut first[0], &mut rest[0]);
                    channel_sums(g, sum);
                    add_adjoint(gx, sum, tmp, up);
                });
        } else {
            w.grad_x
                .par_chunks_mut(pr)
                .zip(w.grad2.par_chunks(p2))
                .zip(w.plane_scratch.par_iter_mut())
                .for_each(|((gx, g), (tmp, up))| add_adjoint(gx, g, tmp, up));
        }
        Ok(Stage2Core {
            t2,
            s2,
            loss2,
            denoiser_seconds,
            out2: self.keep_outputs.then_some(out2),
        })
    }

    /// x = 2·R(img) − 1 ⇒ ∂L/∂img = 2·Rᵀ(∂L/∂x), written straight into (view, row, col, channel)
    /// with a final NaN/∞ guard. Reads ∂L/∂x per channel (not [`Self::grey_gradient`]).
    fn decode_gradient(&self, images: &Images, w: &mut Workspace) -> Images {
        let pr = self.cfg.resolution * self.cfg.resolution;
        let plane_in = images.height * images.width;
        // Zeroed in parallel (every value is overwritten below; the batch is 25 MB at 8 × 512²).
        let mut grad = Images {
            rgb: Vec::new(),
            ..*images
        };
        grad.rgb
            .par_extend(rayon::iter::repeat_n(0.0f32, images.rgb.len()));
        grad.rgb
            .par_chunks_mut(CHANNELS * plane_in)
            .zip(w.grad_x.par_chunks(CHANNELS * pr))
            .zip(w.scratch.par_iter_mut())
            .for_each(|((out, gx), tmp)| {
                self.ops
                    .resize_t
                    .apply_to_interleaved(gx, CHANNELS, out, tmp, |v| nan_to_num(2.0 * v));
            });
        grad
    }

    /// dL/d(grey) = Σ_c ∂L/∂img_c = 2·Rᵀ(Σ_c ∂L/∂x_c) (Rᵀ is linear) of grey `images`: reads
    /// the channel sums the stages accumulated ([`Self::grey_gradient`]; each summed its
    /// gradient's channels at its own resolution, in `f32`, in channel order) and maps one plane
    /// per view back, with the same final NaN/∞ guard as [`Self::decode_gradient`].
    fn decode_grey_gradient(&self, images: &Images, w: &mut Workspace) -> Images {
        let pr = self.cfg.resolution * self.cfg.resolution;
        let plane_in = images.height * images.width;
        // Zeroed in parallel (every value is overwritten below).
        let mut grey = Vec::new();
        grey.par_extend(rayon::iter::repeat_n(0.0f32, images.count * plane_in));
        grey.par_chunks_mut(plane_in)
            .zip(w.grad_x.par_chunks(pr))
            .zip(w.plane_scratch.par_chunks_mut(CHANNELS))
            .for_each(|((out, gx), planes)| {
                self.ops.resize_t.apply_plane(gx, out, &mut planes[0].0);
                out.iter_mut().for_each(|v| *v = nan_to_num(2.0 * *v));
            });
        Images {
            rgb: grey,
            ..*images
        }
    }

    /// ∂L/∂img in the channel count of `images`: [`Self::decode_grey_gradient`] for grey
    /// images (then the stages accumulated [`Self::grey_gradient`] sums), else
    /// [`Self::decode_gradient`].
    fn decode(&self, images: &Images, w: &mut Workspace) -> Images {
        if self.grey_gradient {
            self.decode_grey_gradient(images, w)
        } else {
            self.decode_gradient(images, w)
        }
    }

    /// The shared part of a stage's trace from its UNet output and workspace buffers.
    #[allow(clippy::too_many_arguments)]
    fn score_trace(
        &self,
        out: Option<Tensor>,
        side: usize,
        timesteps: Vec<i64>,
        noise: &[f32],
        grad: &[f32],
        loss: f64,
        stage: &str,
    ) -> Result<ScoreTrace, GuidanceError> {
        let out = out.ok_or_else(|| {
            GuidanceError::InvalidInput(format!("internal: {stage} output not kept"))
        })?;
        let b = self.views;
        let (c, u) = split_cond_uncond(&out, b, CHANNELS, (side, side))?;
        let g = classifier_free_guidance(&c, &u, self.cfg.guidance_scale);
        let shape = [b, CHANNELS, side, side];
        Ok(ScoreTrace {
            timesteps,
            noise: tensor(shape, noise.to_vec()),
            eps_cond: tensor(shape, c),
            eps_uncond: tensor(shape, u),
            eps_guided: tensor(shape, g),
            grad: tensor(shape, grad.to_vec()),
            loss,
        })
    }

    /// Stage I's trace.
    fn stage1_trace(&self, core: Stage1Core, w: &Workspace) -> Result<Stage1Trace, GuidanceError> {
        let (b, r1) = (self.views, self.cfg.stage1_resolution);
        let shape = [b, CHANNELS, r1, r1];
        let n1 = b * CHANNELS * r1 * r1;
        Ok(Stage1Trace {
            z0: tensor(shape, w.z0.clone()),
            z_t: tensor(shape, w.sample1.data[..n1].to_vec()),
            score: self.score_trace(
                core.out1, r1, core.t1, &w.eps1, &w.grad1, core.loss1, "stage-I",
            )?,
        })
    }

    /// Stage II's trace; `weight` is the w_II used.
    fn stage2_trace(
        &self,
        core: Stage2Core,
        weight: f64,
        w: &Workspace,
    ) -> Result<Stage2Trace, GuidanceError> {
        let (b, r2) = (self.views, self.cfg.stage2_resolution);
        let per = CHANNELS * r2 * r2;
        let (mut x_t, mut z_hat_s) = (Vec::with_capacity(b * per), Vec::with_capacity(b * per));
        for v in 0..b {
            let base = v * 2 * per;
            x_t.extend_from_slice(&w.sample2.data[base..base + per]);
            z_hat_s.extend_from_slice(&w.sample2.data[base + per..base + 2 * per]);
        }
        let shape = [b, CHANNELS, r2, r2];
        Ok(Stage2Trace {
            weight,
            x0: tensor(shape, w.x0.clone()),
            z_hat: tensor(shape, w.z_hat.clone()),
            noise_levels: core.s2,
            noise_lowres: tensor(shape, w.eps_s.clone()),
            x_t: tensor(shape, x_t),
            z_hat_s: tensor(shape, z_hat_s),
            score: self.score_trace(
                core.out2, r2, core.t2, &w.eps_t, &w.grad2, core.loss2, "stage-II",
            )?,
        })
    }
}

/// NCHW copy of `(view, row, col, channel)` images.
fn planar(images: &Images) -> Tensor {
    let plane = images.height * images.width;
    let mut data = vec![0.0f32; images.rgb.len()];
    for (dst, src) in data
        .chunks_mut(CHANNELS * plane)
        .zip(images.rgb.chunks(CHANNELS * plane))
    {
        for (p, px) in src.chunks_exact(CHANNELS).enumerate() {
            for (c, &v) in px.iter().enumerate() {
                dst[c * plane + p] = v;
            }
        }
    }
    tensor([images.count, CHANNELS, images.height, images.width], data)
}

impl<'m> CascadedGuidance<'m> {
    /// Builds the guidance. `stage2` may be None (then any positive stage-II weight is an error);
    /// `cond` and `uncond` are the prompt and negative-prompt embeddings (same shape, finite).
    ///
    /// The stage-II weight schedule read by [`Guidance::evaluate`] starts as the reference's
    /// ([`reference_stage2_weight`]) when a stage-II model is given and as constant 0 without one;
    /// [`Self::with_stage2_weight`] replaces it.
    pub fn new(
        stage1: Box<dyn Denoiser + 'm>,
        stage2: Option<Box<dyn Denoiser + 'm>>,
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
        let stage2_weight = if stage2.is_some() {
            reference_stage2_weight()
        } else {
            Schedule::constant(0.0)
        };
        Ok(Self {
            stage1,
            stage2,
            stage2_weight,
            cond,
            uncond,
            config,
            schedule,
            ops: None,
            work: Workspace::default(),
        })
    }

    /// Replaces the stage-II weight schedule w_II(iteration) that [`Guidance::evaluate`] reads.
    #[must_use]
    pub fn with_stage2_weight(mut self, schedule: Schedule) -> Self {
        self.stage2_weight = schedule;
        self
    }

    /// The stage-II weight schedule.
    pub fn stage2_weight(&self) -> &Schedule {
        &self.stage2_weight
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

    /// Checks one call's inputs.
    fn check_call(&self, images: &Images, stage2_weight: f64) -> Result<(), GuidanceError> {
        let (views, height, width) = (images.count, images.height, images.width);
        let channels = images.channels;
        if views == 0 || height == 0 || width == 0 || images.check().is_err() {
            return Err(GuidanceError::InvalidInput(format!(
                "{} image values for {views} views of {height}×{width}×{channels}",
                images.rgb.len()
            )));
        }
        if !stage2_weight.is_finite() || stage2_weight < 0.0 {
            return Err(GuidanceError::InvalidInput(format!(
                "stage-II weight {stage2_weight} must be finite and ≥ 0"
            )));
        }
        if stage2_weight > 0.0 && self.stage2.is_none() {
            return Err(GuidanceError::InvalidInput(format!(
                "stage-II weight is {stage2_weight} but no stage-II model was given (use weight 0 to run stage I only)"
            )));
        }
        Ok(())
    }

    /// One evaluation into the workspace buffers, stage by stage: encode the renders, stage I,
    /// stage II (when its weight is positive), ∂L/∂x in the layout the renders' channel count
    /// picks (see [`Stages::grey_gradient`]; the caller decodes it with [`Stages::decode`]).
    /// Returns the output and what a trace needs; the denoiser outputs are kept only with
    /// `keep_outputs`.
    ///
    /// With `reuse_encoding`, `images` must be the renders of the previous call (the caller's
    /// promise; [`Guidance::evaluate_many`] is the only caller that makes it): x = 2·R(img) − 1
    /// and the buffers derived from it alone (z0, x0, ẑ) are kept instead of recomputed. They
    /// involve no random draw, so the results are those of a fresh encoding, bit for bit.
    fn evaluate_core(
        &mut self,
        images: &Images,
        stage2_weight: f64,
        rng: &mut dyn RngCore,
        injected: &InjectedDraws,
        CoreOptions {
            keep_outputs,
            reuse_encoding,
        }: CoreOptions,
    ) -> Result<(Core, Stages<'_>, &mut Workspace), GuidanceError> {
        self.check_call(images, stage2_weight)?;
        let input_hw = (images.height, images.width);
        if self.ops.as_ref().is_none_or(|o| o.input_hw != input_hw) {
            self.ops = Some(Operators::new(&self.config, input_hw)?);
        }
        let Self {
            stage1,
            stage2,
            cond,
            uncond,
            config: cfg,
            schedule,
            ops: Some(ops),
            work,
            ..
        } = self
        else {
            return Err(GuidanceError::InvalidInput(
                "internal: resize operators missing".into(),
            ));
        };
        let stages = Stages {
            cfg,
            schedule,
            ops,
            cond,
            uncond,
            views: images.count,
            keep_outputs,
            grey_gradient: images.is_grey(),
        };
        if !(reuse_encoding && work.derived.x) {
            stages.encode_renders(images, work)?;
        }
        let stage1 = stages.stage1(stage1.as_mut(), work, rng, injected)?;
        let stage2 = match stage2 {
            Some(model) if stage2_weight > 0.0 => {
                Some(stages.stage2(model.as_mut(), stage2_weight, work, rng, injected)?)
            }
            _ => None,
        };
        let output = GuidanceOutput {
            loss_stage1: cfg.loss_scale * cfg.stage1_weight * stage1.loss1,
            loss_stage2: stage2
                .as_ref()
                .map_or(0.0, |s| cfg.loss_scale * stage2_weight * s.loss2),
            stage2_weight,
            denoiser_seconds: stage1.denoiser_seconds
                + stage2.as_ref().map_or(0.0, |s| s.denoiser_seconds),
            // Decoded by the caller, in the renders' channel count.
            grad_images: Images {
                rgb: Vec::new(),
                ..*images
            },
        };
        Ok((
            Core {
                output,
                stage1,
                stage2,
            },
            stages,
            work,
        ))
    }

    /// [`Guidance::evaluate`] with an explicit stage-II weight w_II instead of the schedule's value
    /// (0 runs stage I only).
    pub fn evaluate_with_weight(
        &mut self,
        images: &Images,
        stage2_weight: f64,
        rng: &mut dyn RngCore,
    ) -> Result<GuidanceOutput, GuidanceError> {
        self.evaluate_untraced(images, stage2_weight, rng, false)
    }

    /// One evaluation with fresh draws and no trace; `reuse_encoding` as in
    /// [`Self::evaluate_core`] (the renders' encoding from the previous call on the same renders).
    fn evaluate_untraced(
        &mut self,
        images: &Images,
        stage2_weight: f64,
        rng: &mut dyn RngCore,
        reuse_encoding: bool,
    ) -> Result<GuidanceOutput, GuidanceError> {
        let (core, stages, work) = self.evaluate_core(
            images,
            stage2_weight,
            rng,
            &InjectedDraws::default(),
            CoreOptions {
                keep_outputs: false,
                reuse_encoding,
            },
        )?;
        let mut output = core.output;
        output.grad_images = stages.decode(images, work);
        Ok(output)
    }

    /// Like [`Self::evaluate_with_weight`], returning every intermediate; `injected` replaces chosen
    /// random draws. Grey images are traced as their RGB expansion ([`Images::to_rgb`]): the
    /// trace's tensors and gradient are RGB.
    pub fn evaluate_traced(
        &mut self,
        images: &Images,
        stage2_weight: f64,
        rng: &mut dyn RngCore,
        injected: &InjectedDraws,
    ) -> Result<GuidanceTrace, GuidanceError> {
        let expanded;
        let images = if images.is_grey() {
            expanded = images.to_rgb();
            &expanded
        } else {
            images
        };
        let (mut core, stages, work) = self.evaluate_core(
            images,
            stage2_weight,
            rng,
            injected,
            CoreOptions {
                keep_outputs: true,
                reuse_encoding: false,
            },
        )?;
        core.output.grad_images = stages.decode_gradient(images, work);
        let r = stages.cfg.resolution;
        let shape = [images.count, CHANNELS, r, r];
        Ok(GuidanceTrace {
            images: planar(images),
            x: tensor(shape, work.x.clone()),
            stage1: stages.stage1_trace(core.stage1, work)?,
            stage2: core
                .stage2
                .map(|s| stages.stage2_trace(s, stage2_weight, work))
                .transpose()?,
            grad_x: tensor(shape, work.grad_x.iter().map(|&v| nan_to_num(v)).collect()),
            output: core.output,
        })
    }
}

impl Guidance for CascadedGuidance<'_> {
    /// w_II is the stage-II weight schedule at `iteration`.
    fn evaluate(
        &mut self,
        images: &Images,
        iteration: u64,
        rng: &mut dyn RngCore,
    ) -> Result<GuidanceOutput, GuidanceError> {
        let weight = self.stage2_weight.at(iteration);
        self.evaluate_with_weight(images, weight, rng)
    }

    /// Encodes the renders once (x = 2·R(img) − 1, z0, x0, ẑ: no random draws) and runs the
    /// stages and the gradient decoding `count` times; bit-identical to `count` calls of
    /// [`Guidance::evaluate`].
    fn evaluate_many(
        &mut self,
        images: &Images,
        iteration: u64,
        count: usize,
        rng: &mut dyn RngCore,
    ) -> Result<Vec<GuidanceOutput>, GuidanceError> {
        let weight = self.stage2_weight.at(iteration);
        (0..count)
            .map(|k| self.evaluate_untraced(images, weight, rng, k > 0))
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sds::{classifier_free_guidance, sds_gradient};

    /// `sds_plane` (branch-free, partial sums) against the spec's steps one after the other:
    /// CFG, then `sds_gradient`, then Σ grad² in one sequential `f64` sum. Values include ones whose
    /// guided prediction overflows to ±∞ (→ ±MAX), a zero weight times ∞ (NaN → 0), and a length
    /// that leaves a remainder after the partial-sum lanes.
    #[test]
    fn sds_plane_equals_cfg_then_sds_gradient() {
        let n = 8 * 37 + 5;
        let cond: Vec<f32> = (0..n)
            .map(|i| match i % 11 {
                0 => 3.0e38,
                1 => -3.0e38,
                _ => ((i * 7919) % 1000) as f32 * 1e-3 - 0.5,
            })
            .collect();
        let uncond: Vec<f32> = (0..n)
            .map(|i| ((i * 104_729) % 1000) as f32 * 1e-3 - 0.5)
            .collect();
        let noise: Vec<f32> = (0..n)
            .map(|i| ((i * 31) % 997) as f32 * 2e-3 - 1.0)
            .collect();
        let g = 100.0;
        for (w, clip) in [(0.7f64, None), (0.0, None), (1.5, Some(2.0f32))] {
            let eps_hat = classifier_free_guidance(&cond, &uncond, g);
            let want = sds_gradient(&eps_hat, &noise, &[w], clip).expect("valid");
            let want_sum: f64 = want.iter().map(|&v| f64::from(v) * f64::from(v)).sum();
            let mut got = vec![0.0f32; n];
            let (sum, bad_c, bad_u) =
                sds_plane(&mut got, &cond, &uncond, &noise, w as f32, g, clip);
            let bits = |v: &[f32]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
            assert_eq!(bits(&got), bits(&want), "w {w}, clip {clip:?}");
            assert!(want.contains(&f32::MAX) || w == 0.0 || clip.is_some());
            assert!(
                (sum - want_sum).abs() <= 1e-12 * want_sum.abs(),
                "{sum} vs {want_sum}"
            );
            assert_eq!((bad_c, bad_u), (0, 0));
        }
        let mut bad = cond.clone();
        bad[3] = f32::NAN;
        bad[n - 1] = f32::INFINITY;
        let mut got = vec![0.0f32; n];
        let (_, bad_c, bad_u) = sds_plane(&mut got, &bad, &uncond, &noise, 0.5, g, None);
        assert_eq!((bad_c, bad_u), (2, 0));
    }
}

//! Score distillation (SDS, stage I) and Cascaded Score Distillation (stage II) for DeepFloyd IF.
//!
//! This crate holds the math and talks to models only through [`Denoiser`] and [`TextEmbedding`].
//! Tensors are `f32`, NCHW, row-major.
//!
//! - [`schedule`]: the DDPM "squaredcos_cap_v2" schedule (ᾱ_t in `f64`), `add_noise`, w(t) = 1 − ᾱ_t,
//!   timestep sampling and Gaussian noise from a caller's RNG.
//! - [`resize`]: antialiased cubic and bilinear resizes as separable linear operators with exact adjoints.
//! - [`sds`]: classifier-free guidance, the SDS gradient with NaN/∞ handling, the logged loss.
//! - [`guidance`]: [`CascadedGuidance`] (stage-I SDS + stage-II CSD) implementing [`Guidance`], with a traced
//!   evaluation for debugging. The full chain rule is derived in `docs/guidance.md`.
//!
//! ```
//! use csd::{CascadedGuidance, Denoiser, Embedding, Guidance, GuidanceConfig, GuidanceError, Images, Tensor};
//! use rand::SeedableRng;
//!
//! /// Predicts ε = 0 for every input (a real backend runs the IF UNet here).
//! struct Zero;
//! impl Denoiser for Zero {
//!     fn predict(&mut self, sample: &Tensor, _t: &[i64], _e: &[&Embedding], _s: Option<&[i64]>)
//!         -> Result<Tensor, GuidanceError> {
//!         let mut shape = sample.shape.clone();
//!         shape[1] = 6; // IF: ε (3 channels) + learned variance (3 channels)
//!         Ok(Tensor::zeros(shape))
//!     }
//! }
//!
//! let emb = |v: f32| Embedding { shape: [77, 8], data: vec![v; 77 * 8] };
//! let mut guidance = CascadedGuidance::new(
//!     Box::new(Zero), Some(Box::new(Zero)), emb(1.0), emb(0.0), GuidanceConfig::default())?
//!     .with_stage2_weight(optim::Schedule::constant(0.2));
//! // 2 views of 64×64, (view, row, col, channel) in [0, 1]
//! let renders = Images::new(2, 64, 64, vec![0.5f32; 2 * 64 * 64 * 3])?;
//! let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(0);
//! let out = guidance.evaluate(&renders, 1, &mut rng)?;
//! assert!(out.grad_images.same_shape(&renders));
//! assert!(out.loss_stage1 > 0.0 && out.loss_stage2 > 0.0);
//! assert_eq!(out.stage2_weight, 0.2);
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

pub mod guidance;
pub mod resize;
pub mod schedule;
pub mod sds;

pub use guidance::{
    CascadedGuidance, GuidanceConfig, GuidanceTrace, InjectedDraws, REFERENCE_STAGE2_WEIGHT,
    ScoreTrace, Stage1Trace, Stage2Trace, reference_stage2_weight,
};
/// The image batch the renderer produces and the guidance consumes (`raster_diff::Images` is the
/// same type).
pub use image_batch::{Images, ImagesError};
pub use resize::{Resize1d, Resize2d};
pub use schedule::{NoiseSchedule, TimestepRange};

/// A dense `f32` tensor in NCHW (or any row-major) layout.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Tensor {
    /// Shape, outermost first.
    pub shape: Vec<usize>,
    /// Row-major values, `shape.iter().product()` of them.
    pub data: Vec<f32>,
}

impl Tensor {
    /// A tensor from a shape and its row-major values; an error when the counts disagree.
    pub fn new(shape: Vec<usize>, data: Vec<f32>) -> Result<Self, GuidanceError> {
        let expected: usize = shape.iter().product();
        if expected != data.len() {
            return Err(GuidanceError::InvalidInput(format!(
                "tensor of shape {shape:?} needs {expected} values, got {}",
                data.len()
            )));
        }
        Ok(Self { shape, data })
    }

    /// A tensor of zeros.
    pub fn zeros(shape: Vec<usize>) -> Self {
        let n = shape.iter().product();
        Self {
            shape,
            data: vec![0.0; n],
        }
    }
}

/// A prompt embedding, e.g. T5 output `(77, 4096)`.
#[derive(Clone, Debug, PartialEq)]
pub struct Embedding {
    /// `(tokens, dim)`.
    pub shape: [usize; 2],
    /// Row-major values.
    pub data: Vec<f32>,
}

/// Errors from models or guidance.
#[derive(Debug, thiserror::Error)]
pub enum GuidanceError {
    /// A model backend failed.
    #[error("model error: {0}")]
    Model(String),
    /// Inputs are inconsistent.
    #[error("invalid guidance input: {0}")]
    InvalidInput(String),
    /// A tensor that must be finite holds NaN or ±∞ (e.g. an fp16 overflow in the text encoder or a
    /// UNet). Guidance refuses to continue: the reference's `nan_to_num` would turn such values into a
    /// zero (or saturated) gradient and the run would "succeed" without changing the mesh.
    #[error("{tensor} has {count} non-finite values (NaN or ±∞) out of {total}; {hint}")]
    NonFinite {
        /// Which tensor, with the model or file it came from (e.g. "stage-I UNet output ε, conditional
        /// branch (stage1 UNet, models/if/unet_stage1.onnx)").
        tensor: String,
        /// How many values are NaN or ±∞.
        count: usize,
        /// How many values the tensor has.
        total: usize,
        /// What to do about it.
        hint: String,
    },
}

/// Number of values that are NaN or ±∞.
pub fn count_non_finite(values: &[f32]) -> usize {
    values.iter().filter(|v| !v.is_finite()).count()
}

/// Checks that an embedding is all finite; `what` names it in the error (e.g. "prompt embedding").
pub fn check_embedding_finite(embedding: &Embedding, what: &str) -> Result<(), GuidanceError> {
    let count = count_non_finite(&embedding.data);
    if count == 0 {
        return Ok(());
    }
    Err(GuidanceError::NonFinite {
        tensor: what.to_string(),
        count,
        total: embedding.data.len(),
        hint: "recompute it (delete the cached file; an fp16 text encoder can overflow, an fp32 export does not)"
            .into(),
    })
}

/// One UNet stage. `sample` is `(N, C, H, W)`; `embeddings[i]` conditions sample `i`;
/// `class_labels` is the stage-II noise level (None for stage I). Returns the model output
/// `(N, C_out, H, W)` (IF: ε in the first 3 channels, learned variance after).
pub trait Denoiser: Send {
    /// What this denoiser is, for error messages (e.g. the model file). Default: "the denoiser".
    fn describe(&self) -> String {
        "the denoiser".into()
    }

    /// Runs the UNet once on a batch.
    fn predict(
        &mut self,
        sample: &Tensor,
        timesteps: &[i64],
        embeddings: &[&Embedding],
        class_labels: Option<&[i64]>,
    ) -> Result<Tensor, GuidanceError>;
}

/// A borrowed denoiser is a denoiser: `Box::new(&mut unet)` lends one UNet session to a guidance
/// that does not outlive it (a batch of prompts reuses one set of sessions, no lock needed).
impl<D: Denoiser + ?Sized> Denoiser for &mut D {
    fn describe(&self) -> String {
        (**self).describe()
    }

    fn predict(
        &mut self,
        sample: &Tensor,
        timesteps: &[i64],
        embeddings: &[&Embedding],
        class_labels: Option<&[i64]>,
    ) -> Result<Tensor, GuidanceError> {
        (**self).predict(sample, timesteps, embeddings, class_labels)
    }
}

/// Text prompt → embedding.
pub trait TextEmbedding {
    /// Encodes one prompt.
    fn embed(&mut self, prompt: &str) -> Result<Embedding, GuidanceError>;
}

/// What the loop receives from a guidance evaluation.
#[derive(Clone, Debug, Default)]
pub struct GuidanceOutput {
    /// Stage-I loss value (for logging; the gradient is what matters). [`CascadedGuidance`] reports the
    /// weighted term `S·a·L_I` with `L_I = ½‖grad_I‖²/B`, so `loss_stage1 + loss_stage2` is the surrogate
    /// objective whose gradient is `grad_images`.
    pub loss_stage1: f64,
    /// Stage-II loss value (0 when skipped); [`CascadedGuidance`]: `S·w_II·L_II`, `L_II = ½‖grad_II‖²/B`.
    pub loss_stage2: f64,
    /// The stage-II weight w_II used for this evaluation (0 for a guidance without a second stage).
    pub stage2_weight: f64,
    /// Wall time spent inside the denoiser calls (the UNets), seconds: what a caller subtracts
    /// from the evaluation's time to get the guidance's own overhead (resizes, noise, CFG, SDS).
    /// 0 for a guidance without a denoiser.
    pub denoiser_seconds: f64,
    /// dL/dimages, same sizes and channel count as the input images (for grey images: dL/d(grey),
    /// the sum over the three channels of the RGB image they stand for).
    pub grad_images: Images,
}

/// The seam between the loop and the semantic loss: renders in, dL/drenders out.
///
/// Renders are grey (one channel) or RGB ([`Images::channels`]); a grey render stands for the RGB
/// image with its value in all three channels ([`Images::to_rgb`]), so its gradient is dL/d(grey) =
/// Σ_c dL/d(channel c). [`CascadedGuidance`] forms that sum with less work than the RGB gradient
/// (each stage sums its gradient's channels before its resize adjoint).
pub trait Guidance: Send {
    /// Evaluates the loss and its image gradient at optimization iteration `iteration` (1-based;
    /// a guidance with iteration-dependent weights, like [`CascadedGuidance`]'s stage-II schedule,
    /// reads them here). `images` hold values in `[0, 1]`; the returned `grad_images` has their
    /// sizes and channel count. All randomness (timesteps, noise) comes from `rng`.
    fn evaluate(
        &mut self,
        images: &Images,
        iteration: u64,
        rng: &mut dyn rand::RngCore,
    ) -> Result<GuidanceOutput, GuidanceError>;

    /// `count` independent evaluations of the same `images` at `iteration`, drawing their
    /// randomness from `rng` one evaluation after the other: the same outputs, in the same order,
    /// as `count` calls of [`Guidance::evaluate`] (the default does exactly that). An
    /// implementation may share the work that depends on the images alone — [`CascadedGuidance`]
    /// encodes the renders once. The loop asks for all the sub-steps of an iteration at once
    /// (they see the same renders), so that the renderer's backward can run them together.
    fn evaluate_many(
        &mut self,
        images: &Images,
        iteration: u64,
        count: usize,
        rng: &mut dyn rand::RngCore,
    ) -> Result<Vec<GuidanceOutput>, GuidanceError> {
        (0..count)
            .map(|_| self.evaluate(images, iteration, rng))
            .collect()
    }
}

//! The per-stage score-distillation formulas: classifier-free guidance, the SDS gradient, its sanitizing,
//! and the logged loss value. Pure functions over `f32` buffers; [`crate::CascadedGuidance`] composes them.

use crate::{GuidanceError, Tensor};

/// Splits a denoiser output of shape `(2B, C_out, H, W)` (conditional half first, as the 2B batch was
/// built) into the first `keep` channels of each half: `(ε_c, ε_u)`, each `(B, keep, H, W)` flattened.
///
/// IF's UNets output ε in channels 0..3 and a learned variance in 3..6; the reference keeps 3 channels.
pub fn split_cond_uncond(
    output: &Tensor,
    batch: usize,
    keep: usize,
    hw: (usize, usize),
) -> Result<(Vec<f32>, Vec<f32>), GuidanceError> {
    check_denoiser_output(output, batch, keep, hw)?;
    let c_out = output.shape[1];
    let plane = hw.0 * hw.1;
    let take = |half: usize| -> Vec<f32> {
        let mut v = Vec::with_capacity(batch * keep * plane);
        for b in 0..batch {
            let base = ((half * batch + b) * c_out) * plane;
            v.extend_from_slice(&output.data[base..base + keep * plane]);
        }
        v
    };
    Ok((take(0), take(1)))
}

/// Checks that a denoiser output is `(2B, ≥ keep, H, W)` with as many values as its shape says.
pub fn check_denoiser_output(
    output: &Tensor,
    batch: usize,
    keep: usize,
    hw: (usize, usize),
) -> Result<(), GuidanceError> {
    let expected_prefix = [2 * batch];
    let ok = output.shape.len() == 4
        && output.shape[..1] == expected_prefix
        && output.shape[1] >= keep
        && (output.shape[2], output.shape[3]) == hw
        && output.data.len() == output.shape.iter().product::<usize>();
    if !ok {
        return Err(GuidanceError::Model(format!(
            "denoiser returned shape {:?} ({} values); expected ({}, ≥{keep}, {}, {})",
            output.shape,
            output.data.len(),
            2 * batch,
            hw.0,
            hw.1
        )));
    }
    Ok(())
}

/// Classifier-free guidance as the reference codes it: `ε̂ = ε_c + g·(ε_c − ε_u)` (in `f32`).
/// With g = 100 this is standard CFG with scale g + 1 = 101.
pub fn classifier_free_guidance(
    eps_cond: &[f32],
    eps_uncond: &[f32],
    guidance_scale: f32,
) -> Vec<f32> {
    eps_cond
        .iter()
        .zip(eps_uncond)
        .map(|(&c, &u)| c + guidance_scale * (c - u))
        .collect()
}

/// `torch.nan_to_num` for `f32`: NaN → 0, +∞ → `f32::MAX`, −∞ → `f32::MIN`; finite values unchanged.
/// Without branches (a clamp, which maps ±∞ to ±MAX and keeps NaN, then a select), so loops that
/// call it vectorize.
#[inline]
pub fn nan_to_num(v: f32) -> f32 {
    let c = v.clamp(f32::MIN, f32::MAX);
    if c.is_nan() { 0.0 } else { c }
}

/// The SDS gradient per sample `b`: `grad = nan_to_num(w(t_b) · (ε̂ − ε))`, optionally clamped to
/// `[−clip, clip]` afterwards (the reference's `grad_clip_val`, off by default). `weights[b]` = w(t_b);
/// each sample is `eps_hat.len() / weights.len()` values.
pub fn sds_gradient(
    eps_hat: &[f32],
    noise: &[f32],
    weights: &[f64],
    clip: Option<f32>,
) -> Result<Vec<f32>, GuidanceError> {
    if eps_hat.len() != noise.len()
        || weights.is_empty()
        || !eps_hat.len().is_multiple_of(weights.len())
    {
        return Err(GuidanceError::InvalidInput(format!(
            "sds_gradient: {} predictions, {} noise values, {} samples",
            eps_hat.len(),
            noise.len(),
            weights.len()
        )));
    }
    let per = eps_hat.len() / weights.len();
    let mut grad = Vec::with_capacity(eps_hat.len());
    for (b, &w) in weights.iter().enumerate() {
        let w = w as f32;
        for (&e_hat, &e) in eps_hat[b * per..(b + 1) * per]
            .iter()
            .zip(&noise[b * per..(b + 1) * per])
        {
            let g = nan_to_num(w * (e_hat - e));
            grad.push(match clip {
                Some(c) => g.clamp(-c, c),
                None => g,
            });
        }
    }
    Ok(grad)
}

/// The reference's logged loss of one stage: `L = ½ ‖z − sg(z − grad)‖² / B = ½ ‖grad‖² / B`
/// (`0.5 · F.mse_loss(z, target, reduction="sum") / B`), whose gradient with respect to z is `grad / B`.
/// Accumulated in `f64` (finite for any sanitized gradient).
pub fn sds_loss(grad: &[f32], batch: usize) -> f64 {
    0.5 * grad.iter().map(|&g| (g as f64) * (g as f64)).sum::<f64>() / batch.max(1) as f64
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cfg_is_cond_plus_scale_times_difference() {
        // ε_c = 0.5, ε_u = 0.25, g = 100: 0.5 + 100·0.25 = 25.5. Equal halves: ε̂ = ε_c.
        assert_eq!(
            classifier_free_guidance(&[0.5, -1.0], &[0.25, -1.0], 100.0),
            vec![25.5, -1.0]
        );
    }

    #[test]
    fn nan_to_num_matches_torch() {
        assert_eq!(nan_to_num(f32::NAN), 0.0);
        assert_eq!(nan_to_num(f32::INFINITY), f32::MAX);
        assert_eq!(nan_to_num(f32::NEG_INFINITY), f32::MIN);
        assert_eq!(nan_to_num(-3.5), -3.5);
    }

    #[test]
    fn sds_gradient_weights_each_sample_and_sanitizes() {
        // Sample 0 (w = 0.5): 0.5·(3 − 1) = 1, 0.5·(NaN − 0) → 0. Sample 1 (w = 2): 2·(∞ − 1) → MAX,
        // 2·(−∞ − 0) → MIN.
        let g = sds_gradient(
            &[3.0, f32::NAN, f32::INFINITY, f32::NEG_INFINITY],
            &[1.0, 0.0, 1.0, 0.0],
            &[0.5, 2.0],
            None,
        )
        .expect("shapes agree");
        assert_eq!(g, vec![1.0, 0.0, f32::MAX, f32::MIN]);
        let clipped =
            sds_gradient(&[3.0, -9.0], &[0.0, 0.0], &[1.0], Some(2.0)).expect("shapes agree");
        assert_eq!(clipped, vec![2.0, -2.0]);
        assert!(sds_gradient(&[1.0; 3], &[1.0; 3], &[1.0, 1.0], None).is_err());
    }

    #[test]
    fn sds_loss_is_half_squared_norm_over_batch() {
        // ½ (1 + 4 + 9 + 16) / 2 = 7.5; f32::MAX² stays finite in f64.
        assert_eq!(sds_loss(&[1.0, -2.0, 3.0, 4.0], 2), 7.5);
        assert!(sds_loss(&[f32::MAX, f32::MIN], 1).is_finite());
    }

    #[test]
    fn split_keeps_first_channels_of_each_half() {
        // 2B = 2 samples, C_out = 2, 1×2 planes; keep 1 channel: cond = sample 0 ch 0, uncond = sample 1 ch 0.
        let t = Tensor {
            shape: vec![2, 2, 1, 2],
            data: vec![1.0, 2.0, 9.0, 9.0, 3.0, 4.0, 8.0, 8.0],
        };
        let (c, u) = split_cond_uncond(&t, 1, 1, (1, 2)).expect("shape ok");
        assert_eq!((c, u), (vec![1.0, 2.0], vec![3.0, 4.0]));
        assert!(split_cond_uncond(&t, 2, 1, (1, 2)).is_err());
        assert!(split_cond_uncond(&t, 1, 3, (1, 2)).is_err());
        let short = Tensor {
            shape: vec![2, 2, 1, 2],
            data: vec![0.0; 7],
        };
        assert!(split_cond_uncond(&short, 1, 1, (1, 2)).is_err());
    }
}

//! Gradient checks of crate `csd`: the resize adjoints and the whole image-gradient chain of
//! `CascadedGuidance` (factor 2 of x = 2·img − 1, the 1/B and loss-scale factors, the adjoints of the
//! 224 cubic, the 64 and 256 bilinear resizes, the NHWC ↔ NCHW layouts).
//!
//! Precision: the resize checks run the operators' `f64` path (tight tolerances). The guidance check compares
//! the product `f32` image gradient with central differences of an `f64` forward written here independently
//! (rtol 1e-5, i.e. f32 rounding with margin). The SDS gradient is not the derivative of any function of
//! the image (the UNet is not differentiated); the check therefore uses the reference's surrogate with the
//! per-stage gradients held fixed (detached, as in `target = (z − grad).detach()`):
//! ℓ(img) = S·a/B·⟨grad_I, D(2R(img) − 1)⟩ + S·w_II/B·⟨grad_II, U(2R(img) − 1)⟩, whose derivative is what
//! `CascadedGuidance` must return. The grey checks take ℓ as a function of one value per pixel spread
//! over the three channels: its derivative is the gradient the guidance returns for the one-channel
//! (grey) images of those values, dL/d(grey).

use super::{Report, Tolerance};
use csd::resize::Resize2d;
use csd::{
    CascadedGuidance, Denoiser, Embedding, Guidance, GuidanceConfig, GuidanceError, Images,
    InjectedDraws, Tensor,
};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

fn random(n: usize, seed: u64) -> Vec<f64> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    (0..n).map(|_| rng.random::<f64>() * 2.0 - 1.0).collect()
}

fn dot(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(x, y)| x * y).sum()
}

/// A denoiser whose output is a fixed smooth function of position, channel and batch index — and ±f32::MAX
/// (finite, but overflowing to ±∞ in classifier-free guidance) on a pattern of pixels when `degenerate`,
/// NaN/±∞ there when `non_finite` (which the guidance must refuse).
struct PatternDenoiser {
    degenerate: bool,
    non_finite: bool,
}

impl Denoiser for PatternDenoiser {
    fn predict(
        &mut self,
        sample: &Tensor,
        _timesteps: &[i64],
        _embeddings: &[&Embedding],
        _class_labels: Option<&[i64]>,
    ) -> Result<Tensor, GuidanceError> {
        let (n, h, w) = (sample.shape[0], sample.shape[2], sample.shape[3]);
        let plane = h * w;
        let mut data = vec![0.0f32; n * 6 * plane];
        for (i, v) in data.iter_mut().enumerate() {
            let (k, p) = (i / plane, i % plane);
            *v = if self.non_finite && p % 7 == 0 {
                [f32::NAN, f32::INFINITY, f32::NEG_INFINITY][k % 3]
            } else if self.degenerate && p % 7 == 0 {
                [f32::MAX, -f32::MAX, 0.5 * f32::MAX][k % 3]
            } else {
                0.3 * ((k as f32) * 0.7 + (p as f32) * 0.013).sin()
            };
        }
        Ok(Tensor {
            shape: vec![n, 6, h, w],
            data,
        })
    }
}

fn guidance(degenerate: bool) -> anyhow::Result<CascadedGuidance<'static>> {
    guidance_with(degenerate, false)
}

fn guidance_with(degenerate: bool, non_finite: bool) -> anyhow::Result<CascadedGuidance<'static>> {
    let cond = Embedding {
        shape: [2, 2],
        data: vec![1.0, 2.0, 3.0, 4.0],
    };
    let uncond = Embedding {
        shape: [2, 2],
        data: vec![0.0; 4],
    };
    Ok(CascadedGuidance::new(
        Box::new(PatternDenoiser {
            degenerate,
            non_finite,
        }),
        Some(Box::new(PatternDenoiser {
            degenerate,
            non_finite,
        })),
        cond,
        uncond,
        GuidanceConfig::default(),
    )?)
}

fn check_resize(
    report: &mut Report,
    name: &str,
    op: Resize2d,
    planes: usize,
    seed: u64,
) -> anyhow::Result<()> {
    let (ih, iw) = op.in_hw();
    let (oh, ow) = op.out_hw();
    let theta = random(planes * ih * iw, seed);
    let cotangent = random(planes * oh * ow, seed + 1);
    let grad = op.adjoint(&cotangent)?;
    // The resize is linear, so the central difference has no truncation error at any step; a large step
    // keeps its round-off (≈ ε·Σ|terms| / 2h, about 1e-9 at h = 1e-3 for 512² inputs) below the tolerance.
    let tol = Tolerance {
        step: 0.1,
        rtol: 1e-8,
        atol: 1e-10,
        directions: 4,
    };
    report.check(name, &theta, &grad, tol, seed + 2, |x| {
        op.apply(x).map(|y| dot(&cotangent, &y)).unwrap_or(f64::NAN)
    });
    Ok(())
}

/// NHWC renders → NCHW, f64.
fn to_nchw(img: &[f64], views: usize, h: usize, w: usize) -> Vec<f64> {
    let plane = h * w;
    let mut out = vec![0.0; img.len()];
    for b in 0..views {
        for p in 0..plane {
            for c in 0..3 {
                out[(b * 3 + c) * plane + p] = img[(b * plane + p) * 3 + c];
            }
        }
    }
    out
}

/// The image the chain is checked at: per pixel and channel, or (`Grey`) one value per pixel
/// spread over the three channels, whose gradient is the guidance's for the one-channel images of
/// those values, dL/d(grey).
#[derive(Clone, Copy, PartialEq)]
enum Input {
    Rgb,
    Grey,
}

fn check_guidance_chain(
    report: &mut Report,
    name: &str,
    (views, h, w): (usize, usize, usize),
    stage2_weight: f64,
    seed: u64,
    input: Input,
) -> anyhow::Result<()> {
    let mut g = guidance(false)?;
    let cfg = g.config().clone();
    let per_pixel = if input == Input::Grey { 1 } else { 3 };
    let theta: Vec<f64> = random(views * h * w * per_pixel, seed)
        .iter()
        .map(|v| 0.5 + 0.5 * v)
        .collect();
    // The render as the guidance sees it (RGB) from θ.
    let rgb = move |x: &[f64]| -> Vec<f64> {
        match input {
            Input::Rgb => x.to_vec(),
            Input::Grey => x.iter().flat_map(|&v| [v; 3]).collect(),
        }
    };
    let img32: Vec<f32> = rgb(&theta).iter().map(|&v| v as f32).collect();
    let batch = imgs(&img32, views, h, w);
    let trace = g.evaluate_traced(
        &batch,
        stage2_weight,
        &mut ChaCha8Rng::seed_from_u64(seed + 1),
        &InjectedDraws::default(),
    )?;
    let grad: Vec<f64> = match input {
        Input::Rgb => trace
            .output
            .grad_images
            .rgb
            .iter()
            .map(|&v| v as f64)
            .collect(),
        // The same draws (same seed), so the same per-stage gradients as the trace's.
        Input::Grey => guidance(false)?
            .with_stage2_weight(optim::Schedule::constant(stage2_weight))
            .evaluate_many(
                &Images {
                    channels: 1,
                    ..imgs(
                        &theta.iter().map(|&v| v as f32).collect::<Vec<_>>(),
                        views,
                        h,
                        w,
                    )
                },
                1,
                1,
                &mut ChaCha8Rng::seed_from_u64(seed + 1),
            )?
            .remove(0)
            .grad_images
            .rgb
            .iter()
            .map(|&v| v as f64)
            .collect(),
    };

    let (r, r1, r2) = (cfg.resolution, cfg.stage1_resolution, cfg.stage2_resolution);
    let resize = Resize2d::cubic_antialias((h, w), (r, r))?;
    let down = Resize2d::bilinear((r, r), (r1, r1))?;
    let up = Resize2d::bilinear((r, r), (r2, r2))?;
    let grad1: Vec<f64> = trace
        .stage1
        .score
        .grad
        .data
        .iter()
        .map(|&v| v as f64)
        .collect();
    let grad2: Option<Vec<f64>> = trace
        .stage2
        .as_ref()
        .map(|s| s.score.grad.data.iter().map(|&v| v as f64).collect());
    let b = views as f64;
    let forward = |theta: &[f64]| -> anyhow::Result<f64> {
        let x: Vec<f64> = resize
            .apply(&to_nchw(&rgb(theta), views, h, w))?
            .iter()
            .map(|v| 2.0 * v - 1.0)
            .collect();
        let mut l = cfg.loss_scale * cfg.stage1_weight / b * dot(&grad1, &down.apply(&x)?);
        if let Some(g2) = &grad2 {
            l += cfg.loss_scale * stage2_weight / b * dot(g2, &up.apply(&x)?);
        }
        Ok(l)
    };
    // The adjoint is the f32 product output: per-element rounding ≈ 3e-8 relative gives absolute errors of
    // ~1e-7 in ⟨∇ℓ, d⟩ (measured), so a direction with a small derivative shows a larger relative error.
    // ℓ is affine in img: no truncation error, so a large step keeps the finite difference's round-off
    // (≈ ε·Σ|terms| / 2h, with Σ|terms| up to ~1e8 here) far below the tolerance.
    let tol = Tolerance {
        step: 0.1,
        rtol: 1e-5,
        atol: 1e-8,
        directions: 4,
    };
    report.check(name, &theta, &grad, tol, seed + 2, |x| {
        forward(x).unwrap_or(f64::NAN)
    });
    Ok(())
}

fn check_degenerate(report: &mut Report) -> anyhow::Result<()> {
    let name =
        "csd/overflowing predictions (±f32::MAX) and images stay finite; NaN/±inf ones are refused";
    let mut refusing = guidance_with(false, true)?;
    let mut rng = ChaCha8Rng::seed_from_u64(98);
    let img = vec![0.5f32; 2 * 64 * 64 * 3];
    match refusing.evaluate_traced(
        &imgs(&img, 2, 64, 64),
        1.0,
        &mut rng,
        &InjectedDraws::default(),
    ) {
        Err(GuidanceError::NonFinite { .. }) => {}
        Err(e) => {
            report.fail(name, format!("NaN predictions: wrong error {e}"));
            return Ok(());
        }
        Ok(_) => {
            report.fail(name, "NaN predictions were accepted".to_string());
            return Ok(());
        }
    }
    let mut g = guidance(true)?;
    let (views, h, w) = (2, 64, 64);
    let mut rng = ChaCha8Rng::seed_from_u64(99);
    for (what, img) in [
        ("black", vec![0.0f32; views * h * w * 3]),
        ("white", vec![1.0f32; views * h * w * 3]),
        ("out of range", vec![1e30f32; views * h * w * 3]),
    ] {
        let out = g.evaluate_traced(
            &imgs(&img, views, h, w),
            1.0,
            &mut rng,
            &InjectedDraws::default(),
        )?;
        let finite = out.output.grad_images.rgb.iter().all(|v| v.is_finite())
            && out.output.loss_stage1.is_finite()
            && out.output.loss_stage2.is_finite();
        if !finite {
            report.fail(name, format!("{what} image: non-finite gradient or loss"));
            return Ok(());
        }
    }
    report.results.push(super::CheckResult {
        name: name.to_string(),
        worst_rel: 0.0,
        failures: Vec::new(),
    });
    Ok(())
}

/// Every `csd` check.
pub fn suite(report: &mut Report) -> anyhow::Result<()> {
    check_resize(
        report,
        "csd/resize cubic antialias 512x512 -> 224 (f64)",
        Resize2d::cubic_antialias((512, 512), (224, 224))?,
        1,
        1,
    )?;
    check_resize(
        report,
        "csd/resize cubic antialias 100x70 -> 224 (f64)",
        Resize2d::cubic_antialias((100, 70), (224, 224))?,
        2,
        11,
    )?;
    check_resize(
        report,
        "csd/resize bilinear 224 -> 64 (f64)",
        Resize2d::bilinear((224, 224), (64, 64))?,
        3,
        21,
    )?;
    check_resize(
        report,
        "csd/resize bilinear 224 -> 256 (f64)",
        Resize2d::bilinear((224, 224), (256, 256))?,
        3,
        31,
    )?;
    check_resize(
        report,
        "csd/resize bilinear 64 -> 256 (f64)",
        Resize2d::bilinear((64, 64), (256, 256))?,
        3,
        41,
    )?;
    check_guidance_chain(
        report,
        "csd/guidance image gradient, 2 views 96x80, w_II 0.3 (f32)",
        (2, 96, 80),
        0.3,
        51,
        Input::Rgb,
    )?;
    check_guidance_chain(
        report,
        "csd/guidance grey gradient (1-channel images), 2 views 96x80, w_II 0.3 (f32)",
        (2, 96, 80),
        0.3,
        56,
        Input::Grey,
    )?;
    check_guidance_chain(
        report,
        "csd/guidance image gradient, 1 view 512x512, stage I only (f32)",
        (1, 512, 512),
        0.0,
        61,
        Input::Rgb,
    )?;
    check_guidance_chain(
        report,
        "csd/guidance image gradient, 3 views 512x512, w_II 1 (f32)",
        (3, 512, 512),
        1.0,
        71,
        Input::Rgb,
    )?;
    check_guidance_chain(
        report,
        "csd/guidance grey gradient (1-channel images), 2 views 512x512, w_II 1 (f32)",
        (2, 512, 512),
        1.0,
        76,
        Input::Grey,
    )?;
    check_degenerate(report)
}

/// The image batch for `views` renders of `h`×`w` (no length check: bad-input tests pass wrong sizes).
fn imgs(data: &[f32], views: usize, h: usize, w: usize) -> Images {
    Images {
        count: views,
        height: h,
        width: w,
        channels: 3,
        rgb: data.to_vec(),
    }
}

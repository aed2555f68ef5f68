//! `CascadedGuidance` against fake denoisers whose outputs are known in closed form. Each test derives the
//! expected values in a comment from the formulas of spec §7 (see also docs/guidance.md).

use csd::resize::Resize2d;
use csd::{
    CascadedGuidance, Denoiser, Embedding, GuidanceConfig, GuidanceError, Images, InjectedDraws,
    NoiseSchedule, Tensor,
};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use std::sync::{Arc, Mutex};

/// One recorded `predict` call.
#[derive(Clone, Debug)]
struct Call {
    sample: Tensor,
    timesteps: Vec<i64>,
    embeddings: Vec<Embedding>,
    class_labels: Option<Vec<i64>>,
}

type Rule = Box<dyn FnMut(&Tensor, &[i64]) -> Tensor + Send>;

/// A denoiser computed by a closure of (sample, timesteps), recording every call.
struct Fake {
    rule: Rule,
    calls: Arc<Mutex<Vec<Call>>>,
}

impl Fake {
    fn boxed(
        rule: impl FnMut(&Tensor, &[i64]) -> Tensor + Send + 'static,
    ) -> (Box<dyn Denoiser>, Arc<Mutex<Vec<Call>>>) {
        let calls = Arc::new(Mutex::new(Vec::new()));
        (
            Box::new(Self {
                rule: Box::new(rule),
                calls: calls.clone(),
            }),
            calls,
        )
    }
}

impl Denoiser for Fake {
    fn predict(
        &mut self,
        sample: &Tensor,
        timesteps: &[i64],
        embeddings: &[&Embedding],
        class_labels: Option<&[i64]>,
    ) -> Result<Tensor, GuidanceError> {
        self.calls.lock().expect("not poisoned").push(Call {
            sample: sample.clone(),
            timesteps: timesteps.to_vec(),
            embeddings: embeddings.iter().map(|e| (*e).clone()).collect(),
            class_labels: class_labels.map(<[i64]>::to_vec),
        });
        Ok((self.rule)(sample, timesteps))
    }
}

/// IF-shaped output `(N, 6, H, W)`: channel c < 3 of sample n is `value(n, c, pixel)`; the variance
/// channels 3..6 hold 1e6 (they must be ignored).
fn output(sample: &Tensor, value: impl Fn(usize, usize, usize) -> f32) -> Tensor {
    let (n, h, w) = (sample.shape[0], sample.shape[2], sample.shape[3]);
    let plane = h * w;
    let mut data = vec![1e6f32; n * 6 * plane];
    for s in 0..n {
        for c in 0..3 {
            for p in 0..plane {
                data[(s * 6 + c) * plane + p] = value(s, c, p);
            }
        }
    }
    Tensor {
        shape: vec![n, 6, h, w],
        data,
    }
}

/// Stage I and II both predicting ε̂ = 0 (both halves), default configuration.
fn zero_prediction_guidance() -> CascadedGuidance<'static> {
    let (stage1, _) = Fake::boxed(|s: &Tensor, _: &[i64]| output(s, |_, _, _| 0.0));
    let (stage2, _) = Fake::boxed(|s: &Tensor, _: &[i64]| output(s, |_, _, _| 0.0));
    default_guidance(stage1, stage2)
}

/// A guidance with both stages, the test embeddings and the default configuration.
fn default_guidance(
    stage1: Box<dyn Denoiser>,
    stage2: Box<dyn Denoiser>,
) -> CascadedGuidance<'static> {
    let (cond, uncond) = embeddings();
    CascadedGuidance::new(
        stage1,
        Some(stage2),
        cond,
        uncond,
        GuidanceConfig::default(),
    )
    .expect("valid")
}

/// Cond rows [1, 2, 3, ...], uncond rows [−1, −2, ...] in a (2, 3) embedding: distinguishable halves.
fn embeddings() -> (Embedding, Embedding) {
    let cond = Embedding {
        shape: [2, 3],
        data: (1..=6).map(|v| v as f32).collect(),
    };
    let uncond = Embedding {
        shape: [2, 3],
        data: (1..=6).map(|v| -(v as f32)).collect(),
    };
    (cond, uncond)
}

/// Smooth test renders `(view, row, col, channel)` in [0, 1].
fn renders(views: usize, h: usize, w: usize) -> Vec<f32> {
    let mut v = Vec::with_capacity(views * h * w * 3);
    for b in 0..views {
        for r in 0..h {
            for c in 0..w {
                for ch in 0..3 {
                    let phase = 0.37 * b as f32 + 1.3 * ch as f32;
                    v.push(
                        0.5 + 0.45
                            * ((r as f32 * 0.05 + phase).sin() * (c as f32 * 0.031 - phase).cos()),
                    );
                }
            }
        }
    }
    v
}

/// The clean model inputs computed independently of `CascadedGuidance`: x at `res`, z0 at `r1`, x0 at `r2`.
fn clean_inputs(
    img: &[f32],
    views: usize,
    h: usize,
    w: usize,
    cfg: &GuidanceConfig,
) -> (Vec<f32>, Vec<f32>, Vec<f32>) {
    let plane = h * w;
    let mut nchw = vec![0.0f64; img.len()];
    for b in 0..views {
        for p in 0..plane {
            for c in 0..3 {
                nchw[(b * 3 + c) * plane + p] = img[(b * plane + p) * 3 + c] as f64;
            }
        }
    }
    let (r, r1, r2) = (cfg.resolution, cfg.stage1_resolution, cfg.stage2_resolution);
    let x: Vec<f64> = Resize2d::cubic_antialias((h, w), (r, r))
        .expect("sizes")
        .apply(&nchw)
        .expect("shape");
    let x: Vec<f64> = x.iter().map(|v| 2.0 * v - 1.0).collect();
    let z0 = Resize2d::bilinear((r, r), (r1, r1))
        .expect("sizes")
        .apply(&x)
        .expect("shape");
    let x0 = Resize2d::bilinear((r, r), (r2, r2))
        .expect("sizes")
        .apply(&x)
        .expect("shape");
    let f = |v: Vec<f64>| v.into_iter().map(|x| x as f32).collect::<Vec<f32>>();
    (f(x), f(z0), f(x0))
}

fn schedule() -> NoiseSchedule {
    NoiseSchedule::squaredcos_cap_v2(1000).expect("valid")
}

fn max_abs(v: &[f32]) -> f32 {
    v.iter().fold(0.0f32, |m, x| m.max(x.abs()))
}

#[test]
fn denoiser_returning_the_true_noise_gives_zero_gradient() {
    // The oracle recovers ε from its noisy input with the clean image known to the test:
    // ε = (z_t − √ᾱ_t z0) / √(1 − ᾱ_t). Both halves agree, so ε̂ = ε_c + g·0 = ε and grad = w(t)(ε − ε) = 0
    // up to f32 rounding of z_t (|Δε|·w ≤ √(1 − ᾱ) · |Δz_t| ≈ 1e-6).
    let (views, h, w) = (3, 96, 80);
    let cfg = GuidanceConfig::default();
    let img = renders(views, h, w);
    let (_, z0, x0) = clean_inputs(&img, views, h, w, &cfg);
    let oracle = |clean: Vec<f32>| {
        let s = schedule();
        move |sample: &Tensor, t: &[i64]| {
            let (c_in, plane) = (sample.shape[1], sample.shape[2] * sample.shape[3]);
            let b = t.len() / 2;
            output(sample, |n, c, p| {
                let a = s.alpha_bar(t[n]).expect("in range");
                let zt = sample.data[(n * c_in + c) * plane + p] as f64;
                let z = clean[((n % b) * 3 + c) * plane + p] as f64;
                ((zt - a.sqrt() * z) / (1.0 - a).sqrt()) as f32
            })
        }
    };
    let (stage1, _) = Fake::boxed(oracle(z0));
    let (stage2, _) = Fake::boxed(oracle(x0));
    let (cond, uncond) = embeddings();
    let mut g = CascadedGuidance::new(stage1, Some(stage2), cond, uncond, cfg).expect("valid");
    let mut rng = ChaCha8Rng::seed_from_u64(11);
    let trace = g
        .evaluate_traced(
            &imgs(&img, views, h, w),
            0.3,
            &mut rng,
            &InjectedDraws::default(),
        )
        .expect("runs");
    let stage2 = trace.stage2.as_ref().expect("stage II ran");
    assert!(
        max_abs(&trace.stage1.score.grad.data) < 1e-5,
        "stage I {}",
        max_abs(&trace.stage1.score.grad.data)
    );
    assert!(
        max_abs(&stage2.score.grad.data) < 1e-5,
        "stage II {}",
        max_abs(&stage2.score.grad.data)
    );
    // Compare with the scale of a wrong prediction (ε̂ = 0 gives |grad| ~ w·|ε| ~ 1).
    assert!(
        max_abs(&trace.output.grad_images.rgb) < 1e-3,
        "{}",
        max_abs(&trace.output.grad_images.rgb)
    );
}

#[test]
fn zero_prediction_gives_minus_weighted_noise() {
    // ε_c = ε_u = 0 ⇒ ε̂ = 0 ⇒ grad = w(t_b)·(0 − ε) = −w(t_b)·ε, per view b, in both stages.
    let (views, h, w) = (2, 64, 64);
    let mut g = zero_prediction_guidance();
    let mut rng = ChaCha8Rng::seed_from_u64(5);
    let trace = g
        .evaluate_traced(
            &imgs(&renders(views, h, w), views, h, w),
            1.0,
            &mut rng,
            &InjectedDraws::default(),
        )
        .expect("runs");
    let s = schedule();
    let st2 = trace.stage2.as_ref().expect("ran");
    for (grad, noise, t) in [
        (
            &trace.stage1.score.grad,
            &trace.stage1.score.noise,
            &trace.stage1.score.timesteps,
        ),
        (&st2.score.grad, &st2.score.noise, &st2.score.timesteps),
    ] {
        let per = grad.data.len() / views;
        for (i, (&gv, &e)) in grad.data.iter().zip(&noise.data).enumerate() {
            let wt = s.weight(t[i / per]).expect("in range");
            assert!(
                (gv as f64 + wt * e as f64).abs() < 1e-6 * (1.0 + e.abs() as f64),
                "{i}: {gv} vs {}",
                -wt * e as f64
            );
        }
        assert!(t.iter().all(|&t| (20..=980).contains(&t)));
    }
    // The loss is ½‖grad‖²/B, scaled by S·a (stage I) and S·w_II (stage II).
    let half_sq =
        |v: &[f32]| 0.5 * v.iter().map(|&x| (x as f64).powi(2)).sum::<f64>() / views as f64;
    assert!(
        (trace.output.loss_stage1 - 100.0 * half_sq(&trace.stage1.score.grad.data)).abs()
            < 1e-9 * trace.output.loss_stage1
    );
    assert!(
        (trace.output.loss_stage2 - 100.0 * 1.0 * half_sq(&st2.score.grad.data)).abs()
            < 1e-9 * trace.output.loss_stage2
    );
}

#[test]
fn distinct_cond_and_uncond_constants_give_the_cfg_combination() {
    // ε_c = 0.5, ε_u = 0.25, g = 100 ⇒ ε̂ = 0.5 + 100·(0.5 − 0.25) = 25.5; grad = w(t)·(25.5 − ε).
    // The batch is [cond × B; uncond × B], so sample n < B is conditional.
    let (views, h, w) = (4, 32, 48);
    let rule = move |s: &Tensor, t: &[i64]| {
        let b = t.len() / 2;
        output(s, move |n, _, _| if n < b { 0.5 } else { 0.25 })
    };
    let (stage1, _) = Fake::boxed(rule);
    let (stage2, _) = Fake::boxed(rule);
    let (cond, uncond) = embeddings();
    let mut g = CascadedGuidance::new(
        stage1,
        Some(stage2),
        cond,
        uncond,
        GuidanceConfig::default(),
    )
    .expect("valid");
    let mut rng = ChaCha8Rng::seed_from_u64(9);
    let trace = g
        .evaluate_traced(
            &imgs(&renders(views, h, w), views, h, w),
            0.5,
            &mut rng,
            &InjectedDraws::default(),
        )
        .expect("runs");
    let s = schedule();
    let st2 = trace.stage2.as_ref().expect("ran");
    for (guided, grad, noise, t) in [
        (
            &trace.stage1.score.eps_guided,
            &trace.stage1.score.grad,
            &trace.stage1.score.noise,
            &trace.stage1.score.timesteps,
        ),
        (
            &st2.score.eps_guided,
            &st2.score.grad,
            &st2.score.noise,
            &st2.score.timesteps,
        ),
    ] {
        assert!(guided.data.iter().all(|&v| v == 25.5));
        let per = grad.data.len() / views;
        for (i, (&gv, &e)) in grad.data.iter().zip(&noise.data).enumerate() {
            let expected = s.weight(t[i / per]).expect("in range") * (25.5 - e as f64);
            assert!(
                (gv as f64 - expected).abs() < 1e-5 * (1.0 + expected.abs()),
                "{gv} vs {expected}"
            );
        }
    }
}

#[test]
fn stage2_is_not_called_at_weight_zero() {
    // With w_II = 0 the stage-II model is never run, the stage-II loss is 0 and the image gradient equals
    // that of a guidance built without a stage-II model (same seed ⇒ same draws).
    let (views, h, w) = (2, 40, 40);
    let img = renders(views, h, w);
    let run = |with_stage2: bool| {
        let (stage1, _) = Fake::boxed(|s: &Tensor, _: &[i64]| {
            output(s, |n, c, p| 0.01 * (n + c) as f32 + 1e-4 * p as f32)
        });
        let (stage2, calls2) = Fake::boxed(|s: &Tensor, _: &[i64]| output(s, |_, _, _| 1.0));
        let (cond, uncond) = embeddings();
        let mut g = CascadedGuidance::new(
            stage1,
            with_stage2.then_some(stage2),
            cond,
            uncond,
            GuidanceConfig::default(),
        )
        .expect("valid");
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        let trace = g
            .evaluate_traced(
                &imgs(&img, views, h, w),
                0.0,
                &mut rng,
                &InjectedDraws::default(),
            )
            .expect("runs");
        let n_calls = calls2.lock().expect("not poisoned").len();
        (trace, n_calls)
    };
    let (with, calls) = run(true);
    let (without, _) = run(false);
    assert_eq!(calls, 0);
    assert!(with.stage2.is_none());
    assert_eq!(with.output.loss_stage2, 0.0);
    assert_eq!(with.output.grad_images, without.output.grad_images);
    assert!(max_abs(&with.output.grad_images.rgb) > 0.0);
}

#[test]
fn overflowing_guidance_gives_saturated_finite_gradients() {
    // Finite but huge predictions overflow in ε̂ = ε_c + 100(ε_c − ε_u) (f32, as the reference). Pixel
    // pattern p mod 4, (ε_c, ε_u):
    //   (MAX, −MAX): ε_c − ε_u = ∞ ⇒ ε̂ = ∞ ⇒ w(∞ − ε) = ∞ → f32::MAX (nan_to_num)
    //   (−MAX, MAX): ε̂ = −∞ → f32::MIN
    //   (1, 0), (0.5, 0.5): finite throughout.
    // The image gradient sums many ±MAX values: it must still come out finite (no NaN, no ∞).
    let rule = |s: &Tensor, t: &[i64]| {
        let b = t.len() / 2;
        output(s, move |n, _, p| match (n < b, p % 4) {
            (true, 0) | (false, 1) => f32::MAX,
            (true, 1) | (false, 0) => -f32::MAX,
            (true, 2) => 1.0,
            (false, 2) => 0.0,
            _ => 0.5,
        })
    };
    let (stage1, _) = Fake::boxed(rule);
    let (stage2, _) = Fake::boxed(rule);
    let (cond, uncond) = embeddings();
    let mut g = CascadedGuidance::new(
        stage1,
        Some(stage2),
        cond,
        uncond,
        GuidanceConfig::default(),
    )
    .expect("valid");
    let (views, h, w) = (2, 64, 64);
    let mut rng = ChaCha8Rng::seed_from_u64(1);
    let trace = g
        .evaluate_traced(
            &imgs(&renders(views, h, w), views, h, w),
            0.2,
            &mut rng,
            &InjectedDraws::default(),
        )
        .expect("runs");
    let st2 = trace.stage2.as_ref().expect("ran");
    for grad in [&trace.stage1.score.grad, &st2.score.grad] {
        for (p, &v) in grad.data.iter().enumerate() {
            match p % 4 {
                0 => assert_eq!(v, f32::MAX, "pixel {p}"),
                1 => assert_eq!(v, f32::MIN, "pixel {p}"),
                _ => assert!(v.is_finite() && v.abs() < 1e3, "pixel {p}: {v}"),
            }
        }
    }
    assert!(trace.output.grad_images.rgb.iter().all(|v| v.is_finite()));
    assert!(trace.grad_x.data.iter().all(|v| v.is_finite()));
    assert!(trace.output.loss_stage1.is_finite() && trace.output.loss_stage2.is_finite());
}

/// A denoiser that names itself, for the error messages.
struct Named(Box<dyn Denoiser>, &'static str);

impl Denoiser for Named {
    fn describe(&self) -> String {
        self.1.to_string()
    }
    fn predict(
        &mut self,
        sample: &Tensor,
        timesteps: &[i64],
        embeddings: &[&Embedding],
        class_labels: Option<&[i64]>,
    ) -> Result<Tensor, GuidanceError> {
        self.0.predict(sample, timesteps, embeddings, class_labels)
    }
}

/// The error of one evaluation (2 views of 64², stage-II weight 0.2) with these denoisers.
fn non_finite_error(stage1: Box<dyn Denoiser>, stage2: Box<dyn Denoiser>) -> GuidanceError {
    let (cond, uncond) = embeddings();
    let mut g = CascadedGuidance::new(
        Box::new(Named(stage1, "fake IF-I, unet1.onnx")),
        Some(Box::new(Named(stage2, "fake IF-II, unet2.onnx"))),
        cond,
        uncond,
        GuidanceConfig::default(),
    )
    .expect("valid");
    let mut rng = ChaCha8Rng::seed_from_u64(1);
    match g.evaluate_with_weight(&imgs(&renders(2, 64, 64), 2, 64, 64), 0.2, &mut rng) {
        Ok(out) => panic!(
            "non-finite predictions were accepted (loss {})",
            out.loss_stage1 + out.loss_stage2
        ),
        Err(e) => e,
    }
}

#[test]
fn non_finite_unet_predictions_are_errors_naming_stage_branch_count_and_model() {
    // Stage I: 5 NaN in the conditional ε (sample 1, channel 2, pixels 0..5); the learned-variance
    // channels (1e6 and beyond) are not looked at.
    let five_nan = |s: &Tensor, t: &[i64]| {
        let b = t.len() / 2;
        output(s, move |n, c, p| {
            if n == b - 1 && c == 2 && p < 5 {
                f32::NAN
            } else {
                0.0
            }
        })
    };
    let clean = |s: &Tensor, _: &[i64]| output(s, |_, _, _| 0.0);
    let e = non_finite_error(Fake::boxed(five_nan).0, Fake::boxed(clean).0);
    let msg = e.to_string();
    assert!(
        matches!(e, GuidanceError::NonFinite { count: 5, total, .. } if total == 2 * 3 * 64 * 64),
        "{e:?}"
    );
    assert!(
        msg.contains("stage-I UNet")
            && msg.contains("conditional branch")
            && msg.contains("fake IF-I, unet1.onnx")
            && msg.contains("5 non-finite"),
        "{msg}"
    );
    // Stage II: +∞ everywhere in the unconditional half; stage I is clean.
    let inf_uncond = |s: &Tensor, t: &[i64]| {
        let b = t.len() / 2;
        output(s, move |n, _, _| if n >= b { f32::INFINITY } else { 0.0 })
    };
    let e = non_finite_error(Fake::boxed(clean).0, Fake::boxed(inf_uncond).0);
    let msg = e.to_string();
    assert!(
        msg.contains("stage-II UNet")
            && msg.contains("unconditional branch")
            && msg.contains("fake IF-II, unet2.onnx")
            && msg.contains(&format!("{} non-finite", 2 * 3 * 256 * 256)),
        "{msg}"
    );
}

#[test]
fn non_finite_embeddings_and_renders_are_refused() {
    let (cond, uncond) = embeddings();
    let fake = || Fake::boxed(|s: &Tensor, _: &[i64]| output(s, |_, _, _| 0.0)).0;
    let mut nan = uncond.clone();
    nan.data.iter_mut().for_each(|v| *v = f32::NAN);
    let e = CascadedGuidance::new(fake(), None, cond.clone(), nan, GuidanceConfig::default())
        .err()
        .map(|e| e.to_string())
        .unwrap_or_default();
    assert!(
        e.contains("negative-prompt embedding") && e.contains("6 non-finite values"),
        "{e}"
    );
    let mut inf = cond.clone();
    inf.data[3] = f32::NEG_INFINITY;
    let e = CascadedGuidance::new(fake(), None, inf, uncond.clone(), GuidanceConfig::default())
        .err()
        .map(|e| e.to_string())
        .unwrap_or_default();
    assert!(
        e.contains("the prompt embedding") && e.contains("1 non-finite"),
        "{e}"
    );

    let mut g = CascadedGuidance::new(fake(), None, cond, uncond, GuidanceConfig::default())
        .expect("valid");
    let mut img = renders(1, 16, 16);
    img[7] = f32::NAN;
    let mut rng = ChaCha8Rng::seed_from_u64(0);
    let e = g
        .evaluate_with_weight(&imgs(&img, 1, 16, 16), 0.0, &mut rng)
        .err()
        .map(|e| e.to_string())
        .unwrap_or_default();
    assert!(
        e.contains("rendered images") && e.contains("1 non-finite"),
        "{e}"
    );
}

/// Total gradient for a tiny case where every operator is known in closed form. Config: resolution 64,
/// stage I 64, stage II 256, renders 64×64. Then R (cubic 64→64) and D (bilinear 64→64) are identities,
/// and Uᵀ (adjoint of bilinear 64→256, align_corners = False) maps a constant field c to 16·c: along each
/// axis every input pixel receives total weight 4 (interior: λ = 1/8, 3/8, 5/8, 7/8 from each side = 2 + 2;
/// border pixel 0: 1 + 1 from the clamped outputs 0, 1, then 7/8 + 5/8 + 3/8 + 1/8).
/// Stage I: ε_c = a_c, ε_u = a_c/2 ⇒ ε̂ = a_c + 100·a_c/2 = 51·a_c; injected ε = 0 ⇒ grad_I = 51·w(t_b)·a_c.
/// Stage II: ε_c = ε_u = β_c ⇒ ε̂ = β_c; ε_t = 0 ⇒ grad_II = w(t'_b)·β_c.
/// With S = 100, a = 1: ∂L/∂img[b, ·, ·, c] = 2·(100/B)·[51·w(t_b)·a_c + w_II·16·w(t'_b)·β_c].
fn check_total_gradient_by_hand(views: usize) {
    let alpha = [0.1f32, -0.2, 0.3];
    let beta = [0.4f32, 0.5, -0.6];
    let (cfg, n) = (
        GuidanceConfig {
            resolution: 64,
            ..GuidanceConfig::default()
        },
        64,
    );
    let (stage1, _) = Fake::boxed(move |s: &Tensor, t: &[i64]| {
        let b = t.len() / 2;
        output(
            s,
            move |k, c, _| if k < b { alpha[c] } else { alpha[c] / 2.0 },
        )
    });
    let (stage2, _) = Fake::boxed(move |s: &Tensor, _: &[i64]| output(s, move |_, c, _| beta[c]));
    let (cond, uncond) = embeddings();
    let mut g = CascadedGuidance::new(stage1, Some(stage2), cond, uncond, cfg).expect("valid");
    let t1: Vec<i64> = (0..views as i64).map(|b| 30 + 100 * b).collect();
    let t2: Vec<i64> = (0..views as i64).map(|b| 950 - 110 * b).collect();
    let injected = InjectedDraws {
        stage1_timesteps: Some(t1.clone()),
        stage1_noise: Some(vec![0.0; views * 3 * 64 * 64]),
        stage2_timesteps: Some(t2.clone()),
        stage2_noise_levels: Some(vec![500; views]),
        stage2_noise_lowres: Some(vec![0.0; views * 3 * 256 * 256]),
        stage2_noise: Some(vec![0.0; views * 3 * 256 * 256]),
    };
    let w2 = 0.25;
    let mut rng = ChaCha8Rng::seed_from_u64(0);
    let out = g
        .evaluate_traced(
            &imgs(&renders(views, n, n), views, n, n),
            w2,
            &mut rng,
            &injected,
        )
        .expect("runs")
        .output;
    let s = schedule();
    for b in 0..views {
        let (wi, wii) = (s.weight(t1[b]).expect("ok"), s.weight(t2[b]).expect("ok"));
        for p in 0..n * n {
            for c in 0..3 {
                let (term1, term2) = (
                    51.0 * wi * alpha[c] as f64,
                    w2 * 16.0 * wii * beta[c] as f64,
                );
                let k = 2.0 * (100.0 / views as f64);
                let expected = k * (term1 + term2);
                let got = out.grad_images.rgb[(b * n * n + p) * 3 + c] as f64;
                let tol = 1e-5 * k * (term1.abs() + term2.abs());
                assert!(
                    (got - expected).abs() < tol,
                    "view {b} pixel {p} ch {c}: {got} vs {expected}"
                );
            }
        }
    }
}

#[test]
fn total_gradient_scale_matches_hand_derivation_batch_1() {
    check_total_gradient_by_hand(1);
}

#[test]
fn total_gradient_scale_matches_hand_derivation_batch_8() {
    check_total_gradient_by_hand(8);
}

#[test]
fn gradient_sum_is_preserved_through_every_resize_adjoint() {
    // Every resize row sums to 1, so Σ (Aᵀ y) = Σ y for all of R, D, U. Hence at 512 px:
    // Σ ∂L/∂img = 2·[(S·a/B)·Σ grad_I + (S·w_II/B)·Σ grad_II].
    let (views, n) = (2, 512);
    let (stage1, _) = Fake::boxed(|s: &Tensor, _: &[i64]| {
        output(s, |k, c, p| ((k * 7 + c * 3 + p) % 11) as f32 * 0.01)
    });
    let (stage2, _) = Fake::boxed(|s: &Tensor, _: &[i64]| {
        output(s, |k, c, p| ((k * 5 + c + p) % 13) as f32 * -0.01)
    });
    let (cond, uncond) = embeddings();
    let mut g = CascadedGuidance::new(
        stage1,
        Some(stage2),
        cond,
        uncond,
        GuidanceConfig::default(),
    )
    .expect("valid");
    let mut rng = ChaCha8Rng::seed_from_u64(21);
    let w2 = 0.7;
    let trace = g
        .evaluate_traced(
            &imgs(&renders(views, n, n), views, n, n),
            w2,
            &mut rng,
            &InjectedDraws::default(),
        )
        .expect("runs");
    let sum = |v: &[f32]| v.iter().map(|&x| x as f64).sum::<f64>();
    let st2 = trace.stage2.as_ref().expect("ran");
    let expected = 2.0
        * (100.0 / views as f64)
        * (sum(&trace.stage1.score.grad.data) + w2 * sum(&st2.score.grad.data));
    let got = sum(&trace.output.grad_images.rgb);
    assert!(
        (got - expected).abs() < 1e-4 * expected.abs().max(1.0),
        "{got} vs {expected}"
    );
}

#[test]
fn model_inputs_have_the_specified_layout() {
    // Stage I: sample (2B, 3, 64, 64) = [z_t; z_t], timesteps [t; t], embeddings [cond × B; uncond × B],
    // no class labels. Stage II: sample (2B, 6, 256, 256), sample n = [x_t(n mod B), ẑ_s(n mod B)] on the
    // channel axis, timesteps [t; t], class labels [s; s]. x_t = √ᾱ_t x0 + √(1−ᾱ_t) ε_t with x0 =
    // bilinear₂₅₆(x), ẑ_s = √ᾱ_s ẑ + √(1−ᾱ_s) ε_s with ẑ = bilinear₂₅₆(bilinear₆₄(x)), all recomputed here.
    let (views, h, w) = (3, 100, 90);
    let cfg = GuidanceConfig::default();
    let img = renders(views, h, w);
    let (_, z0, x0) = clean_inputs(&img, views, h, w, &cfg);
    let z_hat = Resize2d::bilinear((64, 64), (256, 256))
        .expect("sizes")
        .apply(&z0)
        .expect("shape");
    let (stage1, calls1) = Fake::boxed(|s: &Tensor, _: &[i64]| output(s, |_, _, _| 0.0));
    let (stage2, calls2) = Fake::boxed(|s: &Tensor, _: &[i64]| output(s, |_, _, _| 0.0));
    let (cond, uncond) = embeddings();
    let mut g = CascadedGuidance::new(stage1, Some(stage2), cond.clone(), uncond.clone(), cfg)
        .expect("valid");
    let injected = InjectedDraws {
        stage1_timesteps: Some(vec![25, 400, 975]),
        stage2_timesteps: Some(vec![100, 600, 30]),
        stage2_noise_levels: Some(vec![700, 21, 333]),
        ..InjectedDraws::default()
    };
    let mut rng = ChaCha8Rng::seed_from_u64(77);
    let trace = g
        .evaluate_traced(&imgs(&img, views, h, w), 0.1, &mut rng, &injected)
        .expect("runs");
    let s = schedule();
    let noised = |clean: &[f32], noise: &[f32], t: i64| -> Vec<f64> {
        let a = s.alpha_bar(t).expect("ok");
        clean
            .iter()
            .zip(noise)
            .map(|(&c, &e)| a.sqrt() * c as f64 + (1.0 - a).sqrt() * e as f64)
            .collect()
    };
    let close = |got: &[f32], expected: &[f64]| {
        assert_eq!(got.len(), expected.len());
        got.iter()
            .zip(expected)
            .all(|(&g, &e)| (g as f64 - e).abs() < 1e-5)
    };

    let calls1 = calls1.lock().expect("not poisoned");
    assert_eq!(calls1.len(), 1);
    let c1 = &calls1[0];
    assert_eq!(c1.sample.shape, vec![6, 3, 64, 64]);
    assert_eq!(c1.timesteps, vec![25, 400, 975, 25, 400, 975]);
    assert!(c1.class_labels.is_none());
    let per1 = 3 * 64 * 64;
    for n in 0..6 {
        let v = n % 3;
        let exp = noised(
            &z0[v * per1..(v + 1) * per1],
            &trace.stage1.score.noise.data[v * per1..(v + 1) * per1],
            c1.timesteps[n],
        );
        assert!(
            close(&c1.sample.data[n * per1..(n + 1) * per1], &exp),
            "stage-I sample {n}"
        );
        assert_eq!(
            c1.embeddings[n],
            if n < 3 { cond.clone() } else { uncond.clone() }
        );
    }

    let calls2 = calls2.lock().expect("not poisoned");
    assert_eq!(calls2.len(), 1);
    let c2 = &calls2[0];
    let st2 = trace.stage2.as_ref().expect("ran");
    assert_eq!(c2.sample.shape, vec![6, 6, 256, 256]);
    assert_eq!(c2.timesteps, vec![100, 600, 30, 100, 600, 30]);
    assert_eq!(c2.class_labels, Some(vec![700, 21, 333, 700, 21, 333]));
    let per = 3 * 256 * 256;
    for n in 0..6 {
        let v = n % 3;
        let x_t = noised(
            &x0[v * per..(v + 1) * per],
            &st2.score.noise.data[v * per..(v + 1) * per],
            [100, 600, 30][v],
        );
        let z_s = noised(
            &z_hat[v * per..(v + 1) * per],
            &st2.noise_lowres.data[v * per..(v + 1) * per],
            [700, 21, 333][v],
        );
        let base = n * 2 * per;
        assert!(
            close(&c2.sample.data[base..base + per], &x_t),
            "stage-II x_t of sample {n}"
        );
        assert!(
            close(&c2.sample.data[base + per..base + 2 * per], &z_s),
            "stage-II ẑ_s of sample {n}"
        );
        assert_eq!(
            c2.embeddings[n],
            if n < 3 { cond.clone() } else { uncond.clone() }
        );
    }
    // The noises of the two stage-II branches are independent draws.
    assert_ne!(st2.score.noise.data, st2.noise_lowres.data);
}

#[test]
fn evaluate_is_deterministic_per_seed_and_matches_the_trace() {
    let (views, h, w) = (2, 48, 48);
    let img = renders(views, h, w);
    let make = || {
        let (stage1, _) = Fake::boxed(|s: &Tensor, _: &[i64]| {
            output(s, |n, c, p| {
                0.1 * (n as f32 - c as f32) + 1e-3 * (p % 17) as f32
            })
        });
        let (stage2, _) = Fake::boxed(|s: &Tensor, _: &[i64]| {
            output(s, |n, _, p| 0.05 * n as f32 - 1e-3 * (p % 5) as f32)
        });
        default_guidance(stage1, stage2)
    };
    let eval = |seed: u64| {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        make()
            .evaluate_with_weight(&imgs(&img, views, h, w), 0.2, &mut rng)
            .expect("runs")
    };
    let (a, b, c) = (eval(4), eval(4), eval(5));
    assert_eq!(a.grad_images, b.grad_images);
    assert_eq!(a.loss_stage1, b.loss_stage1);
    assert_ne!(a.grad_images, c.grad_images);
    let mut rng = ChaCha8Rng::seed_from_u64(4);
    let traced = make()
        .evaluate_traced(
            &imgs(&img, views, h, w),
            0.2,
            &mut rng,
            &InjectedDraws::default(),
        )
        .expect("runs");
    assert_eq!(traced.output.grad_images, a.grad_images);
    assert_eq!(a.grad_images.rgb.len(), img.len());
}

#[test]
fn bad_inputs_are_typed_errors() {
    let make = |stage2: bool| {
        let (stage1, _) = Fake::boxed(|s: &Tensor, _: &[i64]| output(s, |_, _, _| 0.0));
        let (s2, _) = Fake::boxed(|s: &Tensor, _: &[i64]| output(s, |_, _, _| 0.0));
        let (cond, uncond) = embeddings();
        CascadedGuidance::new(
            stage1,
            stage2.then_some(s2),
            cond,
            uncond,
            GuidanceConfig::default(),
        )
        .expect("valid")
    };
    let img = renders(1, 8, 8);
    let mut rng = ChaCha8Rng::seed_from_u64(0);
    let invalid = |r: Result<csd::GuidanceOutput, GuidanceError>| {
        matches!(r, Err(GuidanceError::InvalidInput(_)))
    };
    assert!(invalid(make(true).evaluate_with_weight(
        &imgs(&img[1..], 1, 8, 8),
        0.0,
        &mut rng
    )));
    assert!(invalid(make(true).evaluate_with_weight(
        &imgs(&img, 0, 8, 8),
        0.0,
        &mut rng
    )));
    assert!(invalid(make(true).evaluate_with_weight(
        &imgs(&img, 1, 8, 8),
        -0.1,
        &mut rng
    )));
    assert!(invalid(make(true).evaluate_with_weight(
        &imgs(&img, 1, 8, 8),
        f64::NAN,
        &mut rng
    )));
    assert!(invalid(make(false).evaluate_with_weight(
        &imgs(&img, 1, 8, 8),
        0.5,
        &mut rng
    )));
    let bad = InjectedDraws {
        stage1_timesteps: Some(vec![20, 30]),
        ..InjectedDraws::default()
    };
    assert!(
        make(true)
            .evaluate_traced(&imgs(&img, 1, 8, 8), 0.0, &mut rng, &bad)
            .is_err()
    );
    let out_of_range = InjectedDraws {
        stage1_timesteps: Some(vec![1000]),
        ..InjectedDraws::default()
    };
    assert!(
        make(true)
            .evaluate_traced(&imgs(&img, 1, 8, 8), 0.0, &mut rng, &out_of_range)
            .is_err()
    );

    // A model returning the wrong shape is a model error, not a panic.
    let (wrong, _) = Fake::boxed(|_: &Tensor, _: &[i64]| Tensor {
        shape: vec![1, 6, 64, 64],
        data: vec![0.0; 6 * 64 * 64],
    });
    let (cond, uncond) = embeddings();
    let mut g = CascadedGuidance::new(
        wrong,
        None,
        cond.clone(),
        uncond.clone(),
        GuidanceConfig::default(),
    )
    .expect("valid");
    assert!(matches!(
        g.evaluate_with_weight(&imgs(&img, 1, 8, 8), 0.0, &mut rng),
        Err(GuidanceError::Model(_))
    ));

    // Construction checks the embeddings and the config.
    let short = Embedding {
        shape: [2, 3],
        data: vec![0.0; 5],
    };
    let other = Embedding {
        shape: [3, 2],
        data: vec![0.0; 6],
    };
    let fake = || Fake::boxed(|s: &Tensor, _: &[i64]| output(s, |_, _, _| 0.0)).0;
    assert!(
        CascadedGuidance::new(
            fake(),
            None,
            short,
            uncond.clone(),
            GuidanceConfig::default()
        )
        .is_err()
    );
    assert!(
        CascadedGuidance::new(fake(), None, cond.clone(), other, GuidanceConfig::default())
            .is_err()
    );
    let bad_cfg = GuidanceConfig {
        timesteps: csd::TimestepRange { min: 20, max: 1000 },
        ..GuidanceConfig::default()
    };
    assert!(CascadedGuidance::new(fake(), None, cond.clone(), uncond.clone(), bad_cfg).is_err());
    let bad_clip = GuidanceConfig {
        grad_clip: Some(0.0),
        ..GuidanceConfig::default()
    };
    assert!(CascadedGuidance::new(fake(), None, cond, uncond, bad_clip).is_err());
}

#[test]
fn timesteps_are_drawn_per_view_per_stage_and_within_the_configured_range() {
    // B = 8 views: t (stage I), t and s (stage II) are 24 independent uniform draws from [20, 980]; the chance
    // that all 8 values of one vector coincide, or that two vectors are equal, is below 1e-20.
    let views = 8;
    let (h, w) = (16, 16);
    let zero = |s: &Tensor, _: &[i64]| output(s, |_, _, _| 0.0);
    let (cond, uncond) = embeddings();
    let (s1, _) = Fake::boxed(zero);
    let (s2, _) = Fake::boxed(zero);
    let mut g = CascadedGuidance::new(
        s1,
        Some(s2),
        cond.clone(),
        uncond.clone(),
        GuidanceConfig::default(),
    )
    .expect("valid");
    let mut rng = ChaCha8Rng::seed_from_u64(123);
    let trace = g
        .evaluate_traced(
            &imgs(&renders(views, h, w), views, h, w),
            0.5,
            &mut rng,
            &InjectedDraws::default(),
        )
        .expect("runs");
    let st2 = trace.stage2.as_ref().expect("ran");
    for t in [
        &trace.stage1.score.timesteps,
        &st2.score.timesteps,
        &st2.noise_levels,
    ] {
        assert_eq!(t.len(), views);
        assert!(t.iter().all(|&x| (20..=980).contains(&x)));
        assert!(t.iter().any(|&x| x != t[0]), "{t:?}");
    }
    assert_ne!(trace.stage1.score.timesteps, st2.score.timesteps);
    assert_ne!(st2.score.timesteps, st2.noise_levels);

    // A configured range is respected: [100, 100] gives t = s = 100 everywhere.
    let cfg = GuidanceConfig {
        timesteps: csd::TimestepRange { min: 100, max: 100 },
        ..GuidanceConfig::default()
    };
    let (s1, _) = Fake::boxed(zero);
    let (s2, _) = Fake::boxed(zero);
    let mut g = CascadedGuidance::new(s1, Some(s2), cond, uncond, cfg).expect("valid");
    let trace = g
        .evaluate_traced(
            &imgs(&renders(views, h, w), views, h, w),
            0.5,
            &mut rng,
            &InjectedDraws::default(),
        )
        .expect("runs");
    let st2 = trace.stage2.as_ref().expect("ran");
    for t in [
        &trace.stage1.score.timesteps,
        &st2.score.timesteps,
        &st2.noise_levels,
    ] {
        assert!(t.iter().all(|&x| x == 100));
    }
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

/// A denoiser predicting ε = 0.1 on every value (IF-shaped output), counting its calls.
struct Constant {
    calls: usize,
}

impl Denoiser for Constant {
    fn predict(
        &mut self,
        sample: &Tensor,
        _t: &[i64],
        _e: &[&Embedding],
        _s: Option<&[i64]>,
    ) -> Result<Tensor, GuidanceError> {
        self.calls += 1;
        Ok(output(sample, |_, _, _| 0.1))
    }
}

#[test]
fn the_trait_reads_the_stage2_weight_schedule_at_the_iteration() {
    use csd::Guidance;
    let (cond, uncond) = embeddings();
    let (views, h, w) = (1, 32, 32);
    let batch = imgs(&renders(views, h, w), views, h, w);
    let make = || {
        CascadedGuidance::new(
            Box::new(Constant { calls: 0 }),
            Some(Box::new(Constant { calls: 0 })),
            cond.clone(),
            uncond.clone(),
            GuidanceConfig::default(),
        )
        .expect("valid")
    };
    // The default schedule with a stage-II model is the reference's: 0 at iteration 1, 0.3 from
    // iteration 1750 on.
    let mut g = make();
    assert_eq!(g.stage2_weight().at(1), 0.0);
    assert_eq!(g.stage2_weight().at(1750), 0.3);
    let mut rng = ChaCha8Rng::seed_from_u64(9);
    let first = g.evaluate(&batch, 1, &mut rng).expect("runs");
    assert_eq!((first.stage2_weight, first.loss_stage2), (0.0, 0.0));
    // evaluate(iteration) ≡ evaluate_with_weight(schedule(iteration)) for the same draws.
    let schedule = optim::Schedule::parse("0.5>0.1:10").expect("valid");
    let w5 = schedule.at(5);
    let mut g = make().with_stage2_weight(schedule);
    let via_trait = g
        .evaluate(&batch, 5, &mut ChaCha8Rng::seed_from_u64(3))
        .expect("runs");
    let direct = make()
        .evaluate_with_weight(&batch, w5, &mut ChaCha8Rng::seed_from_u64(3))
        .expect("runs");
    assert!(w5 > 0.0 && via_trait.stage2_weight == w5);
    assert_eq!(via_trait.grad_images, direct.grad_images);
    assert_eq!(via_trait.loss_stage2, direct.loss_stage2);
    assert!(via_trait.grad_images.same_shape(&batch));
}

#[test]
fn without_a_stage2_model_the_default_schedule_is_zero() {
    use csd::Guidance;
    let (cond, uncond) = embeddings();
    let mut g = CascadedGuidance::new(
        Box::new(Constant { calls: 0 }),
        None,
        cond,
        uncond,
        GuidanceConfig::default(),
    )
    .expect("valid");
    let batch = imgs(&renders(1, 16, 16), 1, 16, 16);
    let mut rng = ChaCha8Rng::seed_from_u64(0);
    for iteration in [1, 500, 5000] {
        let out = g.evaluate(&batch, iteration, &mut rng).expect("runs");
        assert_eq!(out.stage2_weight, 0.0);
    }
}

#[test]
fn guidances_can_borrow_their_denoisers_one_after_another() {
    // Two prompts, one pair of UNets: each guidance borrows them and gives them back.
    let (mut unet1, mut unet2) = (Constant { calls: 0 }, Constant { calls: 0 });
    let (cond, uncond) = embeddings();
    let batch = imgs(&renders(1, 16, 16), 1, 16, 16);
    for prompt in 0..2 {
        let mut g = CascadedGuidance::new(
            Box::new(&mut unet1),
            Some(Box::new(&mut unet2)),
            cond.clone(),
            uncond.clone(),
            GuidanceConfig::default(),
        )
        .expect("valid");
        let mut rng = ChaCha8Rng::seed_from_u64(prompt);
        g.evaluate_with_weight(&batch, 0.5, &mut rng).expect("runs");
    }
    assert_eq!((unet1.calls, unet2.calls), (2, 2));
}

/// A denoiser whose prediction is half its input's first three channels: its output depends on
/// everything the guidance feeds it (renders, noise, timesteps through the noised sample).
fn echo() -> Box<dyn Denoiser> {
    Fake::boxed(|s: &Tensor, _: &[i64]| {
        let (c_in, plane) = (s.shape[1], s.shape[2] * s.shape[3]);
        let data = s.data.clone();
        output(s, move |n, c, p| 0.5 * data[(n * c_in + c) * plane + p])
    })
    .0
}

/// Both stages echo their input (so the gradient depends on the renders), w_II = 0.25.
fn echo_guidance() -> CascadedGuidance<'static> {
    let (cond, uncond) = embeddings();
    CascadedGuidance::new(
        echo(),
        Some(echo()),
        cond,
        uncond,
        GuidanceConfig::default(),
    )
    .expect("valid")
    .with_stage2_weight(optim::Schedule::constant(0.25))
}

#[test]
fn evaluate_many_is_that_many_evaluations_in_sequence_bit_for_bit() {
    use csd::Guidance;
    let (views, h, w) = (2, 40, 36);
    let a = imgs(&renders(views, h, w), views, h, w);
    let b = imgs(
        &renders(views, h, w)
            .iter()
            .map(|v| 1.0 - v)
            .collect::<Vec<_>>(),
        views,
        h,
        w,
    );
    // Sequence: b once (so that the workspace holds another batch's encoding), then 3 × a, then b.
    let mut one_by_one = echo_guidance();
    let mut rng = ChaCha8Rng::seed_from_u64(11);
    let mut expected = vec![one_by_one.evaluate(&b, 7, &mut rng).expect("runs")];
    for _ in 0..3 {
        expected.push(one_by_one.evaluate(&a, 7, &mut rng).expect("runs"));
    }
    expected.push(one_by_one.evaluate(&b, 7, &mut rng).expect("runs"));

    let mut batched = echo_guidance();
    let mut rng2 = ChaCha8Rng::seed_from_u64(11);
    let mut got = batched.evaluate_many(&b, 7, 1, &mut rng2).expect("runs");
    got.extend(batched.evaluate_many(&a, 7, 3, &mut rng2).expect("runs"));
    got.extend(batched.evaluate_many(&b, 7, 1, &mut rng2).expect("runs"));
    assert_eq!(got.len(), expected.len());
    for (k, (g, e)) in got.iter().zip(&expected).enumerate() {
        assert_eq!(g.grad_images, e.grad_images, "evaluation {k}");
        assert_eq!(
            (g.loss_stage1, g.loss_stage2, g.stage2_weight),
            (e.loss_stage1, e.loss_stage2, e.stage2_weight),
            "evaluation {k}"
        );
    }
    // Fresh draws per evaluation: the three evaluations of `a` differ.
    assert_ne!(got[1].grad_images, got[2].grad_images);
    assert!(got[1].loss_stage2 > 0.0);
    // Both generators end in the same state.
    assert_eq!(
        rand::RngCore::next_u64(&mut rng),
        rand::RngCore::next_u64(&mut rng2)
    );
    assert!(
        batched
            .evaluate_many(&a, 7, 0, &mut rng2)
            .expect("runs")
            .is_empty()
    );
}

#[test]
fn grey_renders_take_the_shortcut_with_the_same_bits_as_the_rgb_path() {
    // A grey view (three equal channels, what the renderers produce) is resized once and its
    // planes copied. R and the later resizes act on each channel alone, so the RGB path gives
    // channel c of x, z0, x0 and ẑ from channel c of the input: a batch whose channels 0 and 1
    // are the grey values and whose channel 2 differs takes the RGB path and must give, in its
    // channels 0 and 1, the grey batch's planes bit for bit. 512² renders: the guidance's size,
    // where the resize to 224 runs height first as the interleaved path does.
    let (views, h, w) = (2, 512, 512);
    let rgb = renders(views, h, w);
    let grey: Vec<f32> = rgb.chunks_exact(3).flat_map(|p| [p[0]; 3]).collect();
    let mixed: Vec<f32> = rgb
        .chunks_exact(3)
        .flat_map(|p| [p[0], p[0], p[1]])
        .collect();
    let trace = |img: &[f32]| {
        zero_prediction_guidance()
            .evaluate_traced(
                &imgs(img, views, h, w),
                0.3,
                &mut ChaCha8Rng::seed_from_u64(2),
                &InjectedDraws::default(),
            )
            .expect("runs")
    };
    let (a, b) = (trace(&grey), trace(&mixed));
    let (a2, b2) = (
        a.stage2.as_ref().expect("stage II ran"),
        b.stage2.as_ref().expect("stage II ran"),
    );
    let bits = |v: &[f32]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
    for (name, grey_t, mixed_t) in [
        ("x", &a.x, &b.x),
        ("z0", &a.stage1.z0, &b.stage1.z0),
        ("x0", &a2.x0, &b2.x0),
        ("ẑ", &a2.z_hat, &b2.z_hat),
    ] {
        let plane = grey_t.shape[2] * grey_t.shape[3];
        for v in 0..views {
            let at = |t: &Tensor, c: usize| {
                let i = (v * 3 + c) * plane;
                bits(&t.data[i..i + plane])
            };
            let want = at(mixed_t, 0);
            assert_eq!(
                at(mixed_t, 1),
                want,
                "{name}, view {v}: mixed channels 0 and 1"
            );
            assert_ne!(at(mixed_t, 2), want, "{name}, view {v}: channel 2 differs");
            for c in 0..3 {
                assert_eq!(at(grey_t, c), want, "{name}, view {v}, channel {c}");
            }
        }
    }
}

#[test]
fn grey_images_get_the_channel_sums_of_their_rgb_expansions_gradient() {
    // The same draws and losses as the RGB expansion's evaluations; dL/d(grey) = Σ_c dL/d(channel
    // c), which the grey path forms before the resize adjoints (each stage's and the last one)
    // instead of after (equal up to f32 rounding: about 2e-7 of the largest value here), as a
    // one-channel gradient. Two render sizes: 512² (the resize to 224 runs height first) and
    // 40×36 (width first).
    use csd::Guidance;
    for (views, h, w) in [(2, 512, 512), (3, 40, 36)] {
        let grey: Vec<f32> = renders(views, h, w).into_iter().step_by(3).collect();
        let a = Images::with_channels(views, h, w, 1, grey).expect("grey batch");
        let (mut rgb_guidance, mut grey_guidance) = (echo_guidance(), echo_guidance());
        let mut rng = ChaCha8Rng::seed_from_u64(5);
        let mut rng2 = ChaCha8Rng::seed_from_u64(5);
        let want = rgb_guidance
            .evaluate_many(&a.to_rgb(), 7, 2, &mut rng)
            .expect("runs");
        let got = grey_guidance
            .evaluate_many(&a, 7, 2, &mut rng2)
            .expect("runs");
        assert_eq!(got.len(), 2);
        for (k, (g, e)) in got.iter().zip(&want).enumerate() {
            assert_eq!(
                (g.loss_stage1, g.loss_stage2, g.stage2_weight),
                (e.loss_stage1, e.loss_stage2, e.stage2_weight),
                "{h}×{w}, evaluation {k}"
            );
            assert!(g.grad_images.same_shape(&a), "{h}×{w}: a grey gradient");
            let sums = e.grad_images.channel_sums();
            assert_eq!(g.grad_images.rgb.len(), sums.len());
            let scale = sums.iter().fold(0.0f64, |m, v| m.max(v.abs()));
            assert!(scale > 0.0);
            let worst = g
                .grad_images
                .rgb
                .iter()
                .zip(&sums)
                .fold(0.0f64, |m, (&a, b)| m.max((f64::from(a) - b).abs()));
            assert!(
                worst <= 1e-6 * scale,
                "{h}×{w}, evaluation {k}: {worst:e} against max {scale:e}"
            );
        }
        assert_eq!(
            rand::RngCore::next_u64(&mut rng),
            rand::RngCore::next_u64(&mut rng2)
        );
    }
    // Another channel count is refused.
    let two = Images {
        channels: 2,
        ..imgs(&vec![0.5; 2 * 8 * 8 * 2], 2, 8, 8)
    };
    let e = echo_guidance().evaluate(&two, 1, &mut ChaCha8Rng::seed_from_u64(1));
    assert!(matches!(e, Err(csd::GuidanceError::InvalidInput(_))));
}

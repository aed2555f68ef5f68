//! Overhead of everything in a guidance evaluation that is not the UNet: resizes and their adjoints, noise,
//! CFG, the SDS gradient and layout conversions, for 8 renders of 512×512 → 224 → 64 / 256, with an
//! instant fake denoiser (it only allocates a zero output of the right shape).
//!
//! `cargo run --release -p csd --example bench_csd` (optional args: views, repetitions).

use csd::resize::{PlaneResize, Resize2d};
use csd::schedule::fill_standard_normal;
use csd::sds::classifier_free_guidance;
use csd::{CascadedGuidance, Denoiser, Embedding, GuidanceConfig, GuidanceError, Images, Tensor};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use std::time::Instant;

struct Instant0;

impl Denoiser for Instant0 {
    fn predict(
        &mut self,
        sample: &Tensor,
        _timesteps: &[i64],
        _embeddings: &[&Embedding],
        _class_labels: Option<&[i64]>,
    ) -> Result<Tensor, GuidanceError> {
        let mut shape = sample.shape.clone();
        shape[1] = 6;
        Ok(Tensor::zeros(shape))
    }
}

/// Median wall time in milliseconds of `reps` runs after one warm-up.
fn time_ms(reps: usize, mut f: impl FnMut()) -> f64 {
    f();
    let mut t: Vec<f64> = (0..reps)
        .map(|_| {
            let s = Instant::now();
            f();
            s.elapsed().as_secs_f64() * 1e3
        })
        .collect();
    t.sort_by(f64::total_cmp);
    t[t.len() / 2]
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<usize> = std::env::args()
        .skip(1)
        .filter_map(|a| a.parse().ok())
        .collect();
    let views = args.first().copied().unwrap_or(8);
    let reps = args.get(1).copied().unwrap_or(10);
    let n = 512;
    let images: Vec<f32> = (0..views * n * n * 3)
        .map(|i| ((i * 7919) % 1000) as f32 / 1000.0)
        .collect();
    let emb = Embedding {
        shape: [77, 4096],
        data: vec![0.0; 77 * 4096],
    };
    let mut guidance = CascadedGuidance::new(
        Box::new(Instant0),
        Some(Box::new(Instant0)),
        emb.clone(),
        emb,
        GuidanceConfig::default(),
    )?
    .with_stage2_weight(optim::Schedule::constant(0.3));
    let batch = Images::new(views, n, n, images.clone())?;
    let mut rng = ChaCha8Rng::seed_from_u64(0);
    println!(
        "csd overhead: {views} views of {n}×{n}, median of {reps} runs, {} rayon threads",
        rayon::current_num_threads()
    );

    let row = |what: &str, ms: f64| println!("{what:<58} {ms:>9.2} ms");
    row(
        "evaluate, stage I + stage II (w_II = 0.3)",
        time_ms(reps, || {
            guidance
                .evaluate_with_weight(&batch, 0.3, &mut rng)
                .expect("fake guidance evaluates");
        }),
    );
    // The same minus the time inside the (fake) denoiser calls, which allocate and zero their
    // outputs (16×6×256² f32 for stage II): the guidance's own overhead, as `metrics.jsonl`
    // reports it (`guidance − guidance_denoiser`).
    // A one-channel batch is evaluated as the loop does for the CPU renderer's grey renders
    // (dL/d(grey) instead of dL/d(RGB)).
    let mut outside = |batch: &Images| {
        let mut ms: Vec<f64> = (0..reps)
            .map(|_| {
                let t = Instant::now();
                let denoiser_seconds = guidance
                    .evaluate_with_weight(batch, 0.3, &mut rng)
                    .expect("fake guidance evaluates")
                    .denoiser_seconds;
                (t.elapsed().as_secs_f64() - denoiser_seconds) * 1e3
            })
            .collect();
        ms.sort_by(f64::total_cmp);
        ms[ms.len() / 2]
    };
    let rgb_outside = outside(&batch);
    // Grey renders (three equal channels, what the renderers produce): x, z0, x0 and ẑ are
    // computed once per view and their planes copied.
    let grey: Vec<f32> = images.chunks_exact(3).flat_map(|p| [p[0]; 3]).collect();
    let grey_batch = Images::new(views, n, n, grey)?;
    let grey_outside = outside(&grey_batch);
    let one_channel = images.iter().step_by(3).copied().collect();
    let grey_gradient_outside = outside(&Images::with_channels(views, n, n, 1, one_channel)?);
    row(
        "evaluate, stage I + II, outside the denoiser calls",
        rgb_outside,
    );
    row("  the same, grey renders", grey_outside);
    row(
        "  the same, one-channel grey renders, dL/d(grey) (the loop's CPU path)",
        grey_gradient_outside,
    );
    row(
        "evaluate, stage I only (w_II = 0)",
        time_ms(reps, || {
            guidance
                .evaluate_with_weight(&batch, 0.0, &mut rng)
                .expect("fake guidance evaluates");
        }),
    );

    // The kernels `evaluate` runs (f32 gather resizes, one plane or one interleaved view at a time),
    // here single-threaded over all planes/views: their sum over 2 threads ≈ their share of the total.
    let planes = views * 3;
    let op = |r: Result<Resize2d, GuidanceError>| {
        r.map(|o| (PlaneResize::forward(&o), PlaneResize::adjoint(&o)))
    };
    let (r224, r224_t) = op(Resize2d::cubic_antialias((n, n), (224, 224)))?;
    let (d64, d64_t) = op(Resize2d::bilinear((224, 224), (64, 64)))?;
    let (u256, u256_t) = op(Resize2d::bilinear((224, 224), (256, 256)))?;
    let (u64_256, _) = op(Resize2d::bilinear((64, 64), (256, 256)))?;
    let mut tmp = Vec::new();
    let mut out224 = vec![0.0f32; 3 * 224 * 224];
    let mut out512 = vec![0.0f32; 3 * n * n];
    let view = &images[..3 * n * n];
    row(
        "  cubic AA 512→224, interleaved view → planes (all views)",
        time_ms(reps, || {
            for _ in 0..views {
                r224.apply_from_interleaved(view, 3, &mut out224, &mut tmp);
            }
        }),
    );
    row(
        "  cubic AA adjoint 224→512, planes → interleaved (all views)",
        time_ms(reps, || {
            for _ in 0..views {
                r224_t.apply_to_interleaved(&out224, 3, &mut out512, &mut tmp, |v| 2.0 * v);
            }
        }),
    );
    let plane_row = |what: &str, pr: &PlaneResize, tmp: &mut Vec<f32>| {
        let (ih, iw) = pr.in_hw();
        let (oh, ow) = pr.out_hw();
        let input = vec![0.5f32; ih * iw];
        let mut out = vec![0.0f32; oh * ow];
        row(
            what,
            time_ms(reps, || {
                for _ in 0..planes {
                    pr.apply_plane(&input, &mut out, tmp);
                }
            }),
        );
    };
    plane_row("  bilinear 224→64 (all planes)", &d64, &mut tmp);
    plane_row("  bilinear 224→64 adjoint (all planes)", &d64_t, &mut tmp);
    plane_row("  bilinear 224→256 (all planes)", &u256, &mut tmp);
    plane_row("  bilinear 224→256 adjoint (all planes)", &u256_t, &mut tmp);
    plane_row("  bilinear 64→256 (all planes)", &u64_256, &mut tmp);
    let n2 = 2 * planes * 256 * 256;
    let mut noise = vec![0.0f32; n2];
    row(
        &format!("  Gaussian noise, stage II ({n2} samples, 2 threads)"),
        time_ms(reps, || fill_standard_normal(&mut noise, &mut rng)),
    );
    let eps = vec![0.1f32; planes * 256 * 256];
    row(
        "  CFG at 256 px",
        time_ms(reps, || drop(classifier_free_guidance(&eps, &eps, 100.0))),
    );
    Ok(())
}

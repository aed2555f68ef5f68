//! Overhead of everything in a guidance evaluation that is not the UNet: resizes and their adjoints, noise,
//! CFG, the SDS gradient and layout conversions, for 8 renders of 512×512 → 224 → 64 / 256, with an
//! instant fake denoiser (it only allocates a zero output of the right shape).
//!
//! `cargo run --release -p csd --example bench_csd` (optional args: views, repetitions).

use csd::resize::Resize2d;
use csd::schedule::standard_normal;
use csd::sds::classifier_free_guidance;
use csd::{CascadedGuidance, Denoiser, Embedding, Guidance, GuidanceConfig, GuidanceError, Tensor};
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
    )?;
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
                .evaluate(&images, views, n, n, 0.3, &mut rng)
                .expect("fake guidance evaluates");
        }),
    );
    row(
        "evaluate, stage I only (w_II = 0)",
        time_ms(reps, || {
            guidance
                .evaluate(&images, views, n, n, 0.0, &mut rng)
                .expect("fake guidance evaluates");
        }),
    );

    let planes = views * 3;
    let r224 = Resize2d::cubic_antialias((n, n), (224, 224))?;
    let d64 = Resize2d::bilinear((224, 224), (64, 64))?;
    let u256 = Resize2d::bilinear((224, 224), (256, 256))?;
    let u64_256 = Resize2d::bilinear((64, 64), (256, 256))?;
    let plane512 = vec![0.5f32; planes * n * n];
    let plane224 = vec![0.5f32; planes * 224 * 224];
    let plane224_out = vec![0.5f64; planes * 224 * 224];
    let plane64 = vec![0.5f32; planes * 64 * 64];
    let plane256_f64 = vec![0.5f64; planes * 256 * 256];
    let plane64_f64 = vec![0.5f64; planes * 64 * 64];
    row(
        "  cubic AA 512→224 (f32)",
        time_ms(reps, || drop(r224.apply(&plane512))),
    );
    row(
        "  cubic AA 512→224 adjoint (f64 in, f32 out)",
        time_ms(reps, || drop(r224.adjoint_as::<f64, f32>(&plane224_out))),
    );
    row(
        "  bilinear 224→64 (f32)",
        time_ms(reps, || drop(d64.apply(&plane224))),
    );
    row(
        "  bilinear 224→64 adjoint (f64)",
        time_ms(reps, || drop(d64.adjoint(&plane64_f64))),
    );
    row(
        "  bilinear 224→256 (f32)",
        time_ms(reps, || drop(u256.apply(&plane224))),
    );
    row(
        "  bilinear 224→256 adjoint (f64)",
        time_ms(reps, || drop(u256.adjoint(&plane256_f64))),
    );
    row(
        "  bilinear 64→256 (f32)",
        time_ms(reps, || drop(u64_256.apply(&plane64))),
    );
    let n2 = 2 * planes * 256 * 256;
    row(
        &format!("  Gaussian noise, stage II ({n2} samples)"),
        time_ms(reps, || drop(standard_normal(n2, &mut rng))),
    );
    let eps = vec![0.1f32; planes * 256 * 256];
    row(
        "  CFG at 256 px",
        time_ms(reps, || drop(classifier_free_guidance(&eps, &eps, 100.0))),
    );
    Ok(())
}

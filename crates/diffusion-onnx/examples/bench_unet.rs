//! Per-call time of the IF UNets through ONNX Runtime on a guidance-sized batch.
//!
//! ```sh
//! cargo run --release -p diffusion-onnx --example bench_unet -- [MODEL_DIR] [ITERS] [THREADS]
//! ```
//! Defaults: `fixtures/models/tiny-if`, 10 timed calls after 2 warm-up calls, ONNX Runtime's default
//! thread count. The batch is 16 = 8 views × (conditional + unconditional), as csd sends it: stage I
//! at 64 px (3 channels), stage II at 256 px (6 channels, with noise-level labels).

use std::time::Instant;

use csd::{Denoiser, Embedding, Tensor};
use diffusion_onnx::{ModelDir, OnnxDenoiser, SessionOptions, Stage};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut args = std::env::args().skip(1);
    let dir = args.next().unwrap_or_else(|| {
        concat!(env!("CARGO_MANIFEST_DIR"), "/../../fixtures/models/tiny-if").to_string()
    });
    let iters: usize = args.next().map(|s| s.parse()).transpose()?.unwrap_or(10);
    let threads: Option<usize> = args.next().map(|s| s.parse()).transpose()?;
    let model = ModelDir::open(&dir)?;
    let options = SessionOptions {
        intra_threads: threads,
        ..SessionOptions::default()
    };
    let uncond = model.uncond_embedding()?;
    let cond = Embedding {
        shape: uncond.shape,
        data: uncond.data.iter().map(|v| v * 0.5 + 0.1).collect(),
    };
    let batch = 16;
    let embs: Vec<&Embedding> = (0..batch)
        .map(|i| if i < batch / 2 { &cond } else { &uncond })
        .collect();
    println!(
        "model {dir} ({}), batch {batch}, threads {threads:?}, {iters} timed calls",
        model.manifest().name
    );
    for stage in [Stage::One, Stage::Two] {
        let Some(spec) = model.stage(stage) else {
            continue;
        };
        let (c, side) = (spec.in_channels, spec.sample_size);
        let mut unet = OnnxDenoiser::open(&model, stage, &options)?;
        let n = batch * c * side * side;
        let sample = Tensor {
            shape: vec![batch, c, side, side],
            data: (0..n).map(|i| ((i % 251) as f32 / 125.0) - 1.0).collect(),
        };
        let t: Vec<i64> = (0..batch as i64).map(|i| 20 + 60 * i).collect();
        let labels: Option<Vec<i64>> =
            (stage == Stage::Two).then(|| (0..batch as i64).map(|i| 900 - 50 * i).collect());
        for _ in 0..2 {
            unet.predict(&sample, &t, &embs, labels.as_deref())?;
        }
        let mut ms = Vec::with_capacity(iters);
        for _ in 0..iters {
            let start = Instant::now();
            let out = unet.predict(&sample, &t, &embs, labels.as_deref())?;
            ms.push(start.elapsed().as_secs_f64() * 1e3);
            std::hint::black_box(out);
        }
        ms.sort_by(|a, b| a.total_cmp(b));
        let mean = ms.iter().sum::<f64>() / ms.len().max(1) as f64;
        println!(
            "{} {:?} {side}px: median {:.1} ms, mean {:.1} ms, min {:.1} ms, max {:.1} ms per call",
            stage.key(),
            spec.dtype,
            ms[ms.len() / 2],
            mean,
            ms[0],
            ms[ms.len() - 1]
        );
    }
    Ok(())
}

//! One text iteration's work outside the UNets (issue 10, target 3), with an instant fake
//! denoiser: dARAP forward, 8 renders at 512², the guidance (stage I + II) for both sub-steps,
//! the renderer backward, two dARAP backwards and two Adam steps, on an icosphere of 20,480
//! faces. Runs the library's loop (`run_loop`) with the text objective, alternating between the
//! loop as it is (all sub-steps of an iteration evaluated together) and the same objective
//! driven one sub-step at a time (the trait's default `evaluate_batch`), and prints the median
//! per part of the iterations after each run's first.
//!
//! `cargo run --release -p stylize --example bench_iteration [-- ROUNDS ITERATIONS [LOOPS]]`
//! (defaults 3, 6 and `both`; LOOPS `together` runs only the loop as it is, e.g. under `perf`;
//! pin it with `taskset -c 0,1`, `RAYON_NUM_THREADS=2`). Like the command line it calls
//! `stylize::malloc::retain_freed_buffers` first.

use csd::{CascadedGuidance, Denoiser, Embedding, GuidanceConfig, GuidanceError, Tensor};
use darap::{Darap, DarapOptions};
use optim::{Adam, AdamConfig, Schedule};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use raster_diff::{CameraConfig, CpuRenderer};
use stylize::pipeline::{
    LoopSpec, LoopState, Objective, RecordIterations, SubStepsOneByOne, TextObjective,
    ViewSettings, run_loop,
};

/// Returns zeros of IF's output shape (6 channels) at once: a denoiser that costs only its
/// output's allocation.
struct Instant0;

impl Denoiser for Instant0 {
    fn predict(
        &mut self,
        sample: &Tensor,
        _: &[i64],
        _: &[&Embedding],
        _: Option<&[i64]>,
    ) -> Result<Tensor, GuidanceError> {
        let s = &sample.shape;
        Ok(Tensor {
            shape: vec![s[0], 6, s[2], s[3]],
            data: vec![0.0; s[0] * 6 * s[2] * s[3]],
        })
    }
}

fn objective(faces: &[[u32; 3]]) -> anyhow::Result<TextObjective<'static>> {
    let embedding = Embedding {
        shape: [2, 3],
        data: vec![0.5; 6],
    };
    let guidance = CascadedGuidance::new(
        Box::new(Instant0),
        Some(Box::new(Instant0)),
        embedding.clone(),
        embedding,
        GuidanceConfig::default(),
    )?
    .with_stage2_weight(Schedule::constant(0.3));
    Ok(TextObjective::new(
        Box::new(CpuRenderer::default()),
        Box::new(guidance),
        faces,
        ViewSettings {
            camera: CameraConfig::default(),
            views: 8,
            width: 512,
            height: 512,
            adapt_distance: true,
        },
    ))
}

const PARTS: [&str; 8] = [
    "darap_forward",
    "render",
    "guidance",
    "render_backward",
    "darap_backward",
    "adam",
    "guidance_denoiser",
    "total",
];

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

fn main() -> anyhow::Result<()> {
    // As the command line does (skipped when GLIBC_TUNABLES is set: any value, e.g.
    // `GLIBC_TUNABLES=glibc.malloc.check=0`, measures glibc's default policy).
    let retained = stylize::malloc::retain_freed_buffers();
    let raw: Vec<String> = std::env::args().skip(1).collect();
    let number = |k: usize, default: usize| -> anyhow::Result<usize> {
        raw.get(k).map_or(Ok(default), |a| {
            a.parse()
                .map_err(|e| anyhow::anyhow!("argument {}: {a:?}: {e}", k + 1))
        })
    };
    let rounds = number(0, 3)?;
    let iterations = number(1, 6)?.max(2) as u64;
    let loops = match raw.get(2).map(String::as_str) {
        None | Some("both") => 2,
        Some("together") => 1,
        Some(other) => anyhow::bail!("LOOPS is `both` or `together`, not {other:?}"),
    };
    let (p, f) = mesh_core::shapes::icosphere(5).into_parts();
    let darap = Darap::new(&p, &f, DarapOptions::default())?;
    let spec = LoopSpec {
        iterations,
        steps_per_batch: 2,
        checkpoint_every: 0,
        preview_every: 0,
        halt_after: None,
    };
    println!(
        "{} vertices, {} faces; 8 views at 512², stage I + II (w_II 0.3), instant denoiser; \
         {rounds} rounds of {iterations} iterations, medians over iterations 2..; \
         stylize::malloc::retain_freed_buffers: {retained}",
        p.len(),
        f.len()
    );
    let mut samples: [Vec<Vec<f64>>; 2] = Default::default();
    for _ in 0..rounds {
        for (mode, samples) in samples.iter_mut().enumerate().take(loops) {
            let mut state = LoopState {
                iteration: 0,
                x: darap.rest_normals().to_vec(),
                adam: Adam::new(3 * darap.num_vertices(), AdamConfig::default())?,
                rng: ChaCha8Rng::seed_from_u64(1),
            };
            let mut records = RecordIterations::default();
            let mut text = objective(&f)?;
            let mut one = SubStepsOneByOne(objective(&f)?);
            let obj: &mut dyn Objective = if mode == 0 { &mut text } else { &mut one };
            run_loop(&darap, &spec, &mut state, obj, &mut records)?;
            for r in records.0.iter().skip(1) {
                let get = |k: &str| r.timings.iter().find(|t| t.0 == k).map_or(0.0, |t| t.1);
                let mut row: Vec<f64> = PARTS.iter().map(|k| get(k) * 1e3).collect();
                row.push((get("total") - get("guidance_denoiser")) * 1e3);
                samples.push(row);
            }
        }
    }
    println!(
        "| loop | {} | total − denoiser |",
        PARTS.map(|p| p.to_string()).join(" | ")
    );
    println!("|---|{}---:|", "---:|".repeat(PARTS.len()));
    for (mode, rows) in samples.iter().enumerate().take(loops) {
        let name = ["sub-steps together", "one sub-step at a time"][mode];
        let cols: Vec<String> = (0..=PARTS.len())
            .map(|c| format!("{:.1}", median(rows.iter().map(|r| r[c]).collect())))
            .collect();
        println!("| {name} | {} |", cols.join(" | "));
    }
    Ok(())
}

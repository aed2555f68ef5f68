//! Renderer benchmark: forward and forward+backward of 8 views at 512×512 for icospheres of
//! 5,120, 20,480 and 81,920 faces, per backend (cpu; wgpu when an adapter exists — on a machine
//! without a GPU that is lavapipe, a software Vulkan, so its numbers say nothing about real GPUs).
//!
//! `cargo run --release -p raster-diff --example bench_render [-- --reps N] [--backend cpu|wgpu]`
//!
//! The wgpu backend runs projection, rasterization, shading, antialiasing and their backward as
//! WGSL compute shaders; smooth normals and their adjoint stay on the CPU (see `raster_diff::gpu`).

use std::time::Instant;

use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use raster_diff::{CameraConfig, CpuRenderer, Images, Renderer, sample_views};

fn median(mut xs: Vec<f64>) -> f64 {
    xs.sort_by(f64::total_cmp);
    xs[xs.len() / 2]
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().collect();
    let reps = args
        .iter()
        .position(|a| a == "--reps")
        .and_then(|i| args.get(i + 1))
        .and_then(|s| s.parse().ok())
        .unwrap_or(5usize);
    let only = args
        .iter()
        .position(|a| a == "--backend")
        .and_then(|i| args.get(i + 1))
        .cloned();
    let wanted = |name: &str| only.as_deref().is_none_or(|o| o == name);
    let (w, h, n_views) = (512, 512, 8);
    let views = sample_views(
        &CameraConfig::default(),
        n_views,
        1.0,
        &mut ChaCha8Rng::seed_from_u64(0),
    );
    let mut backends: Vec<Box<dyn Renderer>> = Vec::new();
    if wanted("cpu") {
        backends.push(Box::new(CpuRenderer::default()));
    }
    #[cfg(feature = "gpu")]
    if wanted("wgpu") {
        match raster_diff::gpu::WgpuRenderer::new(raster_diff::RenderSettings::default()) {
            Ok(g) => backends.push(Box::new(g)),
            Err(e) => println!("wgpu backend skipped: {e}"),
        }
    }
    println!("{n_views} views at {w}×{h}, median of {reps} runs (after one warm-up)");
    println!("| backend | faces | vertices | forward (ms) | forward+backward (ms) |");
    println!("|---|---:|---:|---:|---:|");
    for subdivisions in [4, 5, 6] {
        let (v, f) = mesh_core::shapes::icosphere(subdivisions).into_parts();
        for r in backends.iter_mut() {
            let img = r.render(&v, &f, &views, w, h)?;
            let d = Images {
                rgb: img
                    .rgb
                    .iter()
                    .enumerate()
                    .map(|(i, _)| ((i % 7) as f32 - 3.0) * 1e-3)
                    .collect(),
                ..img
            };
            r.backward(&d)?;
            let mut fwd = Vec::new();
            let mut both = Vec::new();
            for _ in 0..reps {
                let t = Instant::now();
                r.render(&v, &f, &views, w, h)?;
                fwd.push(t.elapsed().as_secs_f64() * 1e3);
                let t = Instant::now();
                r.render(&v, &f, &views, w, h)?;
                r.backward(&d)?;
                both.push(t.elapsed().as_secs_f64() * 1e3);
            }
            println!(
                "| {} | {} | {} | {:.1} | {:.1} |",
                r.name(),
                f.len(),
                v.len(),
                median(fwd),
                median(both)
            );
        }
    }
    Ok(())
}

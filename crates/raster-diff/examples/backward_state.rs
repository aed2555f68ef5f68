//! What the CPU renderer keeps between `render` and `backward` (the "most recent render" state),
//! and what it costs: 8 views at 512×512 of a 20,480-face icosphere, bytes kept and the time of
//! render, of backward and of cloning the kept vertex/face copies (what an explicit record would
//! have to own as well). Used for the "Renderer backward state" decision in `docs/architecture.md`.
//!
//! `cargo run -p raster-diff --example backward_state [-- --subdivisions 5] [--reps 5]`

use std::time::Instant;

use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use raster_diff::{CameraConfig, CpuRenderer, Images, Renderer, sample_views};

fn arg(args: &[String], name: &str, default: usize) -> usize {
    args.iter()
        .position(|a| a == name)
        .and_then(|i| args.get(i + 1))
        .and_then(|s| s.parse().ok())
        .unwrap_or(default)
}

fn median(mut xs: Vec<f64>) -> f64 {
    xs.sort_by(f64::total_cmp);
    xs[xs.len() / 2]
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().collect();
    let subdivisions = arg(&args, "--subdivisions", 5) as u32;
    let reps = arg(&args, "--reps", 5).max(1);
    let (w, h, n_views) = (512, 512, 8);
    let views = sample_views(
        &CameraConfig::default(),
        n_views,
        1.0,
        &mut ChaCha8Rng::seed_from_u64(0),
    );
    let (v, f) = mesh_core::shapes::icosphere(subdivisions).into_parts();
    let mut r = CpuRenderer::default();
    let img = r.render(&v, &f, &views, w, h)?;
    let d = Images {
        rgb: (0..img.rgb.len())
            .map(|i| ((i % 7) as f32 - 3.0) * 1e-3)
            .collect(),
        ..img
    };
    r.backward(&d)?;
    let (mut fwd, mut bwd, mut copy) = (Vec::new(), Vec::new(), Vec::new());
    for _ in 0..reps {
        let t = Instant::now();
        let out = r.render(&v, &f, &views, w, h)?;
        fwd.push(t.elapsed().as_secs_f64() * 1e3);
        let t = Instant::now();
        r.backward(&d)?;
        bwd.push(t.elapsed().as_secs_f64() * 1e3);
        let t = Instant::now();
        let copies = (v.to_vec(), f.to_vec());
        copy.push(t.elapsed().as_secs_f64() * 1e3);
        std::hint::black_box((out, copies));
    }
    let kept = r.backward_state_bytes();
    let image_bytes = n_views * w * h * 3 * 4;
    println!(
        "{} faces, {} vertices, {n_views} views at {w}×{h}, median of {reps}",
        f.len(),
        v.len()
    );
    println!(
        "kept for backward: {:.1} MiB (the returned Images: {:.1} MiB)",
        kept as f64 / (1 << 20) as f64,
        image_bytes as f64 / (1 << 20) as f64
    );
    println!(
        "render {:.1} ms, backward {:.1} ms, vertex+face copies {:.3} ms",
        median(fwd),
        median(bwd),
        median(copy)
    );
    Ok(())
}

//! The wgpu backend: shader validation (always) and cross-checks against the CPU reference (when an
//! adapter exists; lavapipe counts).
#![cfg(feature = "gpu")]

use raster_diff::gpu::{RASTERIZE_WGSL, WgpuRenderer};
use raster_diff::{CpuRenderer, Images, RenderSettings, Renderer, orbit_views, shapes};

#[test]
fn wgsl_shaders_validate_with_naga() {
    let module = naga::front::wgsl::parse_str(RASTERIZE_WGSL).expect("rasterize.wgsl parses");
    naga::valid::Validator::new(
        naga::valid::ValidationFlags::all(),
        naga::valid::Capabilities::empty(),
    )
    .validate(&module)
    .expect("rasterize.wgsl validates");
}

fn gpu() -> Option<WgpuRenderer> {
    match WgpuRenderer::new(RenderSettings::default()) {
        Ok(g) => Some(g),
        Err(e) => {
            println!("SKIPPED: no wgpu adapter ({e})");
            None
        }
    }
}

/// GPU coverage uses f32 screen positions, the CPU's f64: a pixel may differ only where its centre
/// lies within f32 rounding of an edge, so on a 96×96 render of an icosphere at most a handful of
/// pixels may see another triangle. Where every pixel agrees, images and gradients are the CPU
/// reference's bit for bit except through the f32 depth used to pick the front pixel at
/// antialiased pairs.
#[test]
fn wgpu_visibility_images_and_gradients_match_cpu() {
    let Some(mut g) = gpu() else { return };
    println!("adapter: {:?}", g.adapter_info());
    let (v, f) = shapes::icosphere(3);
    let views = orbit_views(4, 25.0, 2.6, 90.0);
    let (w, h) = (96, 96);
    let mut c = CpuRenderer::default();
    let ic = c.render(&v, &f, &views, w, h).expect("cpu render");
    let ids_cpu = c.triangle_ids().expect("state");
    let ig = g.render(&v, &f, &views, w, h).expect("gpu render");
    let vis: Vec<u32> = views
        .iter()
        .flat_map(|view| g.visibility(&v, &f, view, w, h).expect("visibility").ids)
        .collect();
    let differing = ids_cpu.iter().zip(&vis).filter(|(a, b)| a != b).count();
    println!("pixels with another triangle: {differing} of {}", vis.len());
    assert!(differing <= 8, "{differing} pixels differ in coverage");
    let max_img = ic
        .rgb
        .iter()
        .zip(&ig.rgb)
        .map(|(a, b)| (a - b).abs())
        .fold(0.0f32, f32::max);
    let d = Images {
        rgb: ic
            .rgb
            .iter()
            .enumerate()
            .map(|(i, _)| ((i * 37) % 11) as f32 - 5.0)
            .collect(),
        ..ic.clone()
    };
    let gc = c.backward(&d).expect("cpu backward");
    let gg = g.backward(&d).expect("gpu backward");
    let norm = |x: &[[f64; 3]]| x.iter().flatten().map(|a| a * a).sum::<f64>().sqrt();
    let diff: Vec<[f64; 3]> = gc
        .iter()
        .zip(&gg)
        .map(|(a, b)| [a[0] - b[0], a[1] - b[1], a[2] - b[2]])
        .collect();
    let rel = norm(&diff) / norm(&gc);
    println!("max image difference {max_img:e}, relative gradient difference {rel:e}");
    if differing == 0 {
        assert!(max_img < 1e-6, "images differ by {max_img}");
        assert!(rel < 1e-9, "gradients differ by {rel}");
    } else {
        // A differing pixel changes its own value and its antialiasing pairs only.
        let changed = ic
            .rgb
            .iter()
            .zip(&ig.rgb)
            .filter(|(a, b)| (*a - *b).abs() > 1e-6)
            .count()
            / 3;
        assert!(
            changed <= 5 * differing,
            "{changed} pixels changed for {differing} coverage differences"
        );
    }
}

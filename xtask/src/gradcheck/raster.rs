//! Gradient checks of the renderer's hand-written adjoints (crate `raster-diff`, CPU backend).
//!
//! The image is piecewise smooth in the vertex positions: coverage (which triangle a pixel centre
//! sees) is piecewise constant, so a central difference is only meaningful while no pixel changes
//! triangle between θ − h·d and θ + h·d. Every image check below therefore records the triangle id
//! of every pixel at θ and fails loudly if a shifted evaluation sees a different coverage (with
//! h = 1e-6 world units ≈ 1e-5 pixels this would need a pixel centre within 1e-5 px of an edge).
//! Kinks inside the shading (two-sided sign flip, clamp of the bent-normal blend, max(n·l, 0))
//! have measure zero and are treated the same way as in the adjoint.

use std::cell::Cell;

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use raster_diff::cpu::math::DVec3;
use raster_diff::cpu::normals;
use raster_diff::cpu::raster::NO_TRIANGLE;
use raster_diff::{CameraConfig, CpuRenderer, RenderSettings, View, sample_views, shapes};

use super::{CheckResult, Report, Tolerance};

const W: usize = 48;
const H: usize = 40;

/// A bumpy icosphere (random radial noise) so silhouettes are not all convex.
fn bumpy_sphere(seed: u64) -> (Vec<[f64; 3]>, Vec<[u32; 3]>) {
    let (mut v, f) = shapes::icosphere(3);
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    for p in v.iter_mut() {
        let r = 0.85 + 0.25 * rng.random::<f64>();
        *p = [p[0] * r, p[1] * r * 1.2, p[2] * r];
    }
    (v, f)
}

fn views(seed: u64) -> Vec<View> {
    sample_views(
        &CameraConfig::default(),
        3,
        1.0,
        &mut ChaCha8Rng::seed_from_u64(seed),
    )
}

fn flatten(v: &[[f64; 3]]) -> Vec<f64> {
    v.iter().flatten().copied().collect()
}

fn unflatten(t: &[f64]) -> Vec<[f64; 3]> {
    t.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect()
}

/// Checks ⟨G, image(θ)⟩ with `settings`; `mask` selects which pixels carry a random weight.
fn image_check(
    report: &mut Report,
    name: &str,
    settings: RenderSettings,
    seed: u64,
    mask: impl Fn(u32) -> bool,
) -> anyhow::Result<()> {
    let (v, f) = bumpy_sphere(seed);
    let views = views(seed + 1);
    let mut r = CpuRenderer::new(settings);
    // The loss is ⟨G, image(θ) − image(θ₀)⟩: the constant offset does not change the gradient but
    // keeps the large constant part (white background) out of the difference quotient's rounding.
    let base = r.render_grey(&v, &f, &views, W, H)?;
    let ids = r
        .triangle_ids()
        .ok_or_else(|| anyhow::anyhow!("no render state"))?;
    let mut rng = ChaCha8Rng::seed_from_u64(seed + 2);
    let g: Vec<f64> = ids
        .iter()
        .map(|&t| {
            if mask(t) {
                rng.random::<f64>() * 2.0 - 1.0
            } else {
                0.0
            }
        })
        .collect();
    let grad = flatten(&r.backward_grey(&g)?);
    let coverage_changed = Cell::new(false);
    let failed_render = Cell::new(false);
    let theta = flatten(&v);
    report.check(
        name,
        &theta,
        &grad,
        Tolerance {
            atol: 1e-8,
            ..Tolerance::default()
        },
        seed + 3,
        |t| {
            let Ok(img) = r.render_grey(&unflatten(t), &f, &views, W, H) else {
                failed_render.set(true);
                return f64::NAN;
            };
            if r.triangle_ids().as_ref() != Some(&ids) {
                coverage_changed.set(true);
            }
            img.iter()
                .zip(&base)
                .zip(&g)
                .map(|((a, a0), b)| (a - a0) * b)
                .sum()
        },
    );
    if coverage_changed.get() {
        report.fail(
            name,
            "pixel coverage changed within ±h: the finite difference is not meaningful".into(),
        );
    }
    if failed_render.get() {
        report.fail(name, "a shifted render failed".into());
    }
    Ok(())
}

/// All renderer checks.
pub fn suite(report: &mut Report) -> anyhow::Result<()> {
    // (a) Interior shading: no antialiasing, so with coverage fixed the image is the shading of
    // each covered pixel centre, smooth in the vertices (barycentrics, normals, view and light).
    image_check(
        report,
        "raster/cpu shading (no AA), covered pixels",
        RenderSettings {
            antialias: false,
            near: 0.5,
        },
        11,
        |t| t != NO_TRIANGLE,
    )?;

    // (b) Smooth vertex normals alone: ⟨G, n(x)⟩.
    {
        let (v, f) = bumpy_sphere(21);
        let mut rng = ChaCha8Rng::seed_from_u64(22);
        let g: Vec<DVec3> = (0..v.len())
            .map(|_| {
                DVec3::new(
                    rng.random::<f64>() - 0.5,
                    rng.random::<f64>() - 0.5,
                    rng.random::<f64>() - 0.5,
                )
            })
            .collect();
        let raw = normals::face_normals_raw(&v, &f);
        let (n, sums) = normals::smooth_normals(&v, &f, &raw);
        let mut dx = vec![DVec3::ZERO; v.len()];
        normals::smooth_normals_adjoint(&v, &f, &n, &sums, &g, &mut dx);
        let grad: Vec<f64> = dx.iter().flat_map(|d| d.to_array()).collect();
        report.check(
            "raster/smooth vertex normals",
            &flatten(&v),
            &grad,
            Tolerance::default(),
            23,
            |t| {
                let x = unflatten(t);
                let raw = normals::face_normals_raw(&x, &f);
                let (n, _) = normals::smooth_normals(&x, &f, &raw);
                n.iter().zip(&g).map(|(a, b)| a.dot(*b)).sum()
            },
        );
    }

    // (c) Silhouette antialiasing: weights only on background pixels, whose colour is constant 1
    // unless a blend moves part of a neighbouring surface colour in; so this loss sees only the
    // antialiasing term (its weight α, a smooth function of the edge's screen position while the
    // edge stays between the same two pixel centres, and the blended-in surface colour).
    image_check(
        report,
        "raster/cpu silhouette AA, background pixels",
        RenderSettings::default(),
        31,
        |t| t == NO_TRIANGLE,
    )?;
    // The whole antialiased image.
    image_check(
        report,
        "raster/cpu full image with AA",
        RenderSettings::default(),
        41,
        |_| true,
    )?;

    // (d) wgpu backend (f32 WGSL forward and backward): coverage and the image gradient agree with
    // the CPU reference (relative L2 ≤ 2e-3: f32 shading adjoint and atomic accumulation).
    match raster_diff::gpu::WgpuRenderer::new(RenderSettings::default()) {
        Err(e) => println!("skip raster/wgpu: no adapter ({e})"),
        Ok(mut gpu) => {
            use raster_diff::{Images, Renderer};
            let name = "raster/wgpu vs cpu image gradient";
            let (v, f) = bumpy_sphere(61);
            let views = views(62);
            let mut cpu = CpuRenderer::default();
            let ic = cpu.render(&v, &f, &views, W, H)?;
            let ids = cpu
                .triangle_ids()
                .ok_or_else(|| anyhow::anyhow!("no render state"))?;
            gpu.render(&v, &f, &views, W, H)?;
            let gpu_ids = gpu.triangle_ids()?;
            let differing = ids.iter().zip(&gpu_ids).filter(|(a, b)| a != b).count();
            let mut rng = ChaCha8Rng::seed_from_u64(63);
            let d = Images {
                rgb: ic.rgb.iter().map(|_| rng.random::<f32>() - 0.5).collect(),
                ..ic
            };
            let (gc, gg) = (cpu.backward(&d)?, gpu.backward(&d)?);
            let norm = |x: &mut dyn Iterator<Item = f64>| x.map(|a| a * a).sum::<f64>().sqrt();
            let diff = norm(
                &mut gc
                    .iter()
                    .flatten()
                    .zip(gg.iter().flatten())
                    .map(|(a, b)| a - b),
            );
            let rel = diff / norm(&mut gc.iter().flatten().copied()).max(1e-300);
            let mut failures = Vec::new();
            // f32 edge tests may flip a pixel whose centre lies within rounding of an edge; a few
            // such pixels are expected on some devices, and then the gradients differ through them.
            if differing > 8 {
                failures.push(format!(
                    "{differing} pixels see another triangle on the GPU"
                ));
            } else if differing > 0 {
                println!(
                    "note {name}: {differing} pixels differ in coverage (f32 edge tests); gradient rel. diff {rel:.3e}"
                );
            } else if rel > 2e-3 {
                failures.push(format!(
                    "same coverage but relative gradient difference {rel:.3e}"
                ));
            }
            report.results.push(CheckResult {
                name: format!("{name} ({})", gpu.adapter_info().name),
                worst_rel: rel,
                failures,
            });
        }
    }

    // Degenerate input: collapsed and sliver triangles must keep the gradient finite.
    {
        let mut v = bumpy_sphere(51).0;
        let f = bumpy_sphere(51).1;
        for k in 0..40 {
            v[k] = v[0];
        }
        let mut r = CpuRenderer::default();
        let views = views(52);
        let img = r.render_grey(&v, &f, &views, W, H)?;
        let g = r.backward_grey(&vec![1.0; img.len()])?;
        let name = "raster/degenerate triangles stay finite";
        if img.iter().any(|x| !x.is_finite()) || g.iter().flatten().any(|x| !x.is_finite()) {
            report.fail(name, "non-finite image or gradient".into());
        } else {
            report.results.push(CheckResult {
                name: name.into(),
                worst_rel: 0.0,
                failures: Vec::new(),
            });
        }
    }
    Ok(())
}

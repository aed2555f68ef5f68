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
use raster_diff::{CameraConfig, CpuRenderer, RenderSettings, View, sample_views};

use super::{CheckResult, Report, Tolerance};

const W: usize = 48;
const H: usize = 40;

/// A bumpy icosphere (random radial noise) so silhouettes are not all convex.
fn bumpy_sphere(seed: u64) -> (Vec<[f64; 3]>, Vec<[u32; 3]>) {
    let (mut v, f) = mesh_core::shapes::icosphere(3).into_parts();
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
    let base = r.render_f64(&v, &f, &views, W, H)?;
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
    let grad = flatten(&r.backward_f64(&g)?);
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
            let Ok(img) = r.render_f64(&unflatten(t), &f, &views, W, H) else {
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

    // (d) wgpu backend (f32 WGSL forward and backward), when an adapter exists (lavapipe counts).
    match raster_diff::gpu::WgpuRenderer::new(RenderSettings::default()) {
        Err(e) => println!("skip raster/wgpu: no adapter ({e})"),
        Ok(gpu) => wgpu_suite(report, gpu)?,
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
        let img = r.render_f64(&v, &f, &views, W, H)?;
        let g = r.backward_f64(&vec![1.0; img.len()])?;
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

/// Two bumpy spheres, the second (radius ≈ 0.5) in front of the first towards +z, so that the
/// views see occlusion boundaries between them. Returns the mesh and the first face of sphere two.
fn two_spheres(seed: u64) -> (Vec<[f64; 3]>, Vec<[u32; 3]>, u32) {
    let (mut v, mut f) = bumpy_sphere(seed);
    let (v2, f2) = bumpy_sphere(seed + 1);
    let (nv, nf) = (v.len() as u32, f.len() as u32);
    v.extend(
        v2.iter()
            .map(|p| [0.5 * p[0] + 0.3, 0.5 * p[1], 0.5 * p[2] + 1.1]),
    );
    f.extend(f2.iter().map(|t| [t[0] + nv, t[1] + nv, t[2] + nv]));
    (v, f, nf)
}

/// Views of [`two_spheres`] from the +z side (elevation 0–40°, azimuth 45–135°).
fn front_views(seed: u64) -> Vec<View> {
    let config = CameraConfig {
        elevation_deg: [0.0, 40.0],
        azimuth_deg: [45.0, 135.0],
        ..CameraConfig::default()
    };
    sample_views(&config, 3, 1.3, &mut ChaCha8Rng::seed_from_u64(seed))
}

/// Image size of the wgpu finite-difference checks (more pixels than the CPU checks: the f32
/// rounding noise of the loss grows like √pixels, its signal like pixels).
const GW: usize = 96;
const GH: usize = 80;

/// Central differences of ⟨G, image⟩ on the wgpu backend itself, in f32.
///
/// The image is f32 (rounding noise ~1e-7–1e-6 per pixel from the f32 shading), so the CPU checks'
/// h = 1e-6 would difference pure noise. Measured on lavapipe: h = 1e-4 is still noise-dominated
/// (10–60 % errors), h = 1e-2 crosses too many kinks (two-sided flips, τ clamps, t = 1/2 swaps);
/// h = 1e-3 world units (≈ 0.015 px per unit of direction at these view distances) is used. Two
/// things keep the difference quotient meaningful at that step:
/// - coverage guard: θ ± h·d are rendered first, and only pixels whose own triangle id and those of
///   their four neighbours are the same at θ − h·d, θ and θ + h·d are weighted (so neither
///   coverage nor any antialiasing pair involving them changed); the adjoint is the wgpu backward
///   of the masked weights at θ;
/// - coherent signal: the weights G are a smooth plane wave in [0.2, 1] (not random signs) and
///   each direction is half a random affine deformation (see [`direction`]), so the loss change
///   adds up over thousands of pixels while the rounding noise only grows like √pixels.
///
/// Tolerance: |fd − an| ≤ 2e-2·max(|fd|, |an|) + 5e-4·|∇ℓ| (measured worst on lavapipe: 1.6e-2
/// relative). Per-vertex agreement of the
/// gradient itself is checked against the CPU's f64 VJP (`raster/wgpu vs cpu image gradient`).
#[allow(clippy::too_many_arguments)]
fn wgpu_fd_check(
    report: &mut Report,
    gpu: &mut raster_diff::gpu::WgpuRenderer,
    name: &str,
    v: &[[f64; 3]],
    f: &[[u32; 3]],
    views: &[View],
    seed: u64,
    select: impl Fn(usize, &[u32]) -> bool,
) -> anyhow::Result<()> {
    use raster_diff::{Images, Renderer};
    const STEP: f64 = 1e-3;
    const RTOL: f64 = 2e-2;
    const ATOL_PER_GRAD: f64 = 5e-4;
    const DIRECTIONS: usize = 3;
    let img0 = gpu.render(v, f, views, GW, GH)?;
    let ids0 = gpu.triangle_ids()?;
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    // Smooth weights (a random plane wave in [0.2, 1]), so the loss's response to a smooth
    // deformation adds up coherently over many pixels while the f32 rounding noise does not.
    let (fx, fy, phase) = (
        rng.random::<f64>() * 3.0,
        rng.random::<f64>() * 3.0,
        rng.random::<f64>() * std::f64::consts::TAU,
    );
    let g: Vec<f64> = (0..ids0.len())
        .map(|p| {
            let (x, y) = (
                (p % GW) as f64 / GW as f64,
                ((p / GW) % GH) as f64 / GH as f64,
            );
            let r = 0.6 + 0.4 * (std::f64::consts::TAU * (fx * x + fy * y) + phase).cos();
            if select(p, &ids0) { r } else { 0.0 }
        })
        .collect();
    let theta = flatten(v);
    let mut failures = Vec::new();
    let mut worst_rel: f64 = 0.0;
    let mut kept_total = 0;
    for k in 0..DIRECTIONS {
        let d = direction(&theta, &mut rng);
        let shifted = |s: f64| -> Vec<[f64; 3]> {
            unflatten(
                &theta
                    .iter()
                    .zip(&d)
                    .map(|(t, di)| t + s * di)
                    .collect::<Vec<_>>(),
            )
        };
        let plus = gpu.render(&shifted(STEP), f, views, GW, GH)?;
        let ids_plus = gpu.triangle_ids()?;
        let minus = gpu.render(&shifted(-STEP), f, views, GW, GH)?;
        let ids_minus = gpu.triangle_ids()?;
        let stable = |p: usize| ids_plus[p] == ids0[p] && ids_minus[p] == ids0[p];
        let (w, h) = (GW, GH);
        let mask: Vec<bool> = (0..ids0.len())
            .map(|p| {
                let (col, row) = (p % w, (p / w) % h);
                stable(p)
                    && (col == 0 || stable(p - 1))
                    && (col + 1 == w || stable(p + 1))
                    && (row == 0 || stable(p - w))
                    && (row + 1 == h || stable(p + w))
            })
            .collect();
        let gm: Vec<f64> = g
            .iter()
            .zip(&mask)
            .map(|(&gi, &m)| if m { gi } else { 0.0 })
            .collect();
        kept_total += gm.iter().filter(|x| **x != 0.0).count();
        let loss = |img: &Images| -> f64 {
            img.rgb
                .chunks_exact(3)
                .zip(&img0.rgb.chunks_exact(3).collect::<Vec<_>>())
                .zip(&gm)
                .map(|((a, a0), gi)| (f64::from(a[0]) - f64::from(a0[0])) * gi)
                .sum()
        };
        let fd = (loss(&plus) - loss(&minus)) / (2.0 * STEP);
        // The adjoint of ⟨G·M, image⟩ at θ (the backward sums the channels: weight channel 0).
        gpu.render(v, f, views, GW, GH)?;
        let mut rgb = vec![0.0f32; img0.rgb.len()];
        for (p, gi) in gm.iter().enumerate() {
            rgb[3 * p] = *gi as f32;
        }
        let grad = flatten(&gpu.backward(&Images {
            rgb,
            ..img0.clone()
        })?);
        let an: f64 = grad.iter().zip(&d).map(|(a, b)| a * b).sum();
        let grad_norm = grad.iter().map(|x| x * x).sum::<f64>().sqrt();
        let err = (fd - an).abs();
        let scale = fd.abs().max(an.abs());
        let rel = if scale > 0.0 { err / scale } else { 0.0 };
        println!(
            "  {name}, direction {k}: fd {fd:.6e}, adjoint {an:.6e}, rel. {rel:.2e}, |grad| {grad_norm:.3e}, {} of {} weighted pixels kept",
            gm.iter().filter(|x| **x != 0.0).count(),
            g.iter().filter(|x| **x != 0.0).count()
        );
        if !fd.is_finite() || !an.is_finite() || err > RTOL * scale + ATOL_PER_GRAD * grad_norm {
            failures.push(format!(
                "direction {k}: finite difference {fd:.6e}, adjoint {an:.6e}, |diff| {err:.3e}"
            ));
        }
        worst_rel = worst_rel.max(rel);
    }
    if kept_total < DIRECTIONS * 100 {
        failures.push(format!(
            "only {kept_total} weighted pixels kept over {DIRECTIONS} directions: the check says little"
        ));
    }
    report.results.push(CheckResult {
        name: format!("{name} ({})", gpu.adapter_info().name),
        worst_rel,
        failures,
    });
    Ok(())
}

/// A unit direction in vertex space: half (in norm) a random affine deformation x ↦ A·x + b,
/// half independent random per-vertex displacements. The affine half moves whole silhouettes and
/// shaded regions coherently, so the loss changes well above the f32 rounding noise; the random
/// half still exercises every vertex's own gradient.
fn direction(theta: &[f64], rng: &mut ChaCha8Rng) -> Vec<f64> {
    let mut a = [0.0; 12];
    a.iter_mut()
        .for_each(|x| *x = rng.random::<f64>() * 2.0 - 1.0);
    let affine: Vec<f64> = theta
        .chunks_exact(3)
        .flat_map(|x| {
            (0..3).map(move |r| {
                a[4 * r] * x[0] + a[4 * r + 1] * x[1] + a[4 * r + 2] * x[2] + a[4 * r + 3]
            })
        })
        .collect();
    let random: Vec<f64> = theta
        .iter()
        .map(|_| rng.random::<f64>() * 2.0 - 1.0)
        .collect();
    let unit = |v: Vec<f64>| {
        let n = v.iter().map(|x| x * x).sum::<f64>().sqrt().max(1e-300);
        v.into_iter().map(move |x| x / n)
    };
    let d: Vec<f64> = unit(affine).zip(unit(random)).map(|(p, q)| p + q).collect();
    unit(d).collect()
}

/// The wgpu checks: finite differences on the wgpu backend itself (interior shading, silhouettes,
/// occlusion boundaries) and agreement of its VJP with the CPU backend's.
fn wgpu_suite(report: &mut Report, mut gpu: raster_diff::gpu::WgpuRenderer) -> anyhow::Result<()> {
    use raster_diff::{Images, Renderer};
    let (v, f) = bumpy_sphere(71);
    let views1 = views(72);
    // Interior shading: no antialiasing, weights on covered pixels.
    gpu.settings.antialias = false;
    wgpu_fd_check(
        report,
        &mut gpu,
        "raster/wgpu fd shading (no AA), covered pixels",
        &v,
        &f,
        &views1,
        73,
        |p, ids| ids[p] != NO_TRIANGLE,
    )?;
    gpu.settings.antialias = true;
    // Silhouettes: weights on background pixels, which only the antialiasing blends change.
    wgpu_fd_check(
        report,
        &mut gpu,
        "raster/wgpu fd silhouette AA, background pixels",
        &v,
        &f,
        &views1,
        74,
        |p, ids| ids[p] == NO_TRIANGLE,
    )?;
    // Occlusion boundaries: two spheres, weights on covered pixels next to a pixel of the other
    // sphere (front pixels blend with the occluded surface behind them and vice versa).
    let (v2, f2, second) = two_spheres(75);
    let views2 = front_views(76);
    let (w, h) = (GW, GH);
    wgpu_fd_check(
        report,
        &mut gpu,
        "raster/wgpu fd occlusion boundaries (AA)",
        &v2,
        &f2,
        &views2,
        77,
        move |p, ids| {
            let object = |q: usize| match ids[q] {
                NO_TRIANGLE => 0,
                t if t < second => 1,
                _ => 2,
            };
            let me = object(p);
            let (col, row) = (p % w, (p / w) % h);
            let neighbours = [
                (col > 0).then(|| p - 1),
                (col + 1 < w).then(|| p + 1),
                (row > 0).then(|| p - w),
                (row + 1 < h).then(|| p + w),
            ];
            me != 0
                && neighbours
                    .iter()
                    .flatten()
                    .any(|&q| object(q) != 0 && object(q) != me)
        },
    )?;
    // Whole image with AA on the two-sphere scene.
    wgpu_fd_check(
        report,
        &mut gpu,
        "raster/wgpu fd full image with AA, two spheres",
        &v2,
        &f2,
        &views2,
        78,
        |_, _| true,
    )?;

    // The wgpu VJP against the CPU VJP on the same render: coverage must agree except at pixel
    // centres within f32 rounding of an edge, and the VJP of a dense random cotangent must agree to
    // a relative L2 of 2e-3 (f32 shading adjoint and atomic accumulation; see docs/renderer.md).
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
    // The CPU renders are grey and the wgpu ones RGB: the same cotangent is the grey one for the
    // CPU and, for the wgpu backend (which sums the channels), that one in channel 0.
    let d = Images {
        rgb: ic.rgb.iter().map(|_| rng.random::<f32>() - 0.5).collect(),
        ..ic
    };
    let d_rgb = Images {
        channels: 3,
        rgb: d.rgb.iter().flat_map(|&v| [v, 0.0, 0.0]).collect(),
        ..d.clone()
    };
    let (gc, gg) = (cpu.backward(&d)?, gpu.backward(&d_rgb)?);
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
    if differing * 1000 > ids.len() {
        failures.push(format!(
            "{differing} of {} pixels see another triangle on the GPU",
            ids.len()
        ));
    } else if differing == 0 && rel > 2e-3 {
        failures.push(format!(
            "same coverage but relative gradient difference {rel:.3e}"
        ));
    } else if differing > 0 {
        println!(
            "note {name}: {differing} pixels differ in coverage (f32 edge tests); gradient rel. diff {rel:.3e}"
        );
    }
    report.results.push(CheckResult {
        name: format!("{name} ({})", gpu.adapter_info().name),
        worst_rel: rel,
        failures,
    });
    Ok(())
}

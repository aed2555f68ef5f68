//! The same assertions run against every backend through `&mut dyn Renderer`: the CPU reference
//! and, when an adapter exists (lavapipe counts), the wgpu backend (otherwise it prints `SKIPPED`
//! and only the CPU runs). Images are the trait's f32 output, so tolerances are f32-level for both
//! backends; the f64-tight versions of some of these for the CPU alone are in tests/cpu.rs.

use glam::DVec3;
use raster_diff::cpu::raster::NO_TRIANGLE;
use raster_diff::cpu::shading::RADIANCE_SCALE;
use raster_diff::{CpuRenderer, Images, RenderSettings, Renderer, View};

/// A backend under test: a renderer and a way to read its last render's triangle ids.
enum Backend {
    Cpu(CpuRenderer),
    #[cfg(feature = "gpu")]
    Gpu(Box<raster_diff::gpu::WgpuRenderer>),
}

impl Backend {
    fn renderer(&mut self) -> &mut dyn Renderer {
        match self {
            Backend::Cpu(r) => r,
            #[cfg(feature = "gpu")]
            Backend::Gpu(r) => r.as_mut(),
        }
    }

    fn ids(&self) -> Vec<u32> {
        match self {
            Backend::Cpu(r) => r.triangle_ids().expect("cpu state"),
            #[cfg(feature = "gpu")]
            Backend::Gpu(r) => r.triangle_ids().expect("gpu ids"),
        }
    }
}

/// Every available backend with these settings.
fn backends(settings: RenderSettings) -> Vec<(String, Backend)> {
    let cpu = (
        "cpu".to_string(),
        Backend::Cpu(CpuRenderer::new(settings.clone())),
    );
    #[cfg(feature = "gpu")]
    match raster_diff::gpu::WgpuRenderer::new(settings) {
        Ok(g) => vec![cpu, ("wgpu".to_string(), Backend::Gpu(Box::new(g)))],
        Err(e) => {
            println!("SKIPPED wgpu: no adapter ({e})");
            vec![cpu]
        }
    }
    #[cfg(not(feature = "gpu"))]
    {
        let _ = settings;
        println!("SKIPPED wgpu: built without the `gpu` feature");
        vec![cpu]
    }
}

fn aa(on: bool) -> RenderSettings {
    RenderSettings {
        antialias: on,
        ..RenderSettings::default()
    }
}

fn front_view(eye_z: f64, light: [f64; 3]) -> View {
    View {
        eye: [0.0, 0.0, eye_z],
        target: [0.0; 3],
        up: [0.0, 1.0, 0.0],
        fov_y_deg: 90.0,
        light_pos: light,
    }
}

/// Rectangle [x0, x1] × [y0, y1] in the plane z, CCW seen from +z.
fn rect(x0: f64, x1: f64, y0: f64, y1: f64, z: f64) -> (Vec<[f64; 3]>, Vec<[u32; 3]>) {
    (
        vec![[x0, y0, z], [x1, y0, z], [x1, y1, z], [x0, y1, z]],
        vec![[0, 1, 2], [0, 2, 3]],
    )
}

/// dL/d(image) that weights the grey value of the given pixels of view 0 by 1.
fn weights(img: &Images, pixels: impl Iterator<Item = usize>) -> Images {
    let mut rgb = vec![0.0; img.rgb.len()];
    for p in pixels {
        rgb[img.channels * p] = 1.0; // channel 0 (RGB: the backward sums the channels): dL/d(grey) = 1
    }
    Images { rgb, ..img.clone() }
}

#[test]
fn facing_quad_matches_lambert_closed_form() {
    let (v, f) = rect(-1.5, 1.5, -1.5, 1.5, 0.0);
    let light = [0.4, -0.3, 1.5];
    let view = front_view(2.0, light);
    let (w, h) = (24, 16);
    for (name, mut b) in backends(aa(false)) {
        let img = b
            .renderer()
            .render(&v, &f, std::slice::from_ref(&view), w, h)
            .expect("render");
        let k = 0.5 * h as f64;
        let mut covered = 0;
        for row in 0..h {
            for col in 0..w {
                let (sx, sy) = (col as f64 + 0.5, row as f64 + 0.5);
                let d = DVec3::new((sx - 0.5 * w as f64) / k, -(sy - 0.5 * h as f64) / k, -1.0);
                let p = DVec3::new(0.0, 0.0, 2.0) + d * 2.0;
                let got = f64::from(img.rgb[img.channels * (row * w + col)]);
                if p.x.abs() < 1.5 && p.y.abs() < 1.5 {
                    covered += 1;
                    let want = RADIANCE_SCALE * (DVec3::from(light) - p).normalize().z.max(0.0);
                    assert!(
                        (got - want).abs() < 2e-6,
                        "{name} pixel ({col},{row}): {got} vs {want}"
                    );
                } else {
                    assert_eq!(got, 1.0, "{name}: background at ({col},{row})");
                }
            }
        }
        assert!(covered > 50, "{name}");
    }
}

#[test]
fn two_sided_shading_lights_reversed_faces_identically() {
    let (v, f) = rect(-0.6, 0.6, -0.6, 0.6, 0.0);
    let flipped: Vec<[u32; 3]> = f.iter().map(|t| [t[0], t[2], t[1]]).collect();
    let view = [front_view(2.5, [1.0, 1.0, 2.0])];
    for (name, mut b) in backends(aa(false)) {
        let a = b.renderer().render(&v, &f, &view, 20, 20).expect("render");
        let c = b
            .renderer()
            .render(&v, &flipped, &view, 20, 20)
            .expect("render");
        let worst = a
            .rgb
            .iter()
            .zip(&c.rgb)
            .map(|(x, y)| (x - y).abs())
            .fold(0.0f32, f32::max);
        assert!(worst < 1e-6, "{name}: {worst}");
    }
}

#[test]
fn depth_test_keeps_the_nearest_surface_in_any_face_order() {
    let (mut v, mut f) = rect(-0.5, 0.5, -0.5, 0.5, 0.0);
    let (v2, f2) = rect(-0.8, 0.8, -0.8, 0.8, -0.5);
    v.extend(v2);
    f.extend(f2.iter().map(|t| [t[0] + 4, t[1] + 4, t[2] + 4]));
    let reversed: Vec<[u32; 3]> = f.iter().rev().copied().collect();
    let view = [front_view(2.0, [0.0, 0.0, 2.0])];
    for (name, mut b) in backends(aa(false)) {
        b.renderer().render(&v, &f, &view, 32, 32).expect("render");
        let ids = b.ids();
        b.renderer()
            .render(&v, &reversed, &view, 32, 32)
            .expect("render");
        let ids_rev = b.ids();
        let centre = 16 * 32 + 16;
        assert!(ids[centre] < 2, "{name}: front quad at the centre");
        assert!(ids_rev[centre] >= 2, "{name}: front quad (now 2, 3)");
        let edge = 16 * 32 + 11;
        assert!(
            ids[edge] >= 2 && ids[edge] != NO_TRIANGLE,
            "{name}: only the back quad covers column 11"
        );
    }
}

/// A loss that wants the background column right of a quad's right edge darker moves that edge in
/// +x: dL/dx < 0 at the edge's two vertices, ~0 at the others; and no gradient without AA.
#[test]
fn silhouette_gradient_moves_the_edge_towards_darker_target() {
    // Right edge at screen x 20.24 (between centres 19.5 and 20.5), t = 0.74 from column 19.
    let (v, f) = rect(-0.5, 0.53, -0.5, 0.5, 0.0);
    let view = [front_view(2.0, [0.0, 0.0, 2.0])];
    let (w, h) = (32, 32);
    for antialias in [true, false] {
        for (name, mut b) in backends(aa(antialias)) {
            let img = b.renderer().render(&v, &f, &view, w, h).expect("render");
            let ids = b.ids();
            assert_eq!(ids[16 * w + 20], NO_TRIANGLE, "{name}");
            assert_ne!(ids[16 * w + 19], NO_TRIANGLE, "{name}");
            let d = weights(&img, (13..19).map(|row| row * w + 20));
            let g = b.renderer().backward(&d).expect("backward");
            if !antialias {
                assert!(
                    g.iter().flatten().all(|x| *x == 0.0),
                    "{name}: no silhouette gradient without AA"
                );
                continue;
            }
            let c19 = img.rgb[img.channels * (16 * w + 19)];
            let want = 1.0 + 0.24 * (c19 - 1.0);
            let got = img.rgb[img.channels * (16 * w + 20)];
            assert!((got - want).abs() < 1e-5, "{name}: {got} vs {want}");
            assert!(
                g[1][0] < -1e-3 && g[2][0] < -1e-3,
                "{name}: right vertices pulled right: {:?} {:?}",
                g[1],
                g[2]
            );
            let scale = g[1][0].abs();
            assert!(
                g[0][0].abs() < 1e-4 * scale && g[3][0].abs() < 1e-4 * scale,
                "{name}: left vertices untouched: {:?} {:?}",
                g[0],
                g[3]
            );
        }
    }
}

/// Occlusion boundary: a small quad in front of a larger one. A loss that wants the pixels just
/// right of the front quad's right edge (which show the back quad) to take the front quad's colour
/// moves that edge in +x; the back quad's vertices get no x-gradient from it.
#[test]
fn occlusion_boundary_gradient_moves_the_front_edge() {
    let (mut v, mut f) = rect(-0.5, 0.53, -0.5, 0.5, 0.0);
    let (v2, f2) = rect(-1.5, 1.5, -1.5, 1.5, -1.0);
    v.extend(v2);
    f.extend(f2.iter().map(|t| [t[0] + 4, t[1] + 4, t[2] + 4]));
    // The light grazes the back quad more than the front one, so they differ in colour.
    let view = [front_view(2.0, [2.0, 0.0, 0.6])];
    let (w, h) = (32, 32);
    for (name, mut b) in backends(aa(true)) {
        let img = b.renderer().render(&v, &f, &view, w, h).expect("render");
        let ids = b.ids();
        assert!(ids[16 * w + 19] < 2, "{name}: front quad at column 19");
        assert!(
            ids[16 * w + 20] >= 2 && ids[16 * w + 20] != NO_TRIANGLE,
            "{name}: back quad (faces 2, 3) at column 20"
        );
        let front = img.rgb[img.channels * (16 * w + 18)];
        let back = img.rgb[img.channels * (16 * w + 22)];
        assert!((front - back).abs() > 0.05, "{name}: {front} vs {back}");
        // L = Σ (c − c_front)² / 2 over column 20: dL/dc = c − c_front.
        let mut d = weights(&img, std::iter::empty());
        for row in 13..19 {
            let p = row * w + 20;
            d.rgb[img.channels * p] = img.rgb[img.channels * p] - front;
        }
        let g = b.renderer().backward(&d).expect("backward");
        assert!(
            g[1][0] < -1e-4 && g[2][0] < -1e-4,
            "{name}: front right vertices pulled right: {:?} {:?}",
            g[1],
            g[2]
        );
        let scale = g[1][0].abs();
        for (k, gk) in g.iter().enumerate().skip(4) {
            assert!(
                gk[0].abs() < 1e-3 * scale,
                "{name}: back vertex {k} moved: {gk:?}"
            );
        }
    }
}

/// With AA the image is continuous as a silhouette edge crosses a pixel centre; without AA it
/// jumps from background to surface colour.
#[test]
fn antialiasing_makes_the_image_continuous_as_an_edge_crosses_a_pixel_centre() {
    let (w, h) = (32, 32);
    let view = [front_view(2.0, [0.0, 0.0, 2.0])];
    for antialias in [true, false] {
        for (name, mut b) in backends(aa(antialias)) {
            // Column 20's centre 20.5 ↔ x = 0.5625; ±1e-5 is ~1e-4 px, far above f32 rounding.
            let mut at = |x_edge: f64| {
                let (v, f) = rect(-0.5, x_edge, -0.5, 0.5, 0.0);
                let img = b.renderer().render(&v, &f, &view, w, h).expect("render");
                (img.rgb[img.channels * (16 * w + 20)], b.ids()[16 * w + 20])
            };
            let (before, id_before) = at(0.5625 - 1e-5);
            let (after, id_after) = at(0.5625 + 1e-5);
            assert_eq!(id_before, NO_TRIANGLE, "{name}");
            assert_ne!(id_after, NO_TRIANGLE, "{name}");
            let jump = (before - after).abs();
            if antialias {
                assert!(jump < 0.01, "{name}: jump with AA {before} → {after}");
            } else {
                assert!(jump > 0.1, "{name}: without AA {before} → {after}");
            }
        }
    }
}

/// A collapsed triangle, a sliver, a triangle crossing the near plane and one behind the eye:
/// images stay in [0, 1] and gradients finite.
#[test]
fn degenerate_geometry_stays_finite() {
    let v = vec![
        [0.1, 0.1, 0.0],
        [0.1, 0.1, 0.0],
        [0.1, 0.1, 0.0],
        [-0.5, -0.5, 0.0],
        [0.5, 0.5, 0.0],
        [0.5, 0.5 + 1e-13, 0.0],
        [-0.3, 0.0, 1.9],
        [0.3, 0.0, 1.0],
        [0.0, 0.3, 1.0],
        [0.0, 0.0, 5.0],
        [1.0, 0.0, 5.0],
        [0.0, 1.0, 5.0],
        [-0.6, -0.2, 0.0],
        [0.6, -0.2, 0.0],
        [0.0, 0.6, 0.0],
    ];
    let f = vec![[0, 1, 2], [3, 4, 5], [6, 7, 8], [9, 10, 11], [12, 13, 14]];
    let views = [
        front_view(2.0, [0.0, 0.0, 2.0]),
        front_view(2.0, [0.0, 0.0, 0.0]),
    ];
    for antialias in [true, false] {
        for (name, mut b) in backends(aa(antialias)) {
            let img = b.renderer().render(&v, &f, &views, 24, 24).expect("render");
            assert!(
                img.rgb
                    .iter()
                    .all(|x| x.is_finite() && (0.0..=1.0).contains(x)),
                "{name}: image out of range"
            );
            let d = Images {
                rgb: vec![1.0; img.rgb.len()],
                ..img
            };
            let g = b.renderer().backward(&d).expect("backward");
            assert!(
                g.iter().flatten().all(|x| x.is_finite()),
                "{name}: non-finite gradient"
            );
            assert!(g.iter().flatten().any(|x| *x != 0.0), "{name}: no gradient");
        }
    }
}

//! Properties of the CPU reference renderer against closed forms and finite differences.

use glam::DVec3;
use raster_diff::cpu::raster::NO_TRIANGLE;
use raster_diff::cpu::shading::RADIANCE_SCALE;
use raster_diff::{CpuRenderer, Images, RenderError, RenderSettings, Renderer, View};

fn front_view(eye_z: f64, light: [f64; 3]) -> View {
    View {
        eye: [0.0, 0.0, eye_z],
        target: [0.0; 3],
        up: [0.0, 1.0, 0.0],
        fov_y_deg: 90.0,
        light_pos: light,
    }
}

/// A view from behind and to the left, lit from its side (the second view of the multi-view tests).
fn back_left_view() -> View {
    View {
        eye: [-0.4, 0.3, -2.6],
        target: [0.0; 3],
        up: [0.0, 1.0, 0.0],
        fov_y_deg: 70.0,
        light_pos: [-2.0, 0.5, -1.0],
    }
}

fn no_aa() -> CpuRenderer {
    CpuRenderer::new(RenderSettings {
        antialias: false,
        ..RenderSettings::default()
    })
}

/// Square [-s, s]² in the plane z = 0, CCW seen from +z.
fn quad(s: f64) -> (Vec<[f64; 3]>, Vec<[u32; 3]>) {
    (
        vec![[-s, -s, 0.0], [s, -s, 0.0], [s, s, 0.0], [-s, s, 0.0]],
        vec![[0, 1, 2], [0, 2, 3]],
    )
}

#[test]
fn facing_quad_matches_lambert_closed_form() {
    // Flat quad: smooth and face normals are both +z, so n = +z whatever τ is. The pixel-centre
    // ray from the eye hits z = 0 at p = eye + s·d with s = −eye_z/d_z; colour = K·max(n·l, 0).
    let (v, f) = quad(1.5);
    let light = [0.4, -0.3, 1.5];
    let view = front_view(2.0, light);
    let (w, h) = (24, 16);
    let mut r = no_aa();
    let grey = r.render_f64(&v, &f, &[view], w, h).expect("render");
    let k = 0.5 * h as f64; // fov 90° → k = H/2.
    let mut covered = 0;
    for row in 0..h {
        for col in 0..w {
            let (sx, sy) = (col as f64 + 0.5, row as f64 + 0.5);
            // Camera looks down −z: right = +x, up = +y.
            let d = DVec3::new((sx - 0.5 * w as f64) / k, -(sy - 0.5 * h as f64) / k, -1.0);
            let p = DVec3::new(0.0, 0.0, 2.0) + d * 2.0;
            let inside = p.x.abs() < 1.5 && p.y.abs() < 1.5;
            let got = grey[row * w + col];
            if inside {
                covered += 1;
                let l = (DVec3::from(light) - p).normalize();
                let want = RADIANCE_SCALE * l.z.max(0.0);
                assert!(
                    (got - want).abs() < 1e-12,
                    "pixel ({col},{row}): {got} vs {want}"
                );
            } else {
                assert_eq!(got, 1.0, "background is white at ({col},{row})");
            }
        }
    }
    assert!(covered > 50);
}

#[test]
fn two_sided_shading_lights_reversed_faces_identically() {
    let (v, f) = quad(0.6);
    let flipped: Vec<[u32; 3]> = f.iter().map(|t| [t[0], t[2], t[1]]).collect();
    let view = front_view(2.5, [1.0, 1.0, 2.0]);
    let a = no_aa()
        .render_f64(&v, &f, std::slice::from_ref(&view), 20, 20)
        .expect("render");
    let b = no_aa()
        .render_f64(&v, &flipped, &[view], 20, 20)
        .expect("render");
    for (x, y) in a.iter().zip(&b) {
        assert!((x - y).abs() < 1e-12);
    }
}

#[test]
fn shared_edge_pixels_are_covered_exactly_once() {
    // The quad fills the image exactly (eye at distance s for fov 90°) and its diagonal passes
    // through the pixel centres (i + ½, i + ½): each centre must go to exactly one triangle.
    let s = 1.0;
    let (v, f) = quad(s);
    let view = front_view(s, [0.0, 0.0, 3.0]);
    let n = 16;
    let mut r = CpuRenderer::new(RenderSettings {
        antialias: false,
        near: 0.1,
    });
    let ids_of = |r: &mut CpuRenderer, faces: &[[u32; 3]]| {
        r.render_f64(&v, faces, std::slice::from_ref(&view), n, n)
            .expect("render");
        r.triangle_ids().expect("state")
    };
    let both = ids_of(&mut r, &f);
    let first = ids_of(&mut r, &f[..1]);
    let second = ids_of(&mut r, &f[1..]);
    let mut on_diagonal = 0;
    for i in 0..n * n {
        let a = first[i] != NO_TRIANGLE;
        let b = second[i] != NO_TRIANGLE;
        assert!(
            a ^ b,
            "pixel {i}: covered by triangle 0: {a}, by triangle 1: {b}"
        );
        assert_ne!(both[i], NO_TRIANGLE, "pixel {i} is a hole");
        on_diagonal += usize::from(i / n == n - 1 - i % n);
    }
    assert_eq!(on_diagonal, n);
}

#[test]
fn depth_test_keeps_the_nearest_surface_in_any_face_order() {
    let (mut v, mut f) = quad(0.5);
    let (v2, f2) = quad(0.8);
    // A larger quad behind (z = −0.5).
    v.extend(v2.iter().map(|p| [p[0], p[1], -0.5]));
    f.extend(f2.iter().map(|t| [t[0] + 4, t[1] + 4, t[2] + 4]));
    let view = front_view(2.0, [0.0, 0.0, 2.0]);
    let mut r = no_aa();
    r.render_f64(&v, &f, std::slice::from_ref(&view), 32, 32)
        .expect("render");
    let ids = r.triangle_ids().expect("state");
    let reversed: Vec<[u32; 3]> = f.iter().rev().copied().collect();
    r.render_f64(&v, &reversed, &[view], 32, 32)
        .expect("render");
    let ids_rev = r.triangle_ids().expect("state");
    let centre = 16 * 32 + 16;
    assert!(ids[centre] < 2, "front quad visible at the centre");
    assert!(
        ids_rev[centre] >= 2,
        "front quad (now faces 2, 3) visible at the centre"
    );
    // Column 11 (centre 4.5 px left of the image centre): the front quad spans ±4 px, the back
    // quad ±5.12 px (k = 16 px per unit at depth 1).
    let edge = 16 * 32 + 11;
    assert!(
        ids[edge] >= 2 && ids[edge] != NO_TRIANGLE,
        "only the back quad covers pixel column 11"
    );
}

/// Loss gradient wanting the silhouette to move: the pixels just right of the quad's right edge
/// should get darker, so the right edge should move in +x (dL/dx < 0 at its two vertices).
#[test]
fn silhouette_gradient_moves_the_edge_towards_darker_target() {
    // Right edge at x = 0.53: screen x = 16 + 16·0.53/2 = 20.24 px (k = 16 px per unit at depth 1,
    // depth 2), between the centres of columns 19 (covered) and 20 (background), t = 0.74.
    let v = vec![
        [-0.5, -0.5, 0.0],
        [0.53, -0.5, 0.0],
        [0.53, 0.5, 0.0],
        [-0.5, 0.5, 0.0],
    ];
    let f = vec![[0, 1, 2], [0, 2, 3]];
    let view = front_view(2.0, [0.0, 0.0, 2.0]);
    let (w, h) = (32, 32);
    // L = Σ over the background column right of the edge (column 20, centre 20.5) of its value.
    let mut d = vec![0.0; w * h];
    for row in 13..19 {
        d[row * w + 20] = 1.0;
    }
    let mut aa = CpuRenderer::default();
    let grey = aa
        .render_f64(&v, &f, std::slice::from_ref(&view), w, h)
        .expect("render");
    let ids = aa.triangle_ids().expect("state");
    assert_eq!(ids[16 * w + 20], NO_TRIANGLE);
    assert_ne!(ids[16 * w + 19], NO_TRIANGLE);
    // Blend weight t − ½ = 0.24 towards the covered neighbour's colour.
    let want = 1.0 + 0.24 * (grey[16 * w + 19] - 1.0);
    assert!(
        (grey[16 * w + 20] - want).abs() < 1e-9,
        "column 20 is 24 % covered: {} vs {want}",
        grey[16 * w + 20]
    );
    let g = aa.backward_f64(&d).expect("backward");
    assert!(
        g[1][0] < -1e-3 && g[2][0] < -1e-3,
        "right vertices pulled right: {:?} {:?}",
        g[1],
        g[2]
    );
    assert!(
        g[0][0].abs() < 1e-12 && g[3][0].abs() < 1e-12,
        "left vertices untouched: {:?} {:?}",
        g[0],
        g[3]
    );
    // Without antialiasing the same loss sees no silhouette and has no gradient.
    let mut plain = no_aa();
    plain.render_f64(&v, &f, &[view], w, h).expect("render");
    let g0 = plain.backward_f64(&d).expect("backward");
    assert!(g0.iter().flatten().all(|x| *x == 0.0));
}

/// Directional finite difference of ⟨G, image⟩ through shading, normals and antialiasing.
#[test]
fn sphere_gradient_matches_central_differences() {
    let (v, f) = mesh_core::shapes::icosphere(2).into_parts();
    let views = [
        View {
            eye: [2.2, 0.9, 1.1],
            target: [0.0; 3],
            up: [0.0, 1.0, 0.0],
            fov_y_deg: 90.0,
            light_pos: [1.5, 2.0, 0.3],
        },
        back_left_view(),
    ];
    let (w, h) = (40, 32);
    let n = views.len() * w * h;
    let gw: Vec<f64> = (0..n)
        .map(|i| ((i * 7919) % 1000) as f64 / 500.0 - 1.0)
        .collect();
    let dir: Vec<[f64; 3]> = (0..v.len())
        .map(|i| {
            let s = |k: usize| (((i * 31 + k * 17) * 2654435761usize) % 2001) as f64 / 1000.0 - 1.0;
            [s(0), s(1), s(2)]
        })
        .collect();
    let mut r = CpuRenderer::default();
    r.render_f64(&v, &f, &views, w, h).expect("render");
    let ids0 = r.triangle_ids().expect("state");
    let g = r.backward_f64(&gw).expect("backward");
    let an: f64 = g
        .iter()
        .zip(&dir)
        .map(|(a, b)| a[0] * b[0] + a[1] * b[1] + a[2] * b[2])
        .sum();
    let eps = 1e-6;
    let mut loss = |s: f64| {
        let vs: Vec<[f64; 3]> = v
            .iter()
            .zip(&dir)
            .map(|(p, d)| [p[0] + s * d[0], p[1] + s * d[1], p[2] + s * d[2]])
            .collect();
        let img = r.render_f64(&vs, &f, &views, w, h).expect("render");
        assert_eq!(
            r.triangle_ids().expect("state"),
            ids0,
            "coverage must not change within ±eps"
        );
        img.iter().zip(&gw).map(|(a, b)| a * b).sum::<f64>()
    };
    let fd = (loss(eps) - loss(-eps)) / (2.0 * eps);
    assert!(an.abs() > 1e-3, "non-trivial gradient");
    assert!(
        (fd - an).abs() <= 1e-6 * an.abs().max(fd.abs()) + 1e-8,
        "fd {fd} vs adjoint {an}"
    );
}

#[test]
fn bad_inputs_give_typed_errors() {
    let (v, f) = quad(0.5);
    let view = front_view(2.0, [0.0, 0.0, 2.0]);
    let mut r = CpuRenderer::default();
    assert!(matches!(
        r.backward_f64(&[]),
        Err(RenderError::NoForwardState)
    ));
    let bad_face = vec![[0, 1, 9]];
    assert!(matches!(
        r.render(&v, &bad_face, std::slice::from_ref(&view), 8, 8),
        Err(RenderError::InvalidInput(_))
    ));
    let nan = vec![[f64::NAN, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]];
    assert!(
        r.render(&nan, &[[0, 1, 2]], std::slice::from_ref(&view), 8, 8)
            .is_err()
    );
    assert!(r.render(&v, &f, std::slice::from_ref(&view), 0, 8).is_err());
    let degenerate_view = View {
        eye: [0.0; 3],
        ..view.clone()
    };
    assert!(r.render(&v, &f, &[degenerate_view], 8, 8).is_err());
    let up_parallel = View {
        eye: [0.0, 3.0, 0.0],
        ..view.clone()
    };
    assert!(r.render(&v, &f, &[up_parallel], 8, 8).is_err());
    let img = r.render(&v, &f, &[view], 8, 8).expect("render");
    let wrong = Images {
        count: 1,
        height: 4,
        width: 8,
        channels: 1,
        rgb: vec![0.0; 32],
    };
    assert!(r.backward(&wrong).is_err());
    // The renders are grey: an RGB gradient of the right size is refused too.
    assert_eq!(img.channels, 1);
    assert!(r.backward(&img.to_rgb()).is_err());
    assert!(r.backward(&img).is_ok());
}

#[test]
fn render_and_backward_are_deterministic_and_repeatable() {
    let (v, f) = mesh_core::shapes::icosphere(3).into_parts();
    let views = raster_diff::orbit_views(3, 25.0, 2.6, 90.0);
    let mut r = CpuRenderer::default();
    let a = r.render(&v, &f, &views, 48, 48).expect("render");
    let d = Images {
        rgb: a
            .rgb
            .iter()
            .enumerate()
            .map(|(i, _)| (i % 13) as f32 - 6.0)
            .collect(),
        ..a.clone()
    };
    let g1 = r.backward(&d).expect("backward");
    let g2 = r.backward(&d).expect("backward again");
    let b = r.render(&v, &f, &views, 48, 48).expect("render");
    let g3 = r.backward(&d).expect("backward");
    assert_eq!(a, b);
    assert_eq!(g1, g2);
    assert_eq!(g1, g3);
}

/// Moving a silhouette edge across a pixel centre flips that pixel's coverage; with antialiasing
/// the image barely changes there (half-covered on both sides), without it the pixel jumps from
/// background to surface colour.
#[test]
fn antialiasing_makes_the_image_continuous_as_an_edge_crosses_a_pixel_centre() {
    let (w, h) = (32, 32);
    let view = front_view(2.0, [0.0, 0.0, 2.0]);
    // Screen x of the right edge = 16 + 8·x (k = 16, depth 2); column 20's centre 20.5 ↔ x = 0.5625.
    let render = |x_edge: f64, antialias: bool| {
        let v = vec![
            [-0.5, -0.5, 0.0],
            [x_edge, -0.5, 0.0],
            [x_edge, 0.5, 0.0],
            [-0.5, 0.5, 0.0],
        ];
        let f = vec![[0, 1, 2], [0, 2, 3]];
        let mut r = CpuRenderer::new(RenderSettings {
            antialias,
            ..RenderSettings::default()
        });
        let g = r
            .render_f64(&v, &f, std::slice::from_ref(&view), w, h)
            .expect("render");
        (
            g[16 * w + 20],
            r.triangle_ids().expect("state")[16 * w + 20],
        )
    };
    let eps = 1e-9;
    let (before, id_before) = render(0.5625 - eps, true);
    let (after, id_after) = render(0.5625 + eps, true);
    assert_eq!(id_before, NO_TRIANGLE);
    assert_ne!(id_after, NO_TRIANGLE);
    // Both sides are a 50/50 mix of white and a surface colour that varies smoothly along the quad.
    assert!(
        (before - after).abs() < 0.01,
        "jump with AA: {before} → {after}"
    );
    let (plain_before, _) = render(0.5625 - eps, false);
    let (plain_after, _) = render(0.5625 + eps, false);
    assert!(
        (plain_before - plain_after).abs() > 0.1,
        "without AA the pixel jumps: {plain_before} → {plain_after}"
    );
}

#[test]
fn backward_state_bytes_counts_ids_colour_and_mesh_and_clears_on_a_failed_render() {
    let (v, f) = quad(0.5);
    let view = front_view(2.0, [0.0, 0.0, 2.0]);
    let mut r = no_aa();
    assert_eq!(r.backward_state_bytes(), 0, "nothing kept before a render");
    let (w, h) = (16, 8);
    r.render(&v, &f, &[view.clone(), view.clone()], w, h)
        .expect("render");
    // At least 12 bytes per pixel per view (u32 id + f64 colour) plus the vertex and face copies.
    let floor = 2 * w * h * 12 + v.len() * 24 + f.len() * 12;
    let kept = r.backward_state_bytes();
    assert!(kept >= floor, "{kept} < {floor}");
    // Twice the views: the per-pixel part doubles.
    r.render(
        &v,
        &f,
        &[view.clone(), view.clone(), view.clone(), view.clone()],
        w,
        h,
    )
    .expect("render");
    assert!(r.backward_state_bytes() >= kept + 2 * w * h * 12);
    assert!(r.render(&v, &[[0, 1, 9]], &[view], w, h).is_err());
    assert_eq!(r.backward_state_bytes(), 0, "a failed render keeps nothing");
}

/// `backward_many` shares the per-pixel work between gradients; each result must be what the
/// gradient alone gives, bit for bit — also where one gradient is zero on pixels the other is not
/// (the skipped pixels of one gradient must not be skipped for the other).
#[test]
fn backward_many_is_one_backward_per_gradient_bit_for_bit() {
    let (v, f) = mesh_core::shapes::icosphere(2).into_parts();
    let views = [front_view(2.5, [1.0, 2.0, 3.0]), back_left_view()];
    let (w, h) = (36, 28);
    let mut r = CpuRenderer::default();
    let img = r.render(&v, &f, &views, w, h).expect("render");
    let grad = |k: usize| Images {
        rgb: (0..img.rgb.len())
            .map(|i| {
                // Gradient 1 is zero on every other pixel.
                if k == 1 && i % 2 == 0 {
                    0.0
                } else {
                    (((i * (7 + k) * 7919) % 1000) as f32 / 500.0 - 1.0) * 1e-2
                }
            })
            .collect(),
        ..img.clone()
    };
    let (g0, g1) = (grad(0), grad(1));
    let alone = [
        r.backward(&g0).expect("backward"),
        r.backward(&g1).expect("backward"),
    ];
    let many = r.backward_many(&[&g0, &g1, &g0]).expect("backward");
    assert_eq!(many.len(), 3);
    assert_eq!(many[0], alone[0]);
    assert_eq!(many[1], alone[1]);
    assert_eq!(many[2], alone[0]);
    assert_ne!(alone[0], alone[1]);
    assert!(alone[1].iter().flatten().any(|x| *x != 0.0));
    assert!(r.backward_many(&[]).expect("no gradients").is_empty());
    // A wrongly shaped gradient among them is an error, not a partial result.
    let short = Images {
        rgb: vec![0.0; 1],
        count: 1,
        height: 1,
        width: 1,
        channels: 1,
    };
    assert!(r.backward_many(&[&g0, &short]).is_err());
}

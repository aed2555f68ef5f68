//! Property tests of the whole layer on procedural meshes (golden data: `tests/golden.rs`).

use super::*;
use crate::mat3::IDENTITY;
use crate::stages::{
    local_step, local_step_vjp, normalize_targets, normalize_targets_vjp, rhs, rhs_vjp,
};
use mesh_core::shapes::{icosphere, obtuse_wavy_grid};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

fn random_targets(n0: &[[f64; 3]], spread: f64, seed: u64) -> Vec<[f64; 3]> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    n0.iter()
        .map(|n| {
            let s = 0.5 + rng.random::<f64>();
            std::array::from_fn(|c| s * (n[c] + spread * (rng.random::<f64>() * 2.0 - 1.0)))
        })
        .collect()
}

fn max_diff(a: &[[f64; 3]], b: &[[f64; 3]]) -> f64 {
    a.iter()
        .zip(b)
        .flat_map(|(p, q)| (0..3).map(move |c| (p[c] - q[c]).abs()))
        .fold(0.0, f64::max)
}

fn recentred(p: &[[f64; 3]]) -> Vec<[f64; 3]> {
    let n = p.len() as f64;
    let m: [f64; 3] = std::array::from_fn(|c| p.iter().map(|x| x[c]).sum::<f64>() / n);
    p.iter()
        .map(|x| [x[0] - m[0], x[1] - m[1], x[2] - m[2]])
        .collect()
}

/// A closed mesh with many obtuse triangles (negative weights): a squashed icosphere.
fn squashed_sphere() -> mesh_core::TriMesh {
    let mut m = icosphere(2);
    for p in &mut m.positions {
        *p = [3.0 * p[0], p[1], 0.4 * p[2]];
    }
    m
}

#[test]
fn identity_rotations_reproduce_rest_mesh() {
    // Closed meshes: every edge has two faces, so b = L p exactly (spec §4.1).
    let squashed = squashed_sphere();
    let w = cotan::cot_weights(&squashed.positions, &squashed.faces).unwrap();
    assert!(
        w.weights.iter().any(|&c| c < 0.0),
        "the squashed sphere should have negative weights"
    );
    for mesh in [icosphere(2), squashed] {
        let layer = Darap::new(&mesh.positions, &mesh.faces, DarapOptions::default()).unwrap();
        let rot = vec![IDENTITY; mesh.positions.len()];
        // b = L p exactly …
        let w = cotan::cot_weights(&mesh.positions, &mesh.faces).unwrap();
        let l = cotan::laplacian_from_weights(mesh.positions.len(), &w).unwrap();
        let lp = l.mul_vec3(&mesh.positions);
        let b = rhs(&RhsPrecompute::new(&mesh.positions, &mesh.faces, &w), &rot);
        assert!(
            max_diff(&b, &lp) < 1e-12,
            "b ≠ L p: {} on {} vertices",
            max_diff(&b, &lp),
            mesh.positions.len()
        );
        // … so the solve gives back the rest positions.
        let x = layer.global_step(&rot);
        assert!(
            max_diff(&x, &mesh.positions) < 1e-11,
            "{}",
            max_diff(&x, &mesh.positions)
        );
    }
}

#[test]
fn open_boundary_edges_enter_rhs_with_half_weight_as_in_reference() {
    // The reference right-hand side gives each face half of the full edge weight, so a boundary
    // edge (one face) contributes c/2: with R = I, b = L' p where L' halves boundary weights.
    let mesh = obtuse_wavy_grid(9);
    let mut w = cotan::cot_weights(&mesh.positions, &mesh.faces).unwrap();
    let boundary = mesh_core::topology::boundary_edges(&mesh.faces);
    assert!(!boundary.is_empty());
    for e in boundary {
        let key = if e[0] < e[1] { e } else { [e[1], e[0]] };
        let k = w.edges.binary_search(&key).unwrap();
        w.weights[k] *= 0.5;
    }
    let l_half = cotan::laplacian_from_weights(mesh.positions.len(), &w).unwrap();
    let full = cotan::cot_weights(&mesh.positions, &mesh.faces).unwrap();
    let pre = RhsPrecompute::new(&mesh.positions, &mesh.faces, &full);
    let b = rhs(&pre, &vec![IDENTITY; mesh.positions.len()]);
    assert!(max_diff(&b, &l_half.mul_vec3(&mesh.positions)) < 1e-12);
}

#[test]
fn rest_normals_as_targets_leave_a_well_shaped_sphere_at_rest_with_small_lambda() {
    // On an icosphere every weight is positive and the gis rule gives R = I when t = n0 and
    // λ·a is small against the one-ring stiffness.
    let mesh = icosphere(2);
    let opts = DarapOptions {
        lambda: 0.5,
        ..Default::default()
    };
    let layer = Darap::new(&mesh.positions, &mesh.faces, opts).unwrap();
    let out = layer.forward(layer.rest_normals()).unwrap();
    assert!(max_diff(&out.positions, &recentred(&mesh.positions)) < 1e-10);
}

#[test]
fn lambda_zero_gives_back_rest_shape() {
    // On a closed mesh with positive weights both rules give R = I at λ = 0.
    let mesh = icosphere(2);
    for rule in [RotationRule::Gis, RotationRule::Procrustes] {
        let opts = DarapOptions {
            lambda: 0.0,
            rotation_rule: rule,
            ..Default::default()
        };
        let layer = Darap::new(&mesh.positions, &mesh.faces, opts).unwrap();
        let x = random_targets(layer.rest_normals(), 1.0, 3);
        let out = layer.forward(&x).unwrap();
        assert!(
            max_diff(&out.positions, &recentred(&mesh.positions)) < 1e-10,
            "{rule:?}"
        );
    }
}

#[test]
fn all_false_mask_gives_rest_shape_and_zero_gradient() {
    for mesh in [icosphere(2), squashed_sphere()] {
        let mut layer = Darap::new(&mesh.positions, &mesh.faces, DarapOptions::default()).unwrap();
        layer
            .set_mask(Some(vec![false; mesh.positions.len()]))
            .unwrap();
        let x = random_targets(layer.rest_normals(), 0.8, 4);
        let out = layer.forward(&x).unwrap();
        assert!(max_diff(&out.positions, &recentred(&mesh.positions)) < 1e-10);
        let g = layer.backward(&out, &out.positions);
        assert!(g.iter().flatten().all(|v| *v == 0.0));
    }
}

#[test]
fn mask_with_wrong_length_is_an_error() {
    let mesh = icosphere(1);
    let mut layer = Darap::new(&mesh.positions, &mesh.faces, DarapOptions::default()).unwrap();
    assert!(matches!(
        layer.set_mask(Some(vec![true; 3])),
        Err(DarapError::LengthMismatch { .. })
    ));
}

#[test]
fn translating_the_rest_mesh_does_not_change_the_result() {
    let mesh = obtuse_wavy_grid(10);
    let shifted: Vec<[f64; 3]> = mesh
        .positions
        .iter()
        .map(|p| [p[0] + 3.0, p[1] - 7.5, p[2] + 0.25])
        .collect();
    for rule in [RotationRule::Gis, RotationRule::Procrustes] {
        let opts = DarapOptions {
            rotation_rule: rule,
            ..Default::default()
        };
        let a = Darap::new(&mesh.positions, &mesh.faces, opts).unwrap();
        let b = Darap::new(&shifted, &mesh.faces, opts).unwrap();
        let x = random_targets(a.rest_normals(), 0.6, 5);
        let pa = a.forward(&x).unwrap().positions;
        let pb = b.forward(&x).unwrap().positions;
        assert!(
            max_diff(&pa, &pb) < 1e-10,
            "{rule:?}: {}",
            max_diff(&pa, &pb)
        );
    }
}

#[test]
fn scaling_the_targets_does_not_change_the_result() {
    let mesh = icosphere(2);
    let layer = Darap::new(&mesh.positions, &mesh.faces, DarapOptions::default()).unwrap();
    let x = random_targets(layer.rest_normals(), 0.6, 6);
    let x3: Vec<[f64; 3]> = x.iter().map(|v| v.map(|c| 3.7 * c)).collect();
    let a = layer.forward(&x).unwrap().positions;
    let b = layer.forward(&x3).unwrap().positions;
    assert!(max_diff(&a, &b) < 1e-12);
}

#[test]
fn set_lambda_equals_fresh_layer() {
    let mesh = obtuse_wavy_grid(8);
    let mut layer = Darap::new(&mesh.positions, &mesh.faces, DarapOptions::default()).unwrap();
    layer.set_lambda(3.0);
    let fresh = Darap::new(
        &mesh.positions,
        &mesh.faces,
        DarapOptions {
            lambda: 3.0,
            ..Default::default()
        },
    )
    .unwrap();
    let x = random_targets(layer.rest_normals(), 0.7, 7);
    let a = layer.forward(&x).unwrap();
    let b = fresh.forward(&x).unwrap();
    assert_eq!(a.positions, b.positions);
    let g = &x; // any cotangent
    assert_eq!(layer.backward(&a, g), fresh.backward(&b, g));
}

#[test]
fn zero_targets_and_flat_meshes_stay_finite() {
    // A flat grid: every K_v has a zero singular value along the normal; zero-length targets hit
    // the 1e-12 clamp; identical targets make repeated singular values likely.
    let mut flat = obtuse_wavy_grid(6);
    for p in &mut flat.positions {
        p[2] = 0.0;
    }
    for mesh in [flat, icosphere(1)] {
        for rule in [RotationRule::Gis, RotationRule::Procrustes] {
            for lambda in [0.0, 8.0, 1e6] {
                let opts = DarapOptions {
                    lambda,
                    rotation_rule: rule,
                    ..Default::default()
                };
                let layer = Darap::new(&mesh.positions, &mesh.faces, opts).unwrap();
                for x in [
                    vec![[0.0; 3]; mesh.positions.len()],
                    vec![[0.0, 0.0, 1.0]; mesh.positions.len()],
                ] {
                    let out = layer.forward(&x).unwrap();
                    assert!(out.positions.iter().flatten().all(|v| v.is_finite()));
                    let g = layer.backward(&out, &out.positions);
                    assert!(
                        g.iter().flatten().all(|v| v.is_finite()),
                        "{rule:?} λ={lambda}"
                    );
                }
            }
        }
    }
}

#[test]
fn bad_inputs_are_typed_errors() {
    let mesh = icosphere(1);
    let layer = Darap::new(&mesh.positions, &mesh.faces, DarapOptions::default()).unwrap();
    assert!(matches!(
        layer.forward(&[[1.0; 3]; 2]),
        Err(DarapError::LengthMismatch { .. })
    ));
    let mut x = layer.rest_normals().to_vec();
    x[5][1] = f64::NAN;
    assert!(matches!(
        layer.forward(&x),
        Err(DarapError::NonFinite { index: 5, .. })
    ));
    assert!(matches!(
        Darap::new(&mesh.positions, &[], DarapOptions::default()),
        Err(DarapError::NoFaces)
    ));
    assert!(matches!(
        Darap::new(&mesh.positions, &[[0, 1, 99]], DarapOptions::default()),
        Err(DarapError::Cotan(CotanError::FaceIndexOutOfRange { .. }))
    ));
    let out = layer.forward(layer.rest_normals()).unwrap();
    assert!(layer.try_backward(&out, &[[0.0; 3]; 3]).is_err());
}

#[test]
fn several_components_are_each_pinned() {
    let a = icosphere(1);
    let n = a.positions.len() as u32;
    let mut positions = a.positions.clone();
    positions.extend(a.positions.iter().map(|p| [p[0] + 4.0, p[1], p[2]]));
    let mut faces = a.faces.clone();
    faces.extend(a.faces.iter().map(|f| f.map(|v| v + n)));
    let layer = Darap::new(&positions, &faces, DarapOptions::default()).unwrap();
    assert_eq!(layer.pins(), &[0, n as usize]);
    let out = layer
        .forward(&random_targets(layer.rest_normals(), 0.5, 8))
        .unwrap();
    assert!(out.positions.iter().flatten().all(|v| v.is_finite()));
}

#[test]
fn results_are_bitwise_identical_across_thread_counts() {
    let mesh = icosphere(3);
    let layer = Darap::new(&mesh.positions, &mesh.faces, DarapOptions::default()).unwrap();
    let x = random_targets(layer.rest_normals(), 0.5, 9);
    let run = |threads: usize| {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap();
        pool.install(|| {
            let out = layer.forward(&x).unwrap();
            let g = layer.backward(&out, &x);
            (out.positions, g)
        })
    };
    assert_eq!(run(1), run(2));
    assert_eq!(run(1), run(1));
}

#[test]
fn backward_matches_central_differences_of_the_whole_chain() {
    for (mesh, rule, lambda) in [
        (icosphere(1), RotationRule::Gis, 8.0),
        (obtuse_wavy_grid(5), RotationRule::Gis, 5.0),
        (obtuse_wavy_grid(5), RotationRule::Procrustes, 40.0),
    ] {
        let opts = DarapOptions {
            lambda,
            rotation_rule: rule,
            ..Default::default()
        };
        let layer = Darap::new(&mesh.positions, &mesh.faces, opts).unwrap();
        let x = random_targets(layer.rest_normals(), 0.4, 10);
        let cot = random_targets(&vec![[0.0; 3]; x.len()], 1.0, 11);
        let loss = |x: &[[f64; 3]]| -> f64 {
            let p = layer.forward(x).unwrap().positions;
            p.iter()
                .zip(&cot)
                .map(|(a, b)| a[0] * b[0] + a[1] * b[1] + a[2] * b[2])
                .sum()
        };
        let out = layer.forward(&x).unwrap();
        let g = layer.backward(&out, &cot);
        let dir = random_targets(&vec![[0.0; 3]; x.len()], 1.0, 12);
        let h = 1e-6;
        let shift = |s: f64| -> Vec<[f64; 3]> {
            x.iter()
                .zip(&dir)
                .map(|(a, d)| std::array::from_fn(|c| a[c] + s * d[c]))
                .collect()
        };
        let fd = (loss(&shift(h)) - loss(&shift(-h))) / (2.0 * h);
        let an: f64 = g
            .iter()
            .zip(&dir)
            .map(|(a, d)| a[0] * d[0] + a[1] * d[1] + a[2] * d[2])
            .sum();
        assert!(
            (fd - an).abs() <= 1e-6 * fd.abs().max(an.abs()) + 1e-9,
            "{rule:?}: fd {fd} vs adjoint {an}"
        );
    }
}

#[test]
fn layer_is_send_and_sync() {
    fn check<T: Send + Sync>() {}
    check::<Darap>();
    check::<Deformation>();
}

#[test]
fn unreferenced_vertices_and_degenerate_faces_stay_finite() {
    // An extra vertex used by no face is its own component (pinned, left at rest); a zero-area
    // face hits the reference's area clamp. Nothing may become NaN.
    let mut mesh = icosphere(1);
    let extra = mesh.positions.len();
    mesh.positions.push([5.0, 5.0, 5.0]);
    let a = mesh.faces[0];
    let mid = mesh.positions.len() as u32;
    let (p0, p1) = (mesh.positions[a[0] as usize], mesh.positions[a[1] as usize]);
    mesh.positions
        .push(std::array::from_fn(|c| 0.5 * (p0[c] + p1[c])));
    mesh.faces.push([a[0], mid, a[1]]); // collinear: zero area
    let opts = DarapOptions {
        post_process: PostProcess::None,
        ..Default::default()
    };
    let layer = Darap::new(&mesh.positions, &mesh.faces, opts).unwrap();
    assert!(layer.pins().contains(&extra));
    let out = layer
        .forward(&random_targets(layer.rest_normals(), 0.5, 13))
        .unwrap();
    assert_eq!(out.positions[extra], [5.0, 5.0, 5.0]);
    assert!(out.positions.iter().flatten().all(|v| v.is_finite()));
    let g = layer.backward(&out, &out.positions);
    assert!(g.iter().flatten().all(|v| v.is_finite()));
}

/// The layer in its internal (solver) vertex order against the public stage functions chained in
/// the mesh's vertex order: identical rotations (same arithmetic per vertex), positions and
/// gradients equal up to the summation order of the right-hand side and the solve.
#[test]
fn layer_matches_the_stage_functions_chained_in_vertex_order() {
    let squashed = squashed_sphere();
    let grid = obtuse_wavy_grid(7);
    for mesh in [squashed, grid] {
        let (p, f) = (&mesh.positions, &mesh.faces);
        let n = p.len();
        let w = cotan::cot_weights(p, f).unwrap();
        let l = cotan::laplacian_from_weights(n, &w).unwrap();
        let mass = cotan::voronoi_mass(p, f).unwrap();
        let k = rest_covariances(p, f, &w);
        let pre = RhsPrecompute::new(p, f, &w);
        let solver = PinnedCholesky::new(&l, &cotan::component_pins(n, f)).unwrap();
        let pinned: Vec<[f64; 3]> = solver.pins().iter().map(|&v| p[v]).collect();
        let diag = mesh_core::geometry::bbox_diagonal(p);
        for (rule, lambda) in [(RotationRule::Gis, 8.0), (RotationRule::Procrustes, 40.0)] {
            for masked in [false, true] {
                let mut layer = Darap::new(
                    p,
                    f,
                    DarapOptions {
                        lambda,
                        rotation_rule: rule,
                        ..Default::default()
                    },
                )
                .unwrap();
                let mask: Option<Vec<bool>> = masked.then(|| (0..n).map(|v| v % 5 != 2).collect());
                layer.set_mask(mask.clone()).unwrap();
                let n0 = layer.rest_normals().to_vec();
                let x = random_targets(&n0, 0.6, 21);
                let g = random_targets(&n0, 1.0, 22);

                let unit = normalize_targets(&x);
                let (rot, tape) = local_step(&k, &mass, lambda, &n0, &unit, rule, mask.as_deref());
                let solved = solver.solve_pinned(&rhs(&pre, &rot), &pinned);
                let (pos, post) = post_process(&solved, diag, PostProcess::RecenterRescale);
                let out = layer.forward(&x).unwrap();
                assert_eq!(out.rotations, rot, "{rule:?} masked {masked}");
                let scale = pos.iter().flatten().fold(0.0f64, |m, v| m.max(v.abs()));
                assert!(max_diff(&out.positions, &pos) < 1e-12 * scale);

                let gs = solver.solve_pinned_adjoint(&post_process_vjp(&post, &g));
                let gu = local_step_vjp(&tape, &mass, lambda, &n0, &rhs_vjp(&pre, &gs));
                let expected = normalize_targets_vjp(&x, &gu);
                let got = layer.backward(&out, &g);
                let gscale = expected
                    .iter()
                    .flatten()
                    .fold(0.0f64, |m, v| m.max(v.abs()));
                assert!(
                    max_diff(&got, &expected) < 1e-10 * gscale,
                    "{rule:?} masked {masked}: {} vs scale {gscale}",
                    max_diff(&got, &expected)
                );
                if masked {
                    for v in (0..n).filter(|v| v % 5 == 2) {
                        assert_eq!(got[v], [0.0; 3]);
                        assert_eq!(out.rotations[v], IDENTITY);
                    }
                }
            }
        }
    }
}

/// Feather weights on an icosphere: 0 for `x < −0.3`, a ramp for `−0.3 ≤ x < 0.2`, 1 beyond.
fn feather(mesh: &mesh_core::TriMesh) -> Vec<f64> {
    mesh.positions
        .iter()
        .map(|p| ((p[0] + 0.3) / 0.5).clamp(0.0, 1.0))
        .collect()
}

#[test]
fn feathered_region_fades_lambda_and_its_vjp_matches_the_chain() {
    let mesh = icosphere(2);
    let n = mesh.positions.len();
    let mut layer = Darap::new(&mesh.positions, &mesh.faces, DarapOptions::default()).unwrap();
    let x = random_targets(layer.rest_normals(), 0.6, 31);
    let g = random_targets(layer.rest_normals(), 1.0, 32);
    let w = feather(&mesh);
    assert!(w.contains(&0.0) && w.iter().any(|&v| v > 0.0 && v < 1.0));
    layer.set_region_weights(Some(w.clone())).unwrap();
    assert_eq!(layer.region_weights().unwrap(), w);
    let out = layer.forward(&x).unwrap();
    // Each rotation is the rule applied to S = K + λ·w·a·n0 t̂ᵀ (identity where w = 0), and
    // stays a rotation.
    let opts = DarapOptions::default();
    let w_ = cotan::cot_weights(&mesh.positions, &mesh.faces).unwrap();
    let k = rest_covariances(&mesh.positions, &mesh.faces, &w_);
    let unit = normalize_targets(&x);
    for v in 0..n {
        let expected = if w[v] == 0.0 {
            IDENTITY
        } else {
            let s = crate::stages::covariance(
                opts.rotation_rule,
                &k[v],
                opts.lambda * w[v] * layer.mass()[v],
                layer.rest_normals()[v],
                unit[v],
            );
            crate::rotation_rule::gis(&s).0
        };
        for i in 0..3 {
            for j in 0..3 {
                assert!(
                    (out.rotations[v][i][j] - expected[i][j]).abs() < 1e-12,
                    "vertex {v}"
                );
            }
        }
        let r = out.rotations[v];
        let rtr: Mat3 = std::array::from_fn(|i| {
            std::array::from_fn(|j| (0..3).map(|c| r[c][i] * r[c][j]).sum::<f64>())
        });
        for i in 0..3 {
            for j in 0..3 {
                assert!(
                    (rtr[i][j] - IDENTITY[i][j]).abs() < 1e-12,
                    "vertex {v} not a rotation"
                );
            }
        }
    }
    // The gradient is exactly zero where w = 0, and matches a central difference.
    let grad = layer.backward(&out, &g);
    for v in (0..n).filter(|&v| w[v] == 0.0) {
        assert_eq!(grad[v], [0.0; 3], "vertex {v} outside the region");
    }
    let loss = |x: &[[f64; 3]]| -> f64 {
        let p = layer.forward(x).unwrap().positions;
        p.iter()
            .zip(&g)
            .map(|(a, b)| a[0] * b[0] + a[1] * b[1] + a[2] * b[2])
            .sum()
    };
    let dir = random_targets(layer.rest_normals(), 1.0, 33);
    let h = 1e-6;
    let xp: Vec<[f64; 3]> = x
        .iter()
        .zip(&dir)
        .map(|(a, d)| std::array::from_fn(|c| a[c] + h * d[c]))
        .collect();
    let xm: Vec<[f64; 3]> = x
        .iter()
        .zip(&dir)
        .map(|(a, d)| std::array::from_fn(|c| a[c] - h * d[c]))
        .collect();
    let fd = (loss(&xp) - loss(&xm)) / (2.0 * h);
    let an: f64 = grad
        .iter()
        .zip(&dir)
        .map(|(a, d)| a[0] * d[0] + a[1] * d[1] + a[2] * d[2])
        .sum();
    assert!(
        (fd - an).abs() < 1e-6 * (1.0 + an.abs()),
        "fd {fd} vs adjoint {an}"
    );
}

#[test]
fn region_weights_of_zero_and_one_are_the_hard_mask() {
    let mesh = squashed_sphere();
    let n = mesh.positions.len();
    let free: Vec<bool> = (0..n).map(|v| v % 4 != 1).collect();
    let mut masked = Darap::new(&mesh.positions, &mesh.faces, DarapOptions::default()).unwrap();
    masked.set_mask(Some(free.clone())).unwrap();
    let mut weighted = Darap::new(&mesh.positions, &mesh.faces, DarapOptions::default()).unwrap();
    weighted
        .set_region_weights(Some(
            free.iter().map(|&f| if f { 1.0 } else { 0.0 }).collect(),
        ))
        .unwrap();
    let x = random_targets(masked.rest_normals(), 0.7, 41);
    let a = masked.forward(&x).unwrap();
    let b = weighted.forward(&x).unwrap();
    assert_eq!(a.positions, b.positions);
    assert_eq!(masked.backward(&a, &x), weighted.backward(&b, &x));
    // Out-of-range and wrong-length weights are errors; None clears the region.
    assert!(matches!(
        weighted.set_region_weights(Some(vec![1.5; n])),
        Err(DarapError::OutOfRange { index: 0, .. })
    ));
    assert!(matches!(
        weighted.set_region_weights(Some(vec![f64::NAN; n])),
        Err(DarapError::OutOfRange { .. })
    ));
    assert!(matches!(
        weighted.set_region_weights(Some(vec![0.5; 2])),
        Err(DarapError::LengthMismatch { .. })
    ));
    weighted.set_region_weights(None).unwrap();
    assert!(weighted.region_weights().is_none());
}

#[test]
fn deformation_scales_with_the_mesh_down_to_a_fiftieth_of_the_normalized_frame() {
    // The reference's area and normal clamps are absolute (1e-6; docs/darap.md): above about
    // 0.02 of the side-2 cube the deformation is the unit-scale one times the scale; far larger
    // meshes are a typed error, not NaN.
    let m = icosphere(3);
    let base = Darap::new(&m.positions, &m.faces, DarapOptions::default()).unwrap();
    let x = random_targets(base.rest_normals(), 0.5, 3);
    let p0 = base.forward(&x).unwrap().positions;
    for scale in [0.02, 0.5, 3.0, 1e10, 1e40, 1e70] {
        let pos: Vec<[f64; 3]> = m.positions.iter().map(|p| p.map(|v| v * scale)).collect();
        let layer = Darap::new(&pos, &m.faces, DarapOptions::default()).unwrap();
        let s = layer.forward(&x).unwrap();
        let scaled: Vec<[f64; 3]> = s.positions.iter().map(|p| p.map(|v| v / scale)).collect();
        assert!(max_diff(&scaled, &p0) < 1e-12, "scale {scale:e}");
        let g = layer.backward(&s, &s.positions.clone());
        assert!(g.iter().flatten().all(|v| v.is_finite()), "scale {scale:e}");
    }
    for scale in [1e80, 1e150, 1e300] {
        let pos: Vec<[f64; 3]> = m.positions.iter().map(|p| p.map(|v| v * scale)).collect();
        assert!(
            matches!(
                Darap::new(&pos, &m.faces, DarapOptions::default()),
                Err(DarapError::Cotan(CotanError::Overflow { .. }))
            ),
            "scale {scale:e}"
        );
    }
}

#[test]
fn strength_one_is_the_forward_pass_bit_for_bit() {
    for rule in [RotationRule::Gis, RotationRule::Procrustes] {
        let mesh = squashed_sphere();
        let mut layer = Darap::new(&mesh.positions, &mesh.faces, DarapOptions::default()).unwrap();
        layer.set_rotation_rule(rule);
        let x = random_targets(layer.rest_normals(), 0.8, 11);
        let plain = layer.forward(&x).unwrap();
        let one = layer.forward_at_strength(&x, 1.0).unwrap();
        assert_eq!(plain.positions, one.positions);
        assert_eq!(plain.rotations, one.rotations);
        assert_eq!(one.strength(), None);
        // … and it stays differentiable.
        assert_eq!(
            layer.backward(&plain, &plain.positions),
            layer.backward(&one, &one.positions)
        );
    }
}

#[test]
fn strength_under_procrustes_is_procrustes_at_the_scaled_lambda() {
    let mesh = obtuse_wavy_grid(10);
    let mut layer = Darap::new(&mesh.positions, &mesh.faces, DarapOptions::default()).unwrap();
    layer.set_rotation_rule(RotationRule::Procrustes);
    let x = random_targets(layer.rest_normals(), 0.8, 12);
    for s in [0.5, 2.0, 3.5] {
        let strong = layer.forward_at_strength(&x, s).unwrap();
        layer.set_lambda(s * DarapOptions::default().lambda);
        let scaled = layer.forward(&x).unwrap();
        layer.set_lambda(DarapOptions::default().lambda);
        assert!(
            max_diff(&strong.positions, &scaled.positions) < 1e-12,
            "s = {s}"
        );
        assert_eq!(strong.strength(), Some(s));
    }
}

/// The gis layer's strength result against the rule written out with three plain forward passes
/// (R(λ) under gis, P(λ) and P(s·λ) under procrustes) and the global step, on a masked mesh: the
/// masked vertices keep `R = I` at every strength.
#[test]
fn strength_under_gis_composes_the_procrustes_increment_with_the_saved_rotations() {
    let mesh = squashed_sphere();
    let n = mesh.positions.len();
    let lambda = 8.0;
    let mut layer = Darap::new(
        &mesh.positions,
        &mesh.faces,
        DarapOptions {
            lambda,
            ..DarapOptions::default()
        },
    )
    .unwrap();
    let mask: Vec<bool> = (0..n).map(|v| v % 3 != 0).collect();
    layer.set_mask(Some(mask.clone())).unwrap();
    let x = random_targets(layer.rest_normals(), 0.8, 13);
    let s = 2.5;
    let strong = layer.forward_at_strength(&x, s).unwrap();

    let saved = layer.forward(&x).unwrap().rotations;
    layer.set_rotation_rule(RotationRule::Procrustes);
    let p_saved = layer.forward(&x).unwrap().rotations;
    layer.set_lambda(s * lambda);
    let p_far = layer.forward(&x).unwrap().rotations;
    let expected: Vec<Mat3> = (0..n)
        .map(|v| {
            mat3::mul(
                &mat3::mul(&p_far[v], &mat3::transpose(&p_saved[v])),
                &saved[v],
            )
        })
        .collect();
    for (v, (a, b)) in strong.rotations.iter().zip(&expected).enumerate() {
        for i in 0..3 {
            for j in 0..3 {
                assert!((a[i][j] - b[i][j]).abs() < 1e-12, "vertex {v}");
            }
        }
        if !mask[v] {
            assert_eq!(*a, IDENTITY, "masked vertex {v} rotates");
        }
    }
    let (positions, _) = post_process(
        &layer.global_step(&expected),
        layer.rest_diag,
        layer.options().post_process,
    );
    assert!(max_diff(&strong.positions, &positions) < 1e-12);
    // A different strength is a different result.
    layer.set_lambda(lambda);
    layer.set_rotation_rule(RotationRule::Gis);
    let plain = layer.forward(&x).unwrap();
    assert!(max_diff(&strong.positions, &plain.positions) > 1e-6);
}

#[test]
fn strength_bad_values_and_backward_are_typed_errors() {
    let mesh = icosphere(1);
    let layer = Darap::new(&mesh.positions, &mesh.faces, DarapOptions::default()).unwrap();
    let x = random_targets(layer.rest_normals(), 0.5, 14);
    for s in [f64::NAN, f64::INFINITY] {
        assert!(matches!(
            layer.forward_at_strength(&x, s),
            Err(DarapError::NonFinite {
                what: "strength",
                ..
            })
        ));
    }
    for s in [0.0, -1.0, f64::MAX] {
        assert!(matches!(
            layer.forward_at_strength(&x, s),
            Err(DarapError::OutOfRange {
                what: "strength",
                ..
            })
        ));
    }
    let strong = layer.forward_at_strength(&x, 2.0).unwrap();
    assert!(matches!(
        layer.try_backward(&strong, &strong.positions),
        Err(DarapError::NotDifferentiable { strength }) if strength == 2.0
    ));
}

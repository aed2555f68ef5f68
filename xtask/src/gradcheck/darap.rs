//! Gradient checks of every hand-written adjoint of `darap`, on a well-shaped closed mesh, an open
//! mesh with obtuse triangles (negative weights) and the golden bunny (gis λ = 8 drives rotations
//! close to a flip there).

use super::{Report, Tolerance};
use darap::Mat3;
use darap::stages;
use darap::{Darap, DarapOptions, PostProcess, RotationRule};
use mesh_core::TriMesh;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

fn rows(v: &[f64]) -> Vec<[f64; 3]> {
    v.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect()
}

fn mats(v: &[f64]) -> Vec<Mat3> {
    v.chunks_exact(9)
        .map(|c| [[c[0], c[1], c[2]], [c[3], c[4], c[5]], [c[6], c[7], c[8]]])
        .collect()
}

fn flat(v: &[[f64; 3]]) -> Vec<f64> {
    v.iter().flatten().copied().collect()
}

fn flat_m(v: &[Mat3]) -> Vec<f64> {
    v.iter().flatten().flatten().copied().collect()
}

fn dot(a: &[[f64; 3]], b: &[[f64; 3]]) -> f64 {
    a.iter()
        .zip(b)
        .map(|(x, y)| x[0] * y[0] + x[1] * y[1] + x[2] * y[2])
        .sum()
}

fn dot_m(a: &[Mat3], b: &[Mat3]) -> f64 {
    flat_m(a).iter().zip(flat_m(b)).map(|(x, y)| x * y).sum()
}

fn random_rows(rng: &mut ChaCha8Rng, n: usize) -> Vec<[f64; 3]> {
    (0..n)
        .map(|_| std::array::from_fn(|_| rng.random::<f64>() * 2.0 - 1.0))
        .collect()
}

fn random_mats(rng: &mut ChaCha8Rng, n: usize) -> Vec<Mat3> {
    (0..n)
        .map(|_| std::array::from_fn(|_| std::array::from_fn(|_| rng.random::<f64>() * 2.0 - 1.0)))
        .collect()
}

/// Targets near the rest normals, of varying length.
fn targets(rng: &mut ChaCha8Rng, n0: &[[f64; 3]], spread: f64) -> Vec<[f64; 3]> {
    n0.iter()
        .map(|n| {
            let s = 0.5 + rng.random::<f64>();
            std::array::from_fn(|c| s * (n[c] + spread * (rng.random::<f64>() * 2.0 - 1.0)))
        })
        .collect()
}

fn meshes() -> anyhow::Result<Vec<(&'static str, TriMesh)>> {
    let path = concat!(env!("CARGO_MANIFEST_DIR"), "/../fixtures/golden/bunny.obj");
    let mut bunny = mesh_core::io::read_mesh(path)?;
    mesh_core::normalize::side2_cube(&mut bunny.positions);
    Ok(vec![
        ("icosphere2", mesh_core::shapes::icosphere(2)),
        ("obtuse_grid8", mesh_core::shapes::obtuse_wavy_grid(8)),
        ("bunny", bunny),
    ])
}

pub fn suite(report: &mut Report) -> anyhow::Result<()> {
    let tol = Tolerance::default();
    let mut rng = ChaCha8Rng::seed_from_u64(42);

    // Rotation rules on random matrices (not tied to a mesh).
    let s = random_mats(&mut rng, 64);
    let g = random_mats(&mut rng, 64);
    for (rule_name, rule) in [
        (
            "gis",
            stages::gis as fn(&Mat3) -> (Mat3, stages::RotationSvd),
        ),
        ("procrustes", stages::procrustes),
    ] {
        let grad: Vec<Mat3> = s
            .iter()
            .zip(&g)
            .map(|(s, g)| stages::rotation_vjp(&rule(s).1, g))
            .collect();
        report.check(
            &format!("darap/rotation_rule/{rule_name}/random"),
            &flat_m(&s),
            &flat_m(&grad),
            tol,
            2,
            |theta| {
                let r: Vec<Mat3> = mats(theta).iter().map(|s| rule(s).0).collect();
                dot_m(&g, &r)
            },
        );
    }

    for (name, mesh) in meshes()? {
        let n = mesh.positions.len();
        let p = &mesh.positions;
        let f = &mesh.faces;
        let weights = cotan::cot_weights(p, f)?;
        let mass = cotan::voronoi_mass(p, f)?;
        let n0 = mesh_core::normals::vertex_normals_area_weighted(p, f);
        let k = stages::rest_covariances(p, f, &weights);
        let x = targets(&mut rng, &n0, 0.5);
        let unit = stages::normalize_targets(&x);

        // Normalization.
        let g3 = random_rows(&mut rng, n);
        let grad = stages::normalize_targets_vjp(&x, &g3);
        report.check(
            &format!("darap/normalize_targets/{name}"),
            &flat(&x),
            &flat(&grad),
            tol,
            3,
            |theta| dot(&g3, &stages::normalize_targets(&rows(theta))),
        );

        // Rotation rules on this mesh's covariances.
        for (rule_name, rule, lambda) in [
            ("gis", RotationRule::Gis, 8.0),
            ("procrustes", RotationRule::Procrustes, 40.0),
        ] {
            let sv: Vec<Mat3> = (0..n)
                .map(|v| stages::covariance(rule, &k[v], lambda * mass[v], n0[v], unit[v]))
                .collect();
            let gm = random_mats(&mut rng, n);
            let apply = |s: &Mat3| match rule {
                RotationRule::Gis => stages::gis(s),
                RotationRule::Procrustes => stages::procrustes(s),
            };
            let grad: Vec<Mat3> = sv
                .iter()
                .zip(&gm)
                .map(|(s, g)| stages::rotation_vjp(&apply(s).1, g))
                .collect();
            report.check(
                &format!("darap/rotation_rule/{rule_name}/{name}"),
                &flat_m(&sv),
                &flat_m(&grad),
                tol,
                4,
                |theta| {
                    let r: Vec<Mat3> = mats(theta).iter().map(|s| apply(s).0).collect();
                    dot_m(&gm, &r)
                },
            );

            // Local step with respect to the unit targets (with and without a mask). The loss sums
            // ~10⁴ SVD-based entries, whose rounding noise (~1e-13 in total) dominates a central
            // difference at h = 1e-6; h = 1e-5 balances rounding and truncation.
            for masked in [false, true] {
                let mask: Option<Vec<bool>> = masked.then(|| (0..n).map(|v| v % 3 != 0).collect());
                let (_, tape) =
                    stages::local_step(&k, &mass, lambda, &n0, &unit, rule, mask.as_deref());
                let grad = stages::local_step_vjp(&tape, &mass, lambda, &n0, &gm);
                let label = if masked { "masked/" } else { "" };
                report.check(
                    &format!("darap/local_step/{rule_name}/{label}{name}"),
                    &flat(&unit),
                    &flat(&grad),
                    Tolerance { step: 1e-5, ..tol },
                    5,
                    |theta| {
                        let (r, _) = stages::local_step(
                            &k,
                            &mass,
                            lambda,
                            &n0,
                            &rows(theta),
                            rule,
                            mask.as_deref(),
                        );
                        dot_m(&gm, &r)
                    },
                );
            }
        }

        // Right-hand side with respect to the rotations.
        let pre = stages::RhsPrecompute::new(p, f, &weights);
        let rot = random_mats(&mut rng, n);
        let gb = random_rows(&mut rng, n);
        let grad = stages::rhs_vjp(&pre, &gb);
        report.check(
            &format!("darap/rhs/{name}"),
            &flat_m(&rot),
            &flat_m(&grad),
            tol,
            6,
            |theta| dot(&gb, &stages::rhs(&pre, &mats(theta))),
        );

        // Pinned solve (the layer's solver) with respect to b.
        let l = cotan::laplacian_from_weights(n, &weights)?;
        let solver = cotan::PinnedCholesky::new(&l, &cotan::component_pins(n, f))?;
        let pinned: Vec<[f64; 3]> = solver.pins().iter().map(|&v| p[v]).collect();
        let b = random_rows(&mut rng, n);
        let grad = solver.solve_pinned_adjoint(&gb);
        report.check(
            &format!("darap/pinned_solve/{name}"),
            &flat(&b),
            &flat(&grad),
            tol,
            7,
            |theta| dot(&gb, &solver.solve_pinned(&rows(theta), &pinned)),
        );

        // Post-processing, all three modes, on a deformed-looking point set.
        let solved: Vec<[f64; 3]> = p
            .iter()
            .zip(&gb)
            .map(|(q, d)| std::array::from_fn(|c| q[c] + 0.05 * d[c]))
            .collect();
        let rest_diag = mesh_core::geometry::bbox_diagonal(p);
        for (mode_name, mode) in [
            ("recenter_rescale", PostProcess::RecenterRescale),
            ("recenter_only", PostProcess::RecenterOnly),
            ("none", PostProcess::None),
        ] {
            let (_, tape) = stages::post_process(&solved, rest_diag, mode);
            let grad = stages::post_process_vjp(&tape, &g3);
            report.check(
                &format!("darap/post_process/{mode_name}/{name}"),
                &flat(&solved),
                &flat(&grad),
                tol,
                8,
                |theta| dot(&g3, &stages::post_process(&rows(theta), rest_diag, mode).0),
            );
        }

        // The whole chain x → positions. The loss ⟨g, positions⟩ is ~25 on the bunny and the forward
        // (local step, solve, post-process) rounds it by ~5–10 ulps, i.e. ~2e-14: at h = 1e-6 a
        // central difference carries ~1e-8 of rounding noise, as large as rtol·|∂| for the small
        // directional derivatives (~1e-3) here — measured on procrustes/bunny, direction 3: the
        // difference to the adjoint is 2.0e-8 at h = 1e-6 but 3.4e-11 at 1e-5 and 5.2e-11 at 1e-4.
        // h = 1e-5 balances rounding and truncation, as for the local step above.
        let chain_tol = Tolerance { step: 1e-5, ..tol };
        for (rule_name, rule, lambda) in [
            ("gis", RotationRule::Gis, 8.0),
            ("procrustes", RotationRule::Procrustes, 40.0),
        ] {
            let layer = Darap::new(
                p,
                f,
                DarapOptions {
                    lambda,
                    rotation_rule: rule,
                    ..Default::default()
                },
            )?;
            let state = layer.forward(&x)?;
            let grad = layer.backward(&state, &g3);
            report.check(
                &format!("darap/chain/{rule_name}/{name}"),
                &flat(&x),
                &flat(&grad),
                chain_tol,
                9,
                |theta| {
                    layer
                        .forward(&rows(theta))
                        .map_or(f64::NAN, |s| dot(&g3, &s.positions))
                },
            );
        }

        // Feathered region (λ faded per vertex): weights 0 on a third of the vertices, 0.4 on
        // another third, through the whole chain.
        let feather: Vec<f64> = (0..n).map(|v| [0.0, 0.4, 1.0][v % 3]).collect();
        for (rule_name, rule, lambda) in [
            ("gis", RotationRule::Gis, 8.0),
            ("procrustes", RotationRule::Procrustes, 40.0),
        ] {
            let mut layer = Darap::new(
                p,
                f,
                DarapOptions {
                    lambda,
                    rotation_rule: rule,
                    ..Default::default()
                },
            )?;
            layer.set_region_weights(Some(feather.clone()))?;
            let state = layer.forward(&x)?;
            let grad = layer.backward(&state, &g3);
            if let Some(v) = (0..n).find(|&v| feather[v] == 0.0 && grad[v] != [0.0; 3]) {
                report.fail(
                    &format!("darap/chain_feathered/{rule_name}/{name}"),
                    format!("vertex {v} has weight 0 but gradient {:?}", grad[v]),
                );
            }
            report.check(
                &format!("darap/chain_feathered/{rule_name}/{name}"),
                &flat(&x),
                &flat(&grad),
                chain_tol,
                11,
                |theta| {
                    layer
                        .forward(&rows(theta))
                        .map_or(f64::NAN, |s| dot(&g3, &s.positions))
                },
            );
        }

        // Degenerate inputs stay finite: zero targets, identical targets, huge λ.
        for lambda in [0.0, 8.0, 1e8] {
            let layer = Darap::new(
                p,
                f,
                DarapOptions {
                    lambda,
                    ..Default::default()
                },
            )?;
            for xd in [vec![[0.0; 3]; n], vec![[0.0, 1.0, 0.0]; n]] {
                let state = layer.forward(&xd)?;
                let grad = layer.backward(&state, &g3);
                if !state
                    .positions
                    .iter()
                    .chain(&grad)
                    .flatten()
                    .all(|v| v.is_finite())
                {
                    report.fail(
                        &format!("darap/degenerate_finite/{name}"),
                        format!("non-finite output at λ = {lambda}"),
                    );
                }
            }
        }
    }
    Ok(())
}

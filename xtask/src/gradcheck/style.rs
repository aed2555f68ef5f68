//! Gradient checks of the model-free style objective (`stylize::style::alignment`):
//! ℓ(P) = Σ_f A_f (1 − n_f · t_f) with respect to the deformed positions P, the same loss through
//! the dARAP layer with respect to the raw targets x, and finiteness on degenerate faces.

use stylize::style::alignment;

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use super::{CheckResult, Report, Tolerance};

fn unit(v: [f64; 3]) -> [f64; 3] {
    let l = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt().max(1e-300);
    v.map(|c| c / l)
}

/// Positions, faces and one unit target normal per face.
type Fixture = (Vec<[f64; 3]>, Vec<[u32; 3]>, Vec<[f64; 3]>);

/// A small closed test mesh (icosphere, 1 subdivision) with jittered vertices and random unit
/// per-face targets.
fn fixture(seed: u64) -> Fixture {
    let (mut p, f) = mesh_core::shapes::icosphere(1).into_parts();
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    for v in &mut p {
        for c in v.iter_mut() {
            *c += 0.05 * (rng.random::<f64>() - 0.5);
        }
    }
    let t = (0..f.len())
        .map(|_| {
            unit([
                rng.random::<f64>() - 0.5,
                rng.random::<f64>() - 0.5,
                rng.random::<f64>() - 0.5,
            ])
        })
        .collect();
    (p, f, t)
}

/// Registers the style checks.
pub fn suite(report: &mut Report) -> anyhow::Result<()> {
    let tol = Tolerance::default();

    // 1. ℓ(P) with respect to positions.
    let (p, f, t) = fixture(11);
    let (_, grad) = alignment::alignment_loss_and_grad(&p, &f, &t);
    let theta: Vec<f64> = p.as_flattened().to_vec();
    report.check(
        "style/alignment_loss wrt deformed positions",
        &theta,
        grad.as_flattened(),
        tol,
        1,
        |th| {
            let q: Vec<[f64; 3]> = th.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect();
            alignment::alignment_loss(&q, &f, &t)
        },
    );

    // 2. ℓ(dARAP(x)) with respect to x (the chain the model-free loop differentiates).
    let (rest, faces) = mesh_core::shapes::icosphere(1).into_parts();
    let layer = darap::Darap::new(
        &rest,
        &faces,
        darap::DarapOptions {
            lambda: 4.0,
            ..darap::DarapOptions::default()
        },
    )?;
    let mut rng = ChaCha8Rng::seed_from_u64(12);
    let x: Vec<[f64; 3]> = layer
        .rest_normals()
        .iter()
        .map(|n| n.map(|c| c + 0.3 * (rng.random::<f64>() - 0.5)))
        .collect();
    let targets: Vec<[f64; 3]> = faces
        .iter()
        .map(|&fc| {
            let n = unit(alignment::face_cross(&rest, fc));
            // Cube style: nearest signed axis.
            let k = (0..3)
                .max_by(|&a, &b| n[a].abs().total_cmp(&n[b].abs()))
                .unwrap_or(0);
            let mut e = [0.0; 3];
            e[k] = n[k].signum();
            e
        })
        .collect();
    let def = layer.forward(&x)?;
    let (_, grad_p) = alignment::alignment_loss_and_grad(&def.positions, &faces, &targets);
    let grad_x = layer.try_backward(&def, &grad_p)?;
    report.check(
        "style/alignment through dARAP wrt targets x",
        x.as_flattened(),
        grad_x.as_flattened(),
        tol,
        2,
        |th| {
            let q: Vec<[f64; 3]> = th.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect();
            match layer.forward(&q) {
                Ok(d) => alignment::alignment_loss(&d.positions, &faces, &targets),
                Err(_) => f64::NAN,
            }
        },
    );

    // 3. Degenerate faces (all corners equal, or collinear) keep loss and gradient finite.
    let p = vec![
        [0.0; 3],
        [0.0; 3],
        [0.0; 3],
        [1.0, 1.0, 1.0],
        [2.0, 2.0, 2.0],
    ];
    let f = vec![[0, 1, 2], [0, 3, 4], [1, 3, 2]];
    let t = vec![[0.0, 0.0, 1.0]; 3];
    let (l, g) = alignment::alignment_loss_and_grad(&p, &f, &t);
    let name = "style/degenerate faces stay finite";
    if l.is_finite() && g.iter().flatten().all(|v| v.is_finite()) {
        report.results.push(CheckResult {
            name: name.into(),
            worst_rel: 0.0,
            failures: Vec::new(),
        });
    } else {
        report.fail(name, format!("loss {l}, gradient {g:?}"));
    }
    Ok(())
}

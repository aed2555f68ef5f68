//! Gradient checks of `cotan`: the adjoint of the pinned solve.

use super::{Report, Tolerance};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

fn rows(v: &[f64]) -> Vec<[f64; 3]> {
    v.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect()
}

fn flat(v: &[[f64; 3]]) -> Vec<f64> {
    v.iter().flatten().copied().collect()
}

fn dot(a: &[[f64; 3]], b: &[[f64; 3]]) -> f64 {
    a.iter()
        .zip(b)
        .map(|(x, y)| x[0] * y[0] + x[1] * y[1] + x[2] * y[2])
        .sum()
}

pub fn suite(report: &mut Report) -> anyhow::Result<()> {
    let meshes = [
        ("icosphere2", mesh_core::shapes::icosphere(2)),
        ("obtuse_grid8", mesh_core::shapes::obtuse_wavy_grid(8)),
    ];
    for (name, mesh) in meshes {
        let l = cotan::laplacian(&mesh.positions, &mesh.faces)?;
        let pins = cotan::component_pins(mesh.positions.len(), &mesh.faces);
        let solver = cotan::PinnedCholesky::new(&l, &pins)?;
        let mut rng = ChaCha8Rng::seed_from_u64(21);
        let n = mesh.positions.len();
        let g: Vec<[f64; 3]> = (0..n)
            .map(|_| std::array::from_fn(|_| rng.random::<f64>() - 0.5))
            .collect();
        let b: Vec<[f64; 3]> = (0..n)
            .map(|_| std::array::from_fn(|_| rng.random::<f64>() - 0.5))
            .collect();
        let pinned: Vec<[f64; 3]> = solver.pins().iter().map(|&p| mesh.positions[p]).collect();
        let grad = solver.solve_pinned_adjoint(&g);
        report.check(
            &format!("cotan/pinned_solve/{name}"),
            &flat(&b),
            &flat(&grad),
            Tolerance::default(),
            1,
            |theta| dot(&g, &solver.solve_pinned(&rows(theta), &pinned)),
        );
    }
    Ok(())
}

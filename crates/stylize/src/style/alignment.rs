//! The model-free objective: area-weighted alignment of a mesh's face normals with per-face targets,
//! and its hand-written adjoint with respect to the vertex positions.
//!
//! For face `f = (i, j, k)` with positions `p_i, p_j, p_k` let
//! `N_f = (p_j − p_i) × (p_k − p_i)` (length = 2·area, outward for CCW faces), `A_f = |N_f|/2`,
//! `n_f = N_f/|N_f|`, and `t_f` a **unit** target. The objective is
//!
//! ```text
//! ℓ(P) = Σ_f A_f (1 − n_f · t_f) = ½ Σ_f (|N_f| − N_f · t_f)
//! ```
//!
//! (since `A_f n_f = N_f/2`): zero exactly when every face points along its target, and a face's
//! weight is its current (deformed) area. The gradient with respect to `N_f` is
//! `G_f = ½ (N_f/|N_f| − t_f)`; for a degenerate face (`|N_f| ≤ 1e-300`) the non-differentiable
//! `|N_f|` term contributes the subgradient 0, so the result is always finite. With
//! `e1 = p_j − p_i`, `e2 = p_k − p_i` and `N = e1 × e2`: `∂ℓ/∂e1 = e2 × G`, `∂ℓ/∂e2 = G × e1`,
//! then `∂ℓ/∂p_j += ∂ℓ/∂e1`, `∂ℓ/∂p_k += ∂ℓ/∂e2`, `∂ℓ/∂p_i −= ∂ℓ/∂e1 + ∂ℓ/∂e2`.
//!
//! This file depends on `std` only: `xtask gradcheck` compiles it directly (see
//! `xtask/src/gradcheck/style.rs`) so the check does not pull in the CLI's model and GPU crates.

fn sub(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

fn cross(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

fn dot(a: [f64; 3], b: [f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

/// Below this `|N_f|` a face counts as degenerate (its normal is undefined).
const DEGENERATE: f64 = 1e-300;

/// `N_f = (p_j − p_i) × (p_k − p_i)` (twice the area times the unit normal). Faces must index
/// into `positions` (the caller validates).
pub fn face_cross(positions: &[[f64; 3]], face: [u32; 3]) -> [f64; 3] {
    let p = |v: u32| positions[v as usize];
    cross(sub(p(face[1]), p(face[0])), sub(p(face[2]), p(face[0])))
}

/// ℓ(P) = Σ_f A_f (1 − n_f · t_f). `targets` holds one unit vector per face.
pub fn alignment_loss(positions: &[[f64; 3]], faces: &[[u32; 3]], targets: &[[f64; 3]]) -> f64 {
    faces
        .iter()
        .zip(targets)
        .map(|(&f, &t)| {
            let n = face_cross(positions, f);
            0.5 * (dot(n, n).sqrt() - dot(n, t))
        })
        .sum()
}

/// ℓ(P) and ∂ℓ/∂P (one row per vertex). Always finite for finite inputs.
pub fn alignment_loss_and_grad(
    positions: &[[f64; 3]],
    faces: &[[u32; 3]],
    targets: &[[f64; 3]],
) -> (f64, Vec<[f64; 3]>) {
    let mut grad = vec![[0.0; 3]; positions.len()];
    let mut loss = 0.0;
    for (&f, &t) in faces.iter().zip(targets) {
        let [i, j, k] = f.map(|v| v as usize);
        let e1 = sub(positions[j], positions[i]);
        let e2 = sub(positions[k], positions[i]);
        let n = cross(e1, e2);
        let len = dot(n, n).sqrt();
        loss += 0.5 * (len - dot(n, t));
        let unit = if len > DEGENERATE {
            [n[0] / len, n[1] / len, n[2] / len]
        } else {
            [0.0; 3]
        };
        let g = [
            0.5 * (unit[0] - t[0]),
            0.5 * (unit[1] - t[1]),
            0.5 * (unit[2] - t[2]),
        ];
        let g1 = cross(e2, g);
        let g2 = cross(g, e1);
        for c in 0..3 {
            grad[j][c] += g1[c];
            grad[k][c] += g2[c];
            grad[i][c] -= g1[c] + g2[c];
        }
    }
    (loss, grad)
}

/// Area-weighted mean alignment `Σ_f A_f n_f·t_f / Σ_f A_f ∈ [−1, 1]` (1: every face on target).
/// Returns 0 for a mesh of zero area.
pub fn mean_alignment(positions: &[[f64; 3]], faces: &[[u32; 3]], targets: &[[f64; 3]]) -> f64 {
    let (mut num, mut den) = (0.0, 0.0);
    for (&f, &t) in faces.iter().zip(targets) {
        let n = face_cross(positions, f);
        num += dot(n, t);
        den += dot(n, n).sqrt();
    }
    if den > 0.0 { num / den } else { 0.0 }
}

//! The global step (spec §4.1–4.2): right-hand side from the rotations, pinned sparse solve.

use crate::local::PAR_MIN_LEN;
use crate::mat3::{Mat3, ZERO, mul_vec};
use cotan::CotWeights;
use rayon::prelude::*;

/// Everything the right-hand side needs that depends only on the rest mesh.
///
/// Per face `f = (i, j, k)` and corner `a` with other corners `b`, `e`, the rest vector
/// `g_{f,a} = (1/6)·[c_ab (p_a − p_b) + c_ae (p_a − p_e)]` (full edge weights `c`, not halved), so
/// that `b_a = Σ_{(f,a)} R_f g_{f,a}` with `R_f = R_i + R_j + R_k` (spec §4.1).
#[derive(Clone, Debug)]
pub struct RhsPrecompute {
    faces: Vec<[u32; 3]>,
    corner_vectors: Vec<[[f64; 3]; 3]>,
    /// Vertex → (face, corner) incidences in CSR form, in increasing face order.
    incidence_ptr: Vec<usize>,
    incidence: Vec<(u32, u8)>,
}

impl RhsPrecompute {
    /// Builds the precompute; `weights` are the mesh's cotangent weights.
    pub fn new(positions: &[[f64; 3]], faces: &[[u32; 3]], weights: &CotWeights) -> Self {
        let corner_vectors = faces
            .iter()
            .map(|f| {
                std::array::from_fn(|a| {
                    let (pa, b, e) = (f[a], f[(a + 1) % 3], f[(a + 2) % 3]);
                    let p = positions[pa as usize];
                    let mut g = [0.0; 3];
                    for other in [b, e] {
                        if other == pa {
                            continue;
                        }
                        let c = weights.get(pa, other).unwrap_or(0.0);
                        let q = positions[other as usize];
                        for d in 0..3 {
                            g[d] += c * (p[d] - q[d]) / 6.0;
                        }
                    }
                    g
                })
            })
            .collect();
        let n = positions.len();
        let mut incidence_ptr = vec![0usize; n + 1];
        for f in faces {
            for &v in f {
                incidence_ptr[v as usize + 1] += 1;
            }
        }
        for i in 0..n {
            incidence_ptr[i + 1] += incidence_ptr[i];
        }
        let mut fill = incidence_ptr.clone();
        let mut incidence = vec![(0u32, 0u8); 3 * faces.len()];
        for (fi, f) in faces.iter().enumerate() {
            for (k, &v) in f.iter().enumerate() {
                incidence[fill[v as usize]] = (fi as u32, k as u8);
                fill[v as usize] += 1;
            }
        }
        Self {
            faces: faces.to_vec(),
            corner_vectors,
            incidence_ptr,
            incidence,
        }
    }

    /// Number of vertices.
    pub fn num_vertices(&self) -> usize {
        self.incidence_ptr.len() - 1
    }
}

/// The right-hand side `b` of the global step (spec §4.1). With every `R = I`, `b = L p` exactly.
/// Deterministic (a gather per vertex in a fixed order).
pub fn rhs(pre: &RhsPrecompute, rotations: &[Mat3]) -> Vec<[f64; 3]> {
    let face_rot: Vec<Mat3> = pre
        .faces
        .par_iter()
        .with_min_len(PAR_MIN_LEN)
        .map(|f| {
            let (a, b, c) = (
                &rotations[f[0] as usize],
                &rotations[f[1] as usize],
                &rotations[f[2] as usize],
            );
            std::array::from_fn(|i| std::array::from_fn(|j| a[i][j] + b[i][j] + c[i][j]))
        })
        .collect();
    (0..pre.num_vertices())
        .into_par_iter()
        .with_min_len(PAR_MIN_LEN)
        .map(|v| {
            let mut acc = [0.0; 3];
            for &(f, k) in &pre.incidence[pre.incidence_ptr[v]..pre.incidence_ptr[v + 1]] {
                let y = mul_vec(
                    &face_rot[f as usize],
                    pre.corner_vectors[f as usize][k as usize],
                );
                acc[0] += y[0];
                acc[1] += y[1];
                acc[2] += y[2];
            }
            acc
        })
        .collect()
}

/// Adjoint of [`rhs`]: given `∂ℓ/∂b`, returns `∂ℓ/∂R_v = Σ_{f ∋ v} Σ_a (∂ℓ/∂b_a) g_{f,a}ᵀ`.
pub fn rhs_vjp(pre: &RhsPrecompute, grad_b: &[[f64; 3]]) -> Vec<Mat3> {
    let face_grad: Vec<Mat3> = pre
        .faces
        .par_iter()
        .zip(pre.corner_vectors.par_iter())
        .with_min_len(PAR_MIN_LEN)
        .map(|(f, g)| {
            let mut m = ZERO;
            for a in 0..3 {
                let gb = grad_b[f[a] as usize];
                for i in 0..3 {
                    for j in 0..3 {
                        m[i][j] += gb[i] * g[a][j];
                    }
                }
            }
            m
        })
        .collect();
    (0..pre.num_vertices())
        .into_par_iter()
        .with_min_len(PAR_MIN_LEN)
        .map(|v| {
            let mut acc = ZERO;
            for &(f, _) in &pre.incidence[pre.incidence_ptr[v]..pre.incidence_ptr[v + 1]] {
                let m = &face_grad[f as usize];
                for i in 0..3 {
                    for j in 0..3 {
                        acc[i][j] += m[i][j];
                    }
                }
            }
            acc
        })
        .collect()
}

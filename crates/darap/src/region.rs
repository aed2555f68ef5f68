//! Feathered regions: a per-vertex weight that blends each rotation with the identity.
//!
//! A localized stylization (method spec: "R = I outside the region") is a weight `w_v ∈ [0, 1]`
//! per vertex. The local step's rotation `R_v` is replaced by
//!
//! ```text
//! R̃_v = w_v · R_v + (1 − w_v) · I
//! ```
//!
//! before the global step. `w = 1` is the free vertex, `w = 0` the hard mask (`R̃ = I`, the
//! vertex keeps its rest one-ring shape). In between, `R̃` is not a rotation but a linear blend:
//! the global step is linear in the per-vertex matrices (spec §4.1), so the blend moves the
//! *edge targets* `R̃ e` linearly from the rest edges to the rotated ones. This is what
//! `--region-feather K` uses over the `K` rings inside a region's boundary
//! (`mesh_core::region::feather_weights`).
//!
//! Adjoint: `∂ℓ/∂R_v = w_v · ∂ℓ/∂R̃_v` (the identity term is constant), so the gradient that
//! reaches the targets of a vertex with `w_v = 0` is exactly zero.

use crate::mat3::Mat3;

/// `R ← w·R + (1 − w)·I` for every vertex, in place. `weights[v] == 1` leaves `R_v` bit for bit.
///
/// # Panics
/// If the slices differ in length (a programming error).
pub fn blend_with_identity(rotations: &mut [Mat3], weights: &[f64]) {
    assert_eq!(rotations.len(), weights.len(), "one weight per rotation");
    for (r, &w) in rotations.iter_mut().zip(weights) {
        if w == 1.0 {
            continue;
        }
        for (i, row) in r.iter_mut().enumerate() {
            for (j, x) in row.iter_mut().enumerate() {
                *x = w * *x + if i == j { 1.0 - w } else { 0.0 };
            }
        }
    }
}

/// Adjoint of [`blend_with_identity`]: `∂ℓ/∂R ← w·∂ℓ/∂R̃`, in place.
///
/// # Panics
/// If the slices differ in length (a programming error).
pub fn blend_with_identity_vjp(grad_rotations: &mut [Mat3], weights: &[f64]) {
    assert_eq!(
        grad_rotations.len(),
        weights.len(),
        "one weight per rotation"
    );
    for (g, &w) in grad_rotations.iter_mut().zip(weights) {
        if w == 1.0 {
            continue;
        }
        for row in g.iter_mut() {
            for x in row.iter_mut() {
                *x *= w;
            }
        }
    }
}

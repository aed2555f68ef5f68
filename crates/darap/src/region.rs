//! Feathered regions: a per-vertex weight that fades the stylization strength λ to zero.
//!
//! A localized stylization (method spec: "R = I outside the region") is a weight `w_v ∈ [0, 1]`
//! per vertex:
//!
//! - `w_v = 0`: the hard mask, `R_v = I` (the vertex keeps its rest one-ring shape and its target
//!   receives exactly zero gradient);
//! - `w_v > 0`: the local step runs with the normal term weighted by `λ·w_v·a_v` instead of
//!   `λ·a_v`, i.e. `S_v = K_v + λ w_v a_v n0_v t̂_vᵀ` (spec §3.2), and `R_v` is the rotation rule
//!   of that covariance.
//!
//! So the feather fades the **strength** λ over the band, and every `R_v` stays a rotation (a
//! linear blend `w·R + (1 − w)·I` would not be one: it shrinks edges by `cos(θ/2)` at `w = ½`). As
//! `w_v → 0`, `R_v → rule(K_v)`, which is the identity wherever `K_v` is negative definite (every
//! vertex of a well-shaped mesh under the `gis` rule: `K_v = −U Σ Uᵀ` gives `R = −U·(−U)ᵀ = I`); at
//! vertices with strongly obtuse one-rings the limit can differ slightly from `I`, so the step to
//! the hard mask at the region's edge is small, not zero.
//!
//! Adjoint: the same local-step VJP with `a_v` replaced by `w_v·a_v`
//! (`∂ℓ/∂t̂_v = λ w_v a_v (∂ℓ/∂S_v)ᵀ n0_v`). `mesh_core::region::feather_weights` builds the
//! weights (a ramp over `K` rings inside the region's boundary).

/// Per-vertex normal weights `w_v·a_v` for the local step (the masses the layer passes to
/// [`crate::stages::local_step`] and [`crate::stages::local_step_vjp`] for a feathered region).
///
/// # Panics
/// If the slices differ in length (a programming error).
pub fn feathered_mass(mass: &[f64], weights: &[f64]) -> Vec<f64> {
    assert_eq!(mass.len(), weights.len(), "one weight per vertex");
    mass.iter().zip(weights).map(|(a, w)| a * w).collect()
}

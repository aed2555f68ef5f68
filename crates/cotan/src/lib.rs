//! Cotangent Laplacian in the reference convention, mixed-Voronoi mass and a pinned sparse
//! Cholesky factorization — the linear-algebra layer under `darap`.
//!
//! # Conventions
//! - Positions are `f64` triples, faces are CCW `u32` index triples (see `mesh_core`).
//! - **Cotangent weights are not halved**: for an interior edge `(i, j)` with opposite angles
//!   `α`, `β`, `c_ij = cot α + cot β` (twice libigl's `cotmatrix` weights). A boundary edge has
//!   one term. Negative (obtuse) weights are kept.
//! - **Laplacian sign**: `L = diag(Σ_j c_ij) − C`, symmetric positive semi-definite (the stiffness
//!   matrix of linear finite elements, times two). Off-diagonals are `−c_ij`; constants per
//!   connected component span its null space.
//! - Triangle areas in the cotangents use Heron's formula with the reference's clamp
//!   `sqrt(max(s(s−A)(s−B)(s−C), 1e-12))` (so no area is below `1e-6`).
//!
//! Everything is available as free functions over slices ([`corner_cotangents`], [`cot_weights`],
//! [`laplacian`], [`voronoi_mass`], [`component_pins`]) plus the [`SymmetricCsr`] matrix and the
//! [`PinnedCholesky`] factorization (symbolic and numeric analysis once, many solves).

#![cfg_attr(test, allow(clippy::unwrap_used))]

mod factor;
mod laplacian;
mod mass;
mod ordering;
mod pinned;
mod weights;

pub use laplacian::{SymmetricCsr, laplacian, laplacian_from_weights};
pub use mass::voronoi_mass;
pub use pinned::{PinnedCholesky, component_pins};
pub use weights::{CotWeights, corner_cotangents, cot_weights, heron_area_clamped};

/// Errors of the `cotan` crate.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum CotanError {
    /// A face refers to a vertex that does not exist.
    #[error("face {face} refers to vertex {vertex}, but the mesh has only {num_vertices} vertices")]
    FaceIndexOutOfRange {
        /// Face index.
        face: usize,
        /// The offending vertex index.
        vertex: u32,
        /// Number of vertices.
        num_vertices: usize,
    },
    /// A position or a matrix entry is NaN or infinite.
    #[error("non-finite value at {what} {index}")]
    NonFinite {
        /// What holds the value (`"vertex"`, `"matrix entry"`).
        what: &'static str,
        /// Its index.
        index: usize,
    },
    /// A face is so large that its clamped Heron area overflows f64 (edge lengths of about 1e77
    /// and above); every other quantity of the mesh would be meaningless.
    #[error(
        "face {face} is too large for f64: its area formula overflows (edge lengths of about 1e77 \
         and above); scale the mesh down, e.g. to the side-2 cube (mesh_core::normalize::side2_cube)"
    )]
    Overflow {
        /// The face.
        face: usize,
    },
    /// The matrix handed to [`PinnedCholesky::new`] is not square or not symmetric in pattern.
    #[error("invalid matrix: {0}")]
    InvalidMatrix(String),
    /// A pin index is out of range or repeated.
    #[error("invalid pin {pin}: {why}")]
    InvalidPin {
        /// The pin.
        pin: usize,
        /// Why it is invalid.
        why: &'static str,
    },
    /// A free vertex has no off-diagonal entries and a zero diagonal: it is referenced by no face.
    #[error(
        "vertex {vertex} is referenced by no face (its Laplacian row is empty); remove unreferenced \
         vertices or pin them"
    )]
    UnreferencedVertex {
        /// The vertex.
        vertex: usize,
    },
    /// A connected component of the matrix graph contains no pinned vertex, so the reduced
    /// Laplacian is singular.
    #[error(
        "the connected component containing vertex {vertex} has no pinned vertex, so the Laplacian \
         stays singular; pin one vertex per component (see `component_pins`)"
    )]
    ComponentWithoutPin {
        /// The lowest vertex of that component.
        vertex: usize,
    },
    /// The numeric Cholesky factorization met a non-positive pivot.
    #[error(
        "the pinned Laplacian is not numerically positive definite (Cholesky pivot {pivot} of {size}); \
         likely causes: degenerate (zero-area or sliver) faces, a component without a pin, or a \
         component far smaller than the mesh (debris whose faces fall under the cotangent weights' \
         area floor; `stylize mesh check` lists the parts: remove the small ones)"
    )]
    NotPositiveDefinite {
        /// Index of the failing pivot, in the fill-reducing order.
        pivot: usize,
        /// Size of the reduced matrix.
        size: usize,
    },
    /// faer ran out of memory or failed for a non-numerical reason.
    #[error("sparse factorization failed: {0}")]
    Factorization(String),
}

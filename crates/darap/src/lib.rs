//! Differentiable ARAP (dARAP): per-vertex target normals to a deformed mesh, with hand-written
//! adjoints (method spec §1–§4; conventions in `docs/darap.md`).
//!
//! # Pipeline and conventions
//! `x` (raw targets, V×3) → `t̂ = x / max(|x|, 1e-12)` → local step (one rotation `R_v` per vertex
//! from `S_v = K_v + λ a_v n0_v t̂_vᵀ`, see [`RotationRule`]) → right-hand side `b` (spec §4.1) →
//! pinned solve `L x = b` (vertex 0, or the lowest vertex of each component, kept at rest) →
//! post-processing ([`PostProcess`]). The root holds the layer ([`Darap`], its options, the
//! [`Deformation`] tape); each stage and its VJP is public under [`stages`].
//!
//! - Laplacian: `L = diag(Σ_j c_ij) − C`, positive semi-definite, `c_ij = cot α + cot β` (**twice**
//!   libigl's weights); λ is defined with respect to these weights.
//! - Matrices act on column vectors: a deformed edge is `R·e`. [`Mat3`] is row-major.
//! - Positions are used as given: callers normalize to the side-2 cube first (spec §1.1,
//!   `mesh_core::normalize::side2_cube`). The reference's area and normal clamps (`1e-6`) are
//!   absolute, so a mesh with much smaller faces deforms differently (docs/darap.md).
//!
//! ```no_run
//! # fn main() -> Result<(), darap::DarapError> {
//! # let (positions, faces): (Vec<[f64; 3]>, Vec<[u32; 3]>) = (vec![], vec![]);
//! let layer = darap::Darap::new(&positions, &faces, darap::DarapOptions::default())?;
//! let x = layer.rest_normals().to_vec(); // the optimization starts from the rest normals
//! let state = layer.forward(&x)?;
//! let grad_x = layer.backward(&state, &state.positions); // ∂(½|p|²)/∂x
//! # let _ = grad_x; Ok(()) }
//! ```

#![cfg_attr(test, allow(clippy::unwrap_used))]

mod batch;
mod global;
mod lanes;
mod local;
mod mat3;
mod post;
pub mod region;
mod rotation_rule;
mod svd3;

pub use cotan::CotanError;
pub use mat3::Mat3;

use global::{PaddedColumns, RhsPrecompute, RhsTransposed, from_padded_columns, padded_columns};
use local::{LocalTape, normalize_target, normalize_target_vjp, rest_covariances};
use post::{PostTape, post_process, post_process_vjp};

pub mod stages {
    //! The stages of the layer and their vector–Jacobian products, each callable alone (the gradient
    //! checks of `cargo xtask gradcheck` test them one by one; [`crate::Darap`] composes them):
    //!
    //! | stage | forward | VJP |
    //! |---|---|---|
    //! | target normalization `t̂ = x / max(‖x‖, 1e-12)` | [`normalize_targets`] | [`normalize_targets_vjp`] |
    //! | rest covariances `K_v` | [`rest_covariances`] | (constant) |
    //! | covariance `S_v = ±K_v + λ a_v n0_v t̂_vᵀ` | [`covariance`] | (inside [`local_step_vjp`]) |
    //! | rotation rule `S → R` | [`gis`], [`procrustes`] (via [`svd3`]) | [`rotation_vjp`] |
    //! | local step (all vertices, tape [`LocalTape`]) | [`local_step`] | [`local_step_vjp`] |
    //! | right-hand side `b` (spec §4.1) | [`rhs`] ([`RhsPrecompute`]) | [`rhs_vjp`] |
    //! | post-processing (tape [`PostTape`]) | [`post_process`] | [`post_process_vjp`] |
    //!
    //! The pinned solve between `rhs` and `post_process` is `cotan::PinnedCholesky` (self-adjoint).

    pub use crate::global::{RhsPrecompute, rhs, rhs_vjp};
    pub use crate::local::{
        LocalTape, covariance, local_step, local_step_vjp, normalize_targets,
        normalize_targets_vjp, rest_covariances,
    };
    pub use crate::post::{PostTape, post_process, post_process_vjp};
    pub use crate::rotation_rule::{
        RotationSvd, SINGULAR_GAP_GUARD, gis, procrustes, rotation_vjp,
    };
    pub use crate::svd3::{Svd3, svd3};
}

use cotan::PinnedCholesky;

/// Which rotation the local step computes from the covariance. Named `gis` / `procrustes` in
/// config files, saved deformations and on the command line ([`std::str::FromStr`],
/// [`std::fmt::Display`], and serde under feature `serde`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
#[cfg_attr(
    feature = "serde",
    derive(serde::Serialize, serde::Deserialize),
    serde(rename_all = "snake_case")
)]
pub enum RotationRule {
    /// The reference rule (spec §3.3, the default): full weights `w = −c` (negative for
    /// well-shaped meshes), `S = K + λ a n0 t̂ᵀ`, `R = −U·diag(1, 1, −s)·Vᵀ`. The paper's λ values
    /// (8; "try 5 or 10") and every saved normals file mean what they mean under this rule.
    #[default]
    Gis,
    /// The textbook rule (spec §3.4): positive weights, `S = −K + λ a n0 t̂ᵀ`, Kabsch
    /// `R = V·diag(1, 1, s)·Uᵀ`. Needs a larger λ for a similar strength.
    Procrustes,
}

/// Post-processing of the solved positions (spec §4.3). Named `recenter_rescale` /
/// `recenter_only` / `none` ([`std::str::FromStr`], [`std::fmt::Display`], serde under feature
/// `serde`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
#[cfg_attr(
    feature = "serde",
    derive(serde::Serialize, serde::Deserialize),
    serde(rename_all = "snake_case")
)]
pub enum PostProcess {
    /// Subtract the centroid, then rescale so the bounding-box diagonal equals the rest mesh's.
    #[default]
    RecenterRescale,
    /// Subtract the centroid only.
    RecenterOnly,
    /// Return the solved positions as they are (vertex 0 — each pin — stays at rest).
    None,
}

/// Options of a [`Darap`] layer. Under feature `serde` this is also the `[darap]` section of a
/// config file (keys `lambda`, `rotation_rule`, `post_process`; missing keys take the defaults,
/// unknown keys are refused).
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(
    feature = "serde",
    derive(serde::Serialize, serde::Deserialize),
    serde(default, deny_unknown_fields)
)]
pub struct DarapOptions {
    /// Strength λ of the normal term (default 8, in the reference weight convention).
    pub lambda: f64,
    /// Rotation rule (default [`RotationRule::Gis`]).
    pub rotation_rule: RotationRule,
    /// Post-processing (default [`PostProcess::RecenterRescale`]).
    pub post_process: PostProcess,
}

impl Default for DarapOptions {
    fn default() -> Self {
        Self {
            lambda: 8.0,
            rotation_rule: RotationRule::Gis,
            post_process: PostProcess::RecenterRescale,
        }
    }
}

/// An option name that is not one of the known ones (parsing [`RotationRule`] or [`PostProcess`]).
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("unknown {what} `{got}` (expected {expected})")]
pub struct UnknownName {
    /// What was being parsed.
    pub what: &'static str,
    /// The name given.
    pub got: String,
    /// The names accepted.
    pub expected: &'static str,
}

impl RotationRule {
    /// Every rule.
    pub const ALL: [RotationRule; 2] = [RotationRule::Gis, RotationRule::Procrustes];

    /// The rule's name: `gis` or `procrustes`.
    pub fn name(self) -> &'static str {
        match self {
            RotationRule::Gis => "gis",
            RotationRule::Procrustes => "procrustes",
        }
    }
}

impl std::fmt::Display for RotationRule {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

impl std::str::FromStr for RotationRule {
    type Err = UnknownName;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        Self::ALL
            .into_iter()
            .find(|r| r.name() == s)
            .ok_or_else(|| UnknownName {
                what: "rotation rule",
                got: s.to_string(),
                expected: "gis or procrustes",
            })
    }
}

impl PostProcess {
    /// Every post-process.
    pub const ALL: [PostProcess; 3] = [
        PostProcess::RecenterRescale,
        PostProcess::RecenterOnly,
        PostProcess::None,
    ];

    /// The post-process's name: `recenter_rescale`, `recenter_only` or `none`.
    pub fn name(self) -> &'static str {
        match self {
            PostProcess::RecenterRescale => "recenter_rescale",
            PostProcess::RecenterOnly => "recenter_only",
            PostProcess::None => "none",
        }
    }
}

impl std::fmt::Display for PostProcess {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

impl std::str::FromStr for PostProcess {
    type Err = UnknownName;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        Self::ALL
            .into_iter()
            .find(|p| p.name() == s)
            .ok_or_else(|| UnknownName {
                what: "post-process",
                got: s.to_string(),
                expected: "recenter_rescale, recenter_only or none",
            })
    }
}

/// Errors of the dARAP layer.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum DarapError {
    /// The Laplacian could not be built or factored.
    #[error(transparent)]
    Cotan(#[from] CotanError),
    /// The mesh has no faces.
    #[error("the mesh has no faces")]
    NoFaces,
    /// An input has the wrong length.
    #[error("{what} has {got} entries, expected {expected} (one per vertex)")]
    LengthMismatch {
        /// Which input.
        what: &'static str,
        /// Expected length.
        expected: usize,
        /// Actual length.
        got: usize,
    },
    /// An input lies outside its allowed range.
    #[error("{what}: entry {index} is out of range")]
    OutOfRange {
        /// Which input.
        what: &'static str,
        /// Where.
        index: usize,
    },
    /// An input is NaN or infinite.
    #[error("{what} {index} is not finite")]
    NonFinite {
        /// Which input.
        what: &'static str,
        /// Where.
        index: usize,
    },
    /// [`Darap::backward`] was given the result of [`Darap::forward_at_strength`] at a strength
    /// other than 1: a re-application control, which keeps no tape.
    #[error(
        "the deformation was re-applied at strength {strength} (forward_at_strength): it has no \
         tape to differentiate; differentiate a plain forward pass"
    )]
    NotDifferentiable {
        /// The strength of the re-application.
        strength: f64,
    },
}

/// A dARAP layer for one rest mesh: everything λ-independent is precomputed once (cotangent
/// weights, rest covariances `K_v`, masses, rest normals, right-hand-side vectors, and the pinned
/// Cholesky factorization).
///
/// **Internal vertex order.** The local step, the right-hand side and the solve run in the
/// solver's fill-reducing order (free vertices as [`PinnedCholesky::solver_order`] lists them,
/// then the pins), fixed at construction: per-vertex data are permuted once, the targets are
/// gathered and the results scattered once per call, and everything in between walks memory in
/// order. Inputs and outputs of the public API are in the mesh's vertex order.
#[derive(Debug)]
pub struct Darap {
    rest_positions: Vec<[f64; 3]>,
    rest_normals: Vec<[f64; 3]>,
    mass: Vec<f64>,
    /// Internal position → vertex (free vertices in solver order, then the pins).
    order: Vec<usize>,
    /// Vertex → internal position (the inverse of `order`), so that results are gathered into
    /// vertex order in one pass instead of zero-filled and scattered.
    position_of: Vec<usize>,
    /// `covariance_rest`, `mass`, `rest_normals` and the mask in internal order.
    covariance_int: Vec<Mat3>,
    mass_int: Vec<f64>,
    normals_int: Vec<[f64; 3]>,
    free_int: Option<Vec<bool>>,
    /// Feather weights in internal order (`None` when every weight is 0 or 1).
    weights_int: Option<Vec<f64>>,
    /// `w_v·a_v` in internal order, the local step's masses when feathered.
    feathered_mass_int: Option<Vec<f64>>,
    /// Rows: free vertices in solver order; columns: internal order.
    rhs: RhsPrecompute,
    /// `−L[free, pins]·x_pins` in solver order (the pins stay at rest), rows padded to four lanes.
    pinned_rhs: Vec<[f64; 4]>,
    solver: PinnedCholesky,
    pinned_values: Vec<[f64; 3]>,
    rest_diag: f64,
    options: DarapOptions,
    free: Option<Vec<bool>>,
}

/// The result of [`Darap::forward`]: deformed positions plus the tape for [`Darap::backward`].
#[derive(Clone, Debug)]
pub struct Deformation {
    /// Deformed positions (after post-processing).
    pub positions: Vec<[f64; 3]>,
    /// Per-vertex rotations of the local step (applied as `R·x`).
    pub rotations: Vec<Mat3>,
    /// The raw targets `x` the forward pass saw.
    targets: Vec<[f64; 3]>,
    local: LocalTape,
    post: PostTape,
    lambda: f64,
    /// The local step's masses (internal order) when the forward pass was feathered.
    feathered_mass_int: Option<Vec<f64>>,
    /// `Some(s)` for a [`Darap::forward_at_strength`] result at `s ≠ 1` (no tape).
    strength: Option<f64>,
}

impl Deformation {
    /// The strength `s ≠ 1` of a [`Darap::forward_at_strength`] result; `None` for a forward pass
    /// (which [`Darap::backward`] can differentiate).
    pub fn strength(&self) -> Option<f64> {
        self.strength
    }
}

impl Darap {
    /// Precomputes the layer for a rest mesh (positions used as given).
    ///
    /// One vertex per connected component is pinned at rest (the lowest index; vertex 0 for a
    /// connected mesh). Vertices referenced by no face are their own components: they stay at rest.
    pub fn new(
        rest_positions: &[[f64; 3]],
        faces: &[[u32; 3]],
        options: DarapOptions,
    ) -> Result<Darap, DarapError> {
        if faces.is_empty() {
            return Err(DarapError::NoFaces);
        }
        let n = rest_positions.len();
        let weights = cotan::cot_weights(rest_positions, faces)?;
        let laplacian = cotan::laplacian_from_weights(n, &weights)?;
        let mass = cotan::voronoi_mass(rest_positions, faces)?;
        let rest_normals = mesh_core::normals::vertex_normals_area_weighted(rest_positions, faces);
        let covariance_rest = rest_covariances(rest_positions, faces, &weights);
        let pins = cotan::component_pins(n, faces);
        let solver = PinnedCholesky::new(&laplacian, &pins)?;
        let pinned_values: Vec<[f64; 3]> =
            solver.pins().iter().map(|&p| rest_positions[p]).collect();
        let order: Vec<usize> = solver
            .solver_order()
            .iter()
            .chain(solver.pins())
            .copied()
            .collect();
        let mut position_of = vec![0usize; n];
        for (k, &v) in order.iter().enumerate() {
            position_of[v] = k;
        }
        let num_free = solver.solver_order().len();
        let row_of: Vec<Option<usize>> = position_of
            .iter()
            .map(|&k| (k < num_free).then_some(k))
            .collect();
        let rhs = RhsPrecompute::with_order(
            rest_positions,
            faces,
            &weights,
            &row_of,
            num_free,
            &position_of,
        );
        let pinned_rhs = solver
            .pinned_rhs_ordered(&pinned_values)
            .iter()
            .map(|r| [r[0], r[1], r[2], 0.0])
            .collect();
        let rest_diag = mesh_core::geometry::bbox_diagonal(rest_positions);
        Ok(Darap {
            covariance_int: order.iter().map(|&v| covariance_rest[v]).collect(),
            mass_int: order.iter().map(|&v| mass[v]).collect(),
            normals_int: order.iter().map(|&v| rest_normals[v]).collect(),
            free_int: None,
            weights_int: None,
            feathered_mass_int: None,
            order,
            position_of,
            rest_positions: rest_positions.to_vec(),
            rest_normals,
            mass,
            rhs,
            pinned_rhs,
            solver,
            pinned_values,
            rest_diag,
            options,
            free: None,
        })
    }

    /// Changes λ; everything else is reused (the normal weight `λ·a_v` is formed per call).
    pub fn set_lambda(&mut self, lambda: f64) {
        self.options.lambda = lambda;
    }

    /// Changes the rotation rule (nothing is recomputed).
    pub fn set_rotation_rule(&mut self, rule: RotationRule) {
        self.options.rotation_rule = rule;
    }

    /// Changes the post-processing.
    pub fn set_post_process(&mut self, mode: PostProcess) {
        self.options.post_process = mode;
    }

    /// Sets a region mask: `free[v] == false` forces `R_v = I` at vertex `v` (it keeps its rest
    /// one-ring shape and receives no gradient). `None` lets every vertex rotate. Clears any
    /// feather weights ([`Darap::set_region_weights`]).
    pub fn set_mask(&mut self, free: Option<Vec<bool>>) -> Result<(), DarapError> {
        if let Some(m) = &free
            && m.len() != self.num_vertices()
        {
            return Err(DarapError::LengthMismatch {
                what: "mask",
                expected: self.num_vertices(),
                got: m.len(),
            });
        }
        self.free_int = free
            .as_ref()
            .map(|m| self.order.iter().map(|&v| m[v]).collect());
        self.free = free;
        self.weights_int = None;
        self.feathered_mass_int = None;
        Ok(())
    }

    /// Sets a feathered region: per vertex a weight `w_v ∈ [0, 1]` that scales the strength of
    /// the normal term, `λ·w_v·a_v` (see [`region`]). `w = 0` is the hard mask of
    /// [`Darap::set_mask`] (`R = I`, exactly zero gradient), `w = 1` a free vertex. `None` lets
    /// every vertex rotate.
    pub fn set_region_weights(&mut self, weights: Option<Vec<f64>>) -> Result<(), DarapError> {
        let Some(w) = weights else {
            return self.set_mask(None);
        };
        if w.len() != self.num_vertices() {
            return Err(DarapError::LengthMismatch {
                what: "region weights",
                expected: self.num_vertices(),
                got: w.len(),
            });
        }
        if let Some(index) = w.iter().position(|x| !(0.0..=1.0).contains(x)) {
            return Err(DarapError::OutOfRange {
                what: "region weight (must lie in [0, 1])",
                index,
            });
        }
        self.set_mask(Some(w.iter().map(|&x| x > 0.0).collect()))?;
        if w.iter().any(|&x| x > 0.0 && x < 1.0) {
            let wi: Vec<f64> = self.order.iter().map(|&v| w[v]).collect();
            self.feathered_mass_int = Some(region::feathered_mass(&self.mass_int, &wi));
            self.weights_int = Some(wi);
        }
        Ok(())
    }

    /// The region's per-vertex weights (vertex order): `None` when every vertex is free, else 1
    /// for free vertices, 0 for masked ones and the feather weight in between.
    pub fn region_weights(&self) -> Option<Vec<f64>> {
        let free = self.free.as_ref()?;
        let mut w: Vec<f64> = free.iter().map(|&f| if f { 1.0 } else { 0.0 }).collect();
        if let Some(wi) = &self.weights_int {
            for (&x, &v) in wi.iter().zip(&self.order) {
                w[v] = x;
            }
        }
        Some(w)
    }

    /// The current options.
    pub fn options(&self) -> DarapOptions {
        self.options
    }

    /// Rest vertex normals `n0` (area weighted, spec §1.2): the initial `x` of an optimization.
    pub fn rest_normals(&self) -> &[[f64; 3]] {
        &self.rest_normals
    }

    /// Rest positions as given to [`Darap::new`].
    pub fn rest_positions(&self) -> &[[f64; 3]] {
        &self.rest_positions
    }

    /// Mixed-Voronoi vertex areas `a_v`.
    pub fn mass(&self) -> &[f64] {
        &self.mass
    }

    /// Number of stored entries of the pinned Laplacian's Cholesky factor (diagonal included):
    /// what one sparse solve walks twice.
    pub fn factor_nnz(&self) -> usize {
        self.solver.factor_nnz()
    }

    /// Pinned vertices (sorted).
    pub fn pins(&self) -> &[usize] {
        self.solver.pins()
    }

    /// Number of vertices.
    pub fn num_vertices(&self) -> usize {
        self.rest_positions.len()
    }

    /// The deformation for raw targets `x` (any length per row; only directions matter).
    pub fn forward(&self, x: &[[f64; 3]]) -> Result<Deformation, DarapError> {
        let n = self.num_vertices();
        if x.len() != n {
            return Err(DarapError::LengthMismatch {
                what: "targets",
                expected: n,
                got: x.len(),
            });
        }
        if let Some(index) = x.iter().position(|v| !v.iter().all(|c| c.is_finite())) {
            return Err(DarapError::NonFinite {
                what: "target",
                index,
            });
        }
        if !self.options.lambda.is_finite() {
            return Err(DarapError::NonFinite {
                what: "lambda",
                index: 0,
            });
        }
        // Targets gathered into the internal order and normalized in one pass.
        let unit: Vec<[f64; 3]> = self.order.iter().map(|&v| normalize_target(x[v])).collect();
        let mass_int = self.feathered_mass_int.as_ref().unwrap_or(&self.mass_int);
        let (columns_int, local) = local::local_step_as::<PaddedColumns>(
            &self.covariance_int,
            mass_int,
            self.options.lambda,
            &self.normals_int,
            &unit,
            self.options.rotation_rule,
            self.free_int.as_deref(),
        );
        let solved = self.solve_internal(&columns_int);
        let (positions, post) = post_process(&solved, self.rest_diag, self.options.post_process);
        let rotations = self
            .position_of
            .iter()
            .map(|&k| from_padded_columns(&columns_int[k]))
            .collect();
        Ok(Deformation {
            positions,
            rotations,
            targets: x.to_vec(),
            local,
            post,
            lambda: self.options.lambda,
            feathered_mass_int: self.feathered_mass_int.clone(),
            strength: None,
        })
    }

    /// Right-hand side and solve for rotations in internal order; positions in vertex order.
    fn solve_internal(&self, columns_int: &[PaddedColumns]) -> Vec<[f64; 3]> {
        // Rows padded to four lanes, the solver's own layout: no copy into or out of it.
        let mut b = self.pinned_rhs.clone();
        global::rhs_add_columns_into(&self.rhs, columns_int, &mut b);
        self.solver.solve_ordered_padded_in_place(&mut b);
        // Internal positions past the free vertices are the pins, in `solver.pins()` order.
        let num_free = b.len();
        self.position_of
            .iter()
            .map(|&k| match b.get(k) {
                Some(x) => [x[0], x[1], x[2]],
                None => self.pinned_values[k - num_free],
            })
            .collect()
    }

    /// The **strength control** of `docs/strength.md`: the result of [`Darap::forward`] pushed
    /// `strength` times as far, in the direction the `procrustes` rule takes as λ grows.
    ///
    /// Per vertex `v`, with the layer's own local step `R_v(λ)` (its rule, its λ, its mask or
    /// region weights) and the `procrustes` rule's rotation `P_v(μ)` at strength μ (same mask
    /// and weights):
    ///
    /// `R_v(s) = P_v(s·λ) · P_v(λ)ᵀ · R_v(λ)`
    ///
    /// (rotations act on column vectors, `R·x`), then the global step and the layer's
    /// post-processing. The increment `P_v(s·λ)·P_v(λ)ᵀ` is the rotation the stable Kabsch rule adds
    /// between λ and s·λ; it is applied on top of the saved result instead of re-running the
    /// reference rule at a larger λ, which flips rotations and collapses the mesh a little past the
    /// optimized λ (measured in `docs/strength.md`).
    ///
    /// - `s = 1` returns `forward(x)` itself (bit for bit);
    /// - on a layer that uses the `procrustes` rule it is `forward(x)` at λ = s·λ;
    /// - `0 < s < 1` moves back towards the `procrustes` result at a smaller λ, **not** towards the
    ///   rest mesh (at s → 0 the rotations tend to `P_v(λ)ᵀ·R_v(λ)`): a weaker re-application is
    ///   [`Darap::forward`] at a smaller λ.
    ///
    /// It is a re-application control, not an optimization one: the returned state keeps no tape,
    /// and [`Darap::try_backward`] refuses it ([`DarapError::NotDifferentiable`]) unless `s = 1`.
    ///
    /// # Errors
    /// As [`Darap::forward`]; [`DarapError::NonFinite`] (`what = "strength"`) for a NaN or
    /// infinite `strength`, [`DarapError::OutOfRange`] for `strength ≤ 0` or `s·λ` past
    /// [`f64::MAX`].
    pub fn forward_at_strength(
        &self,
        x: &[[f64; 3]],
        strength: f64,
    ) -> Result<Deformation, DarapError> {
        if !strength.is_finite() {
            return Err(DarapError::NonFinite {
                what: "strength",
                index: 0,
            });
        }
        let lambda = self.options.lambda;
        if strength <= 0.0 || !(strength * lambda).is_finite() {
            return Err(DarapError::OutOfRange {
                what: "strength",
                index: 0,
            });
        }
        let saved = self.forward(x)?;
        if strength == 1.0 {
            return Ok(saved);
        }
        let unit: Vec<[f64; 3]> = self.order.iter().map(|&v| normalize_target(x[v])).collect();
        let mass_int = self.feathered_mass_int.as_ref().unwrap_or(&self.mass_int);
        let procrustes = |mu: f64| -> Vec<Mat3> {
            let (columns_int, _) = local::local_step_as::<PaddedColumns>(
                &self.covariance_int,
                mass_int,
                mu,
                &self.normals_int,
                &unit,
                RotationRule::Procrustes,
                self.free_int.as_deref(),
            );
            self.position_of
                .iter()
                .map(|&k| from_padded_columns(&columns_int[k]))
                .collect()
        };
        let p_far = procrustes(strength * lambda);
        let rotations: Vec<Mat3> = if self.options.rotation_rule == RotationRule::Procrustes {
            p_far
        } else {
            let p_saved = procrustes(lambda);
            saved
                .rotations
                .iter()
                .zip(p_far.iter().zip(&p_saved))
                .map(|(r, (pf, ps))| mat3::mul(&mat3::mul_nt(pf, ps), r))
                .collect()
        };
        let solved = self.global_step(&rotations);
        let (positions, post) = post_process(&solved, self.rest_diag, self.options.post_process);
        Ok(Deformation {
            positions,
            rotations,
            post,
            strength: Some(strength),
            ..saved
        })
    }

    /// The global step alone: positions (before post-processing) for given rotations.
    /// With all `R = I` this returns the rest positions.
    ///
    /// # Panics
    /// If `rotations.len()` is not the number of vertices (a programming error).
    pub fn global_step(&self, rotations: &[Mat3]) -> Vec<[f64; 3]> {
        assert_eq!(
            rotations.len(),
            self.num_vertices(),
            "one rotation per vertex"
        );
        let columns_int: Vec<PaddedColumns> = self
            .order
            .iter()
            .map(|&v| padded_columns(&rotations[v]))
            .collect();
        self.solve_internal(&columns_int)
    }

    /// `∂ℓ/∂x` for `∂ℓ/∂positions` at the state of a previous [`Darap::forward`].
    ///
    /// # Panics
    /// If `grad_positions.len()` is not the number of vertices (a programming error; see
    /// [`Darap::try_backward`] for a checked version).
    pub fn backward(&self, state: &Deformation, grad_positions: &[[f64; 3]]) -> Vec<[f64; 3]> {
        match self.try_backward(state, grad_positions) {
            Ok(g) => g,
            Err(e) => panic!("Darap::backward: {e}"),
        }
    }

    /// Checked [`Darap::backward`].
    pub fn try_backward(
        &self,
        state: &Deformation,
        grad_positions: &[[f64; 3]],
    ) -> Result<Vec<[f64; 3]>, DarapError> {
        if let Some(strength) = state.strength {
            return Err(DarapError::NotDifferentiable { strength });
        }
        let n = self.num_vertices();
        if grad_positions.len() != n {
            return Err(DarapError::LengthMismatch {
                what: "gradient",
                expected: n,
                got: grad_positions.len(),
            });
        }
        if state.positions.len() != n {
            return Err(DarapError::LengthMismatch {
                what: "deformation state",
                expected: n,
                got: state.positions.len(),
            });
        }
        let grad_solved = post_process_vjp(&state.post, grad_positions);
        // The solve is self-adjoint; the pinned rows of b do not enter it (zero gradient).
        let num_free = self.solver.solver_order().len();
        let mut grad_b: Vec<[f64; 4]> = self.order[..num_free]
            .iter()
            .map(|&v| {
                let g = grad_solved[v];
                [g[0], g[1], g[2], 0.0]
            })
            .collect();
        self.solver.solve_ordered_padded_in_place(&mut grad_b);
        // `∂ℓ/∂R_v` is formed inside the local step's adjoint, vertex by vertex.
        let grad_unit_int = local::local_step_vjp_from(
            &state.local,
            state.feathered_mass_int.as_ref().unwrap_or(&self.mass_int),
            state.lambda,
            &self.normals_int,
            RhsTransposed::new(&self.rhs, &grad_b),
        );
        Ok(state
            .targets
            .iter()
            .zip(&self.position_of)
            .map(|(&x, &k)| normalize_target_vjp(x, grad_unit_int[k]))
            .collect())
    }
}

#[cfg(test)]
mod tests;

#[cfg(test)]
mod option_names {
    use super::{PostProcess, RotationRule};

    #[test]
    fn names_round_trip_and_unknown_names_say_what_is_accepted() {
        for r in RotationRule::ALL {
            assert_eq!(r.to_string().parse::<RotationRule>(), Ok(r));
        }
        for p in PostProcess::ALL {
            assert_eq!(p.to_string().parse::<PostProcess>(), Ok(p));
        }
        assert_eq!(RotationRule::Gis.to_string(), "gis");
        assert_eq!(PostProcess::RecenterRescale.to_string(), "recenter_rescale");
        let e = "kabsch".parse::<RotationRule>().unwrap_err().to_string();
        assert!(
            e.contains("kabsch") && e.contains("gis or procrustes"),
            "{e}"
        );
        assert!("Gis".parse::<RotationRule>().is_err());
    }
}

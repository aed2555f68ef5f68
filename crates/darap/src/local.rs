//! The local step (spec §3): per-vertex covariance from the rest one-ring and the target normal,
//! then a rotation rule.

use crate::RotationRule;
use crate::batch::{SvdLanes, d01, rotation_vjp_lanes, rule_lanes, svd3_lanes};
use crate::global::{PaddedColumns, RhsTransposed, padded_columns};
use crate::lanes::{F, FALSE, M3, Mask, W, dispatch, lane, mask_bit};
use crate::mat3::{IDENTITY, Mat3, ZERO, mul_tvec, outer, sub};
use crate::rotation_rule::RotationSvd;
use crate::svd3::Svd3;
use cotan::CotWeights;
use rayon::prelude::*;
use std::mem::MaybeUninit;

/// Minimum number of vertices per rayon task.
pub(crate) const PAR_MIN_LEN: usize = 1024;

/// Target normalization `t̂ = x / max(|x|, 1e-12)` (spec §3.2, §5).
pub fn normalize_targets(x: &[[f64; 3]]) -> Vec<[f64; 3]> {
    x.iter().map(|&v| normalize_target(v)).collect()
}

/// One target of [`normalize_targets`].
#[inline]
pub(crate) fn normalize_target(v: [f64; 3]) -> [f64; 3] {
    let inv = 1.0 / (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt().max(1e-12);
    [v[0] * inv, v[1] * inv, v[2] * inv]
}

/// Adjoint of [`normalize_targets`]: `∂ℓ/∂x = (g − t̂ (t̂·g)) / |x|` where `|x| > 1e-12`, and
/// `g / 1e-12` where the clamp is active (there the map is linear).
pub fn normalize_targets_vjp(x: &[[f64; 3]], grad_unit: &[[f64; 3]]) -> Vec<[f64; 3]> {
    x.iter()
        .zip(grad_unit)
        .map(|(&v, &g)| normalize_target_vjp(v, g))
        .collect()
}

/// One target of [`normalize_targets_vjp`].
#[inline]
pub(crate) fn normalize_target_vjp(v: [f64; 3], g: [f64; 3]) -> [f64; 3] {
    let n = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
    // One division: `t̂` exactly as [`normalize_target`] forms it, then the products by `1/|x|`.
    let inv = 1.0 / n.max(1e-12);
    if n > 1e-12 {
        let t = [v[0] * inv, v[1] * inv, v[2] * inv];
        let tg = t[0] * g[0] + t[1] * g[1] + t[2] * g[2];
        [
            (g[0] - t[0] * tg) * inv,
            (g[1] - t[1] * tg) * inv,
            (g[2] - t[2] * tg) * inv,
        ]
    } else {
        [g[0] * inv, g[1] * inv, g[2] * inv]
    }
}

/// Rest covariances `K_v = Σ_{(a→b) ∈ N(v)} w_ab e_ab e_abᵀ` (spec §3.1–3.2) with the **full**
/// weight `w_ab = L[a, b] = −c_ab` and `e_ab = p_b − p_a`.
///
/// `N(v)` holds the three CCW half-edges of every face incident to `v` (spokes and rims, as the
/// reference builds it). `weights` are the mesh's [`CotWeights`] (c_ab, not halved).
pub fn rest_covariances(
    positions: &[[f64; 3]],
    faces: &[[u32; 3]],
    weights: &CotWeights,
) -> Vec<Mat3> {
    let mut k = vec![ZERO; positions.len()];
    for f in faces {
        let mut m = ZERO;
        for h in 0..3 {
            let (a, b) = (f[h], f[(h + 1) % 3]);
            if a == b {
                continue;
            }
            let w = -weights.get(a, b).unwrap_or(0.0);
            let e = sub(positions[b as usize], positions[a as usize]);
            let ee = outer(e, e);
            for i in 0..3 {
                for j in 0..3 {
                    m[i][j] += w * ee[i][j];
                }
            }
        }
        for &v in f {
            let kv = &mut k[v as usize];
            for i in 0..3 {
                for j in 0..3 {
                    kv[i][j] += m[i][j];
                }
            }
        }
    }
    k
}

/// The covariance of one vertex for a rule: `S = K + λ a n0 t̂ᵀ` for [`RotationRule::Gis`],
/// `S = −K + λ a n0 t̂ᵀ` (positive weights) for [`RotationRule::Procrustes`].
#[inline]
pub fn covariance(
    rule: RotationRule,
    k: &Mat3,
    normal_weight: f64,
    n0: [f64; 3],
    t: [f64; 3],
) -> Mat3 {
    let sign = match rule {
        RotationRule::Gis => 1.0,
        RotationRule::Procrustes => -1.0,
    };
    let mut s = ZERO;
    for i in 0..3 {
        for j in 0..3 {
            s[i][j] = sign * k[i][j] + normal_weight * n0[i] * t[j];
        }
    }
    s
}

/// What [`local_step_vjp`] needs: per vertex the SVD of `S_v`, the rule's sign pattern and
/// whether the vertex was free, stored by batches of 8 vertices (the lane width; structure of
/// arrays).
#[derive(Clone, Debug)]
pub struct LocalTape {
    rule: RotationRule,
    len: usize,
    chunks: Vec<TapeChunk>,
}

#[derive(Clone, Copy, Debug)]
struct TapeChunk {
    svd: SvdLanes,
    d2: F,
    free: Mask,
}

impl LocalTape {
    /// Number of vertices.
    pub fn len(&self) -> usize {
        self.len
    }

    /// Whether the tape holds no vertex.
    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    /// The rule the local step applied.
    pub fn rule(&self) -> RotationRule {
        self.rule
    }

    /// Vertex `v`'s record (as the scalar [`crate::stages::gis`] /
    /// [`crate::stages::procrustes`] return it); `None` where the mask forced `R = I` or
    /// `v` is out of range.
    pub fn get(&self, v: usize) -> Option<RotationSvd> {
        if v >= self.len {
            return None;
        }
        let (c, l) = (v / W, v % W);
        let chunk = &self.chunks[c];
        if !lane(chunk.free, l) {
            return None;
        }
        let lane =
            |m: &M3| -> Mat3 { std::array::from_fn(|i| std::array::from_fn(|j| m[i][j][l])) };
        let d01 = d01(self.rule);
        Some(RotationSvd {
            svd: Svd3 {
                u: lane(&chunk.svd.u),
                sigma: std::array::from_fn(|k| chunk.svd.sigma[k][l]),
                v: lane(&chunk.svd.v),
            },
            d: [d01, d01, chunk.d2[l]],
            transposed: self.rule == RotationRule::Procrustes,
        })
    }
}

/// The local step: `R_v = rule(S_v)` with `S_v` from [`covariance`] and normal weight
/// `λ·mass[v]`; vertices with `free[v] == false` get `R_v = I`.
///
/// `targets_unit` are unit target normals (see [`normalize_targets`]). Runs 8 vertices (the lane
/// width) per SIMD batch; each vertex's result is bit for bit that of the scalar rule
/// ([`crate::stages::gis`], [`crate::stages::procrustes`]). Deterministic for any
/// number of rayon threads (each vertex is independent).
///
/// # Panics
/// If the slices differ in length (a programming error).
pub fn local_step(
    covariance_rest: &[Mat3],
    mass: &[f64],
    lambda: f64,
    rest_normals: &[[f64; 3]],
    targets_unit: &[[f64; 3]],
    rule: RotationRule,
    free: Option<&[bool]>,
) -> (Vec<Mat3>, LocalTape) {
    local_step_as::<Mat3>(
        covariance_rest,
        mass,
        lambda,
        rest_normals,
        targets_unit,
        rule,
        free,
    )
}

/// How [`local_step_as`] stores a rotation: as a matrix ([`Mat3`]) or as the right-hand side's
/// [`PaddedColumns`], which the layer's forward pass uses to skip a conversion pass.
pub(crate) trait RotationLayout: Copy + Send + Sync {
    /// `R = I`.
    const IDENTITY: Self;
    /// Lane `l` of `r`.
    fn from_lane(r: &M3, l: usize) -> Self;
}

impl RotationLayout for Mat3 {
    const IDENTITY: Self = IDENTITY;
    #[inline(always)]
    fn from_lane(r: &M3, l: usize) -> Self {
        std::array::from_fn(|i| std::array::from_fn(|j| r[i][j][l]))
    }
}

impl RotationLayout for PaddedColumns {
    const IDENTITY: Self = [
        [1.0, 0.0, 0.0, 0.0],
        [0.0, 1.0, 0.0, 0.0],
        [0.0, 0.0, 1.0, 0.0],
    ];
    #[inline(always)]
    fn from_lane(r: &M3, l: usize) -> Self {
        padded_columns(&Mat3::from_lane(r, l))
    }
}

/// [`local_step`] with the rotations stored as `R`.
pub(crate) fn local_step_as<R: RotationLayout>(
    covariance_rest: &[Mat3],
    mass: &[f64],
    lambda: f64,
    rest_normals: &[[f64; 3]],
    targets_unit: &[[f64; 3]],
    rule: RotationRule,
    free: Option<&[bool]>,
) -> (Vec<R>, LocalTape) {
    let n = covariance_rest.len();
    assert!(
        mass.len() == n
            && rest_normals.len() == n
            && targets_unit.len() == n
            && free.is_none_or(|m| m.len() == n),
        "local_step: inputs differ in length"
    );
    // Every rotation and tape chunk is written exactly once, in place, by the batch kernels
    // (no zero fill before, no copy of each 1.5 kB chunk out of the kernel's return value).
    let num_chunks = n.div_ceil(W);
    let mut rotations: Vec<R> = Vec::with_capacity(n);
    let mut chunks: Vec<TapeChunk> = Vec::with_capacity(num_chunks);
    rotations.spare_capacity_mut()[..n]
        .par_chunks_mut(W)
        .zip(chunks.spare_capacity_mut()[..num_chunks].par_iter_mut())
        .enumerate()
        .with_min_len(PAR_MIN_LEN / W)
        .for_each(|(c, (out, tape))| {
            dispatch(LocalChunk {
                base: c * W,
                covariance_rest,
                mass,
                lambda,
                rest_normals,
                targets_unit,
                rule,
                free,
                out,
                tape,
            })
        });
    // SAFETY: the loop above ran `local_chunk` on every batch, which writes each element of its
    // `out` slice and its `tape` slot; together the batches cover the first `n` rotations and the
    // first `num_chunks` chunks exactly. (Were a batch to panic, the lengths would stay 0; both
    // element types are `Copy`, so nothing would be dropped.)
    #[allow(unsafe_code)]
    unsafe {
        rotations.set_len(n);
        chunks.set_len(num_chunks);
    }
    (
        rotations,
        LocalTape {
            rule,
            len: n,
            chunks,
        },
    )
}

/// One batch of [`local_step`] as a `pulp` kernel: [`dispatch`] runs `with_simd` inside a
/// function compiled for the CPU's instruction set, and everything below it is `inline(always)`,
/// so the lane loops are vectorized with that instruction set (a closure would be compiled
/// separately, for the baseline SSE2).
struct LocalChunk<'a, R> {
    base: usize,
    covariance_rest: &'a [Mat3],
    mass: &'a [f64],
    lambda: f64,
    rest_normals: &'a [[f64; 3]],
    targets_unit: &'a [[f64; 3]],
    rule: RotationRule,
    free: Option<&'a [bool]>,
    out: &'a mut [MaybeUninit<R>],
    tape: &'a mut MaybeUninit<TapeChunk>,
}

impl<R: RotationLayout> pulp::WithSimd for LocalChunk<'_, R> {
    type Output = ();
    #[inline(always)]
    fn with_simd<S: pulp::Simd>(self, _simd: S) {
        local_chunk(
            self.base,
            self.covariance_rest,
            self.mass,
            self.lambda,
            self.rest_normals,
            self.targets_unit,
            self.rule,
            self.free,
            self.out,
            self.tape,
        )
    }
}

/// One batch of [`local_step_vjp`] as a `pulp` kernel (see [`LocalChunk`]).
struct LocalVjpChunk<'a, G> {
    base: usize,
    chunk: &'a TapeChunk,
    rule: RotationRule,
    mass: &'a [f64],
    lambda: f64,
    rest_normals: &'a [[f64; 3]],
    grad_rotations: G,
    out: &'a mut [[f64; 3]],
}

/// Where [`local_step_vjp_from`] reads `∂ℓ/∂R_v`: a slice, or the right-hand side's adjoint
/// ([`RhsTransposed`]) formed vertex by vertex inside the kernel (no `∂ℓ/∂R` array).
pub(crate) trait RotationGradients: Copy + Send + Sync {
    /// `∂ℓ/∂R_v`.
    fn get<S: pulp::Simd>(self, simd: S, v: usize) -> Mat3;
}

impl RotationGradients for &[Mat3] {
    #[inline(always)]
    fn get<S: pulp::Simd>(self, _simd: S, v: usize) -> Mat3 {
        self[v]
    }
}

impl RotationGradients for RhsTransposed<'_> {
    #[inline(always)]
    fn get<S: pulp::Simd>(self, simd: S, v: usize) -> Mat3 {
        self.column(simd, v)
    }
}

impl<G: RotationGradients> pulp::WithSimd for LocalVjpChunk<'_, G> {
    type Output = ();
    #[inline(always)]
    fn with_simd<S: pulp::Simd>(self, simd: S) {
        local_vjp_chunk(
            simd,
            self.base,
            self.chunk,
            self.rule,
            self.mass,
            self.lambda,
            self.rest_normals,
            self.grad_rotations,
            self.out,
        )
    }
}

#[inline(always)]
fn local_chunk<R: RotationLayout>(
    base: usize,
    covariance_rest: &[Mat3],
    mass: &[f64],
    lambda: f64,
    rest_normals: &[[f64; 3]],
    targets_unit: &[[f64; 3]],
    rule: RotationRule,
    free: Option<&[bool]>,
    out: &mut [MaybeUninit<R>],
    tape: &mut MaybeUninit<TapeChunk>,
) {
    let mut s: M3 = [[[0.0; W]; 3]; 3];
    let mut is_free: Mask = FALSE;
    for l in 0..out.len() {
        let v = base + l;
        let sv = covariance(
            rule,
            &covariance_rest[v],
            lambda * mass[v],
            rest_normals[v],
            targets_unit[v],
        );
        for i in 0..3 {
            for j in 0..3 {
                s[i][j][l] = sv[i][j];
            }
        }
        is_free[l] = mask_bit(free.is_none_or(|m| m[v]));
    }
    let svd = svd3_lanes(&s);
    let (r, d2) = rule_lanes(&svd, rule);
    for (l, o) in out.iter_mut().enumerate() {
        o.write(if lane(is_free, l) {
            R::from_lane(&r, l)
        } else {
            R::IDENTITY
        });
    }
    tape.write(TapeChunk {
        svd,
        d2,
        free: is_free,
    });
}

/// Adjoint of [`local_step`] with respect to the unit targets:
/// `∂ℓ/∂t̂_v = λ a_v · (∂ℓ/∂S_v)ᵀ n0_v`, zero at masked vertices. Each vertex's `∂ℓ/∂S_v` is bit
/// for bit [`crate::stages::rotation_vjp`].
///
/// # Panics
/// If the slices differ in length from the tape (a programming error).
pub fn local_step_vjp(
    tape: &LocalTape,
    mass: &[f64],
    lambda: f64,
    rest_normals: &[[f64; 3]],
    grad_rotations: &[Mat3],
) -> Vec<[f64; 3]> {
    assert_eq!(
        grad_rotations.len(),
        tape.len,
        "local_step_vjp: inputs differ in length from the tape"
    );
    local_step_vjp_from(tape, mass, lambda, rest_normals, grad_rotations)
}

/// [`local_step_vjp`] with `∂ℓ/∂R` read from `grad_rotations` (which must cover the tape's
/// vertices).
pub(crate) fn local_step_vjp_from<G: RotationGradients>(
    tape: &LocalTape,
    mass: &[f64],
    lambda: f64,
    rest_normals: &[[f64; 3]],
    grad_rotations: G,
) -> Vec<[f64; 3]> {
    let n = tape.len;
    assert!(
        mass.len() == n && rest_normals.len() == n,
        "local_step_vjp: inputs differ in length from the tape"
    );
    let mut out = vec![[0.0; 3]; n];
    out.par_chunks_mut(W)
        .zip(tape.chunks.par_iter())
        .enumerate()
        .with_min_len(PAR_MIN_LEN / W)
        .for_each(|(c, (out, chunk))| {
            dispatch(LocalVjpChunk {
                base: c * W,
                chunk,
                rule: tape.rule,
                mass,
                lambda,
                rest_normals,
                grad_rotations,
                out,
            })
        });
    out
}

#[inline(always)]
fn local_vjp_chunk<S: pulp::Simd, G: RotationGradients>(
    simd: S,
    base: usize,
    chunk: &TapeChunk,
    rule: RotationRule,
    mass: &[f64],
    lambda: f64,
    rest_normals: &[[f64; 3]],
    grad_rotations: G,
    out: &mut [[f64; 3]],
) {
    let mut g: M3 = [[[0.0; W]; 3]; 3];
    for l in 0..out.len() {
        let gv = grad_rotations.get(simd, base + l);
        for i in 0..3 {
            for j in 0..3 {
                g[i][j][l] = gv[i][j];
            }
        }
    }
    let ds = rotation_vjp_lanes(&chunk.svd, chunk.d2, rule, &g);
    for (l, o) in out.iter_mut().enumerate() {
        let v = base + l;
        *o = if lane(chunk.free, l) {
            let dsv: Mat3 = std::array::from_fn(|i| std::array::from_fn(|j| ds[i][j][l]));
            let g = mul_tvec(&dsv, rest_normals[v]);
            let w = lambda * mass[v];
            [w * g[0], w * g[1], w * g[2]]
        } else {
            [0.0; 3]
        };
    }
}

//! The local step's per-vertex kernels on [`W`](crate::lanes::W) vertices at once: the 3×3 SVD
//! ([`crate::stages::svd3`]), the rotation rules ([`crate::stages`]) and their adjoint
//! ([`crate::stages::rotation_vjp`]).
//!
//! Each lane evaluates **the same sequence of IEEE operations** as the scalar functions, so its
//! results are bit for bit the scalar ones (tested against them on random, rank-deficient and
//! repeated-singular-value matrices). The scalar one-sided Jacobi stops after the first sweep
//! that rotates nothing; here a batch sweeps until every lane has had such a sweep. That changes
//! nothing for a lane that is already done: a sweep without rotation leaves its columns as they
//! are, so the next sweep makes the same (skip) decisions. Lanes are independent; data-dependent
//! branches of the scalar code become selects.

use crate::RotationRule;
use crate::lanes::{
    F, FALSE, M3, Mask, V3, W, abs, add, all, and, any, col, cross, det, div, dot, eq, ge, gt,
    identity, is_finite, is_nan, le, lt, mask_bit, matmul, mul, neg, not, or, select, select3,
    splat, sqrt, sub, transpose,
};

/// `S = U·diag(σ)·Vᵀ` for every lane (see [`crate::stages::Svd3`]).
#[derive(Clone, Copy, Debug)]
pub(crate) struct SvdLanes {
    pub u: M3,
    pub sigma: V3,
    pub v: M3,
}

/// `x / |x|` and whether `|x|` is positive and finite (`mat3`'s `normalize`).
#[inline(always)]
fn normalize(x: V3) -> (V3, Mask) {
    let n = sqrt(dot(x, x));
    let ok = and(gt(n, splat(0.0)), is_finite(n));
    ([div(x[0], n), div(x[1], n), div(x[2], n)], ok)
}

/// `svd3::any_orthogonal`: a unit vector orthogonal to the unit vector `u`.
#[inline(always)]
fn any_orthogonal(u: V3) -> V3 {
    let a = [abs(u[0]), abs(u[1]), abs(u[2])];
    let first = and(le(a[0], a[1]), le(a[0], a[2]));
    let second = and(not(first), le(a[1], a[2]));
    let third = and(not(first), not(second));
    let one = splat(1.0);
    let zero = splat(0.0);
    let axis = [
        select(first, one, zero),
        select(second, one, zero),
        select(third, one, zero),
    ];
    let (y, ok) = normalize(cross(u, axis));
    select3(ok, y, [zero, zero, one])
}

/// `x[0]` where `m[0]`, else `x[1]` where `m[1]`, else `x[2]`, lane by lane. A function, not a
/// closure: closures are compiled for the baseline instruction set and not inlined into the
/// dispatched kernel (see [`crate::lanes::dispatch`]).
#[inline(always)]
fn pick(m: [Mask; 2], x: [F; 3]) -> F {
    select(m[0], x[0], select(m[1], x[1], x[2]))
}

/// The columns of `m` reordered: column `k` of the result is [`pick`]`(slot[k], row)` per row.
#[inline(always)]
fn permute_columns(m: &M3, slot: [[Mask; 2]; 3]) -> M3 {
    let mut out = *m;
    for (o, r) in out.iter_mut().zip(m) {
        *o = [pick(slot[0], *r), pick(slot[1], *r), pick(slot[2], *r)];
    }
    out
}

/// One Jacobi rotation of the sweep in [`svd3_lanes`]: columns `P` and `Q` of `a` made orthogonal,
/// the same rotation applied to `v`; lanes whose pair is already orthogonal are left unchanged and
/// the others are marked in `rotated`.
#[inline(always)]
fn jacobi_pair<const P: usize, const Q: usize>(a: &mut M3, v: &mut M3, rotated: &mut Mask) {
    let ap = col(a, P);
    let aq = col(a, Q);
    let alpha = dot(ap, ap);
    let beta = dot(aq, aq);
    let gamma = dot(ap, aq);
    let skip = or(
        eq(gamma, splat(0.0)),
        le(mul(gamma, gamma), mul(splat(1e-30), mul(alpha, beta))),
    );
    if all(skip) {
        return;
    }
    *rotated = or(*rotated, not(skip));
    // `svd3::rotation_tangent`, its operations in its order.
    let d = sub(beta, alpha);
    let q2 = mul(splat(2.0), gamma);
    let sign = select(lt(d, splat(0.0)), splat(-1.0), splat(1.0));
    let t = div(
        mul(sign, q2),
        add(abs(d), sqrt(add(mul(d, d), mul(q2, q2)))),
    );
    let c = div(splat(1.0), sqrt(add(splat(1.0), mul(t, t))));
    let sn = mul(c, t);
    for m in [a, v] {
        for row in m.iter_mut() {
            let (x, y) = (row[P], row[Q]);
            row[P] = select(skip, x, sub(mul(c, x), mul(sn, y)));
            row[Q] = select(skip, y, add(mul(sn, x), mul(c, y)));
        }
    }
}

/// The one-sided Jacobi SVD of [`crate::stages::svd3`], lane by lane.
#[inline(always)]
pub(crate) fn svd3_lanes(s: &M3) -> SvdLanes {
    let mut magnitude = splat(0.0);
    for row in s {
        for &x in row {
            let ax = abs(x);
            magnitude = select(gt(ax, magnitude), ax, magnitude);
        }
    }
    let scaled = and(gt(magnitude, splat(0.0)), is_finite(magnitude));
    let inv = select(scaled, div(splat(1.0), magnitude), splat(1.0));
    let mut a: M3 = *s;
    for row in a.iter_mut() {
        for x in row.iter_mut() {
            *x = mul(*x, inv);
        }
    }
    let mut v = identity();
    for _sweep in 0..32 {
        // The pairs (0, 1), (0, 2), (1, 2) as separate instances, so that every column index is a
        // constant and the columns can stay in registers.
        let mut rotated: Mask = FALSE;
        jacobi_pair::<0, 1>(&mut a, &mut v, &mut rotated);
        jacobi_pair::<0, 2>(&mut a, &mut v, &mut rotated);
        jacobi_pair::<1, 2>(&mut a, &mut v, &mut rotated);
        if !any(rotated) {
            break;
        }
    }
    let s0 = sqrt(dot(col(&a, 0), col(&a, 0)));
    let s1 = sqrt(dot(col(&a, 1), col(&a, 1)));
    let s2 = sqrt(dot(col(&a, 2), col(&a, 2)));
    // Stable descending sort of three: column i goes before column j when σ_i > σ_j, or when
    // σ_i = σ_j and i < j. `first_k[i]`: column i lands in slot k.
    let b01 = ge(s0, s1);
    let b02 = ge(s0, s2);
    let b12 = ge(s1, s2);
    let to0 = [and(b01, b02), and(not(b01), b12)];
    let to1 = [not(eq_mask(b01, b02)), eq_mask(b01, b12)];
    let to2 = [and(not(b01), not(b02)), and(b01, not(b12))];
    let sigma = [
        pick(to0, [s0, s1, s2]),
        pick(to1, [s0, s1, s2]),
        pick(to2, [s0, s1, s2]),
    ];
    let a = permute_columns(&a, [to0, to1, to2]);
    let v = permute_columns(&v, [to0, to1, to2]);

    let tau = mul(splat(1e-13), sigma[0]);
    let zero = splat(0.0);
    let one = splat(1.0);
    let (u1, ok1) = normalize(col(&a, 0));
    let u1 = select3(ok1, u1, [one, zero, zero]);
    let a2 = col(&a, 1);
    let d = dot(u1, a2);
    let (w, ok2) = normalize([
        sub(a2[0], mul(d, u1[0])),
        sub(a2[1], mul(d, u1[1])),
        sub(a2[2], mul(d, u1[2])),
    ]);
    let use_w = and(gt(sigma[1], tau), ok2);
    // Only rank-deficient lanes need the fallback (a square root and three divisions): skipped
    // when no lane does, which changes no lane's result.
    let u2 = if all(use_w) {
        w
    } else {
        select3(use_w, w, any_orthogonal(u1))
    };
    let u3 = cross(u1, u2);
    let flip = and(gt(sigma[2], tau), lt(dot(u3, col(&a, 2)), zero));
    let u3 = select3(flip, [neg(u3[0]), neg(u3[1]), neg(u3[2])], u3);
    let degenerate = or(le(sigma[0], zero), is_nan(sigma[0]));
    let id = identity();
    let mut u: M3 = id;
    for i in 0..3 {
        u[i] = [
            select(degenerate, id[i][0], u1[i]),
            select(degenerate, id[i][1], u2[i]),
            select(degenerate, id[i][2], u3[i]),
        ];
    }
    let unscaled = eq(inv, one);
    let sigma = [
        select(unscaled, sigma[0], mul(sigma[0], magnitude)),
        select(unscaled, sigma[1], mul(sigma[1], magnitude)),
        select(unscaled, sigma[2], mul(sigma[2], magnitude)),
    ];
    SvdLanes { u, sigma, v }
}

/// Lane-wise `if c { a } else { b }` on masks.
#[inline(always)]
fn select_mask(c: Mask, a: Mask, b: Mask) -> Mask {
    let mut r = a;
    for i in 0..W {
        r[i] = (a[i] & c[i]) | (b[i] & !c[i]);
    }
    r
}

#[inline(always)]
fn eq_mask(a: Mask, b: Mask) -> Mask {
    let mut r = a;
    for i in 0..W {
        r[i] = mask_bit(a[i] == b[i]);
    }
    r
}

/// The sign pattern `d = (d01, d01, d2)` of a rule: `d01` is −1 for gis and +1 for Procrustes;
/// `d2` per lane (see [`rule_lanes`]).
#[inline(always)]
pub(crate) fn d01(rule: RotationRule) -> f64 {
    match rule {
        RotationRule::Gis => -1.0,
        RotationRule::Procrustes => 1.0,
    }
}

/// `R` of a rotation rule ([`crate::stages::gis`], [`crate::stages::procrustes`])
/// from the lanes' SVD, and the per-lane last sign `d2` of the pattern.
#[inline(always)]
pub(crate) fn rule_lanes(svd: &SvdLanes, rule: RotationRule) -> (M3, F) {
    let sign = mul(det(&svd.u), det(&svd.v));
    let positive = gt(sign, splat(0.0));
    // gis: d = (−1, −1, +1) if det U det V > 0 else (−1, −1, −1); Procrustes: (1, 1, ±1).
    let d2 = select(positive, splat(1.0), splat(-1.0));
    let d = [splat(d01(rule)), splat(d01(rule)), d2];
    let mut ud: M3 = svd.u;
    for row in ud.iter_mut() {
        for j in 0..3 {
            row[j] = mul(row[j], d[j]);
        }
    }
    let r = matmul(&ud, &transpose(&svd.v));
    match rule {
        RotationRule::Gis => (r, d2),
        RotationRule::Procrustes => (transpose(&r), d2),
    }
}

/// [`crate::stages::rotation_vjp`] lane by lane: `∂ℓ/∂S` from `G = ∂ℓ/∂R`.
#[inline(always)]
pub(crate) fn rotation_vjp_lanes(svd: &SvdLanes, d2: F, rule: RotationRule, grad_r: &M3) -> M3 {
    let g = match rule {
        RotationRule::Gis => *grad_r,
        RotationRule::Procrustes => transpose(grad_r),
    };
    let sigma = svd.sigma;
    let zero = splat(0.0);
    let guard = mul(splat(crate::rotation_rule::SINGULAR_GAP_GUARD), sigma[0]);
    let degenerate = or(le(sigma[0], zero), is_nan(sigma[0]));
    let h = matmul(&matmul(&transpose(&svd.u), &g), &svd.v);
    let d = [splat(d01(rule)), splat(d01(rule)), d2];
    // d_i = d_j: always for (0, 1); for pairs with 2, where d2 = d01.
    let same2 = eq(d2, splat(d01(rule)));
    let mut q: M3 = [[zero; 3]; 3];
    for i in 0..3 {
        for j in 0..3 {
            if i == j {
                continue;
            }
            let den_same = add(sigma[i], sigma[j]);
            let num_same = mul(d[i], sub(h[i][j], h[j][i]));
            if i != 2 && j != 2 {
                q[i][j] = select(gt(den_same, guard), div(num_same, den_same), zero);
                continue;
            }
            let den_diff = sub(sigma[j], sigma[i]);
            let num_diff = mul(d[j], add(h[i][j], h[j][i]));
            // One division per lane of the selected case's numerator by its denominator (bit for
            // bit the scalar branch's quotient).
            let (num, den) = (
                select(same2, num_same, num_diff),
                select(same2, den_same, den_diff),
            );
            let ok = select_mask(same2, gt(den_same, guard), gt(abs(den_diff), guard));
            q[i][j] = select(ok, div(num, den), zero);
        }
    }
    let ds = matmul(&matmul(&svd.u, &q), &transpose(&svd.v));
    let mut ds = ds;
    for row in ds.iter_mut() {
        for x in row.iter_mut() {
            *x = select(degenerate, zero, *x);
        }
    }
    ds
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::lanes::dispatch;
    use crate::mat3::Mat3;
    use crate::rotation_rule::{RotationSvd, gis, procrustes, rotation_vjp};
    use crate::svd3::svd3;
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    // The kernels as `pulp` ops, so that the test runs the lanes compiled as the layer runs them
    // (with the CPU's instruction set), not a baseline-compiled closure.
    struct SvdOp<'a>(&'a M3);
    impl pulp::WithSimd for SvdOp<'_> {
        type Output = SvdLanes;
        #[inline(always)]
        fn with_simd<S: pulp::Simd>(self, _simd: S) -> SvdLanes {
            svd3_lanes(self.0)
        }
    }
    struct RuleOp<'a>(&'a SvdLanes, RotationRule);
    impl pulp::WithSimd for RuleOp<'_> {
        type Output = (M3, F);
        #[inline(always)]
        fn with_simd<S: pulp::Simd>(self, _simd: S) -> (M3, F) {
            rule_lanes(self.0, self.1)
        }
    }
    struct VjpOp<'a>(&'a SvdLanes, F, RotationRule, &'a M3);
    impl pulp::WithSimd for VjpOp<'_> {
        type Output = M3;
        #[inline(always)]
        fn with_simd<S: pulp::Simd>(self, _simd: S) -> M3 {
            rotation_vjp_lanes(self.0, self.1, self.2, self.3)
        }
    }

    fn to_lanes(ms: &[Mat3]) -> M3 {
        std::array::from_fn(|i| std::array::from_fn(|j| std::array::from_fn(|l| ms[l][i][j])))
    }

    fn lane(m: &M3, l: usize) -> Mat3 {
        std::array::from_fn(|i| std::array::from_fn(|j| m[i][j][l]))
    }

    fn bits(m: &Mat3) -> [[u64; 3]; 3] {
        m.map(|r| r.map(f64::to_bits))
    }

    /// Matrices that exercise every branch of the scalar SVD and rules: random, rank 0/1/2,
    /// repeated singular values (with and without reflections), tiny and huge scales, a
    /// permutation that needs the sort, and exact zeros in the off-diagonal tests.
    pub(crate) fn hard_matrices() -> Vec<Mat3> {
        let c = 0.3f64.cos();
        let s = 0.3f64.sin();
        let mut m: Vec<Mat3> = vec![
            [[0.0; 3]; 3],
            [[1.0, 2.0, 3.0], [2.0, 4.0, 6.0], [-1.0, -2.0, -3.0]],
            [[1.0, 2.0, 3.0], [2.0, 4.0, 6.0], [3.0, 6.0, 9.0]],
            [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 0.0]],
            [[0.0, 0.0, 0.0], [0.0, 0.0, 0.0], [0.0, 0.0, 5.0]],
            [[1e-300, 0.0, 0.0], [0.0, 1e-300, 0.0], [0.0, 0.0, 0.0]],
            [
                [2.0 * c, -2.0 * s, 0.0],
                [2.0 * s, 2.0 * c, 0.0],
                [0.0, 0.0, 2.0],
            ],
            [[3.0, 0.0, 0.0], [0.0, -3.0, 0.0], [0.0, 0.0, 1.0]],
            [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]],
            [[-1.0, 0.0, 0.0], [0.0, -1.0, 0.0], [0.0, 0.0, -1.0]],
            [[2.0, 0.0, 0.0], [0.0, 2.0, 0.0], [0.0, 0.0, -2.0]],
            [[0.0, 0.0, 1.0], [0.0, 3.0, 0.0], [2.0, 0.0, 0.0]],
            [[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]],
            [[1e200, 3e199, 0.0], [0.0, 1e199, 0.0], [0.0, 0.0, 1e-100]],
            [[1.0, 1e-17, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]],
            [[0.0, 0.0, 0.0], [1.0, 1.0, 1.0], [0.0, 0.0, 0.0]],
            [[-0.0, 0.0, -0.0], [0.0, -0.0, 0.0], [-0.0, -0.0, -0.0]],
        ];
        // Rank-one and rank-two products of random vectors, and matrices with two equal singular
        // values from random rotations.
        let mut rng = ChaCha8Rng::seed_from_u64(11);
        let r3 = |rng: &mut ChaCha8Rng| -> [f64; 3] {
            std::array::from_fn(|_| rng.random::<f64>() * 2.0 - 1.0)
        };
        for _ in 0..40 {
            let (a, b, c2, d) = (r3(&mut rng), r3(&mut rng), r3(&mut rng), r3(&mut rng));
            m.push(std::array::from_fn(|i| {
                std::array::from_fn(|j| a[i] * b[j])
            }));
            m.push(std::array::from_fn(|i| {
                std::array::from_fn(|j| a[i] * b[j] + c2[i] * d[j])
            }));
            let q = gis(&std::array::from_fn(|i| {
                std::array::from_fn(|j| a[i] * b[j] + c2[i] * d[j] + (i + j) as f64 * 0.1)
            }))
            .0;
            let p = gis(&std::array::from_fn(|i| {
                std::array::from_fn(|j| b[i] * c2[j] - (i * j) as f64 * 0.3)
            }))
            .0;
            let sv = [2.0, 2.0, 0.5];
            let sv2 = [1.5, 0.25, 0.25];
            // Two columns ~1e-75 and ~1e-160 of the largest: the Jacobi tangent's squares
            // underflow there (see `svd3::rotation_tangent`).
            let sv3 = [1.0, 1e-75, 3e-76];
            let sv4 = [1.0, 2e-160, 1e-160];
            for sv in [sv, sv2, sv3, sv4] {
                m.push(std::array::from_fn(|i| {
                    std::array::from_fn(|j| (0..3).map(|k| q[i][k] * sv[k] * p[j][k]).sum())
                }));
            }
        }
        for _ in 0..400 {
            m.push(std::array::from_fn(|_| r3(&mut rng)));
        }
        m
    }

    fn check_lanes(ms: &[Mat3]) {
        let mut rng = ChaCha8Rng::seed_from_u64(5);
        for chunk in ms.chunks(W) {
            let mut batch = chunk.to_vec();
            batch.resize(W, [[0.0; 3]; 3]);
            let grads: Vec<Mat3> = (0..W)
                .map(|_| std::array::from_fn(|_| std::array::from_fn(|_| rng.random::<f64>())))
                .collect();
            let s = to_lanes(&batch);
            let g = to_lanes(&grads);
            let svd = dispatch(SvdOp(&s));
            for rule in [RotationRule::Gis, RotationRule::Procrustes] {
                let (r, d2) = dispatch(RuleOp(&svd, rule));
                let ds = dispatch(VjpOp(&svd, d2, rule, &g));
                for (l, m) in batch.iter().enumerate() {
                    let reference = svd3(m);
                    assert_eq!(bits(&lane(&svd.u, l)), bits(&reference.u), "U of {m:?}");
                    assert_eq!(bits(&lane(&svd.v, l)), bits(&reference.v), "V of {m:?}");
                    for k in 0..3 {
                        assert_eq!(svd.sigma[k][l].to_bits(), reference.sigma[k].to_bits());
                    }
                    let (r_ref, tape): (Mat3, RotationSvd) = match rule {
                        RotationRule::Gis => gis(m),
                        RotationRule::Procrustes => procrustes(m),
                    };
                    assert_eq!(bits(&lane(&r, l)), bits(&r_ref), "{rule:?} R of {m:?}");
                    assert_eq!(d2[l], tape.d[2]);
                    let ds_ref = rotation_vjp(&tape, &grads[l]);
                    assert_eq!(bits(&lane(&ds, l)), bits(&ds_ref), "{rule:?} vjp of {m:?}");
                }
            }
        }
    }

    #[test]
    fn lanes_reproduce_the_scalar_svd_rules_and_adjoint_bit_for_bit() {
        check_lanes(&hard_matrices());
    }

    #[test]
    fn a_lane_is_independent_of_its_neighbours() {
        // The same matrix next to matrices that need many more sweeps gives the same bits.
        let hard = hard_matrices();
        for m in hard.iter().take(40) {
            let mut batch = vec![*m; W];
            check_lanes(&batch);
            for (k, other) in hard.iter().rev().take(W - 1).enumerate() {
                batch[k + 1] = *other;
            }
            check_lanes(&batch);
        }
    }
}

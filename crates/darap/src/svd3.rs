//! A dedicated, robust 3×3 singular value decomposition in f64.
//!
//! Method: one-sided (Hestenes) Jacobi. The columns of `A = S` are rotated pairwise until they are
//! mutually orthogonal to working precision (`(a_p·a_q)² ≤ 1e-30·|a_p|²|a_q|²`); the same rotations
//! accumulate into `V`. Then `σ_i = |a_i|`, sorted descending, and `U` is built from the columns by
//! Gram–Schmidt and a cross product, so it is orthogonal to rounding even when `S` is rank
//! deficient (a column whose `σ` is below `1e-13·σ_1` is replaced by a unit vector orthogonal to
//! the others; its sign is taken from the data when `σ_3` is above that threshold). Singular values
//! keep high relative accuracy (unlike an eigen-decomposition of `SᵀS`). No allocation, no NaN for
//! any finite input (including `S = 0`), and bit-identical results for identical inputs.

use crate::mat3::{IDENTITY, Mat3, cross, dot};

/// `S = U·diag(σ)·Vᵀ` with `σ_1 ≥ σ_2 ≥ σ_3 ≥ 0` and `U`, `V` orthogonal (determinant ±1).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Svd3 {
    /// Left singular vectors as columns.
    pub u: Mat3,
    /// Singular values, descending.
    pub sigma: [f64; 3],
    /// Right singular vectors as columns.
    pub v: Mat3,
}

fn col(m: &Mat3, j: usize) -> [f64; 3] {
    [m[0][j], m[1][j], m[2][j]]
}

fn set_col(m: &mut Mat3, j: usize, c: [f64; 3]) {
    for i in 0..3 {
        m[i][j] = c[i];
    }
}

fn normalize(x: [f64; 3]) -> Option<[f64; 3]> {
    let n = dot(x, x).sqrt();
    (n > 0.0 && n.is_finite()).then(|| [x[0] / n, x[1] / n, x[2] / n])
}

/// A unit vector orthogonal to the unit vector `u`.
fn any_orthogonal(u: [f64; 3]) -> [f64; 3] {
    let a = u.map(f64::abs);
    let axis = if a[0] <= a[1] && a[0] <= a[2] {
        [1.0, 0.0, 0.0]
    } else if a[1] <= a[2] {
        [0.0, 1.0, 0.0]
    } else {
        [0.0, 0.0, 1.0]
    };
    normalize(cross(u, axis)).unwrap_or([0.0, 0.0, 1.0])
}

/// The tangent `t = tan θ` of the Jacobi rotation that makes columns `p` and `q` orthogonal,
/// given `α = |a_p|²`, `β = |a_q|²`, `γ = a_p·a_q ≠ 0`: the smaller root of `t² + 2ζt − 1 = 0`
/// with `ζ = (β − α)/(2γ)` (Golub & Van Loan, Alg. 8.5.2), written without `ζ`:
/// `t = sgn(d)·q / (|d| + √(d² + q²))` with `d = β − α`, `q = 2γ` (`sgn(0) = +1`, so `α = β`
/// gives `t = sgn γ`). One division and one square root instead of two divisions and a root;
/// `|t| ≤ 1`. The squares cannot overflow: the columns are scaled so that `α, β ≤ 3`. They can
/// underflow only when `|d|` and `|q|` are both below ~1e-154, i.e. for two columns whose norms are
/// ~1e-70 of the largest (the rank-deficient part, below the `1e-13·σ_1` threshold); there `t`
/// loses accuracy but stays finite (`q² ≥ γ² > 0` for a pair that is not skipped) and the
/// rotation stays orthogonal.
#[inline]
fn rotation_tangent(alpha: f64, beta: f64, gamma: f64) -> f64 {
    let d = beta - alpha;
    let q = 2.0 * gamma;
    let sign = if d < 0.0 { -1.0 } else { 1.0 };
    (sign * q) / (d.abs() + (d * d + q * q).sqrt())
}

/// The SVD of a 3×3 matrix (see the module docs). Non-finite input gives non-finite output; callers
/// validate their inputs.
pub fn svd3(s: &Mat3) -> Svd3 {
    // Work on S / max|S_ij| so that squared norms neither underflow nor overflow.
    let magnitude = s.iter().flatten().fold(0.0f64, |m, x| m.max(x.abs()));
    let inv = if magnitude > 0.0 && magnitude.is_finite() {
        1.0 / magnitude
    } else {
        1.0
    };
    let mut a = s.map(|row| row.map(|x| x * inv));
    let mut v = IDENTITY;
    const PAIRS: [(usize, usize); 3] = [(0, 1), (0, 2), (1, 2)];
    for _sweep in 0..32 {
        let mut rotated = false;
        for (p, q) in PAIRS {
            let ap = col(&a, p);
            let aq = col(&a, q);
            let alpha = dot(ap, ap);
            let beta = dot(aq, aq);
            let gamma = dot(ap, aq);
            if gamma == 0.0 || gamma * gamma <= 1e-30 * (alpha * beta) {
                continue;
            }
            rotated = true;
            let t = rotation_tangent(alpha, beta, gamma);
            let c = 1.0 / (1.0 + t * t).sqrt();
            let sn = c * t;
            for i in 0..3 {
                let (x, y) = (a[i][p], a[i][q]);
                a[i][p] = c * x - sn * y;
                a[i][q] = sn * x + c * y;
                let (x, y) = (v[i][p], v[i][q]);
                v[i][p] = c * x - sn * y;
                v[i][q] = sn * x + c * y;
            }
        }
        if !rotated {
            break;
        }
    }
    let mut sigma = [0, 1, 2].map(|j| dot(col(&a, j), col(&a, j)).sqrt());
    // Sort descending (stable, three elements), permuting columns of A and V alike.
    let mut order = [0usize, 1, 2];
    order.sort_by(|&i, &j| sigma[j].total_cmp(&sigma[i]));
    let (a0, v0, s0) = (a, v, sigma);
    for (k, &o) in order.iter().enumerate() {
        set_col(&mut a, k, col(&a0, o));
        set_col(&mut v, k, col(&v0, o));
        sigma[k] = s0[o];
    }

    let tau = 1e-13 * sigma[0];
    let u = if sigma[0] <= 0.0 || sigma[0].is_nan() {
        IDENTITY
    } else {
        let u1 = normalize(col(&a, 0)).unwrap_or([1.0, 0.0, 0.0]);
        let u2 = if sigma[1] > tau {
            let a2 = col(&a, 1);
            let d = dot(u1, a2);
            normalize([a2[0] - d * u1[0], a2[1] - d * u1[1], a2[2] - d * u1[2]])
                .unwrap_or_else(|| any_orthogonal(u1))
        } else {
            any_orthogonal(u1)
        };
        let mut u3 = cross(u1, u2);
        if sigma[2] > tau && dot(u3, col(&a, 2)) < 0.0 {
            u3 = u3.map(|x| -x);
        }
        let mut u = IDENTITY;
        set_col(&mut u, 0, u1);
        set_col(&mut u, 1, u2);
        set_col(&mut u, 2, u3);
        u
    };
    let sigma = if inv == 1.0 {
        sigma
    } else {
        sigma.map(|x| x * magnitude)
    };
    Svd3 { u, sigma, v }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mat3::{det, mul, mul_tn, transpose};
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    fn reconstruct(d: &Svd3) -> Mat3 {
        let mut us = d.u;
        for i in 0..3 {
            for j in 0..3 {
                us[i][j] *= d.sigma[j];
            }
        }
        mul(&us, &transpose(&d.v))
    }

    fn assert_valid(s: &Mat3, d: &Svd3, tol: f64) {
        let scale = s
            .iter()
            .flatten()
            .map(|x| x.abs())
            .fold(0.0, f64::max)
            .max(1e-300);
        let r = reconstruct(d);
        for i in 0..3 {
            for j in 0..3 {
                assert!(
                    (r[i][j] - s[i][j]).abs() <= tol * scale,
                    "reconstruction {r:?} vs {s:?}"
                );
            }
        }
        for m in [d.u, d.v] {
            let g = mul_tn(&m, &m);
            for i in 0..3 {
                for j in 0..3 {
                    let e = if i == j { 1.0 } else { 0.0 };
                    assert!((g[i][j] - e).abs() < 1e-13, "not orthogonal: {g:?}");
                }
            }
        }
        assert!(d.sigma[0] >= d.sigma[1] && d.sigma[1] >= d.sigma[2] && d.sigma[2] >= 0.0);
        assert!(
            d.u.iter()
                .chain(d.v.iter())
                .flatten()
                .all(|x| x.is_finite())
        );
    }

    #[test]
    fn random_matrices_are_reconstructed_with_orthogonal_factors() {
        let mut rng = ChaCha8Rng::seed_from_u64(7);
        for _ in 0..2000 {
            let s: Mat3 =
                std::array::from_fn(|_| std::array::from_fn(|_| rng.random::<f64>() * 2.0 - 1.0));
            let d = svd3(&s);
            assert_valid(&s, &d, 1e-14);
            let sign = det(&d.u) * det(&d.v);
            assert!((sign * d.sigma.iter().product::<f64>() - det(&s)).abs() < 1e-13);
        }
    }

    #[test]
    fn rank_deficient_and_zero_matrices_give_orthogonal_factors() {
        let cases: [Mat3; 5] = [
            [[0.0; 3]; 3],
            [[1.0, 2.0, 3.0], [2.0, 4.0, 6.0], [-1.0, -2.0, -3.0]],
            [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 0.0]],
            [[0.0, 0.0, 0.0], [0.0, 0.0, 0.0], [0.0, 0.0, 5.0]],
            [[1e-300, 0.0, 0.0], [0.0, 1e-300, 0.0], [0.0, 0.0, 0.0]],
        ];
        for s in cases {
            assert_valid(&s, &svd3(&s), 1e-14);
        }
    }

    #[test]
    fn columns_far_below_the_largest_give_orthogonal_factors() {
        // Rotated diag(1, σ2, σ3) with σ2, σ3 so small that the Jacobi tangent's squares
        // (d² + q²) underflow for the pair of small columns: the factors stay orthogonal and
        // finite, and S is reconstructed to the precision of its largest entry.
        let r = |a: f64, b: f64| {
            let (ca, sa, cb, sb) = (a.cos(), a.sin(), b.cos(), b.sin());
            mul(
                &[[ca, -sa, 0.0], [sa, ca, 0.0], [0.0, 0.0, 1.0]],
                &[[1.0, 0.0, 0.0], [0.0, cb, -sb], [0.0, sb, cb]],
            )
        };
        for (k, sv) in [
            [1.0, 1e-75, 3e-76],
            [1.0, 2e-160, 1e-160],
            [1.0, 1e-300, 1e-300],
        ]
        .into_iter()
        .enumerate()
        {
            let (l, rr) = (r(0.3 + k as f64, 1.1), r(-0.7, 2.0 + k as f64));
            let dg = [[sv[0], 0.0, 0.0], [0.0, sv[1], 0.0], [0.0, 0.0, sv[2]]];
            let s = mul(&mul(&l, &dg), &transpose(&rr));
            let d = svd3(&s);
            assert_valid(&s, &d, 1e-14);
            assert!((d.sigma[0] - 1.0).abs() < 1e-14);
        }
    }

    #[test]
    fn repeated_singular_values_are_handled() {
        // A rotation times a scalar: all three singular values equal.
        let c = 0.3f64.cos();
        let sn = 0.3f64.sin();
        let s = [
            [2.0 * c, -2.0 * sn, 0.0],
            [2.0 * sn, 2.0 * c, 0.0],
            [0.0, 0.0, 2.0],
        ];
        let d = svd3(&s);
        assert_valid(&s, &d, 1e-14);
        for x in d.sigma {
            assert!((x - 2.0).abs() < 1e-14);
        }
        // Two equal values and a reflection.
        let s = [[3.0, 0.0, 0.0], [0.0, -3.0, 0.0], [0.0, 0.0, 1.0]];
        assert_valid(&s, &svd3(&s), 1e-14);
    }

    #[test]
    fn small_singular_value_keeps_relative_accuracy() {
        // diag(1, 1e-5, 1e-12) rotated on both sides: σ_3 is recovered to high relative accuracy.
        let r = |a: f64| {
            [
                [a.cos(), -a.sin(), 0.0],
                [a.sin(), a.cos(), 0.0],
                [0.0, 0.0, 1.0],
            ]
        };
        let q = |a: f64| {
            [
                [1.0, 0.0, 0.0],
                [0.0, a.cos(), -a.sin()],
                [0.0, a.sin(), a.cos()],
            ]
        };
        let l = mul(&r(0.4), &q(1.1));
        let rr = mul(&q(-0.7), &r(2.0));
        let dg = [[1.0, 0.0, 0.0], [0.0, 1e-5, 0.0], [0.0, 0.0, 1e-9]];
        let s = mul(&mul(&l, &dg), &rr);
        let d = svd3(&s);
        assert!((d.sigma[1] / 1e-5 - 1.0).abs() < 1e-9);
        assert!((d.sigma[2] / 1e-9 - 1.0).abs() < 1e-5);
    }

    #[test]
    fn identical_inputs_give_identical_bits() {
        let s = [[0.3, -1.2, 0.7], [2.0, 0.1, -0.4], [0.9, 0.9, 0.05]];
        assert_eq!(svd3(&s), svd3(&s));
    }
}

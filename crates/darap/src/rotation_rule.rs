//! Rotation rules of the local step (spec §3.3, §3.4) and their adjoint (spec §3.5).
//!
//! Both rules write the result as `R = U·diag(d)·Vᵀ` (or its transpose) from the SVD
//! `S = U·diag(σ)·Vᵀ`, with a sign pattern `d ∈ {±1}³` that is piecewise constant in `S`. The
//! pattern and the SVD are kept in a [`RotationSvd`] tape for the adjoint.

use crate::mat3::{Mat3, ZERO, det, mul, mul_nt, mul_tn, transpose};
use crate::svd3::{Svd3, svd3};

/// What the adjoint of a rotation rule needs: the SVD of `S`, the sign pattern and whether the
/// result was transposed (`R = (U·diag(d)·Vᵀ)ᵀ`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RotationSvd {
    /// SVD of the covariance.
    pub svd: Svd3,
    /// Sign pattern `d`.
    pub d: [f64; 3],
    /// `true` when `R = V·diag(d)·Uᵀ` (the Procrustes rule).
    pub transposed: bool,
}

fn u_d_vt(svd: &Svd3, d: [f64; 3]) -> Mat3 {
    let mut ud = svd.u;
    for i in 0..3 {
        for j in 0..3 {
            ud[i][j] *= d[j];
        }
    }
    mul_nt(&ud, &svd.v)
}

/// The reference ("gis") rule, spec §3.3: with `s = det(U)·det(V)`,
/// `R = U·diag(−1, −1, +1)·Vᵀ` if `s > 0`, `R = −U·Vᵀ` if `s < 0` — equivalently
/// `R = −U·diag(1, 1, −s)·Vᵀ`, the rotation that maximizes `⟨R, −S⟩_F` over SO(3).
/// `R` acts on column vectors (`R·x`).
pub fn gis(s: &Mat3) -> (Mat3, RotationSvd) {
    let svd = svd3(s);
    let sign = det(&svd.u) * det(&svd.v);
    let d = if sign > 0.0 {
        [-1.0, -1.0, 1.0]
    } else {
        [-1.0, -1.0, -1.0]
    };
    (
        u_d_vt(&svd, d),
        RotationSvd {
            svd,
            d,
            transposed: false,
        },
    )
}

/// The textbook (Kabsch) rule, spec §3.4: `R = V·diag(1, 1, s)·Uᵀ`, the rotation that maximizes
/// `tr(R·S)`. Used with positive weights and `+λ a n0 tᵀ` in the covariance.
pub fn procrustes(s: &Mat3) -> (Mat3, RotationSvd) {
    let svd = svd3(s);
    let sign = if det(&svd.u) * det(&svd.v) > 0.0 {
        1.0
    } else {
        -1.0
    };
    let d = [1.0, 1.0, sign];
    (
        transpose(&u_d_vt(&svd, d)),
        RotationSvd {
            svd,
            d,
            transposed: true,
        },
    )
}

/// Relative threshold of the adjoint's guards (see [`rotation_vjp`]).
pub const SINGULAR_GAP_GUARD: f64 = 1e-10;

/// Adjoint of a rotation rule: given `G = ∂ℓ/∂R`, returns `∂ℓ/∂S` (spec §3.5).
///
/// With `H = Uᵀ G V` (after transposing `G` for the Procrustes rule), for `i ≠ j`:
/// `Q_ij = d_i (H_ij − H_ji)/(σ_i + σ_j)` when `d_i = d_j`, and
/// `Q_ij = d_j (H_ij + H_ji)/(σ_j − σ_i)` when `d_i ≠ d_j`; `Q_ii = 0`; `∂ℓ/∂S = U Q Vᵀ`.
///
/// **Guard.** Where a denominator is at most `SINGULAR_GAP_GUARD · σ_1` in magnitude (two
/// singular values that coincide while their signs differ, or `σ_i + σ_j ≈ 0` — a rank-deficient
/// `S`), the rule is not differentiable (R jumps or is not unique) and that `Q_ij` is set to 0.
/// For `S = 0` the whole gradient is 0. The result is always finite for finite `G`.
pub fn rotation_vjp(tape: &RotationSvd, grad_r: &Mat3) -> Mat3 {
    let RotationSvd { svd, d, transposed } = tape;
    let g = if *transposed {
        transpose(grad_r)
    } else {
        *grad_r
    };
    let sigma = svd.sigma;
    let guard = SINGULAR_GAP_GUARD * sigma[0];
    if sigma[0] <= 0.0 || sigma[0].is_nan() {
        return ZERO;
    }
    let h = mul(&mul_tn(&svd.u, &g), &svd.v);
    let mut q = ZERO;
    for i in 0..3 {
        for j in 0..3 {
            if i == j {
                continue;
            }
            if d[i] == d[j] {
                let den = sigma[i] + sigma[j];
                if den > guard {
                    q[i][j] = d[i] * (h[i][j] - h[j][i]) / den;
                }
            } else {
                let den = sigma[j] - sigma[i];
                if den.abs() > guard {
                    q[i][j] = d[j] * (h[i][j] + h[j][i]) / den;
                }
            }
        }
    }
    mul_nt(&mul(&svd.u, &q), &svd.v)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mat3::IDENTITY;
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    fn rand_mat(rng: &mut ChaCha8Rng) -> Mat3 {
        std::array::from_fn(|_| std::array::from_fn(|_| rng.random::<f64>() * 2.0 - 1.0))
    }

    fn is_rotation(r: &Mat3) -> bool {
        let g = mul_tn(r, r);
        (0..3).all(|i| (0..3).all(|j| (g[i][j] - if i == j { 1.0 } else { 0.0 }).abs() < 1e-12))
            && (det(r) - 1.0).abs() < 1e-12
    }

    fn frob(a: &Mat3, b: &Mat3) -> f64 {
        (0..3)
            .map(|i| (0..3).map(|j| a[i][j] * b[i][j]).sum::<f64>())
            .sum()
    }

    #[test]
    fn both_rules_return_proper_rotations() {
        let mut rng = ChaCha8Rng::seed_from_u64(1);
        for _ in 0..500 {
            let s = rand_mat(&mut rng);
            assert!(is_rotation(&gis(&s).0));
            assert!(is_rotation(&procrustes(&s).0));
        }
    }

    #[test]
    fn gis_maximizes_alignment_with_minus_s_and_procrustes_with_s_transpose() {
        // Compare against many random rotations (from the rules applied to random matrices).
        let mut rng = ChaCha8Rng::seed_from_u64(2);
        for _ in 0..100 {
            let s = rand_mat(&mut rng);
            let neg: Mat3 = s.map(|r| r.map(|x| -x));
            let rg = gis(&s).0;
            let rp = procrustes(&s).0;
            for _ in 0..50 {
                let q = gis(&rand_mat(&mut rng)).0;
                assert!(frob(&rg, &neg) >= frob(&q, &neg) - 1e-12);
                // tr(R S) = ⟨Rᵀ, S⟩.
                assert!(frob(&transpose(&rp), &s) >= frob(&transpose(&q), &s) - 1e-12);
            }
        }
    }

    #[test]
    fn procrustes_of_symmetric_positive_definite_is_identity() {
        let s = [[3.0, 0.5, 0.1], [0.5, 2.0, 0.2], [0.1, 0.2, 1.0]];
        let r = procrustes(&s).0;
        for i in 0..3 {
            for j in 0..3 {
                assert!((r[i][j] - IDENTITY[i][j]).abs() < 1e-12);
            }
        }
        // and gis of its negative is the identity too
        let r = gis(&s.map(|row| row.map(|x| -x))).0;
        for i in 0..3 {
            for j in 0..3 {
                assert!((r[i][j] - IDENTITY[i][j]).abs() < 1e-12);
            }
        }
    }

    #[test]
    fn vjp_matches_central_differences_on_random_matrices() {
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        for rule in [gis as fn(&Mat3) -> (Mat3, RotationSvd), procrustes] {
            for _ in 0..50 {
                let s = rand_mat(&mut rng);
                let g = rand_mat(&mut rng);
                let dir = rand_mat(&mut rng);
                let (_, tape) = rule(&s);
                let an = frob(&rotation_vjp(&tape, &g), &dir);
                let h = 1e-6;
                let shift = |t: f64| -> Mat3 {
                    std::array::from_fn(|i| std::array::from_fn(|j| s[i][j] + t * dir[i][j]))
                };
                let (rp, tp) = rule(&shift(h));
                let (rm, tm) = rule(&shift(-h));
                if tp.d != tape.d || tm.d != tape.d {
                    continue; // crossed a switch of the sign pattern
                }
                let fd = (frob(&rp, &g) - frob(&rm, &g)) / (2.0 * h);
                assert!(
                    (fd - an).abs() <= 1e-6 * (1.0 + fd.abs()),
                    "fd {fd} vs adjoint {an}"
                );
            }
        }
    }

    #[test]
    fn vjp_stays_finite_for_repeated_and_zero_singular_values() {
        let g = [[0.3, -1.0, 2.0], [0.5, 0.1, -0.7], [1.1, 0.2, 0.4]];
        let cases: [Mat3; 5] = [
            ZERO,
            IDENTITY,
            [[2.0, 0.0, 0.0], [0.0, 2.0, 0.0], [0.0, 0.0, -2.0]],
            [[1.0, 0.0, 0.0], [0.0, 0.0, 0.0], [0.0, 0.0, 0.0]],
            [[1.0, 2.0, 3.0], [2.0, 4.0, 6.0], [3.0, 6.0, 9.0]],
        ];
        for s in cases {
            for rule in [gis as fn(&Mat3) -> (Mat3, RotationSvd), procrustes] {
                let (r, tape) = rule(&s);
                assert!(r.iter().flatten().all(|x| x.is_finite()));
                let ds = rotation_vjp(&tape, &g);
                assert!(ds.iter().flatten().all(|x| x.is_finite()), "{s:?} → {ds:?}");
            }
        }
    }
}

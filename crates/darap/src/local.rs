//! The local step (spec §3): per-vertex covariance from the rest one-ring and the target normal,
//! then a rotation rule.

use crate::RotationRule;
use crate::mat3::{IDENTITY, Mat3, ZERO, mul_tvec, outer, sub};
use crate::rotation_rule::{RotationSvd, gis, procrustes, rotation_vjp};
use cotan::CotWeights;
use rayon::prelude::*;

/// Minimum number of vertices per rayon task.
pub(crate) const PAR_MIN_LEN: usize = 1024;

/// Target normalization `t̂ = x / max(|x|, 1e-12)` (spec §3.2, §5).
pub fn normalize_targets(x: &[[f64; 3]]) -> Vec<[f64; 3]> {
    x.iter()
        .map(|v| {
            let inv = 1.0 / (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt().max(1e-12);
            [v[0] * inv, v[1] * inv, v[2] * inv]
        })
        .collect()
}

/// Adjoint of [`normalize_targets`]: `∂ℓ/∂x = (g − t̂ (t̂·g)) / |x|` where `|x| > 1e-12`, and
/// `g / 1e-12` where the clamp is active (there the map is linear).
pub fn normalize_targets_vjp(x: &[[f64; 3]], grad_unit: &[[f64; 3]]) -> Vec<[f64; 3]> {
    x.iter()
        .zip(grad_unit)
        .map(|(v, g)| {
            let n = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
            if n > 1e-12 {
                let t = [v[0] / n, v[1] / n, v[2] / n];
                let tg = t[0] * g[0] + t[1] * g[1] + t[2] * g[2];
                [
                    (g[0] - t[0] * tg) / n,
                    (g[1] - t[1] * tg) / n,
                    (g[2] - t[2] * tg) / n,
                ]
            } else {
                [g[0] / 1e-12, g[1] / 1e-12, g[2] / 1e-12]
            }
        })
        .collect()
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

/// Per-vertex record of the local step for the adjoint; `None` where the mask forces `R = I`.
pub type LocalTape = Vec<Option<RotationSvd>>;

/// The local step: `R_v = rule(S_v)` with `S_v` from [`covariance`] and normal weight
/// `λ·mass[v]`; vertices with `free[v] == false` get `R_v = I`.
///
/// `targets_unit` are unit target normals (see [`normalize_targets`]). Deterministic for any
/// number of rayon threads (each vertex is independent).
pub fn local_step(
    covariance_rest: &[Mat3],
    mass: &[f64],
    lambda: f64,
    rest_normals: &[[f64; 3]],
    targets_unit: &[[f64; 3]],
    rule: RotationRule,
    free: Option<&[bool]>,
) -> (Vec<Mat3>, LocalTape) {
    (0..covariance_rest.len())
        .into_par_iter()
        .with_min_len(PAR_MIN_LEN)
        .map(|v| {
            if free.is_some_and(|m| !m[v]) {
                return (IDENTITY, None);
            }
            let s = covariance(
                rule,
                &covariance_rest[v],
                lambda * mass[v],
                rest_normals[v],
                targets_unit[v],
            );
            let (r, tape) = match rule {
                RotationRule::Gis => gis(&s),
                RotationRule::Procrustes => procrustes(&s),
            };
            (r, Some(tape))
        })
        .unzip()
}

/// Adjoint of [`local_step`] with respect to the unit targets:
/// `∂ℓ/∂t̂_v = λ a_v · (∂ℓ/∂S_v)ᵀ n0_v`, zero at masked vertices.
pub fn local_step_vjp(
    tape: &[Option<RotationSvd>],
    mass: &[f64],
    lambda: f64,
    rest_normals: &[[f64; 3]],
    grad_rotations: &[Mat3],
) -> Vec<[f64; 3]> {
    (0..tape.len())
        .into_par_iter()
        .with_min_len(PAR_MIN_LEN)
        .map(|v| match &tape[v] {
            None => [0.0; 3],
            Some(t) => {
                let ds = rotation_vjp(t, &grad_rotations[v]);
                let g = mul_tvec(&ds, rest_normals[v]);
                let w = lambda * mass[v];
                [w * g[0], w * g[1], w * g[2]]
            }
        })
        .collect()
}

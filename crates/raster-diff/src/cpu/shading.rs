//! Per-pixel shading of spec §6 and its adjoint, side by side.
//!
//! For a pixel whose centre ray `eye + s·d` hits face (x0, x1, x2):
//! - perspective-correct barycentrics from the ray: with P_i = x_i − eye,
//!   a_0 = d·(P_1 × P_2), a_1 = d·(P_2 × P_0), a_2 = d·(P_0 × P_1), w_i = a_i / Σ a_j
//!   (the barycentrics of the ray–plane intersection, equal to screen-space barycentrics
//!   interpolated with 1/z weights);
//! - p = eye + Σ w_i P_i; n_s = normalize(Σ w_i n_i) (n_i smooth vertex normals);
//!   n_g = normalize((x1 − x0) × (x2 − x0)); v = normalize(eye − p);
//! - two-sided: if v·n_g < 0, n_s ← −n_s and n_g ← −n_g;
//! - bent normal: τ = clamp((v·n_s)/0.1, 0, 1), n = (1 − τ) n_g + τ n_s (not renormalized);
//! - l = normalize(light − p); colour c = kd · max(n·l, 0)/π · light_power with kd = 0.5 and
//!   light_power = 5, the same value in the three channels.

use glam::DVec3;

use super::lanes::{self, L, LANES, Mask, V};
use super::math::{cross_adjoint, normalize, normalize_adjoint};

/// Diffuse albedo (grey).
pub const KD: f64 = 0.5;
/// Light intensity (no falloff).
pub const LIGHT_POWER: f64 = 5.0;
/// Width of the bent-normal blend in v·n_s.
pub const BENT_WIDTH: f64 = 0.1;
/// 1 / [`BENT_WIDTH`] (exactly 10): τ is computed as (v·n_s) · 10, a multiplication instead of a
/// division by 0.1 (the two differ by at most an ulp).
const INV_BENT_WIDTH: f64 = 1.0 / BENT_WIDTH;

/// The per-triangle part of the shading of one view: everything that does not depend on the
/// pixel's ray (P_i, their cross products, the face normal), computed once for the run of pixels
/// a triangle covers (the renderer keeps recently used ones). `Default` is all zeros, a placeholder
/// that shades nothing meaningful.
#[derive(Clone, Copy, Debug, Default)]
pub struct Triangle {
    /// P_i = x_i − eye.
    p: [DVec3; 3],
    /// P_1 × P_2, P_2 × P_0, P_0 × P_1: a_i = d·(P_j × P_k).
    p_cross: [DVec3; 3],
    /// Smooth vertex normals at the corners (unit).
    n: [DVec3; 3],
    e1: DVec3,
    e2: DVec3,
    g: DVec3,
    ng: DVec3,
    ng_inv: f64,
    eye: DVec3,
    light: DVec3,
}

impl Triangle {
    /// Corners `x` with smooth normals `n`, seen from `eye`, lit from `light`.
    #[inline(always)]
    pub fn new(x: [DVec3; 3], n: [DVec3; 3], eye: DVec3, light: DVec3) -> Self {
        let p = [x[0] - eye, x[1] - eye, x[2] - eye];
        let p_cross = [p[1].cross(p[2]), p[2].cross(p[0]), p[0].cross(p[1])];
        let (e1, e2) = (p[1] - p[0], p[2] - p[0]);
        let g = e1.cross(e2);
        let (ng, ng_inv) = normalize(g);
        Self {
            p,
            p_cross,
            n,
            e1,
            e2,
            g,
            ng,
            ng_inv,
            eye,
            light,
        }
    }
}

struct Forward {
    /// 1 / Σ a_j.
    s_inv: f64,
    w: [f64; 3],
    ns_raw: DVec3,
    ns: DVec3,
    ns_inv: f64,
    vv: DVec3,
    v: DVec3,
    v_inv: f64,
    sign: f64,
    tau_raw: f64,
    tau: f64,
    n: DVec3,
    ll: DVec3,
    l: DVec3,
    l_inv: f64,
    dot: f64,
}

#[inline(always)]
fn forward(t: &Triangle, ray: DVec3) -> Forward {
    let p = &t.p;
    let a = [
        ray.dot(t.p_cross[0]),
        ray.dot(t.p_cross[1]),
        ray.dot(t.p_cross[2]),
    ];
    let s_inv = 1.0 / (a[0] + a[1] + a[2]);
    let w = [a[0] * s_inv, a[1] * s_inv, a[2] * s_inv];
    let q = p[0] * w[0] + p[1] * w[1] + p[2] * w[2];
    let ns_raw = t.n[0] * w[0] + t.n[1] * w[1] + t.n[2] * w[2];
    let (ns, ns_inv) = normalize(ns_raw);
    let ng = t.ng;
    let vv = -q;
    let (v, v_inv) = normalize(vv);
    let sign = if v.dot(ng) < 0.0 { -1.0 } else { 1.0 };
    let tau_raw = v.dot(ns * sign) * INV_BENT_WIDTH;
    let tau = tau_raw.clamp(0.0, 1.0);
    let n = ng * (sign * (1.0 - tau)) + ns * (sign * tau);
    let ll = t.light - (t.eye + q);
    let (l, l_inv) = normalize(ll);
    let dot = n.dot(l);
    Forward {
        s_inv,
        w,
        ns_raw,
        ns,
        ns_inv,
        vv,
        v,
        v_inv,
        sign,
        tau_raw,
        tau,
        n,
        ll,
        l,
        l_inv,
        dot,
    }
}

/// Scale from max(n·l, 0) to colour: kd · light_power / π.
pub const RADIANCE_SCALE: f64 = KD * LIGHT_POWER / std::f64::consts::PI;

/// Shaded grey value, in [0, kd·light_power/π] ≈ [0, 0.796], of the pixel whose centre ray
/// (world direction, any length) is `ray` on triangle `t`.
#[inline(always)]
pub fn shade(t: &Triangle, ray: DVec3) -> f64 {
    RADIANCE_SCALE * forward(t, ray).dot.max(0.0)
}

/// The gradient of [`shade`]'s colour c with respect to the corners: (dc/dx_i, dc/dn_i), or
/// `None` where the diffuse term is clamped (n·l ≤ 0) and c does not depend on the geometry.
/// The adjoint for dL/dc is this times dL/dc (the map is linear in it): the renderer's backward
/// computes it once per pixel and scales it by each image gradient's dL/dc, so several
/// gradients share the per-pixel work.
///
/// Piecewise choices (the two-sided sign, the clamp of τ and the max in the diffuse term) are
/// treated as constants; their kinks have measure zero.
#[inline(always)]
pub fn shade_jacobian(t: &Triangle, ray: DVec3) -> Option<([DVec3; 3], [DVec3; 3])> {
    let fw = forward(t, ray);
    let mut dp = [DVec3::ZERO; 3];
    let mut dn_corner = [DVec3::ZERO; 3];
    if fw.dot <= 0.0 {
        return None;
    }
    let ddot = RADIANCE_SCALE;
    let dn = fw.l * ddot;
    let dl = fw.n * ddot;
    let dll = normalize_adjoint(fw.ll, fw.l, fw.l_inv, dl);
    // ll = light − eye − q
    let mut dq = -dll;
    // n = sign·((1 − τ) n_g + τ n_s)
    let ns_s = fw.ns * fw.sign;
    let ng_s = t.ng * fw.sign;
    let dtau = dn.dot(ns_s - ng_s);
    let mut dns_s = dn * fw.tau;
    let dng_s = dn * (1.0 - fw.tau);
    let mut dv = DVec3::ZERO;
    if fw.tau_raw > 0.0 && fw.tau_raw < 1.0 {
        let dtau_raw = dtau * INV_BENT_WIDTH;
        dv += ns_s * dtau_raw;
        dns_s += fw.v * dtau_raw;
    }
    let dns = dns_s * fw.sign;
    let dng = dng_s * fw.sign;
    // v = normalize(−q)
    dq -= normalize_adjoint(fw.vv, fw.v, fw.v_inv, dv);
    // n_g = normalize(e1 × e2)
    let dg = normalize_adjoint(t.g, t.ng, t.ng_inv, dng);
    let (de1, de2) = cross_adjoint(t.e1, t.e2, dg);
    dp[1] += de1;
    dp[2] += de2;
    dp[0] -= de1 + de2;
    // n_s = normalize(Σ w_i n_i)
    let dns_raw = normalize_adjoint(fw.ns_raw, fw.ns, fw.ns_inv, dns);
    let mut dw = [0.0; 3];
    for i in 0..3 {
        dn_corner[i] = dns_raw * fw.w[i];
        dw[i] += t.n[i].dot(dns_raw);
        // q = Σ w_i P_i
        dp[i] += dq * fw.w[i];
        dw[i] += t.p[i].dot(dq);
    }
    // w_i = a_i / S
    let wdw = fw.w[0] * dw[0] + fw.w[1] * dw[1] + fw.w[2] * dw[2];
    let da = [
        (dw[0] - wdw) * fw.s_inv,
        (dw[1] - wdw) * fw.s_inv,
        (dw[2] - wdw) * fw.s_inv,
    ];
    let d = ray;
    // a_0 = d·(P1 × P2) = P1·(P2 × d) = P2·(d × P1), and cyclically.
    for i in 0..3 {
        let (j, k) = ((i + 1) % 3, (i + 2) % 3);
        dp[j] += t.p[k].cross(d) * da[i];
        dp[k] += d.cross(t.p[j]) * da[i];
    }
    Some((dp, dn_corner))
}

/// [`Triangle`]s of several pixels, one per lane (see [`super::lanes`]).
#[derive(Clone, Copy, Debug, Default)]
pub(crate) struct TriangleLanes {
    p: [V; 3],
    p_cross: [V; 3],
    n: [V; 3],
    e1: V,
    e2: V,
    g: V,
    ng: V,
    ng_inv: L,
    eye: V,
    light: V,
}

impl TriangleLanes {
    /// The triangles `ts`, lane `l` from `ts[l]`.
    #[inline(always)]
    pub fn gather(ts: &[Triangle; LANES]) -> Self {
        let v = |f: &dyn Fn(&Triangle) -> DVec3| V::gather(std::array::from_fn(|l| f(&ts[l])));
        Self {
            p: std::array::from_fn(|i| v(&|t| t.p[i])),
            p_cross: std::array::from_fn(|i| v(&|t| t.p_cross[i])),
            n: std::array::from_fn(|i| v(&|t| t.n[i])),
            e1: v(&|t| t.e1),
            e2: v(&|t| t.e2),
            g: v(&|t| t.g),
            ng: v(&|t| t.ng),
            ng_inv: L(std::array::from_fn(|l| ts[l].ng_inv)),
            eye: v(&|t| t.eye),
            light: v(&|t| t.light),
        }
    }
}

/// [`Forward`] per lane.
struct ForwardLanes {
    s_inv: L,
    w: [L; 3],
    ns_raw: V,
    ns: V,
    ns_inv: L,
    vv: V,
    v: V,
    v_inv: L,
    sign: L,
    tau_raw: L,
    tau: L,
    n: V,
    ll: V,
    l: V,
    l_inv: L,
    dot: L,
}

/// [`forward`] per lane, the same operations in the same order.
#[inline(always)]
fn forward_lanes(t: &TriangleLanes, ray: V) -> ForwardLanes {
    let p = &t.p;
    let a = [
        ray.dot(t.p_cross[0]),
        ray.dot(t.p_cross[1]),
        ray.dot(t.p_cross[2]),
    ];
    let s_inv = L::splat(1.0) / (a[0] + a[1] + a[2]);
    let w = [a[0] * s_inv, a[1] * s_inv, a[2] * s_inv];
    let q = p[0] * w[0] + p[1] * w[1] + p[2] * w[2];
    let ns_raw = t.n[0] * w[0] + t.n[1] * w[1] + t.n[2] * w[2];
    let (ns, ns_inv) = lanes::normalize(ns_raw);
    let ng = t.ng;
    let vv = -q;
    let (v, v_inv) = lanes::normalize(vv);
    let sign = L::select(v.dot(ng).lt(L::splat(0.0)), L::splat(-1.0), L::splat(1.0));
    let tau_raw = v.dot(ns * sign) * L::splat(INV_BENT_WIDTH);
    let tau = tau_raw.clamp(0.0, 1.0);
    let n = ng * (sign * (L::splat(1.0) - tau)) + ns * (sign * tau);
    let ll = t.light - (t.eye + q);
    let (l, l_inv) = lanes::normalize(ll);
    let dot = n.dot(l);
    ForwardLanes {
        s_inv,
        w,
        ns_raw,
        ns,
        ns_inv,
        vv,
        v,
        v_inv,
        sign,
        tau_raw,
        tau,
        n,
        ll,
        l,
        l_inv,
        dot,
    }
}

/// [`shade_jacobian`] of one pixel per lane: `(dc/dx_i, dc/dn_i, some)`, where lane `l` of the
/// Jacobians is what `shade_jacobian(t_l, ray_l)` returns when `some[l]` (bit for bit), and
/// meaningless where it returns `None`.
#[inline(always)]
pub(crate) fn shade_jacobian_lanes(t: &TriangleLanes, ray: V) -> ([V; 3], [V; 3], Mask) {
    let fw = forward_lanes(t, ray);
    // `shade_jacobian` returns None exactly when dot ≤ 0 (a NaN dot gives Some).
    let some = fw.dot.le(L::splat(0.0)).map(|clamped| !clamped);
    let zero = V::ZERO;
    let ddot = L::splat(RADIANCE_SCALE);
    let dn = fw.l * ddot;
    let dl = fw.n * ddot;
    let dll = lanes::normalize_adjoint(fw.ll, fw.l, fw.l_inv, dl);
    let mut dq = -dll;
    let ns_s = fw.ns * fw.sign;
    let ng_s = t.ng * fw.sign;
    let dtau = dn.dot(ns_s - ng_s);
    let mut dns_s = dn * fw.tau;
    let dng_s = dn * (L::splat(1.0) - fw.tau);
    // The bent-normal blend's interior, where τ is not clamped.
    let blend = lanes::and(fw.tau_raw.gt(L::splat(0.0)), fw.tau_raw.lt(L::splat(1.0)));
    let dtau_raw = dtau * L::splat(INV_BENT_WIDTH);
    let dv = V::select(blend, zero + ns_s * dtau_raw, zero);
    dns_s = V::select(blend, dns_s + fw.v * dtau_raw, dns_s);
    let dns = dns_s * fw.sign;
    let dng = dng_s * fw.sign;
    dq = dq - lanes::normalize_adjoint(fw.vv, fw.v, fw.v_inv, dv);
    let dg = lanes::normalize_adjoint(t.g, t.ng, t.ng_inv, dng);
    // cross_adjoint(e1, e2, dg) = (e2 × dg, dg × e1)
    let (de1, de2) = (t.e2.cross(dg), dg.cross(t.e1));
    let mut dp = [zero - (de1 + de2), zero + de1, zero + de2];
    let dns_raw = lanes::normalize_adjoint(fw.ns_raw, fw.ns, fw.ns_inv, dns);
    let mut dn_corner = [zero; 3];
    let mut dw = [L::splat(0.0); 3];
    for i in 0..3 {
        dn_corner[i] = dns_raw * fw.w[i];
        dw[i] = dw[i] + t.n[i].dot(dns_raw);
        dp[i] = dp[i] + dq * fw.w[i];
        dw[i] = dw[i] + t.p[i].dot(dq);
    }
    let wdw = fw.w[0] * dw[0] + fw.w[1] * dw[1] + fw.w[2] * dw[2];
    let da = [
        (dw[0] - wdw) * fw.s_inv,
        (dw[1] - wdw) * fw.s_inv,
        (dw[2] - wdw) * fw.s_inv,
    ];
    let d = ray;
    for i in 0..3 {
        let (j, k) = ((i + 1) % 3, (i + 2) % 3);
        dp[j] = dp[j] + t.p[k].cross(d) * da[i];
        dp[k] = dp[k] + d.cross(t.p[j]) * da[i];
    }
    (dp, dn_corner, some)
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    fn bits(v: DVec3) -> [u64; 3] {
        v.to_array().map(f64::to_bits)
    }

    /// Lane `l` of the lane-wise Jacobian is the scalar [`shade_jacobian`] of lane `l`'s triangle
    /// and ray, bit for bit, on random triangles covering every branch: lit and unlit pixels,
    /// both sides (the two-sided sign), τ clamped at 0, at 1 and in between, and corner normals
    /// whose interpolation falls under the normalization's floor.
    #[test]
    fn lane_jacobian_equals_the_scalar_one_bit_for_bit() {
        let mut rng = ChaCha8Rng::seed_from_u64(5);
        let unit = |rng: &mut ChaCha8Rng| {
            DVec3::new(
                rng.random::<f64>() - 0.5,
                rng.random::<f64>() - 0.5,
                rng.random::<f64>() - 0.5,
            )
        };
        let (mut lit, mut unlit, mut blended, mut floored) = (0, 0, 0, 0);
        for case in 0..4000 {
            let ts: [Triangle; LANES] = std::array::from_fn(|_| {
                let x = [unit(&mut rng), unit(&mut rng), unit(&mut rng)];
                let mut n = [unit(&mut rng), unit(&mut rng), unit(&mut rng)].map(|v| v.normalize());
                if case % 50 == 0 {
                    // Tiny corner normals: |Σ w_i n_i|² under the normalization's floor.
                    n = n.map(|v| v * 1e-11);
                }
                let eye = DVec3::new(0.1, 0.2, 3.0) + unit(&mut rng);
                Triangle::new(x, n, eye, eye + unit(&mut rng) * 4.0)
            });
            // Rays through a point inside each triangle (and sometimes outside it).
            let rays: [DVec3; LANES] = std::array::from_fn(|l| {
                let (a, b) = (rng.random::<f64>(), rng.random::<f64>());
                let spread = if case % 7 == 0 { 3.0 } else { 1.0 };
                let (a, b) = if a + b > 1.0 {
                    (1.0 - a, 1.0 - b)
                } else {
                    (a, b)
                };
                let p = ts[l].p;
                p[0] + (p[1] - p[0]) * (a * spread) + (p[2] - p[0]) * b
            });
            let (dx, dn, some) = shade_jacobian_lanes(&TriangleLanes::gather(&ts), V::gather(rays));
            for l in 0..LANES {
                let scalar = shade_jacobian(&ts[l], rays[l]);
                assert_eq!(some[l], scalar.is_some(), "case {case} lane {l}");
                let fw = forward(&ts[l], rays[l]);
                if fw.tau_raw > 0.0 && fw.tau_raw < 1.0 {
                    blended += 1;
                }
                if fw.ns_raw.length_squared() <= crate::cpu::math::NORMALIZE_EPS2 {
                    floored += 1;
                }
                let Some((sx, sn)) = scalar else {
                    unlit += 1;
                    continue;
                };
                lit += 1;
                for k in 0..3 {
                    assert_eq!(bits(dx[k].lane(l)), bits(sx[k]), "case {case} lane {l}");
                    assert_eq!(bits(dn[k].lane(l)), bits(sn[k]), "case {case} lane {l}");
                }
            }
        }
        assert!(lit > 1000 && unlit > 1000 && blended > 100 && floored > 0);
    }
}

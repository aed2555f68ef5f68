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

use super::math::{cross_adjoint, normalize, normalize_adjoint};

/// Diffuse albedo (grey).
pub const KD: f64 = 0.5;
/// Light intensity (no falloff).
pub const LIGHT_POWER: f64 = 5.0;
/// Width of the bent-normal blend in v·n_s.
pub const BENT_WIDTH: f64 = 0.1;

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
    s: f64,
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
    let s = a[0] + a[1] + a[2];
    let w = [a[0] / s, a[1] / s, a[2] / s];
    let q = p[0] * w[0] + p[1] * w[1] + p[2] * w[2];
    let ns_raw = t.n[0] * w[0] + t.n[1] * w[1] + t.n[2] * w[2];
    let (ns, ns_inv) = normalize(ns_raw);
    let ng = t.ng;
    let vv = -q;
    let (v, v_inv) = normalize(vv);
    let sign = if v.dot(ng) < 0.0 { -1.0 } else { 1.0 };
    let tau_raw = v.dot(ns * sign) / BENT_WIDTH;
    let tau = tau_raw.clamp(0.0, 1.0);
    let n = ng * (sign * (1.0 - tau)) + ns * (sign * tau);
    let ll = t.light - (t.eye + q);
    let (l, l_inv) = normalize(ll);
    let dot = n.dot(l);
    Forward {
        s,
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
        let dtau_raw = dtau / BENT_WIDTH;
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
        (dw[0] - wdw) / fw.s,
        (dw[1] - wdw) / fw.s,
        (dw[2] - wdw) / fw.s,
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

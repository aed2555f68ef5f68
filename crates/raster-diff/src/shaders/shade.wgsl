// Shading pass and its adjoint (prefixed with common.wgsl and grad.wgsl), one invocation per
// pixel — gid.x column, gid.y row, gid.z view — the math of cpu::shading::shade / shade_jacobian (times dL/dc)
// in f32: ray barycentrics a_i = d·(P_j × P_k) with P_i = x_i − eye, w_i = a_i / Σa;
// q = Σ w_i P_i; n_s = normalize(Σ w_i n_i); n_g = normalize((x_1 − x_0) × (x_2 − x_0));
// v = normalize(−q); two-sided flip when v·n_g < 0; τ = clamp(v·n_s / 0.1, 0, 1);
// n = (1 − τ) n_g + τ n_s; l = normalize(light − eye − q); colour = 0.5 · max(n·l, 0)/π · 5;
// background 1.0.
//
// Arranged for f32 (algebraically the same as the CPU's f64 formulas): with the edges
// e_1 = x_1 − x_0, e_2 = x_2 − x_0 taken from the world positions, P_0 = x_0 − eye, and
// P_1 = P_0 + e_1, P_2 = P_0 + e_2, the barycentrics are
//   a_1 = d·(e_2 × P_0), a_2 = d·(P_0 × e_1), S = Σa = d·(e_1 × e_2), w_0 = 1 − w_1 − w_2,
//   q = P_0 + w_1 e_1 + w_2 e_2, Σ w_i n_i = n_0 + w_1 (n_1 − n_0) + w_2 (n_2 − n_0).
// The CPU form differentiates w_i = a_i/S through P_i·dq and d·(P_j × P_k), whose terms are
// |P|/|e| times larger than their sum and cancel; in f32 that cost up to ~1e-2 of the VJP on fine
// meshes. Here every large vector appears only as P_0 − q = −(w_1 e_1 + w_2 e_2) (small and exact
// up to rounding of the small terms), using P_0 × d = (P_0 − q) × d since q ∥ d.
//
// Both run over the list of covered pixels built by classify.wgsl. `shade` writes the colour
// before antialiasing to img[0, P) and, as the output of pixels that no blend changes, to
// img[P, 2P). `shade_backward` reads dL/d(colour) from dimg[P, 2P) and adds dL/dx_i and dL/dn_i of the visible triangle's corners to `grad` (f32 atomic
// adds as CAS loops on the bit patterns: the summation order, hence the f32 rounding, depends on
// scheduling).

@group(0) @binding(2) var<storage, read> verts: array<vec4<f32>>;
@group(0) @binding(3) var<storage, read> normals: array<vec4<f32>>;
@group(0) @binding(4) var<storage, read> faces: array<u32>;
@group(0) @binding(7) var<storage, read> vis: array<u32>;
@group(0) @binding(8) var<storage, read_write> img: array<f32>;
@group(0) @binding(9) var<storage, read> dimg: array<f32>;
@group(0) @binding(11) var<storage, read> lists: array<u32>;

const RADIANCE_SCALE: f32 = 0.7957747154594767; // 0.5 · 5 / π
const BENT_WIDTH: f32 = 0.1;

struct Fragment {
    x0: vec3<f32>,
    x1: vec3<f32>,
    x2: vec3<f32>,
    n0: vec3<f32>,
    n1: vec3<f32>,
    n2: vec3<f32>,
    eye: vec3<f32>,
    light: vec3<f32>,
    ray: vec3<f32>,
}

struct Forward {
    p0: vec3<f32>,
    e1: vec3<f32>,
    e2: vec3<f32>,
    s: f32,
    w0: f32,
    w1: f32,
    w2: f32,
    // P_0 − q = −(w_1 e_1 + w_2 e_2).
    r0: vec3<f32>,
    ns_raw: vec3<f32>,
    ns: vec3<f32>,
    ns_inv: f32,
    g: vec3<f32>,
    ng: vec3<f32>,
    ng_inv: f32,
    vv: vec3<f32>,
    v: vec3<f32>,
    v_inv: f32,
    sign: f32,
    tau_raw: f32,
    tau: f32,
    n: vec3<f32>,
    ll: vec3<f32>,
    l: vec3<f32>,
    l_inv: f32,
    dot_nl: f32,
}

// 1 / sqrt(max(|x|², 1e-20)) (spec §6's guarded normalization).
fn inv_len(x: vec3<f32>) -> f32 {
    return 1.0 / sqrt(max(dot(x, x), NORMALIZE_EPS2));
}

// Adjoint of y = x · inv_len(x).
fn normalize_adjoint(x: vec3<f32>, y: vec3<f32>, inv: f32, dy: vec3<f32>) -> vec3<f32> {
    if (dot(x, x) > NORMALIZE_EPS2) {
        return (dy - y * dot(y, dy)) * inv;
    }
    return dy * inv;
}

fn forward_of(f: Fragment) -> Forward {
    var r: Forward;
    let d = f.ray;
    r.p0 = f.x0 - f.eye;
    r.e1 = f.x1 - f.x0;
    r.e2 = f.x2 - f.x0;
    r.g = cross(r.e1, r.e2);
    r.s = dot(d, r.g);
    r.w1 = dot(d, cross(r.e2, r.p0)) / r.s;
    r.w2 = dot(d, cross(r.p0, r.e1)) / r.s;
    r.w0 = 1.0 - r.w1 - r.w2;
    r.r0 = -(r.e1 * r.w1 + r.e2 * r.w2);
    let q = r.p0 - r.r0;
    r.ns_raw = f.n0 + (f.n1 - f.n0) * r.w1 + (f.n2 - f.n0) * r.w2;
    r.ns_inv = inv_len(r.ns_raw);
    r.ns = r.ns_raw * r.ns_inv;
    r.ng_inv = inv_len(r.g);
    r.ng = r.g * r.ng_inv;
    r.vv = -q;
    r.v_inv = inv_len(r.vv);
    r.v = r.vv * r.v_inv;
    r.sign = select(1.0, -1.0, dot(r.v, r.ng) < 0.0);
    r.tau_raw = dot(r.v, r.ns * r.sign) / BENT_WIDTH;
    r.tau = clamp(r.tau_raw, 0.0, 1.0);
    r.n = r.ng * (r.sign * (1.0 - r.tau)) + r.ns * (r.sign * r.tau);
    r.ll = f.light - (f.eye + q);
    r.l_inv = inv_len(r.ll);
    r.l = r.ll * r.l_inv;
    r.dot_nl = dot(r.n, r.l);
    return r;
}

// The fragment of pixel (view, row, column), which triangle t covers.
fn fragment_at(view: u32, row: u32, col: u32, t: u32) -> Fragment {
    let cam = cams[view];
    let i0 = faces[3u * t];
    let i1 = faces[3u * t + 1u];
    let i2 = faces[3u * t + 2u];
    return Fragment(
        verts[i0].xyz,
        verts[i1].xyz,
        verts[i2].xyz,
        normals[i0].xyz,
        normals[i1].xyz,
        normals[i2].xyz,
        cam.eye.xyz,
        cam.light.xyz,
        pixel_ray(cam, vec2<f32>(f32(col) + 0.5, f32(row) + 0.5)),
    );
}

// The pixel at position k of the covered list, as (global index, view, row, column); false
// past the list's end.
struct Covered {
    ok: bool,
    i: u32,
    view: u32,
    row: u32,
    col: u32,
    t: u32,
}

fn covered_pixel(k: u32) -> Covered {
    var c: Covered;
    c.ok = k < lists[LIST_COVERED_LEN];
    if (!c.ok) {
        return c;
    }
    c.i = lists[LIST_HEADER + k];
    c.view = c.i / pixels_per_view();
    let px = c.i % pixels_per_view();
    c.row = px / params.width;
    c.col = px % params.width;
    c.t = ~vis[total_pixels() + c.i];
    return c;
}

// Over the covered list (background pixels were written by `classify`): the colour goes to both
// halves of `img`; the antialiasing pass then overwrites the output of pixels next to another id.
@compute @workgroup_size(64)
fn shade(
    @builtin(workgroup_id) wg: vec3<u32>,
    @builtin(num_workgroups) num_wg: vec3<u32>,
    @builtin(local_invocation_index) li: u32,
) {
    let c = covered_pixel(list_position(wg, num_wg, li));
    if (!c.ok) {
        return;
    }
    let fw = forward_of(fragment_at(c.view, c.row, c.col, c.t));
    let colour = RADIANCE_SCALE * max(fw.dot_nl, 0.0);
    img[c.i] = colour;
    img[total_pixels() + c.i] = colour;
}

// Adds the adjoint of pixel (view, row, col), which sees triangle t, for dL/d(colour) = dc to
// `grad`. Piecewise choices (two-sided sign, clamp of τ, max in the diffuse term) are constants.
fn add_pixel_adjoint(view: u32, row: u32, col: u32, t: u32, dc: f32) {
    let f = fragment_at(view, row, col, t);
    let fw = forward_of(f);
    if (fw.dot_nl <= 0.0) {
        return;
    }
    let ddot = dc * RADIANCE_SCALE;
    let dn = fw.l * ddot;
    let dl = fw.n * ddot;
    // ll = light − eye − q
    var dq = -normalize_adjoint(fw.ll, fw.l, fw.l_inv, dl);
    // n = sign·((1 − τ) n_g + τ n_s)
    let ns_s = fw.ns * fw.sign;
    let ng_s = fw.ng * fw.sign;
    let dtau = dot(dn, ns_s - ng_s);
    var dns_s = dn * fw.tau;
    let dng_s = dn * (1.0 - fw.tau);
    var dv = vec3<f32>(0.0);
    if (fw.tau_raw > 0.0 && fw.tau_raw < 1.0) {
        let dtau_raw = dtau / BENT_WIDTH;
        dv += ns_s * dtau_raw;
        dns_s += fw.v * dtau_raw;
    }
    let dns = dns_s * fw.sign;
    let dng = dng_s * fw.sign;
    // v = normalize(−q)
    dq -= normalize_adjoint(fw.vv, fw.v, fw.v_inv, dv);
    // n_g = normalize(g), g = e1 × e2: dL/de1 = e2 × dg, dL/de2 = dg × e1.
    let dg = normalize_adjoint(fw.g, fw.ng, fw.ng_inv, dng);
    var de1 = cross(fw.e2, dg);
    var de2 = cross(dg, fw.e1);
    // Σ w_i n_i = n_0 + w_1 (n_1 − n_0) + w_2 (n_2 − n_0), normalized to n_s.
    let dns_raw = normalize_adjoint(fw.ns_raw, fw.ns, fw.ns_inv, dns);
    // q = P_0 + w_1 e_1 + w_2 e_2.
    let dw1 = dot(f.n1 - f.n0, dns_raw) + dot(fw.e1, dq);
    let dw2 = dot(f.n2 - f.n0, dns_raw) + dot(fw.e2, dq);
    var dp0 = dq;
    de1 += dq * fw.w1;
    de2 += dq * fw.w2;
    // w_k = a_k / S.
    let da1 = dw1 / fw.s;
    let da2 = dw2 / fw.s;
    let ds = -(fw.w1 * dw1 + fw.w2 * dw2) / fw.s;
    let d = f.ray;
    // a_1 = d·(e_2 × P_0) = P_0·(d × e_2) = e_2·(P_0 × d), with P_0 × d = (P_0 − q) × d;
    // a_2 = d·(P_0 × e_1) = P_0·(e_1 × d) = e_1·(d × P_0); S = d·(e_1 × e_2).
    let r0xd = cross(fw.r0, d);
    dp0 += cross(d, fw.e2) * da1 + cross(fw.e1, d) * da2;
    de2 += r0xd * da1 + cross(d, fw.e1) * ds;
    de1 += -r0xd * da2 + cross(fw.e2, d) * ds;
    let i0 = faces[3u * t];
    let i1 = faces[3u * t + 1u];
    let i2 = faces[3u * t + 2u];
    add_grad3(i0, dp0 - de1 - de2);
    add_grad3(i1, de1);
    add_grad3(i2, de2);
    let nv = params.num_verts;
    add_grad3(nv + i0, dns_raw * fw.w0);
    add_grad3(nv + i1, dns_raw * fw.w1);
    add_grad3(nv + i2, dns_raw * fw.w2);
}

// Over the covered list: dL/d(colour) from dimg[P, 2P).
@compute @workgroup_size(64)
fn shade_backward(
    @builtin(workgroup_id) wg: vec3<u32>,
    @builtin(num_workgroups) num_wg: vec3<u32>,
    @builtin(local_invocation_index) li: u32,
) {
    let c = covered_pixel(list_position(wg, num_wg, li));
    if (!c.ok) {
        return;
    }
    let dc = dimg[total_pixels() + c.i];
    if (dc != 0.0) {
        add_pixel_adjoint(c.view, c.row, c.col, c.t, dc);
    }
}

// Shading pass and its adjoint (prefixed with common.wgsl and grad.wgsl), one invocation per pixel — gid.x column, gid.y row, gid.z view —
// a port of cpu::shading::shade / shade_adjoint in f32 (see that module for the math):
// ray barycentrics a_i = d·(P_j × P_k) with P_i = x_i − eye, w_i = a_i / Σa; q = Σ w_i P_i;
// n_s = normalize(Σ w_i n_i); n_g = normalize((P_1 − P_0) × (P_2 − P_0)); v = normalize(−q);
// two-sided flip when v·n_g < 0; τ = clamp(v·n_s / 0.1, 0, 1); n = (1 − τ) n_g + τ n_s;
// l = normalize(light − eye − q); colour = 0.5 · max(n·l, 0)/π · 5; background 1.0.
//
// `shade` writes img[0, P) (colour before antialiasing). `shade_backward` reads dL/d(colour) from
// dimg[P, 2P) and adds dL/dx_i and dL/dn_i of the visible triangle's corners to `grad` (f32 atomic
// adds as CAS loops on the bit patterns: the summation order, hence the f32 rounding, depends on
// scheduling).

@group(0) @binding(2) var<storage, read> verts: array<vec4<f32>>;
@group(0) @binding(3) var<storage, read> normals: array<vec4<f32>>;
@group(0) @binding(4) var<storage, read> faces: array<u32>;
@group(0) @binding(7) var<storage, read> vis: array<u32>;
@group(0) @binding(8) var<storage, read_write> img: array<f32>;
@group(0) @binding(9) var<storage, read> dimg: array<f32>;

const RADIANCE_SCALE: f32 = 0.7957747154594767; // 0.5 · 5 / π
const BENT_WIDTH: f32 = 0.1;
const BACKGROUND: f32 = 1.0;

struct Fragment {
    x: array<vec3<f32>, 3>,
    n: array<vec3<f32>, 3>,
    eye: vec3<f32>,
    light: vec3<f32>,
    ray: vec3<f32>,
}

struct Forward {
    p: array<vec3<f32>, 3>,
    s: f32,
    w: array<f32, 3>,
    ns_raw: vec3<f32>,
    ns: vec3<f32>,
    ns_inv: f32,
    e1: vec3<f32>,
    e2: vec3<f32>,
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
    r.p = array<vec3<f32>, 3>(f.x[0] - f.eye, f.x[1] - f.eye, f.x[2] - f.eye);
    let a = array<f32, 3>(
        dot(f.ray, cross(r.p[1], r.p[2])),
        dot(f.ray, cross(r.p[2], r.p[0])),
        dot(f.ray, cross(r.p[0], r.p[1])),
    );
    r.s = a[0] + a[1] + a[2];
    r.w = array<f32, 3>(a[0] / r.s, a[1] / r.s, a[2] / r.s);
    let q = r.p[0] * r.w[0] + r.p[1] * r.w[1] + r.p[2] * r.w[2];
    r.ns_raw = f.n[0] * r.w[0] + f.n[1] * r.w[1] + f.n[2] * r.w[2];
    r.ns_inv = inv_len(r.ns_raw);
    r.ns = r.ns_raw * r.ns_inv;
    r.e1 = r.p[1] - r.p[0];
    r.e2 = r.p[2] - r.p[0];
    r.g = cross(r.e1, r.e2);
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

// The fragment of pixel (view, row, column) if a triangle covers it.
fn fragment_at(view: u32, row: u32, col: u32, t: u32) -> Fragment {
    let cam = cams[view];
    var f: Fragment;
    for (var i = 0u; i < 3u; i = i + 1u) {
        let v = faces[3u * t + i];
        f.x[i] = verts[v].xyz;
        f.n[i] = normals[v].xyz;
    }
    f.eye = cam.eye.xyz;
    f.light = cam.light.xyz;
    f.ray = pixel_ray(cam, vec2<f32>(f32(col) + 0.5, f32(row) + 0.5));
    return f;
}

@compute @workgroup_size(64)
fn shade(@builtin(global_invocation_id) gid: vec3<u32>) {
    let col = gid.x;
    let row = gid.y;
    let view = gid.z;
    if (col >= params.width || row >= params.height || view >= params.num_views) {
        return;
    }
    let i = view * pixels_per_view() + row * params.width + col;
    let t = ~vis[total_pixels() + i];
    if (t == NO_TRIANGLE) {
        img[i] = BACKGROUND;
        return;
    }
    let fw = forward_of(fragment_at(view, row, col, t));
    img[i] = RADIANCE_SCALE * max(fw.dot_nl, 0.0);
}

// Adds the adjoint of pixel (view, row, col), which sees triangle t, for dL/d(colour) = dc to
// `grad`. A separate function so that its large local variables exist only for pixels that
// contribute (local variables are zero-initialized at function entry).
fn add_pixel_adjoint(view: u32, row: u32, col: u32, t: u32, dc: f32) {
    // `var`s: their arrays are indexed dynamically below.
    var f = fragment_at(view, row, col, t);
    var fw = forward_of(f);
    if (fw.dot_nl <= 0.0) {
        return;
    }
    var dp = array<vec3<f32>, 3>(vec3<f32>(0.0), vec3<f32>(0.0), vec3<f32>(0.0));
    let ddot = dc * RADIANCE_SCALE;
    let dn = fw.l * ddot;
    let dl = fw.n * ddot;
    let dll = normalize_adjoint(fw.ll, fw.l, fw.l_inv, dl);
    // ll = light − eye − q
    var dq = -dll;
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
    // n_g = normalize(e1 × e2); adjoint of g = e1 × e2 is (e2 × dg, dg × e1).
    let dg = normalize_adjoint(fw.g, fw.ng, fw.ng_inv, dng);
    let de1 = cross(fw.e2, dg);
    let de2 = cross(dg, fw.e1);
    dp[1] += de1;
    dp[2] += de2;
    dp[0] -= de1 + de2;
    // n_s = normalize(Σ w_i n_i)
    let dns_raw = normalize_adjoint(fw.ns_raw, fw.ns, fw.ns_inv, dns);
    var dw = array<f32, 3>(0.0, 0.0, 0.0);
    var dn_corner = array<vec3<f32>, 3>(vec3<f32>(0.0), vec3<f32>(0.0), vec3<f32>(0.0));
    for (var k = 0u; k < 3u; k = k + 1u) {
        dn_corner[k] = dns_raw * fw.w[k];
        dw[k] += dot(f.n[k], dns_raw);
        // q = Σ w_i P_i
        dp[k] += dq * fw.w[k];
        dw[k] += dot(fw.p[k], dq);
    }
    // w_i = a_i / S
    let wdw = fw.w[0] * dw[0] + fw.w[1] * dw[1] + fw.w[2] * dw[2];
    var da = array<f32, 3>((dw[0] - wdw) / fw.s, (dw[1] - wdw) / fw.s, (dw[2] - wdw) / fw.s);
    let d = f.ray;
    // a_i = d·(P_j × P_k) = P_j·(P_k × d) = P_k·(d × P_j)
    for (var k = 0u; k < 3u; k = k + 1u) {
        let j = (k + 1u) % 3u;
        let m = (k + 2u) % 3u;
        dp[j] += cross(fw.p[m], d) * da[k];
        dp[m] += cross(d, fw.p[j]) * da[k];
    }
    let nv = params.num_verts;
    for (var k = 0u; k < 3u; k = k + 1u) {
        let v = faces[3u * t + k];
        add_grad3(v, dp[k]);
        add_grad3(nv + v, dn_corner[k]);
    }
}

@compute @workgroup_size(64)
fn shade_backward(@builtin(global_invocation_id) gid: vec3<u32>) {
    let col = gid.x;
    let row = gid.y;
    let view = gid.z;
    if (col >= params.width || row >= params.height || view >= params.num_views) {
        return;
    }
    let i = view * pixels_per_view() + row * params.width + col;
    let t = ~vis[total_pixels() + i];
    let dc = dimg[total_pixels() + i];
    if (t != NO_TRIANGLE && dc != 0.0) {
        add_pixel_adjoint(view, row, col, t, dc);
    }
}

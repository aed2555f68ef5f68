// Silhouette antialiasing and its adjoint (prefixed with common.wgsl and grad.wgsl), a per-pixel
// *gather* port of cpu::antialias (see that module and docs/renderer.md for the rules): one
// invocation per pixel of the boundary list (classify.wgsl) evaluates the blend of each of its
// (up to) four neighbour pairs exactly as the CPU does for that pair and keeps the ones that
// concern it. Both pixels of a pair evaluate the same pair with the same arithmetic, so every
// blend is seen identically by its target and its source; no atomics in the forward pass.
//
// Pair (a, b), b the right (axis 0) or lower (axis 1) neighbour, with different triangle ids: the
// front pixel F is the covered one (other is background) or the nearer one (depth a ≤ depth b);
// T its triangle. The first of T's silhouette edges (boundary, non-manifold, or the two faces
// facing opposite ways from the eye, facing = g_f·(eye − x_0) > 0), in corner order, that crosses
// the segment between the two centres at t ∈ [0, 1] (from F's centre) gives
// t > 1/2: c_O += (t − 1/2)(c_F − c_O); t < 1/2: c_F += (1/2 − t)(c_O − c_F).

@group(0) @binding(2) var<storage, read> verts: array<vec4<f32>>;
@group(0) @binding(4) var<storage, read> faces: array<u32>;
@group(0) @binding(5) var<storage, read> adjacency: array<u32>;
@group(0) @binding(6) var<storage, read> proj: array<vec4<f32>>;
@group(0) @binding(7) var<storage, read> vis: array<u32>;
@group(0) @binding(8) var<storage, read_write> img: array<f32>;
@group(0) @binding(9) var<storage, read_write> dimg: array<f32>;
@group(0) @binding(11) var<storage, read> lists: array<u32>;

// c[target] += alpha · (c[source] − c[target]); pixel indices within the view.
struct Blend {
    found: bool,
    target_px: u32,
    source_px: u32,
    va: u32,
    vb: u32,
    alpha: f32,
    // dα/dx of the two edge vertices (world space).
    d_alpha_a: vec3<f32>,
    d_alpha_b: vec3<f32>,
}

fn triangle_at(view: u32, px: u32) -> u32 {
    return ~vis[total_pixels() + view * pixels_per_view() + px];
}

fn depth_at(view: u32, px: u32) -> f32 {
    return bitcast<f32>(~vis[view * pixels_per_view() + px]);
}

fn centre(px: u32) -> vec2<f32> {
    return vec2<f32>(f32(px % params.width) + 0.5, f32(px / params.width) + 0.5);
}

fn front_facing(f: u32, eye: vec3<f32>) -> bool {
    let x0 = verts[faces[3u * f]].xyz;
    let x1 = verts[faces[3u * f + 1u]].xyz;
    let x2 = verts[faces[3u * f + 2u]].xyz;
    return dot(cross(x1 - x0, x2 - x0), eye - x0) > 0.0;
}

// Gradients of (sx, sy) with respect to the world point projected to p = (sx, sy, z, _)
// (cpu::raster::Camera::screen_jacobian, with x_c/z and y_c/z recovered from the screen point).
fn screen_jacobian(cam: Cam, p: vec4<f32>) -> array<vec3<f32>, 2> {
    let k = cam.kc.x;
    let xz = (p.x - cam.kc.y) / k;
    let yz = (cam.kc.z - p.y) / k;
    let s = k / p.z;
    return array<vec3<f32>, 2>(
        (cam.right.xyz - cam.forward.xyz * xz) * s,
        -(cam.up.xyz - cam.forward.xyz * yz) * s,
    );
}

// The blend of pair (a, a + 1) (axis 0) or (a, a + W) (axis 1) of `view`, if any.
fn find_blend(view: u32, a: u32, axis: u32) -> Blend {
    var r: Blend;
    r.found = false;
    let b = select(a + params.width, a + 1u, axis == 0u);
    let ia = triangle_at(view, a);
    let ib = triangle_at(view, b);
    if (ia == ib) {
        return r;
    }
    let a_front = ib == NO_TRIANGLE || (ia != NO_TRIANGLE && depth_at(view, a) <= depth_at(view, b));
    let front = select(b, a, a_front);
    let other = select(a, b, a_front);
    let tri = select(ib, ia, a_front);
    let cf = centre(front);
    let co = centre(other);
    let cam = cams[view];
    let eye = cam.eye.xyz;
    let facing_tri = front_facing(tri, eye);
    let o = 1u - axis;
    for (var k = 0u; k < 3u; k = k + 1u) {
        let adj = adjacency[3u * tri + k];
        var silhouette = adj == BOUNDARY_EDGE || adj == NON_MANIFOLD_EDGE;
        if (!silhouette) {
            silhouette = front_facing(adj, eye) != facing_tri;
        }
        if (!silhouette) {
            continue;
        }
        let va = faces[3u * tri + k];
        let vb = faces[3u * tri + (k + 1u) % 3u];
        let pa = proj[view * params.num_verts + va];
        let pb = proj[view * params.num_verts + vb];
        if (pa.z <= 0.0 || pb.z <= 0.0) {
            continue;
        }
        let sa = pa.xy;
        let sb = pb.xy;
        // The segment runs along `axis`; the crossing line is coordinate `o` = const.
        let line = comp(cf, o);
        let da = comp(sa, o) - line;
        let db = comp(sb, o) - line;
        if (da * db >= 0.0) {
            continue;
        }
        let den = comp(sb, o) - comp(sa, o);
        let s = (line - comp(sa, o)) / den;
        let crossing = comp(sa, axis) + s * (comp(sb, axis) - comp(sa, axis));
        let step = comp(co, axis) - comp(cf, axis);
        let t = (crossing - comp(cf, axis)) / step;
        if (!(t >= 0.0 && t <= 1.0)) {
            continue;
        }
        // d crossing / d(screen of a, b), components (along axis, along o) mapped to (x, y).
        let slope = (comp(sb, axis) - comp(sa, axis)) / den;
        let along_a = 1.0 - s;
        let across_a = slope * (s - 1.0);
        let along_b = s;
        let across_b = -slope * s;
        var ds_a = vec2<f32>(along_a, across_a);
        var ds_b = vec2<f32>(along_b, across_b);
        if (axis == 1u) {
            ds_a = vec2<f32>(across_a, along_a);
            ds_b = vec2<f32>(across_b, along_b);
        }
        var dalpha_dt = -1.0;
        r.found = true;
        r.va = va;
        r.vb = vb;
        if (t > 0.5) {
            r.target_px = other;
            r.source_px = front;
            r.alpha = t - 0.5;
            dalpha_dt = 1.0;
        } else {
            r.target_px = front;
            r.source_px = other;
            r.alpha = 0.5 - t;
        }
        let scale = dalpha_dt / step;
        let ja = screen_jacobian(cam, pa);
        let jb = screen_jacobian(cam, pb);
        r.d_alpha_a = (ja[0] * ds_a.x + ja[1] * ds_a.y) * scale;
        r.d_alpha_b = (jb[0] * ds_b.x + jb[1] * ds_b.y) * scale;
        return r;
    }
    return r;
}

// Antialiasing change of pixel px (colour c before antialiasing) from pair blend `bl`:
// α·(c_source − c) if px is the blend's target, else 0.
fn colour_term(view: u32, px: u32, c: f32, bl: Blend) -> f32 {
    if (bl.found && bl.target_px == px) {
        return bl.alpha * (img[view * pixels_per_view() + bl.source_px] - c);
    }
    return 0.0;
}

// Antialiased colour of pixel px (colour c before antialiasing) from the blends of its (up to)
// four neighbour pairs. The pairs are visited one by one, without an array of blends: local
// arrays indexed at run time cost scratch memory on every invocation on some adapters.
fn gather_colour(view: u32, px: u32, c: f32) -> f32 {
    let col = px % params.width;
    let row = px / params.width;
    var out = c;
    if (col > 0u) {
        out += colour_term(view, px, c, find_blend(view, px - 1u, 0u));
    }
    if (col + 1u < params.width) {
        out += colour_term(view, px, c, find_blend(view, px, 0u));
    }
    if (row > 0u) {
        out += colour_term(view, px, c, find_blend(view, px - params.width, 1u));
    }
    if (row + 1u < params.height) {
        out += colour_term(view, px, c, find_blend(view, px, 1u));
    }
    return out;
}

// Position k of the boundary list as (global index, view, pixel within the view); the global
// index is P or more past the list's end.
fn boundary_pixel(k: u32) -> vec3<u32> {
    if (k >= lists[LIST_BOUNDARY_LEN]) {
        return vec3<u32>(total_pixels(), 0u, 0u);
    }
    let i = lists[LIST_HEADER + total_pixels() + k];
    return vec3<u32>(i, i / pixels_per_view(), i % pixels_per_view());
}

// Over the boundary list (pixels with a neighbour of another triangle id; the others' output was
// written by shade / classify): img[P + i] = antialiased colour.
@compute @workgroup_size(64)
fn antialias(
    @builtin(workgroup_id) wg: vec3<u32>,
    @builtin(num_workgroups) num_wg: vec3<u32>,
    @builtin(local_invocation_index) li: u32,
) {
    let b = boundary_pixel(list_position(wg, num_wg, li));
    if (b.x >= total_pixels()) {
        return;
    }
    img[total_pixels() + b.x] = gather_colour(b.y, b.z, img[b.x]);
}

// Adjoint contribution of pair blend `bl` to dL/d(colour of px), where g_px = dL/d(output of
// px); when px is the blend's target, also adds the blend's visibility gradient
// dL/dα · dα/dx (dL/dα = g_px · (c_source − c_px)) to `grad`.
fn adjoint_term(view: u32, px: u32, g_px: f32, bl: Blend) -> f32 {
    let base = view * pixels_per_view();
    if (!bl.found) {
        return 0.0;
    }
    if (bl.target_px == px) {
        let d_alpha = g_px * (img[base + bl.source_px] - img[base + px]);
        add_grad3(bl.va, bl.d_alpha_a * d_alpha);
        add_grad3(bl.vb, bl.d_alpha_b * d_alpha);
        return -g_px * bl.alpha;
    }
    if (bl.source_px == px) {
        return dimg[base + bl.target_px] * bl.alpha;
    }
    return 0.0;
}

// dL/d(colour before antialiasing) of pixel px from the blends of its neighbour pairs.
fn gather_adjoint(view: u32, px: u32, g_px: f32) -> f32 {
    let col = px % params.width;
    let row = px / params.width;
    var d_colour = g_px;
    if (col > 0u) {
        d_colour += adjoint_term(view, px, g_px, find_blend(view, px - 1u, 0u));
    }
    if (col + 1u < params.width) {
        d_colour += adjoint_term(view, px, g_px, find_blend(view, px, 0u));
    }
    if (row > 0u) {
        d_colour += adjoint_term(view, px, g_px, find_blend(view, px - params.width, 1u));
    }
    if (row + 1u < params.height) {
        d_colour += adjoint_term(view, px, g_px, find_blend(view, px, 1u));
    }
    return d_colour;
}

// Adjoint over the boundary list: dimg[P + i] = dL/d(colour before antialiasing) from
// dimg[i] = dL/d(output) (the backward uploads dL/d(output) to both halves, so pixels off the
// list keep d_colour = d_out), and the visibility gradient dL/dα · dα/dx of every blend added by
// its target pixel (each blend has one target, so each is added once) to grad's dL/dx part.
@compute @workgroup_size(64)
fn antialias_backward(
    @builtin(workgroup_id) wg: vec3<u32>,
    @builtin(num_workgroups) num_wg: vec3<u32>,
    @builtin(local_invocation_index) li: u32,
) {
    let b = boundary_pixel(list_position(wg, num_wg, li));
    if (b.x >= total_pixels()) {
        return;
    }
    dimg[total_pixels() + b.x] = gather_adjoint(b.y, b.z, dimg[b.x]);
}

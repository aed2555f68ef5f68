// Visibility pass: one invocation per (triangle, view) — gid.x triangle, gid.y view — scans the
// pixel centres of its screen bounding box with the CPU backend's conventions (pixel centres at
// i + 0.5, top-left fill rule after orienting the triangle clockwise on screen, depth =
// perspective-correct z, triangles with a vertex nearer than the near plane are not drawn).
//
// `vis` starts zeroed and holds bitwise complements, so that zero means "nothing drawn":
// entry `raster_depth` keeps the nearest depth per pixel with atomicMax on ~bits (positive floats
// order like their u32 bits, so the largest complement is the smallest depth); entry `raster_id`
// then writes, among triangles whose depth equals the kept one, ~(smallest triangle id) with
// atomicMax, so ties resolve like the CPU backend. A pixel nothing covers reads ~0 = NO_TRIANGLE.

@group(0) @binding(4) var<storage, read> faces: array<u32>;
@group(0) @binding(6) var<storage, read> proj: array<vec4<f32>>;
@group(0) @binding(7) var<storage, read_write> vis: array<atomic<u32>>;

// (a − p) × (b − p): exactly antisymmetric in (a, b).
fn edge(a: vec2<f32>, b: vec2<f32>, p: vec2<f32>) -> f32 {
    return (a.x - p.x) * (b.y - p.y) - (a.y - p.y) * (b.x - p.x);
}

fn owns(a: vec2<f32>, b: vec2<f32>) -> bool {
    let d = b - a;
    return d.y < 0.0 || (d.y == 0.0 && d.x > 0.0);
}

fn covers(e: f32, owned: bool) -> bool {
    return e > 0.0 || (e == 0.0 && owned);
}

fn is_finite(x: f32) -> bool {
    // NaN fails both comparisons; ±inf fails one.
    return x > -3.0e38 && x < 3.0e38;
}

fn raster(t: u32, view: u32, write_ids: bool) {
    if (t >= params.num_faces || view >= params.num_views) {
        return;
    }
    let base = view * params.num_verts;
    let a = proj[base + faces[3u * t]];
    var b = proj[base + faces[3u * t + 1u]];
    var c = proj[base + faces[3u * t + 2u]];
    if (a.w == 0.0 || b.w == 0.0 || c.w == 0.0) {
        return;
    }
    var area = edge(a.xy, b.xy, c.xy);
    if (area == 0.0 || !is_finite(area)) {
        return;
    }
    if (area < 0.0) {
        let tmp = b;
        b = c;
        c = tmp;
        area = -area;
    }
    let lo = min(a.xy, min(b.xy, c.xy));
    let hi = max(a.xy, max(b.xy, c.xy));
    let fw = f32(params.width);
    let fh = f32(params.height);
    let x0f = max(ceil(lo.x - 0.5), 0.0);
    let x1f = min(floor(hi.x - 0.5), fw - 1.0);
    let y0f = max(ceil(lo.y - 0.5), 0.0);
    let y1f = min(floor(hi.y - 0.5), fh - 1.0);
    if (!(x0f <= x1f && y0f <= y1f)) {
        return;
    }
    let x0 = u32(x0f);
    let x1 = u32(x1f);
    let y0 = u32(y0f);
    let y1 = u32(y1f);
    let own0 = owns(b.xy, c.xy);
    let own1 = owns(c.xy, a.xy);
    let own2 = owns(a.xy, b.xy);
    let inv_area = 1.0 / area;
    let pixel0 = view * pixels_per_view();
    let ids0 = total_pixels();
    for (var y = y0; y <= y1; y = y + 1u) {
        for (var x = x0; x <= x1; x = x + 1u) {
            let p = vec2<f32>(f32(x) + 0.5, f32(y) + 0.5);
            let e0 = edge(b.xy, c.xy, p);
            let e1 = edge(c.xy, a.xy, p);
            let e2 = edge(a.xy, b.xy, p);
            if (!(covers(e0, own0) && covers(e1, own1) && covers(e2, own2))) {
                continue;
            }
            let inv_z = (e0 / a.z + e1 / b.z + e2 / c.z) * inv_area;
            let key = ~bitcast<u32>(1.0 / inv_z);
            let i = pixel0 + y * params.width + x;
            if (!write_ids) {
                atomicMax(&vis[i], key);
            } else if (atomicLoad(&vis[i]) == key) {
                atomicMax(&vis[ids0 + i], ~t);
            }
        }
    }
}

@compute @workgroup_size(64)
fn raster_depth(@builtin(global_invocation_id) gid: vec3<u32>) {
    raster(gid.x, gid.y, false);
}

@compute @workgroup_size(64)
fn raster_id(@builtin(global_invocation_id) gid: vec3<u32>) {
    raster(gid.x, gid.y, true);
}

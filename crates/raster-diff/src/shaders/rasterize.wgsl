// Visibility pass of the wgpu backend: one invocation per triangle scans the pixel centres of its
// screen bounding box with the CPU backend's conventions (pixel centres at i + 0.5, top-left fill
// rule after orienting the triangle clockwise on screen, depth = perspective-correct z).
//
// Pass 0 keeps the nearest depth per pixel with atomicMin on the f32 bit pattern (positive floats
// order like their u32 bits). Pass 1 writes, among triangles whose depth equals the kept depth,
// the smallest triangle id (atomicMin), so ties resolve like the CPU backend.

struct Params {
    width: u32,
    height: u32,
    num_faces: u32,
    pass_index: u32,
}

@group(0) @binding(0) var<uniform> params: Params;
// Per vertex: screen x, screen y (pixels, y down), depth z, 1.0 if z >= near else 0.0.
@group(0) @binding(1) var<storage, read> verts: array<vec4<f32>>;
// Three vertex indices per face.
@group(0) @binding(2) var<storage, read> faces: array<u32>;
@group(0) @binding(3) var<storage, read_write> depth: array<atomic<u32>>;
@group(0) @binding(4) var<storage, read_write> ids: array<atomic<u32>>;

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

@compute @workgroup_size(64)
fn main(@builtin(global_invocation_id) gid: vec3<u32>) {
    let t = gid.x;
    if (t >= params.num_faces) {
        return;
    }
    let a = verts[faces[3u * t]];
    var b = verts[faces[3u * t + 1u]];
    var c = verts[faces[3u * t + 2u]];
    if (a.w == 0.0 || b.w == 0.0 || c.w == 0.0) {
        return;
    }
    var area = edge(a.xy, b.xy, c.xy);
    if (area == 0.0) {
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
    if (hi.x < 0.5 || hi.y < 0.5 || lo.x > fw - 0.5 || lo.y > fh - 0.5) {
        return;
    }
    let x0 = u32(max(ceil(lo.x - 0.5), 0.0));
    let x1 = u32(min(floor(hi.x - 0.5), fw - 1.0));
    let y0 = u32(max(ceil(lo.y - 0.5), 0.0));
    let y1 = u32(min(floor(hi.y - 0.5), fh - 1.0));
    let own0 = owns(b.xy, c.xy);
    let own1 = owns(c.xy, a.xy);
    let own2 = owns(a.xy, b.xy);
    for (var y = y0; y <= y1; y = y + 1u) {
        for (var x = x0; x <= x1; x = x + 1u) {
            let p = vec2<f32>(f32(x) + 0.5, f32(y) + 0.5);
            let e0 = edge(b.xy, c.xy, p);
            let e1 = edge(c.xy, a.xy, p);
            let e2 = edge(a.xy, b.xy, p);
            if (!(covers(e0, own0) && covers(e1, own1) && covers(e2, own2))) {
                continue;
            }
            let inv_z = (e0 / a.z + e1 / b.z + e2 / c.z) / area;
            let bits = bitcast<u32>(1.0 / inv_z);
            let i = y * params.width + x;
            if (params.pass_index == 0u) {
                atomicMin(&depth[i], bits);
            } else if (atomicLoad(&depth[i]) == bits) {
                atomicMin(&ids[i], t);
            }
        }
    }
}

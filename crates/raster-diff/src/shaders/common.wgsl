// Declarations shared by every pass of the wgpu backend (prepended to each shader file by
// src/gpu/mod.rs, so every module below sees them). All arithmetic is f32.
//
// Buffer bindings (group 0) use one numbering across all shader files; each pass declares only the
// buffers it touches, and each pipeline's bind group holds exactly those:
//   0 params (uniform)           1 cams: per view camera          2 verts: world xyz per vertex
//   3 normals: smooth n per vertex 4 faces: 3 indices per face    5 adjacency: 3 per face
//   6 proj: per view per vertex (sx, sy, z, 1 if z >= near else 0)
//   7 vis: per view per pixel, [0, P) ~depth bits, [P, 2P) ~triangle id (0 = nothing drawn)
//   8 img: [0, P) colour before antialiasing, [P, 2P) antialiased output
//   9 dimg: [0, P) dL/d(output), [P, 2P) dL/d(colour before antialiasing)
//  10 grad: f32 bits, [0, 3V) dL/dx, [3V, 6V) dL/dn (smooth normals), added with CAS loops
//  11 lists: compacted pixel lists and their indirect dispatch arguments (see classify.wgsl)
// where P = num_views · width · height and pixel (view, row, column) is at view·W·H + row·W + column.

struct Params {
    width: u32,
    height: u32,
    num_views: u32,
    num_verts: u32,
    num_faces: u32,
    antialias: u32,
    near: f32,
    _pad: u32,
}

// One view: camera frame (world), light position, and the projection constants.
struct Cam {
    eye: vec4<f32>,
    right: vec4<f32>,
    up: vec4<f32>,
    forward: vec4<f32>,
    light: vec4<f32>,
    // k (pixels per unit of x_c/z), cx = W/2, cy = H/2, unused.
    kc: vec4<f32>,
}

const NO_TRIANGLE: u32 = 0xffffffffu;
const BOUNDARY_EDGE: u32 = 0xffffffffu;
const NON_MANIFOLD_EDGE: u32 = 0xfffffffeu;
const NORMALIZE_EPS2: f32 = 1e-20;
const BACKGROUND: f32 = 1.0;
// Layout of `lists` (binding 11): dispatch arguments at 0 and 3, lengths at 6 and 7, then the
// covered list at LIST_HEADER and the boundary list at LIST_HEADER + P.
const LIST_COVERED_LEN: u32 = 6u;
const LIST_BOUNDARY_LEN: u32 = 7u;
const LIST_HEADER: u32 = 8u;

@group(0) @binding(0) var<uniform> params: Params;
@group(0) @binding(1) var<storage, read> cams: array<Cam>;

fn pixels_per_view() -> u32 {
    return params.width * params.height;
}

fn total_pixels() -> u32 {
    return params.num_views * params.width * params.height;
}

// World direction of the ray through screen point s (unit depth along forward), as
// cpu::raster::Camera::pixel_ray.
fn pixel_ray(cam: Cam, s: vec2<f32>) -> vec3<f32> {
    let k = cam.kc.x;
    return cam.right.xyz * ((s.x - cam.kc.y) / k) - cam.up.xyz * ((s.y - cam.kc.z) / k)
        + cam.forward.xyz;
}

// Position k in a list processed by a 2D indirect dispatch of 64-wide workgroups.
fn list_position(wg: vec3<u32>, num_wg: vec3<u32>, local: u32) -> u32 {
    return (wg.y * num_wg.x + wg.x) * 64u + local;
}

// Component i (0 or 1) of a 2-vector.
fn comp(v: vec2<f32>, i: u32) -> f32 {
    return select(v.x, v.y, i == 1u);
}

// Projection pass: one invocation per (vertex, view) — gid.x vertex, gid.y view — writes the
// screen position (pixels, origin top-left, y down) and depth of cpu::raster::project_vertices:
// camera coordinates (r·(X − eye), u·(X − eye), f·(X − eye)), sx = cx + k·x_c/z,
// sy = cy − k·y_c/z. w = 1 when the vertex may be drawn (z ≥ near, z not NaN), else 0.

@group(0) @binding(2) var<storage, read> verts: array<vec4<f32>>;
@group(0) @binding(6) var<storage, read_write> proj: array<vec4<f32>>;

@compute @workgroup_size(64)
fn project(@builtin(global_invocation_id) gid: vec3<u32>) {
    let v = gid.x;
    let view = gid.y;
    if (v >= params.num_verts || view >= params.num_views) {
        return;
    }
    let cam = cams[view];
    let p = verts[v].xyz - cam.eye.xyz;
    let c = vec3<f32>(dot(p, cam.right.xyz), dot(p, cam.up.xyz), dot(p, cam.forward.xyz));
    let k = cam.kc.x;
    let s = vec2<f32>(cam.kc.y + k * c.x / c.z, cam.kc.z - k * c.y / c.z);
    // `c.z >= near` is false for NaN.
    let ok = select(0.0, 1.0, c.z >= params.near);
    proj[view * params.num_verts + v] = vec4<f32>(s, c.z, ok);
}

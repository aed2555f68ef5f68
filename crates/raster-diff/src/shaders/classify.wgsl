// Pixel classification after rasterization (prefixed with common.wgsl): one invocation per pixel
// — gid.x column, gid.y row, gid.z view — appends the pixel's global index to the list of
// covered pixels (shading and its adjoint run over it) and, with antialiasing on, to the list of
// pixels with a neighbour of another triangle id (only those can take part in a blend; the
// antialiasing passes run over it), and writes the background value of uncovered pixels. Lists
// are in `lists` (binding 11): words [0, 3) and [3, 6) are the indirect dispatch arguments of the
// two lists (written by `dispatch_args`), 6 and 7 their lengths, then the covered list at
// [8, 8 + P) and the boundary list at [8 + P, 8 + 2P). The order within a list depends on
// scheduling; every pass over a list writes only its own pixel's outputs, so results do not.

@group(0) @binding(7) var<storage, read> vis: array<u32>;
@group(0) @binding(8) var<storage, read_write> img: array<f32>;
@group(0) @binding(11) var<storage, read_write> lists: array<atomic<u32>>;

fn triangle_at(view: u32, px: u32) -> u32 {
    return ~vis[total_pixels() + view * pixels_per_view() + px];
}

// Whether any of pixel px's neighbour pairs has two different triangle ids.
fn on_id_boundary(view: u32, px: u32, t: u32) -> bool {
    let col = px % params.width;
    let row = px / params.width;
    return (col > 0u && triangle_at(view, px - 1u) != t)
        || (col + 1u < params.width && triangle_at(view, px + 1u) != t)
        || (row > 0u && triangle_at(view, px - params.width) != t)
        || (row + 1u < params.height && triangle_at(view, px + params.width) != t);
}

@compute @workgroup_size(64)
fn classify(@builtin(global_invocation_id) gid: vec3<u32>) {
    let col = gid.x;
    let row = gid.y;
    let view = gid.z;
    if (col >= params.width || row >= params.height || view >= params.num_views) {
        return;
    }
    let px = row * params.width + col;
    let i = view * pixels_per_view() + px;
    let t = triangle_at(view, px);
    if (t != NO_TRIANGLE) {
        let k = atomicAdd(&lists[LIST_COVERED_LEN], 1u);
        atomicStore(&lists[LIST_HEADER + k], i);
    } else {
        img[i] = BACKGROUND;
        img[total_pixels() + i] = BACKGROUND;
    }
    if (params.antialias != 0u && on_id_boundary(view, px, t)) {
        let k = atomicAdd(&lists[LIST_BOUNDARY_LEN], 1u);
        atomicStore(&lists[LIST_HEADER + total_pixels() + k], i);
    }
}

// Indirect dispatch arguments (x, y, 1) of both lists: ceil(len / 64) workgroups, folded into
// two dimensions so that neither exceeds 65535.
@compute @workgroup_size(1)
fn dispatch_args() {
    for (var which = 0u; which < 2u; which = which + 1u) {
        let len = atomicLoad(&lists[LIST_COVERED_LEN + which]);
        let groups = (len + 63u) / 64u;
        let x = min(groups, 65535u);
        let y = select(1u, (groups + x - 1u) / x, x > 0u);
        atomicStore(&lists[3u * which], x);
        atomicStore(&lists[3u * which + 1u], y);
        atomicStore(&lists[3u * which + 2u], 1u);
    }
}

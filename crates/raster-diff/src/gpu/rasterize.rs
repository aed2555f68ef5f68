//! Host side of `rasterize.wgsl`: visibility (triangle id and depth per pixel) with a depth test,
//! two passes of atomics (nearest depth, then smallest id at that depth).

use super::buffers::{B_FACES, B_PARAMS, B_PROJ, B_VIS, Buffers};
use super::device::{Pass, Pipelines, module};
use super::{RASTERIZE_WGSL, WgpuRenderer};

/// The `raster_depth` and `raster_id` pipelines.
pub(super) fn pipelines(device: &wgpu::Device) -> (Pass, Pass) {
    let m = module(device, "rasterize.wgsl", RASTERIZE_WGSL);
    (
        Pass::new(
            device,
            &m,
            "raster_depth",
            &[B_PARAMS, B_FACES, B_PROJ, B_VIS],
        ),
        Pass::new(device, &m, "raster_id", &[B_PARAMS, B_FACES, B_PROJ, B_VIS]),
    )
}

/// Records both visibility passes: one thread per (face, view) each.
pub(super) fn encode(
    encoder: &mut wgpu::CommandEncoder,
    ps: &Pipelines,
    b: &Buffers,
    fgroups: u32,
    nviews: u32,
) {
    WgpuRenderer::dispatch(encoder, &ps.raster_depth, &b.bind[1], [fgroups, nviews, 1]);
    WgpuRenderer::dispatch(encoder, &ps.raster_id, &b.bind[2], [fgroups, nviews, 1]);
}

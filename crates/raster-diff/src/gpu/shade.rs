//! Host side of `shade.wgsl`: `shade` over the covered list (the CPU `shading::shade` math per
//! pixel) and `shade_backward` (port of `shading::shade_jacobian` times dL/dc), which adds into the per-vertex
//! dL/dx and dL/dn buffers.

use super::buffers::{
    B_CAMS, B_DIMG, B_FACES, B_GRAD, B_IMG, B_LISTS, B_NORMALS, B_PARAMS, B_VERTS, B_VIS, Buffers,
    COVERED_ARGS,
};
use super::device::{Pass, Pipelines, module};
use super::{SHADE_WGSL, WgpuRenderer};

/// The `shade` and `shade_backward` pipelines.
pub(super) fn pipelines(device: &wgpu::Device) -> (Pass, Pass) {
    let m = module(device, "shade.wgsl", SHADE_WGSL);
    (
        Pass::new(
            device,
            &m,
            "shade",
            &[
                B_PARAMS, B_CAMS, B_VERTS, B_NORMALS, B_FACES, B_VIS, B_IMG, B_LISTS,
            ],
        ),
        Pass::new(
            device,
            &m,
            "shade_backward",
            &[
                B_PARAMS, B_CAMS, B_VERTS, B_NORMALS, B_FACES, B_VIS, B_DIMG, B_GRAD, B_LISTS,
            ],
        ),
    )
}

/// Records the shading over the covered list (indirect dispatch).
pub(super) fn encode(encoder: &mut wgpu::CommandEncoder, ps: &Pipelines, b: &Buffers) {
    let lists = &b.storage[B_LISTS as usize];
    WgpuRenderer::dispatch_indirect(encoder, &ps.shade, &b.bind[3], lists, COVERED_ARGS);
}

/// Records the shading adjoint over the covered list.
pub(super) fn encode_backward(encoder: &mut wgpu::CommandEncoder, ps: &Pipelines, b: &Buffers) {
    let lists = &b.storage[B_LISTS as usize];
    WgpuRenderer::dispatch_indirect(encoder, &ps.shade_backward, &b.bind[6], lists, COVERED_ARGS);
}

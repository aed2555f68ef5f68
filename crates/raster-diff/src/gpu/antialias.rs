//! Host side of `antialias.wgsl`: `antialias` over the boundary list (silhouette antialiasing as
//! a per-pixel gather over the four neighbour pairs, the rules of [`crate::cpu::antialias`]) and
//! `antialias_backward` (dL/d(colour) by gather, and the visibility gradient dL/dα · dα/dx of each
//! blend, added by its target pixel).

use super::buffers::{
    B_ADJ, B_CAMS, B_DIMG, B_FACES, B_GRAD, B_IMG, B_LISTS, B_PARAMS, B_PROJ, B_VERTS, B_VIS,
    BOUNDARY_ARGS, Buffers,
};
use super::device::{Pass, Pipelines, module};
use super::{ANTIALIAS_WGSL, WgpuRenderer};

/// The `antialias` and `antialias_backward` pipelines.
pub(super) fn pipelines(device: &wgpu::Device) -> (Pass, Pass) {
    let m = module(device, "antialias.wgsl", ANTIALIAS_WGSL);
    (
        Pass::new(
            device,
            &m,
            "antialias",
            &[
                B_PARAMS, B_CAMS, B_VERTS, B_FACES, B_ADJ, B_PROJ, B_VIS, B_IMG, B_LISTS,
            ],
        ),
        Pass::new(
            device,
            &m,
            "antialias_backward",
            &[
                B_PARAMS, B_CAMS, B_VERTS, B_FACES, B_ADJ, B_PROJ, B_VIS, B_IMG, B_DIMG, B_GRAD,
                B_LISTS,
            ],
        ),
    )
}

/// Records the antialiasing over the boundary list (indirect dispatch).
pub(super) fn encode(encoder: &mut wgpu::CommandEncoder, ps: &Pipelines, b: &Buffers) {
    let lists = &b.storage[B_LISTS as usize];
    WgpuRenderer::dispatch_indirect(encoder, &ps.antialias, &b.bind[4], lists, BOUNDARY_ARGS);
}

/// Records the antialiasing adjoint over the boundary list.
pub(super) fn encode_backward(encoder: &mut wgpu::CommandEncoder, ps: &Pipelines, b: &Buffers) {
    let lists = &b.storage[B_LISTS as usize];
    WgpuRenderer::dispatch_indirect(
        encoder,
        &ps.antialias_backward,
        &b.bind[5],
        lists,
        BOUNDARY_ARGS,
    );
}

//! Host side of `project.wgsl`: screen position and depth per vertex per view.

use super::buffers::{B_CAMS, B_PARAMS, B_PROJ, B_VERTS, Buffers};
use super::device::{Pass, Pipelines, module};
use super::{PROJECT_WGSL, WgpuRenderer};

/// The `project` pipeline.
pub(super) fn pipeline(device: &wgpu::Device) -> Pass {
    let m = module(device, "project.wgsl", PROJECT_WGSL);
    Pass::new(device, &m, "project", &[B_PARAMS, B_CAMS, B_VERTS, B_PROJ])
}

/// Records the projection: one thread per (vertex, view).
pub(super) fn encode(
    encoder: &mut wgpu::CommandEncoder,
    ps: &Pipelines,
    b: &Buffers,
    vgroups: u32,
    nviews: u32,
) {
    WgpuRenderer::dispatch(encoder, &ps.project, &b.bind[0], [vgroups, nviews, 1]);
}

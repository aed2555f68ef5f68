//! Host side of `classify.wgsl`: per pixel, appends covered pixels to one list and pixels with a
//! neighbour of another triangle id to another (atomic counters), writes the background value 1.0
//! elsewhere, and turns the list lengths into indirect dispatch arguments.

use super::buffers::{B_IMG, B_LISTS, B_PARAMS, B_VIS, Buffers, LIST_HEADER};
use super::device::{Pass, Pipelines, module};
use super::{CLASSIFY_WGSL, WgpuRenderer};

/// The `classify` and `dispatch_args` pipelines.
pub(super) fn pipelines(device: &wgpu::Device) -> (Pass, Pass) {
    let m = module(device, "classify.wgsl", CLASSIFY_WGSL);
    (
        Pass::new(device, &m, "classify", &[B_PARAMS, B_VIS, B_IMG, B_LISTS]),
        Pass::new(device, &m, "dispatch_args", &[B_LISTS]),
    )
}

/// Records the pixel lists: covered pixels (shading) and pixels next to another id
/// (antialiasing), then their dispatch arguments.
pub(super) fn encode(
    encoder: &mut wgpu::CommandEncoder,
    ps: &Pipelines,
    b: &Buffers,
    pixel_groups: [u32; 3],
) {
    let lists = &b.storage[B_LISTS as usize];
    encoder.clear_buffer(lists, 0, Some(4 * LIST_HEADER));
    WgpuRenderer::dispatch(encoder, &ps.classify, &b.bind[7], pixel_groups);
    WgpuRenderer::dispatch(encoder, &ps.dispatch_args, &b.bind[8], [1, 1, 1]);
}

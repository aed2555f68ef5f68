//! Device buffers: the binding numbers of `common.wgsl`, the uniform and camera layouts, the
//! buffers and bind groups (made per shape), and the uploads of a render's inputs.

use glam::DVec3;

use super::WgpuRenderer;
use crate::cpu::raster::Camera;

// Binding numbers (see common.wgsl).
pub(super) const B_PARAMS: u32 = 0;
pub(super) const B_CAMS: u32 = 1;
pub(super) const B_VERTS: u32 = 2;
pub(super) const B_NORMALS: u32 = 3;
pub(super) const B_FACES: u32 = 4;
pub(super) const B_ADJ: u32 = 5;
pub(super) const B_PROJ: u32 = 6;
pub(super) const B_VIS: u32 = 7;
pub(super) const B_IMG: u32 = 8;
pub(super) const B_DIMG: u32 = 9;
pub(super) const B_GRAD: u32 = 10;
pub(super) const B_LISTS: u32 = 11;
pub(super) const NUM_BINDINGS: usize = 12;
/// Words before the pixel lists in `lists` (dispatch arguments and lengths, see classify.wgsl).
pub(super) const LIST_HEADER: u64 = 8;
/// Byte offsets of the indirect dispatch arguments of the covered and boundary lists.
pub(super) const COVERED_ARGS: u64 = 0;
pub(super) const BOUNDARY_ARGS: u64 = 12;

/// `Params` of common.wgsl.
#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
pub(super) struct Params {
    pub(super) width: u32,
    pub(super) height: u32,
    pub(super) num_views: u32,
    pub(super) num_verts: u32,
    pub(super) num_faces: u32,
    pub(super) antialias: u32,
    pub(super) near: f32,
    pub(super) _pad: u32,
}

/// `Cam` of common.wgsl.
#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
pub(super) struct GpuCam {
    pub(super) eye: [f32; 4],
    pub(super) right: [f32; 4],
    pub(super) up: [f32; 4],
    pub(super) forward: [f32; 4],
    pub(super) light: [f32; 4],
    pub(super) kc: [f32; 4],
}

pub(super) fn v4(v: DVec3) -> [f32; 4] {
    [v.x as f32, v.y as f32, v.z as f32, 0.0]
}

impl From<&Camera> for GpuCam {
    fn from(c: &Camera) -> Self {
        Self {
            eye: v4(c.eye),
            right: v4(c.right),
            up: v4(c.up),
            forward: v4(c.forward),
            light: v4(c.light),
            kc: [c.k as f32, c.cx as f32, c.cy as f32, 0.0],
        }
    }
}

/// Sizes the buffers were made for.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) struct Shape {
    pub(super) verts: usize,
    pub(super) faces: usize,
    pub(super) views: usize,
    pub(super) width: usize,
    pub(super) height: usize,
}

impl Shape {
    pub(super) fn pixels(&self) -> usize {
        self.views * self.width * self.height
    }
}

pub(super) struct Buffers {
    pub(super) shape: Shape,
    /// Indexed by binding number.
    pub(super) storage: Vec<wgpu::Buffer>,
    pub(super) readback_img: wgpu::Buffer,
    pub(super) readback_grad: wgpu::Buffer,
    pub(super) bind: Vec<wgpu::BindGroup>,
    /// The face list whose faces and adjacency are on the device.
    pub(super) faces: Option<Vec<[u32; 3]>>,
}

impl WgpuRenderer {
    pub(super) fn make_buffers(&self, shape: Shape) -> Buffers {
        let d = &self.device;
        let p = shape.pixels() as u64;
        let nv = shape.verts as u64;
        // Binding sizes must be non-zero.
        let sizes: [u64; NUM_BINDINGS] = [
            std::mem::size_of::<Params>() as u64,
            96 * shape.views.max(1) as u64,
            16 * nv.max(1),
            16 * nv.max(1),
            12 * shape.faces.max(1) as u64,
            12 * shape.faces.max(1) as u64,
            16 * (shape.views as u64 * nv).max(1),
            8 * p.max(1),
            8 * p.max(1),
            8 * p.max(1),
            24 * nv.max(1),
            4 * (LIST_HEADER + 2 * p),
        ];
        let names = [
            "params",
            "cams",
            "verts",
            "normals",
            "faces",
            "adjacency",
            "proj",
            "vis",
            "img",
            "dimg",
            "grad",
            "lists",
        ];
        let storage: Vec<wgpu::Buffer> = sizes
            .iter()
            .zip(names)
            .enumerate()
            .map(|(b, (&size, name))| {
                let kind = if b == B_PARAMS as usize {
                    wgpu::BufferUsages::UNIFORM
                } else if b == B_LISTS as usize {
                    wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::INDIRECT
                } else {
                    wgpu::BufferUsages::STORAGE
                };
                d.create_buffer(&wgpu::BufferDescriptor {
                    label: Some(name),
                    size,
                    usage: kind | wgpu::BufferUsages::COPY_DST | wgpu::BufferUsages::COPY_SRC,
                    mapped_at_creation: false,
                })
            })
            .collect();
        let readback = |label: &str, size: u64| {
            d.create_buffer(&wgpu::BufferDescriptor {
                label: Some(label),
                size,
                usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
                mapped_at_creation: false,
            })
        };
        let readback_img = readback("readback image", 4 * p.max(1));
        let readback_grad = readback("readback gradient", 24 * nv.max(1));
        let ps = &self.passes;
        let bind = [
            &ps.project,
            &ps.raster_depth,
            &ps.raster_id,
            &ps.shade,
            &ps.antialias,
            &ps.antialias_backward,
            &ps.shade_backward,
            &ps.classify,
            &ps.dispatch_args,
        ]
        .iter()
        .map(|pass| {
            let entries: Vec<wgpu::BindGroupEntry> = pass
                .bindings
                .iter()
                .map(|&b| wgpu::BindGroupEntry {
                    binding: b,
                    resource: storage[b as usize].as_entire_binding(),
                })
                .collect();
            d.create_bind_group(&wgpu::BindGroupDescriptor {
                label: Some(pass.name),
                layout: &pass.pipeline.get_bind_group_layout(0),
                entries: &entries,
            })
        })
        .collect();
        Buffers {
            shape,
            storage,
            readback_img,
            readback_grad,
            bind,
            faces: None,
        }
    }
}

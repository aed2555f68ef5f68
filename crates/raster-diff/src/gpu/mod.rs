//! The wgpu backend (feature `gpu`): forward and backward as WGSL compute shaders, f32 throughout.
//!
//! What runs where, per `render`:
//! - **CPU (f64)**: input validation, camera frames, the smooth vertex normals
//!   ([`crate::cpu::normals`], O(V + F)), and — once per face list, cached — the face adjacency
//!   used to find silhouette edges. These are uploaded as f32.
//! - **GPU**, all views of the batch in one dispatch per pass (`src/shaders/`, each file prefixed
//!   with `common.wgsl`):
//!   1. `project.wgsl`: screen position and depth per vertex per view;
//!   2. `rasterize.wgsl`: visibility (triangle id and depth per pixel) with a depth test, two
//!      passes of atomics (nearest depth, then smallest id at that depth);
//!   3. `classify.wgsl`: per pixel, appends covered pixels to one list and pixels with a
//!      neighbour of another triangle id to another (atomic counters), writes the background
//!      value 1.0 elsewhere, and turns the list lengths into indirect dispatch arguments;
//!   4. `shade.wgsl` `shade`, over the covered list: the CPU `shading::shade` math per pixel;
//!   5. `antialias.wgsl` `antialias`, over the boundary list: silhouette antialiasing as a
//!      per-pixel gather over the four neighbour pairs (deterministic, no atomics), the rules of
//!      [`crate::cpu::antialias`].
//!
//!   The lists keep the heavy passes off pixels where they would do nothing; on lavapipe (which
//!   runs 8-wide SIMD with execution masks, so code that is present but not taken still costs
//!   time) this made forward and forward+backward 2–2.7× faster.
//!
//! Per `backward` (the VJP of the most recent `render`, repeatable):
//! - **GPU**: `antialias_backward` over the boundary list (dL/d(colour) by gather, and the
//!   visibility gradient dL/dα · dα/dx of each blend, added by its target pixel), then
//!   `shade_backward` over the covered list (port of `shading::shade_jacobian` times dL/dc), both adding into per-vertex dL/dx and dL/dn (smooth normal)
//!   buffers with f32 atomic adds (compare-exchange loops on the bit patterns, `grad.wgsl`).
//! - **CPU (f64)**: the adjoint of the smooth normals, which turns dL/dn into dL/dx.
//!
//! Determinism: the forward pass is deterministic (its atomics take minima/maxima or hand out list
//! slots, and every pass over a list writes only its own pixel's outputs). The backward's
//! atomic adds run in scheduling order, so gradients vary run to run at the f32 rounding level,
//! whereas the CPU backend's are bit-identical. Agreement with the CPU reference (tests/gpu.rs):
//! f32 projection and edge tests can hand a pixel whose centre lies within rounding of an edge to
//! another triangle (a handful of 2.1 M pixels for 8 views at 512²); images agree to ~1e-5 where
//! coverage agrees; the VJP's relative L2 difference is ~1e-5–3e-4 for 1k–82k faces (the shading
//! math is arranged for f32, see `shade.wgsl`; numbers in docs/renderer.md, "Precision and
//! determinism").
//!
//! Buffers, bind groups and pipelines are kept across calls and rebuilt only when the vertex,
//! face, view or pixel counts change; faces and adjacency are uploaded only when the face list
//! changes. Input is validated on the CPU before anything is sent, and sizes beyond the device's
//! limits are reported as [`RenderError::DeviceLimit`].
//!
//! Files: `device.rs` (adapter, pipelines, limits, dispatch and read-back helpers),
//! `buffers.rs` (binding numbers, layouts, buffers and bind groups), and one host file per pass —
//! `project.rs`, `rasterize.rs`, `classify.rs`, `shade.rs`, `antialias.rs`, each building its
//! pipelines and recording its dispatches — mirroring `cpu/`; this file holds the shader sources
//! and the `Renderer` implementation that sequences the passes.

mod antialias;
mod buffers;
mod classify;
mod device;
mod project;
mod rasterize;
mod shade;

use glam::DVec3;

use crate::cpu::raster::Camera;
use crate::cpu::{RenderSettings, antialias as cpu_antialias, normals, validate};
use crate::{Images, RenderError, Renderer, View};
use buffers::{
    B_ADJ, B_CAMS, B_DIMG, B_FACES, B_GRAD, B_IMG, B_NORMALS, B_PARAMS, B_VERTS, B_VIS, Buffers,
    GpuCam, Params, Shape, v4,
};
use device::{Pipelines, WORKGROUP};

/// Declarations shared by every shader (bindings, camera layout, helpers).
pub const COMMON_WGSL: &str = include_str!("../shaders/common.wgsl");
/// f32 atomic adds into the gradient buffer (backward passes).
pub const GRAD_WGSL: &str = include_str!("../shaders/grad.wgsl");
/// Projection pass (`common.wgsl` + `project.wgsl`).
pub const PROJECT_WGSL: &str = concat!(
    include_str!("../shaders/common.wgsl"),
    include_str!("../shaders/project.wgsl")
);
/// Pixel classification into compacted lists (`common.wgsl` + `classify.wgsl`).
pub const CLASSIFY_WGSL: &str = concat!(
    include_str!("../shaders/common.wgsl"),
    include_str!("../shaders/classify.wgsl")
);
/// Visibility pass (`common.wgsl` + `rasterize.wgsl`).
pub const RASTERIZE_WGSL: &str = concat!(
    include_str!("../shaders/common.wgsl"),
    include_str!("../shaders/rasterize.wgsl")
);
/// Shading and its adjoint (`common.wgsl` + `grad.wgsl` + `shade.wgsl`).
pub const SHADE_WGSL: &str = concat!(
    include_str!("../shaders/common.wgsl"),
    include_str!("../shaders/grad.wgsl"),
    include_str!("../shaders/shade.wgsl")
);
/// Silhouette antialiasing and its adjoint (`common.wgsl` + `grad.wgsl` + `antialias.wgsl`).
pub const ANTIALIAS_WGSL: &str = concat!(
    include_str!("../shaders/common.wgsl"),
    include_str!("../shaders/grad.wgsl"),
    include_str!("../shaders/antialias.wgsl")
);
/// Every complete shader module, by name.
pub const SHADERS: [(&str, &str); 5] = [
    ("project", PROJECT_WGSL),
    ("rasterize", RASTERIZE_WGSL),
    ("classify", CLASSIFY_WGSL),
    ("shade", SHADE_WGSL),
    ("antialias", ANTIALIAS_WGSL),
];

/// What `backward` needs from the most recent `render` (the rest stays on the device).
struct ForwardState {
    vertices: Vec<[f64; 3]>,
    faces: Vec<[u32; 3]>,
    normals: Vec<DVec3>,
    normal_sums: Vec<DVec3>,
    shape: Shape,
}

/// Renderer running forward and backward as WGSL compute shaders (see the module docs for what
/// runs where).
pub struct WgpuRenderer {
    /// Rendering options (antialiasing, near plane), as for the CPU renderer.
    pub settings: RenderSettings,
    device: wgpu::Device,
    queue: wgpu::Queue,
    info: wgpu::AdapterInfo,
    passes: Pipelines,
    buffers: Option<Buffers>,
    state: Option<ForwardState>,
}

impl std::fmt::Debug for WgpuRenderer {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("WgpuRenderer")
            .field("adapter", &self.info.name)
            .field("settings", &self.settings)
            .finish_non_exhaustive()
    }
}

impl WgpuRenderer {
    /// Triangle id per pixel of the most recent render, `(view, row, column)`
    /// ([`NO_TRIANGLE`](crate::cpu::raster::NO_TRIANGLE) for background).
    pub fn triangle_ids(&self) -> Result<Vec<u32>, RenderError> {
        let st = self.state.as_ref().ok_or(RenderError::NoForwardState)?;
        let b = self.buffers.as_ref().ok_or(RenderError::NoForwardState)?;
        let p = st.shape.pixels();
        if p == 0 {
            return Ok(Vec::new());
        }
        let scope = self.device.push_error_scope(wgpu::ErrorFilter::Validation);
        let mut encoder = self
            .device
            .create_command_encoder(&wgpu::CommandEncoderDescriptor {
                label: Some("triangle ids"),
            });
        let bytes = 4 * p as u64;
        encoder.copy_buffer_to_buffer(&b.storage[B_VIS as usize], bytes, &b.readback_img, 0, bytes);
        let words = self.submit_and_read(encoder, &b.readback_img, p, scope)?;
        Ok(words.into_iter().map(|w| !w).collect())
    }
}

/// RGB images (the grey shading's value in all three channels, as the guidance's RGB path takes
/// them); `backward` takes RGB gradients and maps their channel sums back.
impl Renderer for WgpuRenderer {
    fn name(&self) -> String {
        format!(
            "wgpu on {} ({:?}): raster, shading, AA and their backward in WGSL; normals on cpu",
            self.info.name, self.info.device_type
        )
    }

    fn render(
        &mut self,
        vertices: &[[f64; 3]],
        faces: &[[u32; 3]],
        views: &[View],
        width: usize,
        height: usize,
    ) -> Result<Images, RenderError> {
        self.state = None;
        // Everything the GPU will index is checked here first.
        validate(vertices, faces, width, height)?;
        let cams: Vec<GpuCam> = views
            .iter()
            .map(|v| Camera::new(v, width, height).map(|c| GpuCam::from(&c)))
            .collect::<Result<_, _>>()?;
        let shape = Shape {
            verts: vertices.len(),
            faces: faces.len(),
            views: views.len(),
            width,
            height,
        };
        self.check_limits(&shape)?;
        let face_raw = normals::face_normals_raw(vertices, faces);
        let (vnormals, sums) = normals::smooth_normals(vertices, faces, &face_raw);
        if self.buffers.as_ref().is_none_or(|b| b.shape != shape) {
            let scope = self.device.push_error_scope(wgpu::ErrorFilter::Validation);
            let buffers = self.make_buffers(shape);
            if let Some(e) = pollster::block_on(scope.pop()) {
                self.buffers = None;
                return Err(RenderError::Gpu(format!("creating buffers: {e}")));
            }
            self.buffers = Some(buffers);
        }
        if let Some(b) = self.buffers.as_mut()
            && b.faces.as_deref() != Some(faces)
        {
            if !faces.is_empty() {
                let adjacency = cpu_antialias::face_adjacency(faces);
                self.queue.write_buffer(
                    &b.storage[B_FACES as usize],
                    0,
                    bytemuck::cast_slice(faces),
                );
                self.queue.write_buffer(
                    &b.storage[B_ADJ as usize],
                    0,
                    bytemuck::cast_slice(&adjacency),
                );
            }
            b.faces = Some(faces.to_vec());
        }
        let Some(b) = self.buffers.as_ref() else {
            return Err(RenderError::Gpu("buffers missing".into()));
        };
        let q = &self.queue;
        let params = Params {
            width: width as u32,
            height: height as u32,
            num_views: views.len() as u32,
            num_verts: vertices.len() as u32,
            num_faces: faces.len() as u32,
            antialias: u32::from(self.settings.antialias),
            near: self.settings.near as f32,
            _pad: 0,
        };
        q.write_buffer(
            &b.storage[B_PARAMS as usize],
            0,
            bytemuck::bytes_of(&params),
        );
        if !cams.is_empty() {
            q.write_buffer(&b.storage[B_CAMS as usize], 0, bytemuck::cast_slice(&cams));
        }
        if !vertices.is_empty() {
            let pos: Vec<[f32; 4]> = vertices
                .iter()
                .map(|p| [p[0] as f32, p[1] as f32, p[2] as f32, 1.0])
                .collect();
            let nrm: Vec<[f32; 4]> = vnormals.iter().map(|&n| v4(n)).collect();
            q.write_buffer(&b.storage[B_VERTS as usize], 0, bytemuck::cast_slice(&pos));
            q.write_buffer(
                &b.storage[B_NORMALS as usize],
                0,
                bytemuck::cast_slice(&nrm),
            );
        }
        let p = shape.pixels();
        let scope = self.device.push_error_scope(wgpu::ErrorFilter::Validation);
        let mut encoder = self
            .device
            .create_command_encoder(&wgpu::CommandEncoderDescriptor {
                label: Some("render"),
            });
        encoder.clear_buffer(&b.storage[B_VIS as usize], 0, None);
        let nviews = views.len() as u32;
        let ps = &self.passes;
        let vgroups = (vertices.len() as u32).div_ceil(WORKGROUP);
        let fgroups = (faces.len() as u32).div_ceil(WORKGROUP);
        let pixel_groups = [(width as u32).div_ceil(WORKGROUP), height as u32, nviews];
        project::encode(&mut encoder, ps, b, vgroups, nviews);
        rasterize::encode(&mut encoder, ps, b, fgroups, nviews);
        classify::encode(&mut encoder, ps, b, pixel_groups);
        shade::encode(&mut encoder, ps, b);
        antialias::encode(&mut encoder, ps, b);
        let bytes = 4 * p as u64;
        if p > 0 {
            encoder.copy_buffer_to_buffer(
                &b.storage[B_IMG as usize],
                bytes,
                &b.readback_img,
                0,
                bytes,
            );
        }
        let words = self.submit_and_read(encoder, &b.readback_img, p, scope)?;
        let mut rgb = Vec::with_capacity(3 * p);
        for w in words {
            rgb.extend_from_slice(&[f32::from_bits(w); 3]);
        }
        self.state = Some(ForwardState {
            vertices: vertices.to_vec(),
            faces: faces.to_vec(),
            normals: vnormals,
            normal_sums: sums,
            shape,
        });
        Ok(Images {
            count: views.len(),
            height,
            width,
            channels: image_batch::CHANNELS,
            rgb,
        })
    }

    fn backward(&mut self, d_images: &Images) -> Result<Vec<[f64; 3]>, RenderError> {
        let st = self.state.as_ref().ok_or(RenderError::NoForwardState)?;
        let b = self.buffers.as_ref().ok_or(RenderError::NoForwardState)?;
        let s = st.shape;
        // The three channels are one grey value: dL/d(grey) is the channel sum.
        d_images.check_gradient_shape(s.views, s.height, s.width, image_batch::CHANNELS)?;
        let d_grey: Vec<f32> = d_images
            .channel_sums()
            .into_iter()
            .map(|g| g as f32)
            .collect();
        let p = s.pixels();
        let nv = s.verts;
        if nv == 0 {
            return Ok(Vec::new());
        }
        let q = &self.queue;
        if p > 0 {
            // Both halves: pixels off the boundary list keep dL/d(colour) = dL/d(output).
            let dimg = &b.storage[B_DIMG as usize];
            q.write_buffer(dimg, 0, bytemuck::cast_slice(&d_grey));
            q.write_buffer(dimg, 4 * p as u64, bytemuck::cast_slice(&d_grey));
        }
        let scope = self.device.push_error_scope(wgpu::ErrorFilter::Validation);
        let mut encoder = self
            .device
            .create_command_encoder(&wgpu::CommandEncoderDescriptor {
                label: Some("backward"),
            });
        encoder.clear_buffer(&b.storage[B_GRAD as usize], 0, None);
        antialias::encode_backward(&mut encoder, &self.passes, b);
        shade::encode_backward(&mut encoder, &self.passes, b);
        let bytes = 24 * nv as u64;
        encoder.copy_buffer_to_buffer(&b.storage[B_GRAD as usize], 0, &b.readback_grad, 0, bytes);
        let words = self.submit_and_read(encoder, &b.readback_grad, 6 * nv, scope)?;
        let g = |i: usize| f64::from(f32::from_bits(words[i]));
        let mut dx: Vec<DVec3> = (0..nv)
            .map(|v| DVec3::new(g(3 * v), g(3 * v + 1), g(3 * v + 2)))
            .collect();
        let dn: Vec<DVec3> = (0..nv)
            .map(|v| DVec3::new(g(3 * (nv + v)), g(3 * (nv + v) + 1), g(3 * (nv + v) + 2)))
            .collect();
        normals::smooth_normals_adjoint(
            &st.vertices,
            &st.faces,
            &st.normals,
            &st.normal_sums,
            &dn,
            &mut dx,
        );
        Ok(dx.into_iter().map(Into::into).collect())
    }
}

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
//!   `shade_backward` over the covered list (port of `shading::shade_adjoint`), both adding into per-vertex dL/dx and dL/dn (smooth normal)
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

use std::sync::mpsc;

use glam::DVec3;

use crate::cpu::raster::Camera;
use crate::cpu::{RenderSettings, antialias, normals, validate};
use crate::{Images, RenderError, Renderer, View};

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

/// Threads per workgroup along x in every shader.
const WORKGROUP: u32 = 64;
/// Storage buffers bound by the widest pass (`antialias_backward`).
const STORAGE_BUFFERS_NEEDED: u32 = 10;

// Binding numbers (see common.wgsl).
const B_PARAMS: u32 = 0;
const B_CAMS: u32 = 1;
const B_VERTS: u32 = 2;
const B_NORMALS: u32 = 3;
const B_FACES: u32 = 4;
const B_ADJ: u32 = 5;
const B_PROJ: u32 = 6;
const B_VIS: u32 = 7;
const B_IMG: u32 = 8;
const B_DIMG: u32 = 9;
const B_GRAD: u32 = 10;
const B_LISTS: u32 = 11;
const NUM_BINDINGS: usize = 12;
/// Words before the pixel lists in `lists` (dispatch arguments and lengths, see classify.wgsl).
const LIST_HEADER: u64 = 8;
/// Byte offsets of the indirect dispatch arguments of the covered and boundary lists.
const COVERED_ARGS: u64 = 0;
const BOUNDARY_ARGS: u64 = 12;

fn gpu_err(e: impl std::fmt::Display) -> RenderError {
    RenderError::Gpu(e.to_string())
}

/// `Params` of common.wgsl.
#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
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

/// `Cam` of common.wgsl.
#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct GpuCam {
    eye: [f32; 4],
    right: [f32; 4],
    up: [f32; 4],
    forward: [f32; 4],
    light: [f32; 4],
    kc: [f32; 4],
}

fn v4(v: DVec3) -> [f32; 4] {
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

/// One compute pipeline and the bindings its entry point uses.
struct Pass {
    pipeline: wgpu::ComputePipeline,
    bindings: &'static [u32],
    name: &'static str,
}

struct Pipelines {
    project: Pass,
    raster_depth: Pass,
    raster_id: Pass,
    classify: Pass,
    dispatch_args: Pass,
    shade: Pass,
    antialias: Pass,
    antialias_backward: Pass,
    shade_backward: Pass,
}

/// Sizes the buffers were made for.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
struct Shape {
    verts: usize,
    faces: usize,
    views: usize,
    width: usize,
    height: usize,
}

impl Shape {
    fn pixels(&self) -> usize {
        self.views * self.width * self.height
    }
}

struct Buffers {
    shape: Shape,
    /// Indexed by binding number.
    storage: Vec<wgpu::Buffer>,
    readback_img: wgpu::Buffer,
    readback_grad: wgpu::Buffer,
    bind: Vec<wgpu::BindGroup>,
    /// The face list whose faces and adjacency are on the device.
    faces: Option<Vec<[u32; 3]>>,
}

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

fn limit(what: impl Into<String>, needed: u64, limit: u64) -> Result<(), RenderError> {
    if needed > limit {
        Err(RenderError::DeviceLimit {
            what: what.into(),
            needed,
            limit,
        })
    } else {
        Ok(())
    }
}

impl WgpuRenderer {
    /// Opens the default adapter (high performance preferred) and builds the pipelines. Errors
    /// when there is no adapter or the device cannot bind enough storage buffers.
    pub fn new(settings: RenderSettings) -> Result<Self, RenderError> {
        let instance =
            wgpu::Instance::new(wgpu::InstanceDescriptor::new_without_display_handle_from_env());
        let adapter = pollster::block_on(instance.request_adapter(&wgpu::RequestAdapterOptions {
            power_preference: wgpu::PowerPreference::HighPerformance,
            ..Default::default()
        }))
        .map_err(gpu_err)?;
        let info = adapter.get_info();
        let limits = adapter.limits();
        limit(
            "storage buffers per shader stage",
            u64::from(STORAGE_BUFFERS_NEEDED),
            u64::from(limits.max_storage_buffers_per_shader_stage),
        )?;
        let (device, queue) = pollster::block_on(adapter.request_device(&wgpu::DeviceDescriptor {
            label: Some("raster-diff"),
            required_limits: limits,
            ..Default::default()
        }))
        .map_err(gpu_err)?;
        let scope = device.push_error_scope(wgpu::ErrorFilter::Validation);
        let module = |name: &str, src: &str| {
            device.create_shader_module(wgpu::ShaderModuleDescriptor {
                label: Some(name),
                source: wgpu::ShaderSource::Wgsl(src.into()),
            })
        };
        let project_m = module("project.wgsl", PROJECT_WGSL);
        let raster_m = module("rasterize.wgsl", RASTERIZE_WGSL);
        let classify_m = module("classify.wgsl", CLASSIFY_WGSL);
        let shade_m = module("shade.wgsl", SHADE_WGSL);
        let aa_m = module("antialias.wgsl", ANTIALIAS_WGSL);
        let pass = |m: &wgpu::ShaderModule, entry: &'static str, bindings: &'static [u32]| Pass {
            pipeline: device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
                label: Some(entry),
                layout: None,
                module: m,
                entry_point: Some(entry),
                compilation_options: Default::default(),
                cache: None,
            }),
            bindings,
            name: entry,
        };
        let passes = Pipelines {
            project: pass(&project_m, "project", &[B_PARAMS, B_CAMS, B_VERTS, B_PROJ]),
            raster_depth: pass(
                &raster_m,
                "raster_depth",
                &[B_PARAMS, B_FACES, B_PROJ, B_VIS],
            ),
            raster_id: pass(&raster_m, "raster_id", &[B_PARAMS, B_FACES, B_PROJ, B_VIS]),
            classify: pass(&classify_m, "classify", &[B_PARAMS, B_VIS, B_IMG, B_LISTS]),
            dispatch_args: pass(&classify_m, "dispatch_args", &[B_LISTS]),
            shade: pass(
                &shade_m,
                "shade",
                &[
                    B_PARAMS, B_CAMS, B_VERTS, B_NORMALS, B_FACES, B_VIS, B_IMG, B_LISTS,
                ],
            ),
            antialias: pass(
                &aa_m,
                "antialias",
                &[
                    B_PARAMS, B_CAMS, B_VERTS, B_FACES, B_ADJ, B_PROJ, B_VIS, B_IMG, B_LISTS,
                ],
            ),
            antialias_backward: pass(
                &aa_m,
                "antialias_backward",
                &[
                    B_PARAMS, B_CAMS, B_VERTS, B_FACES, B_ADJ, B_PROJ, B_VIS, B_IMG, B_DIMG,
                    B_GRAD, B_LISTS,
                ],
            ),
            shade_backward: pass(
                &shade_m,
                "shade_backward",
                &[
                    B_PARAMS, B_CAMS, B_VERTS, B_NORMALS, B_FACES, B_VIS, B_DIMG, B_GRAD, B_LISTS,
                ],
            ),
        };
        if let Some(e) = pollster::block_on(scope.pop()) {
            return Err(RenderError::Gpu(format!("building the pipelines: {e}")));
        }
        Ok(Self {
            settings,
            device,
            queue,
            info,
            passes,
            buffers: None,
            state: None,
        })
    }

    /// The adapter in use.
    pub fn adapter_info(&self) -> &wgpu::AdapterInfo {
        &self.info
    }

    /// Whether the adapter is a software (CPU) implementation such as lavapipe.
    pub fn is_software(&self) -> bool {
        self.info.device_type == wgpu::DeviceType::Cpu
    }

    /// The largest storage buffer binding this renderer will use, in bytes (the device's binding
    /// and buffer size limits, and 4 GiB − 1 so that shader indices fit u32).
    pub fn max_storage_buffer_binding_size(&self) -> u64 {
        let l = self.device.limits();
        l.max_storage_buffer_binding_size
            .min(l.max_buffer_size.min(u64::from(u32::MAX)))
    }

    /// Checks a shape against the device limits.
    fn check_limits(&self, s: &Shape) -> Result<(), RenderError> {
        let l = self.device.limits();
        let max_binding = self.max_storage_buffer_binding_size();
        let p = s.pixels() as u64;
        limit(
            "storage buffer of 2 × views × width × height f32 (visibility, image, image gradient)",
            8 * p,
            max_binding,
        )?;
        limit(
            "pixel lists buffer ((8 + 2 × views × width × height) × 4 bytes)",
            4 * (LIST_HEADER + 2 * p),
            max_binding,
        )?;
        limit(
            "projected vertices buffer (views × vertices × 16 bytes)",
            16 * (s.views * s.verts) as u64,
            max_binding,
        )?;
        limit(
            "vertex gradient buffer (6 × vertices × 4 bytes)",
            24 * s.verts as u64,
            max_binding,
        )?;
        limit(
            "face buffer (faces × 12 bytes)",
            12 * s.faces as u64,
            max_binding,
        )?;
        limit(
            "camera buffer (views × 96 bytes)",
            96 * s.views as u64,
            max_binding,
        )?;
        let groups = u64::from(l.max_compute_workgroups_per_dimension);
        let per = u64::from(WORKGROUP);
        limit(
            "workgroups along x for the vertices",
            (s.verts as u64).div_ceil(per),
            groups,
        )?;
        limit(
            "workgroups along x for the faces",
            (s.faces as u64).div_ceil(per),
            groups,
        )?;
        limit(
            "workgroups along x for the image columns",
            (s.width as u64).div_ceil(per),
            groups,
        )?;
        limit(
            "workgroups along y (rows, views)",
            s.height.max(s.views) as u64,
            groups,
        )
    }

    fn make_buffers(&self, shape: Shape) -> Buffers {
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

    /// Records one dispatch of `pass` (bind group `bind`) into `encoder`.
    fn dispatch(
        encoder: &mut wgpu::CommandEncoder,
        pass: &Pass,
        bind: &wgpu::BindGroup,
        groups: [u32; 3],
    ) {
        if groups.contains(&0) {
            return;
        }
        let mut cp = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
            label: Some(pass.name),
            timestamp_writes: None,
        });
        cp.set_pipeline(&pass.pipeline);
        cp.set_bind_group(0, bind, &[]);
        cp.dispatch_workgroups(groups[0], groups[1], groups[2]);
    }

    /// Records one indirect dispatch of `pass`, its workgroup counts read from `args` at `offset`.
    fn dispatch_indirect(
        encoder: &mut wgpu::CommandEncoder,
        pass: &Pass,
        bind: &wgpu::BindGroup,
        args: &wgpu::Buffer,
        offset: u64,
    ) {
        let mut cp = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
            label: Some(pass.name),
            timestamp_writes: None,
        });
        cp.set_pipeline(&pass.pipeline);
        cp.set_bind_group(0, bind, &[]);
        cp.dispatch_workgroups_indirect(args, offset);
    }

    /// Submits `encoder` (which must end with a copy into `readback`), waits, and returns the
    /// first `words` 32-bit words of `readback`. Validation errors become [`RenderError::Gpu`].
    fn submit_and_read(
        &self,
        encoder: wgpu::CommandEncoder,
        readback: &wgpu::Buffer,
        words: usize,
        scope: wgpu::ErrorScopeGuard,
    ) -> Result<Vec<u32>, RenderError> {
        self.queue.submit([encoder.finish()]);
        if let Some(e) = pollster::block_on(scope.pop()) {
            return Err(RenderError::Gpu(e.to_string()));
        }
        let bytes = (4 * words) as u64;
        let slice = readback.slice(..bytes.max(4));
        let (tx, rx) = mpsc::channel();
        slice.map_async(wgpu::MapMode::Read, move |r| {
            let _ = tx.send(r);
        });
        self.device
            .poll(wgpu::PollType::wait_indefinitely())
            .map_err(gpu_err)?;
        rx.recv().map_err(gpu_err)?.map_err(gpu_err)?;
        let out = {
            let view = slice.get_mapped_range().map_err(gpu_err)?;
            bytemuck::cast_slice::<u8, u32>(&view)[..words].to_vec()
        };
        readback.unmap();
        Ok(out)
    }

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
                let adjacency = antialias::face_adjacency(faces);
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
        Self::dispatch(&mut encoder, &ps.project, &b.bind[0], [vgroups, nviews, 1]);
        Self::dispatch(
            &mut encoder,
            &ps.raster_depth,
            &b.bind[1],
            [fgroups, nviews, 1],
        );
        Self::dispatch(
            &mut encoder,
            &ps.raster_id,
            &b.bind[2],
            [fgroups, nviews, 1],
        );
        // Pixel lists: covered pixels (shading) and pixels next to another id (antialiasing).
        let lists = &b.storage[B_LISTS as usize];
        encoder.clear_buffer(lists, 0, Some(4 * LIST_HEADER));
        Self::dispatch(&mut encoder, &ps.classify, &b.bind[7], pixel_groups);
        Self::dispatch(&mut encoder, &ps.dispatch_args, &b.bind[8], [1, 1, 1]);
        Self::dispatch_indirect(&mut encoder, &ps.shade, &b.bind[3], lists, COVERED_ARGS);
        Self::dispatch_indirect(
            &mut encoder,
            &ps.antialias,
            &b.bind[4],
            lists,
            BOUNDARY_ARGS,
        );
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
            rgb,
        })
    }

    fn backward(&mut self, d_images: &Images) -> Result<Vec<[f64; 3]>, RenderError> {
        let st = self.state.as_ref().ok_or(RenderError::NoForwardState)?;
        let b = self.buffers.as_ref().ok_or(RenderError::NoForwardState)?;
        let s = st.shape;
        let d_grey: Vec<f32> = d_images
            .grey_gradient(s.views, s.height, s.width)?
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
        let ps = &self.passes;
        let lists = &b.storage[B_LISTS as usize];
        Self::dispatch_indirect(
            &mut encoder,
            &ps.antialias_backward,
            &b.bind[5],
            lists,
            BOUNDARY_ARGS,
        );
        Self::dispatch_indirect(
            &mut encoder,
            &ps.shade_backward,
            &b.bind[6],
            lists,
            COVERED_ARGS,
        );
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

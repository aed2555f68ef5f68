//! The wgpu backend (feature `gpu`) — **partial**: the visibility pass (which triangle each pixel
//! centre sees, with a depth test) runs as a WGSL compute shader (`shaders/rasterize.wgsl`);
//! shading, silhouette antialiasing and the whole backward pass then run on the CPU reference code
//! from those visibility buffers. So images and gradients are the CPU backend's up to the f32
//! precision of the GPU's coverage and depth tests.
//!
//! Vertices are projected on the CPU (f64, then f32 screen positions and depths are uploaded).

use std::sync::mpsc;

use wgpu::util::DeviceExt;

use crate::cpu::raster::{Camera, NO_TRIANGLE, project_vertices};
use crate::cpu::{CpuRenderer, RenderSettings, Visibility};
use crate::{Images, RenderError, Renderer, View};

/// WGSL source of the visibility pass.
pub const RASTERIZE_WGSL: &str = include_str!("shaders/rasterize.wgsl");

const WORKGROUP: u32 = 64;

fn gpu_err(e: impl std::fmt::Display) -> RenderError {
    RenderError::Gpu(e.to_string())
}

#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct Params {
    width: u32,
    height: u32,
    num_faces: u32,
    pass_index: u32,
}

/// Renderer whose rasterization runs on a wgpu device (see the module docs for what runs where).
pub struct WgpuRenderer {
    device: wgpu::Device,
    queue: wgpu::Queue,
    pipeline: wgpu::ComputePipeline,
    info: wgpu::AdapterInfo,
    cpu: CpuRenderer,
}

impl std::fmt::Debug for WgpuRenderer {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("WgpuRenderer")
            .field("adapter", &self.info.name)
            .finish_non_exhaustive()
    }
}

impl WgpuRenderer {
    /// Opens the default adapter (high performance preferred). Errors when there is none.
    pub fn new(settings: RenderSettings) -> Result<Self, RenderError> {
        let instance =
            wgpu::Instance::new(wgpu::InstanceDescriptor::new_without_display_handle_from_env());
        let adapter = pollster::block_on(instance.request_adapter(&wgpu::RequestAdapterOptions {
            power_preference: wgpu::PowerPreference::HighPerformance,
            ..Default::default()
        }))
        .map_err(gpu_err)?;
        let info = adapter.get_info();
        let (device, queue) = pollster::block_on(adapter.request_device(&wgpu::DeviceDescriptor {
            label: Some("raster-diff"),
            required_limits: adapter.limits(),
            ..Default::default()
        }))
        .map_err(gpu_err)?;
        let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("rasterize.wgsl"),
            source: wgpu::ShaderSource::Wgsl(RASTERIZE_WGSL.into()),
        });
        let pipeline = device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
            label: Some("rasterize"),
            layout: None,
            module: &module,
            entry_point: Some("main"),
            compilation_options: Default::default(),
            cache: None,
        });
        Ok(Self {
            device,
            queue,
            pipeline,
            info,
            cpu: CpuRenderer::new(settings),
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

    /// The GPU visibility pass for one view.
    pub fn visibility(
        &self,
        vertices: &[[f64; 3]],
        faces: &[[u32; 3]],
        view: &View,
        width: usize,
        height: usize,
    ) -> Result<Visibility, RenderError> {
        let camera = Camera::new(view, width, height)?;
        let near = self.cpu.settings.near;
        let verts: Vec<[f32; 4]> = project_vertices(&camera, vertices)
            .iter()
            .map(|p| {
                let ok = p.cam.z >= near;
                [
                    p.screen[0] as f32,
                    p.screen[1] as f32,
                    p.cam.z as f32,
                    if ok { 1.0 } else { 0.0 },
                ]
            })
            .collect();
        let n = width * height;
        let groups = u32::try_from(faces.len().div_ceil(WORKGROUP as usize)).map_err(gpu_err)?;
        if groups > self.device.limits().max_compute_workgroups_per_dimension {
            return Err(RenderError::InvalidInput(format!(
                "{} faces are too many for one dispatch",
                faces.len()
            )));
        }
        if faces.is_empty() || vertices.is_empty() {
            return Ok(Visibility {
                ids: vec![NO_TRIANGLE; n],
                depth: vec![f64::INFINITY; n],
            });
        }
        let d = &self.device;
        let storage = |label: &str, bytes: &[u8], usage: wgpu::BufferUsages| {
            d.create_buffer_init(&wgpu::util::BufferInitDescriptor {
                label: Some(label),
                contents: bytes,
                usage,
            })
        };
        let ro = wgpu::BufferUsages::STORAGE;
        let rw = wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC;
        let vbuf = storage("verts", bytemuck::cast_slice(&verts), ro);
        let fbuf = storage("faces", bytemuck::cast_slice(faces), ro);
        let init = vec![u32::MAX; n];
        let depth = storage("depth", bytemuck::cast_slice(&init), rw);
        let ids = storage("ids", bytemuck::cast_slice(&init), rw);
        let size = (n * 4) as u64;
        let readback = d.create_buffer(&wgpu::BufferDescriptor {
            label: Some("readback"),
            size: 2 * size,
            usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let mut encoder = d.create_command_encoder(&wgpu::CommandEncoderDescriptor {
            label: Some("rasterize"),
        });
        for pass_index in 0..2u32 {
            let params = Params {
                width: width as u32,
                height: height as u32,
                num_faces: faces.len() as u32,
                pass_index,
            };
            let pbuf = storage(
                "params",
                bytemuck::bytes_of(&params),
                wgpu::BufferUsages::UNIFORM,
            );
            let bind = d.create_bind_group(&wgpu::BindGroupDescriptor {
                label: Some("rasterize"),
                layout: &self.pipeline.get_bind_group_layout(0),
                entries: &[
                    wgpu::BindGroupEntry {
                        binding: 0,
                        resource: pbuf.as_entire_binding(),
                    },
                    wgpu::BindGroupEntry {
                        binding: 1,
                        resource: vbuf.as_entire_binding(),
                    },
                    wgpu::BindGroupEntry {
                        binding: 2,
                        resource: fbuf.as_entire_binding(),
                    },
                    wgpu::BindGroupEntry {
                        binding: 3,
                        resource: depth.as_entire_binding(),
                    },
                    wgpu::BindGroupEntry {
                        binding: 4,
                        resource: ids.as_entire_binding(),
                    },
                ],
            });
            let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
                label: Some("rasterize"),
                timestamp_writes: None,
            });
            pass.set_pipeline(&self.pipeline);
            pass.set_bind_group(0, &bind, &[]);
            pass.dispatch_workgroups(groups, 1, 1);
        }
        encoder.copy_buffer_to_buffer(&depth, 0, &readback, 0, size);
        encoder.copy_buffer_to_buffer(&ids, 0, &readback, size, size);
        self.queue.submit([encoder.finish()]);
        let (tx, rx) = mpsc::channel();
        readback.slice(..).map_async(wgpu::MapMode::Read, move |r| {
            let _ = tx.send(r);
        });
        d.poll(wgpu::PollType::wait_indefinitely())
            .map_err(gpu_err)?;
        rx.recv().map_err(gpu_err)?.map_err(gpu_err)?;
        let out = {
            let bytes = readback.slice(..).get_mapped_range().map_err(gpu_err)?;
            let words: Vec<u32> = bytes
                .chunks_exact(4)
                .map(|c| u32::from_le_bytes([c[0], c[1], c[2], c[3]]))
                .collect();
            let depth = words[..n]
                .iter()
                .map(|&b| {
                    if b == u32::MAX {
                        f64::INFINITY
                    } else {
                        f64::from(f32::from_bits(b))
                    }
                })
                .collect();
            Visibility {
                ids: words[n..2 * n].to_vec(),
                depth,
            }
        };
        readback.unmap();
        Ok(out)
    }
}

impl Renderer for WgpuRenderer {
    fn name(&self) -> String {
        format!(
            "wgpu visibility on {} ({:?}) + cpu shading/AA/backward",
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
        // Validate on the CPU side first so the GPU never sees an out-of-range index.
        // Invalid input never reaches the GPU: the CPU renderer reports it as a typed error.
        let n = vertices.len();
        if faces.iter().any(|f| f.iter().any(|&v| v as usize >= n))
            || vertices.iter().flatten().any(|c| !c.is_finite())
            || width == 0
            || height == 0
        {
            return self.cpu.render(vertices, faces, views, width, height);
        }
        let vis = views
            .iter()
            .map(|v| self.visibility(vertices, faces, v, width, height))
            .collect::<Result<Vec<_>, _>>()?;
        let grey = self
            .cpu
            .render_grey_with(vertices, faces, views, width, height, Some(vis))?;
        Ok(Images::from_grey(views.len(), height, width, &grey))
    }

    fn backward(&mut self, d_images: &Images) -> Result<Vec<[f64; 3]>, RenderError> {
        self.cpu.backward(d_images)
    }
}

//! The device: adapter and queue, the compute pipelines of every pass, device limits, and the
//! helpers that record dispatches and read results back.

use std::sync::mpsc;

use super::buffers::{LIST_HEADER, Shape};
use super::{WgpuRenderer, antialias, classify, project, rasterize, shade};
use crate::RenderError;
use crate::cpu::RenderSettings;

/// Threads per workgroup along x in every shader.
pub(super) const WORKGROUP: u32 = 64;
/// Storage buffers bound by the widest pass (`antialias_backward`).
const STORAGE_BUFFERS_NEEDED: u32 = 10;

pub(super) fn gpu_err(e: impl std::fmt::Display) -> RenderError {
    RenderError::Gpu(e.to_string())
}

/// One compute pipeline and the bindings its entry point uses.
pub(super) struct Pass {
    pub(super) pipeline: wgpu::ComputePipeline,
    pub(super) bindings: &'static [u32],
    pub(super) name: &'static str,
}

pub(super) struct Pipelines {
    pub(super) project: Pass,
    pub(super) raster_depth: Pass,
    pub(super) raster_id: Pass,
    pub(super) classify: Pass,
    pub(super) dispatch_args: Pass,
    pub(super) shade: Pass,
    pub(super) antialias: Pass,
    pub(super) antialias_backward: Pass,
    pub(super) shade_backward: Pass,
}

impl Pass {
    /// The compute pipeline of `entry` in `module` (layout derived from the shader).
    pub(super) fn new(
        device: &wgpu::Device,
        module: &wgpu::ShaderModule,
        entry: &'static str,
        bindings: &'static [u32],
    ) -> Self {
        Pass {
            pipeline: device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
                label: Some(entry),
                layout: None,
                module,
                entry_point: Some(entry),
                compilation_options: Default::default(),
                cache: None,
            }),
            bindings,
            name: entry,
        }
    }
}

/// A shader module from WGSL source.
pub(super) fn module(device: &wgpu::Device, name: &str, src: &str) -> wgpu::ShaderModule {
    device.create_shader_module(wgpu::ShaderModuleDescriptor {
        label: Some(name),
        source: wgpu::ShaderSource::Wgsl(src.into()),
    })
}

impl Pipelines {
    /// Every pass's pipelines (each pass file builds its own).
    fn new(device: &wgpu::Device) -> Self {
        let project = project::pipeline(device);
        let (raster_depth, raster_id) = rasterize::pipelines(device);
        let (classify, dispatch_args) = classify::pipelines(device);
        let (shade, shade_backward) = shade::pipelines(device);
        let (antialias, antialias_backward) = antialias::pipelines(device);
        Self {
            project,
            raster_depth,
            raster_id,
            classify,
            dispatch_args,
            shade,
            antialias,
            antialias_backward,
            shade_backward,
        }
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
        let passes = Pipelines::new(&device);
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
    pub(super) fn check_limits(&self, s: &Shape) -> Result<(), RenderError> {
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

    /// Records one dispatch of `pass` (bind group `bind`) into `encoder`.
    pub(super) fn dispatch(
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
    pub(super) fn dispatch_indirect(
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
    pub(super) fn submit_and_read(
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
}

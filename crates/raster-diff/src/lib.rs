//! Differentiable triangle rasterizer with the reference cameras and shading.
//!
//! Images are `f32` in `[0, 1]`, laid out `(view, row, column, channel)` with row 0 at the top:
//! grey (one channel) from the CPU backend, RGB from the wgpu backend (the same grey value in
//! every channel; the shading is grey).
//!
//! - [`backend`]: the backend choice ([`Backend`]: `auto`, `cpu`, `gpu`) and [`select_renderer`].
//! - [`camera`]: the reference view sampler, turntable orbits, the adaptive distance multiplier.
//! - [`cpu`]: the CPU reference backend [`CpuRenderer`] (forward and VJP, silhouette antialiasing).
//! - [`image`]: PNG output and contact sheets.
//!
//! Conventions (projection, pixel centres, fill rule, shading) are in `docs/renderer.md` and in the
//! module docs of [`cpu::raster`], [`cpu::shading`] and [`cpu::antialias`].

pub mod backend;
pub mod camera;
pub mod cpu;
#[cfg(feature = "gpu")]
pub mod gpu;
pub mod image;

pub use backend::{Backend, select_renderer};
pub use camera::{CameraConfig, adapt_multiplier, orbit_views, sample_views};
pub use cpu::{CpuRenderer, RenderSettings};

/// One camera view and its light.
#[derive(Clone, Debug, PartialEq)]
pub struct View {
    /// Camera position (world space).
    pub eye: [f64; 3],
    /// Point the camera looks at.
    pub target: [f64; 3],
    /// World up direction (+y by default).
    pub up: [f64; 3],
    /// Vertical field of view in degrees (90° = focal length 1, the reference's effective value).
    pub fov_y_deg: f64,
    /// Point light position; only its direction from the shaded point matters (no falloff).
    pub light_pos: [f64; 3],
}

/// A batch of rendered images, `(view, row, column, channel)` row-major, grey or RGB: the type the guidance
/// takes too (it lives in the dependency-free `image-batch` crate so that `csd` can name it without
/// depending on the renderer).
pub use image_batch::{Images, ImagesError};

/// Errors from rendering.
#[derive(Debug, thiserror::Error)]
pub enum RenderError {
    /// The inputs are inconsistent (for example a face index out of range).
    #[error("invalid render input: {0}")]
    InvalidInput(String),
    /// `backward` was called before any `render`.
    #[error("backward called without a preceding render")]
    NoForwardState,
    /// A GPU backend failed.
    #[error("GPU backend error: {0}")]
    Gpu(String),
    /// The request exceeds a limit of the GPU device (buffer size, dispatch size, bindings).
    #[error("GPU device limit exceeded: {what} needs {needed}, the device allows {limit}")]
    DeviceLimit {
        /// What hit the limit (e.g. "storage buffer `vis` (2 × views × pixels × 4 bytes)").
        what: String,
        /// The amount needed.
        needed: u64,
        /// The device's limit.
        limit: u64,
    },
    /// The backend asked for cannot run here (`gpu` without an adapter, or in a build without
    /// the `gpu` feature).
    #[error("renderer backend `{backend}` is not available: {reason}")]
    BackendUnavailable {
        /// The backend asked for.
        backend: Backend,
        /// Why it cannot run.
        reason: String,
    },
}

impl From<ImagesError> for RenderError {
    fn from(e: ImagesError) -> Self {
        RenderError::InvalidInput(e.to_string())
    }
}

/// The seam between the optimization loop and a rendering backend.
///
/// A backend's renders have the channel count it chooses ([`Images::channels`]): the CPU backend's
/// are grey (one channel, its shading's value), the wgpu backend's RGB (the grey value in all three
/// channels). `backward` takes image gradients of the render's channel count.
///
/// `backward` is the vector-Jacobian product of the **most recent** `render` call: it may be
/// called several times for one render. The loop takes two Adam steps per render batch and maps
/// both sub-steps' image gradients back with one [`backward_many`](Renderer::backward_many).
pub trait Renderer: Send {
    /// Backend name for logs ("cpu", "wgpu (lavapipe)", …).
    fn name(&self) -> String;
    /// Renders `views` of the mesh at `width`×`height`.
    fn render(
        &mut self,
        vertices: &[[f64; 3]],
        faces: &[[u32; 3]],
        views: &[View],
        width: usize,
        height: usize,
    ) -> Result<Images, RenderError>;
    /// Maps dL/dimages (same layout and channel count as the last render's output) to
    /// dL/dvertices.
    fn backward(&mut self, d_images: &Images) -> Result<Vec<[f64; 3]>, RenderError>;
    /// [`backward`](Self::backward) for several image gradients of the same render: one
    /// dL/dvertices per gradient, in order, each equal to what `backward` returns for it alone.
    /// The default calls `backward` once per gradient; a backend may share the work that does
    /// not depend on the gradient (the CPU backend visits every pixel once).
    fn backward_many(&mut self, d_images: &[&Images]) -> Result<Vec<Vec<[f64; 3]>>, RenderError> {
        d_images.iter().map(|d| self.backward(d)).collect()
    }
}

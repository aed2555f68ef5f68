//! Which backend renders: the choice a config file names ([`Backend`], the `render.backend` key)
//! and the selection that turns it into a renderer ([`select_renderer`]).

use crate::{CpuRenderer, RenderError, Renderer};

/// The renderer backend to use.
///
/// Under feature `serde` it (de)serializes as `"auto"`, `"cpu"` or `"gpu"` (a config file's
/// `render.backend` key embeds it).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
#[cfg_attr(
    feature = "serde",
    derive(serde::Serialize, serde::Deserialize),
    serde(rename_all = "snake_case")
)]
pub enum Backend {
    /// The wgpu backend on a hardware adapter, else the CPU renderer (on a software adapter such
    /// as lavapipe the CPU renderer is faster; without the `gpu` feature it is the only one).
    #[default]
    Auto,
    /// The CPU reference renderer.
    Cpu,
    /// The wgpu backend on whatever adapter there is, a software one (lavapipe) included; an
    /// error when there is none or this build lacks the `gpu` feature.
    Gpu,
}

impl Backend {
    /// The name a config file uses (`"auto"`, `"cpu"`, `"gpu"`).
    pub fn name(self) -> &'static str {
        match self {
            Backend::Auto => "auto",
            Backend::Cpu => "cpu",
            Backend::Gpu => "gpu",
        }
    }
}

impl std::fmt::Display for Backend {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

/// The renderer `backend` asks for, and a sentence saying what was chosen and why (for the log):
///
/// - [`Backend::Cpu`]: the CPU renderer (`"cpu (2 threads): requested"`);
/// - [`Backend::Auto`]: the wgpu renderer when the adapter is a real (non-CPU) GPU; on a software
///   adapter (lavapipe), without any adapter, or without the `gpu` feature the CPU renderer, the
///   sentence saying which of these it was. Never an error;
/// - [`Backend::Gpu`]: the wgpu renderer on any adapter, or [`RenderError::BackendUnavailable`]
///   when there is no adapter or the build lacks the `gpu` feature (no silent fallback).
pub fn select_renderer(backend: Backend) -> Result<(Box<dyn Renderer>, String), RenderError> {
    match backend {
        Backend::Cpu => {
            let r = CpuRenderer::default();
            let why = format!("{}: requested", r.name());
            Ok((Box::new(r), why))
        }
        Backend::Auto => Ok(select_auto()),
        Backend::Gpu => select_gpu(),
    }
}

#[cfg(feature = "gpu")]
fn select_auto() -> (Box<dyn Renderer>, String) {
    let cpu = CpuRenderer::default();
    match crate::gpu::WgpuRenderer::new(crate::RenderSettings::default()) {
        Ok(g) if !g.is_software() => {
            let why = format!("{}: a hardware adapter was found", g.name());
            (Box::new(g), why)
        }
        Ok(g) => {
            let why = format!(
                "{}: the only adapter is a software one ({})",
                cpu.name(),
                g.adapter_info().name
            );
            (Box::new(cpu), why)
        }
        Err(e) => {
            let why = format!("{}: no usable GPU adapter ({e})", cpu.name());
            (Box::new(cpu), why)
        }
    }
}

#[cfg(not(feature = "gpu"))]
fn select_auto() -> (Box<dyn Renderer>, String) {
    let cpu = CpuRenderer::default();
    let why = format!("{}: built without the `gpu` feature", cpu.name());
    (Box::new(cpu), why)
}

#[cfg(feature = "gpu")]
fn select_gpu() -> Result<(Box<dyn Renderer>, String), RenderError> {
    match crate::gpu::WgpuRenderer::new(crate::RenderSettings::default()) {
        Ok(g) => {
            let why = if g.is_software() {
                format!("{}: requested (a software adapter)", g.name())
            } else {
                format!("{}: requested (a hardware adapter)", g.name())
            };
            Ok((Box::new(g), why))
        }
        Err(e) => Err(RenderError::BackendUnavailable {
            backend: Backend::Gpu,
            reason: format!("no usable GPU adapter ({e})"),
        }),
    }
}

#[cfg(not(feature = "gpu"))]
fn select_gpu() -> Result<(Box<dyn Renderer>, String), RenderError> {
    Err(RenderError::BackendUnavailable {
        backend: Backend::Gpu,
        reason: "this build lacks raster-diff's `gpu` feature (the wgpu backend)".into(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cpu_is_the_cpu_renderer_and_auto_never_fails() {
        let (r, why) = select_renderer(Backend::Cpu).expect("the CPU renderer always exists");
        assert!(r.name().starts_with("cpu"), "{}", r.name());
        assert_eq!(why, format!("{}: requested", r.name()));
        let (_, why) = select_renderer(Backend::Auto).expect("auto falls back to the CPU");
        assert!(!why.is_empty());
        assert_eq!(Backend::default(), Backend::Auto);
    }

    #[test]
    fn gpu_is_the_wgpu_backend_or_an_error_never_the_cpu_renderer() {
        match select_renderer(Backend::Gpu) {
            Ok((r, why)) => {
                assert!(!r.name().starts_with("cpu"), "{why}");
                assert!(why.contains("requested"), "{why}");
            }
            Err(e) => {
                let text = e.to_string();
                assert!(
                    matches!(
                        e,
                        RenderError::BackendUnavailable {
                            backend: Backend::Gpu,
                            ..
                        }
                    ),
                    "{text}"
                );
                assert!(text.contains("`gpu`"), "{text}");
            }
        }
    }
}

//! How much memory one UNet stage needs on its device, estimated before the first iteration from
//! the model files and the batch (docs/models.md, "Memory per device").
//!
//! The model: **weights** as resident on the device plus **activations** of the samples in one
//! session call.
//! - Weights: the stage's files (graph + external data), 1× on CUDA (the weights stay in their own
//!   dtype) and for fp32 models. On the CPU an fp16 model with graph optimizations on keeps fp32
//!   copies of its weights (ONNX Runtime folds the casts at load): 2.2× the file resident and 3.5×
//!   at the load peak (measured at 64 px, docs/models.md); with graph optimizations off the casts
//!   run in each call and their fp32 outputs add ≈ 0.75× the file (the 64 px low-memory row: 4.42
//!   GiB peak for a 2.31 GiB file).
//! - Activations: [`ACTIVATION_BYTES_PER_PIXEL_FP32`] per pixel of one sample at the stage's
//!   resolution, halved for fp16 on CUDA (on the CPU an fp16 model computes in fp32), scaled by the
//!   stage's width relative to the calibration model (`sqrt(parameters / 1.24 B)`), times the
//!   samples in one call (`max_batch`, else the whole 2 × views batch).
//!
//! Calibrated on **one** measurement: the 1.24 B-parameter random stage-II UNet, fp32, low-memory
//! settings, one 256 px sample per call, peak RSS 7.12 GiB with 4.80 GiB of weights → 2.32 GiB for
//! one sample. The other measured rows are the check (`tests::estimate_against_the_measured_peaks`).
//! Stage I (IF-I-XL) activations are extrapolated, not measured.

use crate::manifest::{Dtype, ModelDir, Stage};
use crate::runtime::{Device, SessionOptions};

/// Bytes of live activations per pixel of one fp32 sample for the calibration UNet (1.24 B
/// parameters): 2.32 GiB / 256².
pub const ACTIVATION_BYTES_PER_PIXEL_FP32: f64 = 2.32 * 1_073_741_824.0 / 65_536.0;
/// Parameters of the calibration UNet (`scripts/realsize_check.py`).
pub const CALIBRATION_PARAMETERS: f64 = 1.24e9;
/// Fixed process overhead counted once per device on the CPU (runtime, mesh, renderer buffers):
/// the 1.3 GiB a whole run with the tiny models peaks at (docs/models.md, "Runtime memory").
pub const CPU_BASE_BYTES: u64 = 1_400_000_000;
/// Fixed overhead per CUDA device (context, cuBLAS/cuDNN handles and workspaces): ≈ 0.6 GiB, a
/// common figure for a CUDA context with cuDNN loaded; not measured here.
pub const CUDA_BASE_BYTES: u64 = 650_000_000;

/// The estimate for one stage.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct StageMemory {
    /// Weights resident on the device during a call, bytes.
    pub weights: u64,
    /// The peak while loading (fp16 on the CPU with graph optimizations: the fp16 weights and their
    /// fp32 copies side by side), bytes.
    pub load_peak: u64,
    /// Activations of one session call, bytes.
    pub activations: u64,
    /// Samples in one session call.
    pub samples_per_call: usize,
}

impl StageMemory {
    /// The peak: the larger of the load peak and weights plus one call's activations.
    pub fn total(&self) -> u64 {
        self.load_peak.max(self.weights + self.activations)
    }
}

/// The estimate for `stage` of `model` on `options.device` when csd hands it `batch` samples
/// (2 × views) at `pixels` = H × W. None when the manifest has no such stage or its files cannot
/// be measured.
pub fn estimate_stage(
    model: &ModelDir,
    stage: Stage,
    options: &SessionOptions,
    batch: usize,
    pixels: usize,
) -> Option<StageMemory> {
    let spec = model.stage(stage)?;
    let file = model.weight_bytes(stage)?;
    let parameters = model.approx_parameters(stage)? as f64;
    Some(estimate(
        file, parameters, spec.dtype, options, batch, pixels,
    ))
}

/// [`estimate_stage`] from the numbers alone.
pub fn estimate(
    file_bytes: u64,
    parameters: f64,
    dtype: Dtype,
    options: &SessionOptions,
    batch: usize,
    pixels: usize,
) -> StageMemory {
    let on_cpu = options.device == Device::Cpu;
    let f = file_bytes as f64;
    let (weights, load_peak) = match (on_cpu, dtype, options.graph_optimizations) {
        (true, Dtype::Fp16, true) => (2.2 * f, 3.5 * f),
        (true, Dtype::Fp16, false) => (1.75 * f, 1.75 * f),
        _ => (f, f),
    };
    let bytes_per_pixel = match (on_cpu, dtype) {
        (false, Dtype::Fp16) => ACTIVATION_BYTES_PER_PIXEL_FP32 / 2.0,
        _ => ACTIVATION_BYTES_PER_PIXEL_FP32,
    };
    let width = (parameters / CALIBRATION_PARAMETERS).sqrt();
    let samples_per_call = options.max_batch.unwrap_or(batch).clamp(1, batch.max(1));
    let activations = bytes_per_pixel * width * pixels as f64 * samples_per_call as f64;
    StageMemory {
        weights: weights.round() as u64,
        load_peak: load_peak.round() as u64,
        activations: activations.round() as u64,
        samples_per_call,
    }
}

/// Total memory of the machine (`MemTotal` of `/proc/meminfo`), when it can be read.
pub fn host_memory_bytes() -> Option<u64> {
    let text = std::fs::read_to_string("/proc/meminfo").ok()?;
    let line = text.lines().find(|l| l.starts_with("MemTotal:"))?;
    let kib: u64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kib * 1024)
}

/// Bytes as GiB with two decimals.
pub fn gib(bytes: u64) -> String {
    format!("{:.2} GiB", bytes as f64 / 1_073_741_824.0)
}

#[cfg(test)]
mod tests {
    use super::*;

    const GIB: f64 = 1_073_741_824.0;

    /// The 256 px rows of docs/models.md ("At 256 px the activations count"): the stage-I + stage-II
    /// UNet files on disk (the stage-I file is the tiny one, ≈ 0.1 / 0.2 GB), one stage-II call of
    /// `samples` 256 px samples, and the measured peak RSS of `stylize debug-guidance` (no mesh
    /// loop, so no [`CPU_BASE_BYTES`]). The estimate (stage II + stage I's file) must come within
    /// 15 % of each; the fp32 low-memory row is the calibration itself, the other three are checks
    /// (their factors come from the 64 px measurements, not from these rows).
    #[test]
    fn estimate_against_the_measured_peaks() {
        // (dtype, stage-II file GiB, stage-I file GiB, low memory, samples per call, measured GiB)
        let rows = [
            (Dtype::Fp32, 4.61, 0.19, true, 1, 7.12),
            (Dtype::Fp32, 4.61, 0.19, false, 2, 9.59),
            (Dtype::Fp16, 2.31, 0.09, true, 1, 5.67),
            (Dtype::Fp16, 2.31, 0.09, false, 2, 9.70),
        ];
        for (dtype, file2, file1, low, samples, measured) in rows {
            let mut options = if low {
                SessionOptions::low_memory()
            } else {
                SessionOptions::default()
            };
            options.max_batch = Some(samples);
            let file = (file2 * GIB) as u64;
            let per = if dtype == Dtype::Fp16 { 2.0 } else { 4.0 };
            let e = estimate(file, file as f64 / per, dtype, &options, 2, 65_536);
            let total = (e.total() + (file1 * GIB) as u64) as f64 / GIB;
            let error = (total - measured) / measured;
            assert!(
                error.abs() <= 0.15,
                "{dtype:?} low_memory={low}: estimate {total:.2} GiB vs measured {measured} GiB ({:+.0} %)",
                100.0 * error
            );
        }
    }

    #[test]
    fn the_batch_and_the_device_change_the_activations() {
        let opts = SessionOptions::default();
        let cpu = estimate(2_000_000_000, 1e9, Dtype::Fp16, &opts, 16, 65_536);
        assert_eq!(cpu.samples_per_call, 16);
        assert_eq!(cpu.weights, 4_400_000_000);
        assert_eq!(cpu.load_peak, 7_000_000_000);
        let gpu_opts = SessionOptions {
            device: Device::Cuda { device_id: 0 },
            ..SessionOptions::default()
        };
        let gpu = estimate(2_000_000_000, 1e9, Dtype::Fp16, &gpu_opts, 16, 65_536);
        assert_eq!(gpu.weights, 2_000_000_000);
        assert!((gpu.activations as f64 - cpu.activations as f64 / 2.0).abs() < 2.0);
        let split = SessionOptions {
            max_batch: Some(4),
            ..gpu_opts
        };
        let four = estimate(2_000_000_000, 1e9, Dtype::Fp16, &split, 16, 65_536);
        assert_eq!(four.samples_per_call, 4);
        assert!((four.activations as f64 * 4.0 - gpu.activations as f64).abs() < 8.0);
    }
}

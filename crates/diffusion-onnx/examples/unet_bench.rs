//! One UNet, timed per call with and without IO binding, or checked against the CPU provider.
//!
//! ```text
//! cargo run --release -p diffusion-onnx --example unet_bench -- [OPTIONS]
//!   --model DIR            model directory (default: fixtures/models/tiny-if)
//!   --stage 1|2            which UNet (default 2)
//!   --device cpu|cuda:N    execution provider (cuda needs `--features diffusion-onnx/cuda`)
//!   --batch N              samples per call (default 16: 8 views × cond/uncond)
//!   --px N                 image side (default 256 for stage II, 64 for stage I)
//!   --reps N               timed calls per path (default 10), after one warm-up call each
//!   --io-binding both|on|off   which paths to time (default both, interleaved A B A B …)
//!   --flop-per-sample F    FLOPs of one sample at this size, to print TFLOP/s
//!   --compare-cpu          instead of timing: run the same inputs on `--device` and on the CPU
//!                          provider and fail when max |a − b| > atol + rtol · max |b|
//!   --tol ATOL,RTOL        tolerance of --compare-cpu (default 1e-4,1e-4 for fp32 models with TF32
//!                          off, 1e-2,1e-2 for fp16 models)
//! ```
//! Prints one line per path: `io_binding=on  median 123.4 ms  min 120.0 ms  [TFLOP/s 98.7]`.

use std::path::PathBuf;
use std::time::Instant;

use csd::Denoiser;
use diffusion_onnx::{Device, Dtype, ModelDir, OnnxDenoiser, SessionOptions, Stage};

fn parse_device(s: &str) -> Result<Device, String> {
    match s {
        "cpu" => Ok(Device::Cpu),
        _ => s
            .strip_prefix("cuda:")
            .and_then(|n| n.parse().ok())
            .map(|device_id| Device::Cuda { device_id })
            .ok_or_else(|| format!("--device {s}: write cpu or cuda:N")),
    }
}

struct Args {
    model: PathBuf,
    stage: Stage,
    device: Device,
    batch: usize,
    px: Option<usize>,
    reps: usize,
    io: Vec<bool>,
    flop: Option<f64>,
    compare: bool,
    tol: Option<(f32, f32)>,
}

fn args() -> Result<Args, String> {
    let mut a = Args {
        model: PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../fixtures/models/tiny-if"),
        stage: Stage::Two,
        device: Device::Cpu,
        batch: 16,
        px: None,
        reps: 10,
        io: vec![true, false],
        flop: None,
        compare: false,
        tol: None,
    };
    let mut it = std::env::args().skip(1);
    while let Some(flag) = it.next() {
        let mut value = || it.next().ok_or(format!("{flag} needs a value"));
        let num = |v: String| v.parse::<usize>().map_err(|e| format!("{flag} {v}: {e}"));
        match flag.as_str() {
            "--model" => a.model = value()?.into(),
            "--stage" => {
                a.stage = match value()?.as_str() {
                    "1" => Stage::One,
                    "2" => Stage::Two,
                    v => return Err(format!("--stage {v}: 1 or 2")),
                }
            }
            "--device" => a.device = parse_device(&value()?)?,
            "--batch" => a.batch = num(value()?)?,
            "--px" => a.px = Some(num(value()?)?),
            "--reps" => a.reps = num(value()?)?,
            "--io-binding" => {
                a.io = match value()?.as_str() {
                    "both" => vec![true, false],
                    "on" => vec![true],
                    "off" => vec![false],
                    v => return Err(format!("--io-binding {v}: both, on or off")),
                }
            }
            "--flop-per-sample" => {
                let v = value()?;
                a.flop = Some(
                    v.parse()
                        .map_err(|e| format!("--flop-per-sample {v}: {e}"))?,
                );
            }
            "--compare-cpu" => a.compare = true,
            "--tol" => {
                let v = value()?;
                let (x, y) = v.split_once(',').ok_or("--tol ATOL,RTOL")?;
                a.tol = Some((
                    x.parse().map_err(|e| format!("--tol {v}: {e}"))?,
                    y.parse().map_err(|e| format!("--tol {v}: {e}"))?,
                ));
            }
            "-h" | "--help" => {
                return Err(
                    "see the doc comment of crates/diffusion-onnx/examples/unet_bench.rs".into(),
                );
            }
            f => return Err(format!("unknown option {f}")),
        }
    }
    if a.batch == 0 || a.reps == 0 || a.px == Some(0) {
        return Err("--batch, --reps and --px must be at least 1".into());
    }
    Ok(a)
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let a = args()?;
    let model = ModelDir::open(&a.model)?;
    let spec = model
        .stage(a.stage)
        .ok_or(format!("{} has no {}", a.model.display(), a.stage.key()))?
        .clone();
    let px = a.px.unwrap_or(spec.sample_size);
    let n = a.batch;
    let e = model.uncond_embedding()?;
    let mut cond = e.clone();
    cond.data.iter_mut().for_each(|v| *v += 0.1);
    let x = csd::Tensor {
        shape: vec![n, spec.in_channels, px, px],
        data: (0..n * spec.in_channels * px * px)
            .map(|i| ((i % 997) as f32 / 498.0) - 1.0)
            .collect(),
    };
    let embs: Vec<_> = (0..n).map(|i| if i < n / 2 { &cond } else { &e }).collect();
    let t: Vec<i64> = (0..n as i64).map(|i| 20 + (960 * i) / n as i64).collect();
    let s: Vec<i64> = (0..n as i64).map(|i| 980 - (960 * i) / n as i64).collect();
    let labels = (a.stage == Stage::Two).then_some(s.as_slice());
    let open = |device, io_binding| {
        let mut o = SessionOptions {
            device,
            io_binding,
            ..SessionOptions::default()
        };
        if a.compare {
            o.cuda.tf32 = false;
        }
        OnnxDenoiser::open(&model, a.stage, &o).map_err(Box::<dyn std::error::Error>::from)
    };
    println!(
        "{} {} ({}), {} on {}: batch {n} × {} × {px}², {:.1} MB in",
        a.model.display(),
        a.stage.key(),
        spec.dtype.as_str(),
        if a.compare {
            "CUDA-vs-CPU check"
        } else {
            "timing"
        },
        a.device,
        spec.in_channels,
        (x.data.len() * 4) as f64 / 1e6
    );
    if a.compare {
        let (atol, rtol) = a.tol.unwrap_or(match spec.dtype {
            Dtype::Fp32 => (1e-4, 1e-4),
            Dtype::Fp16 => (1e-2, 1e-2),
        });
        let got = open(a.device, true)?.predict(&x, &t, &embs, labels)?;
        let want = open(Device::Cpu, true)?.predict(&x, &t, &embs, labels)?;
        let scale = want.data.iter().fold(0f32, |m, v| m.max(v.abs()));
        let err = got
            .data
            .iter()
            .zip(&want.data)
            .fold(0f32, |m, (p, q)| m.max((p - q).abs()));
        let tol = atol + rtol * scale;
        let finite = got.data.iter().all(|v| v.is_finite());
        println!(
            "max |{} − cpu| = {err:.3e} (tolerance {tol:.3e} = {atol:e} + {rtol:e} · max|y| {scale:.3}){}",
            a.device,
            if finite { "" } else { ", NON-FINITE values" }
        );
        if !(finite && err <= tol) {
            return Err("FAIL: the devices disagree beyond the tolerance".into());
        }
        println!("PASS");
        return Ok(());
    }
    let mut paths = Vec::new();
    for &io in &a.io {
        let mut unet = open(a.device, io)?;
        let start = Instant::now();
        unet.predict(&x, &t, &embs, labels)?; // warm-up: cuDNN search, memory planning
        let first = start.elapsed().as_secs_f64();
        paths.push((io, unet, first, Vec::new()));
    }
    for _ in 0..a.reps {
        for (_, unet, _, times) in &mut paths {
            let start = Instant::now();
            std::hint::black_box(unet.predict(&x, &t, &embs, labels)?);
            times.push(start.elapsed().as_secs_f64());
        }
    }
    for (io, _, first, times) in &mut paths {
        times.sort_by(f64::total_cmp);
        let median = times[times.len() / 2];
        let tflops = a
            .flop
            .map(|f| format!("  {:.1} TFLOP/s", f * n as f64 / median / 1e12))
            .unwrap_or_default();
        println!(
            "io_binding={:<3}  first {:9.1} ms  median {:9.1} ms  min {:9.1} ms{tflops}",
            if *io { "on" } else { "off" },
            *first * 1e3,
            median * 1e3,
            times[0] * 1e3
        );
    }
    Ok(())
}

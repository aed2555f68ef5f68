//! `stylize debug-guidance` (hidden): one guidance evaluation dumped to .npz for inspection.
//!
//! Loads the model directory's UNets, takes the prompt embeddings from the cache (or the encoder),
//! runs [`csd::CascadedGuidance::evaluate_traced`] once with a seeded RNG (ChaCha8, `--seed`) on the
//! given images, and writes every intermediate to an `.npz`:
//!
//! | key | shape | what |
//! |---|---|---|
//! | `images` | (B, 3, H, W) f32 | input renders in [0, 1], NCHW |
//! | `x` | (B, 3, 224, 224) | 2·resize₂₂₄(img) − 1 |
//! | `stage1_{z0,noise,z_t,eps_cond,eps_uncond,eps_guided,grad}` | (B, 3, 64, 64) | stage I (SDS) |
//! | `stage1_timesteps` | (B,) i64 | t per view |
//! | `stage2_{x0,z_hat,noise,noise_lowres,x_t,z_hat_s,eps_cond,eps_uncond,eps_guided,grad}` | (B, 3, 256, 256) | stage II (CSD), only when its weight > 0 |
//! | `stage2_timesteps`, `stage2_noise_levels` | (B,) i64 | t and s per view |
//! | `grad_x` | (B, 3, 224, 224) | ∂L/∂x |
//! | `grad_images` | (B, H, W, 3) | ∂L/∂images, the layout of the renders |
//! | `loss_stage1`, `loss_stage2`, `stage2_weight` | () f64 | losses as reported, the weight used |
//! | `seed` | () i64 | the RNG seed |
//! | `embedding_cond`, `embedding_uncond` | (tokens, dim) | the text conditioning |

use std::path::PathBuf;

#[cfg(feature = "text")]
use std::path::Path;

#[cfg(feature = "text")]
use anyhow::{Context, bail};
#[cfg(feature = "text")]
use csd::{CascadedGuidance, Denoiser, GuidanceConfig, InjectedDraws};
#[cfg(feature = "text")]
use diffusion_onnx::{
    EmbeddingCache, ModelDir, OnnxDenoiser, SessionOptions, Stage, prompt_embeddings,
};
#[cfg(feature = "text")]
use npy::npz::NpzWriter;
#[cfg(feature = "text")]
use npy::{NpyArray, NpyData, parse_npy};
#[cfg(feature = "text")]
use rand::SeedableRng;

/// Arguments of `stylize debug-guidance`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// Model directory (manifest.toml + .onnx files).
    #[arg(long)]
    pub model: PathBuf,
    /// Renders as one `.npy`: (views, H, W, 3) or (H, W, 3), f32 in [0, 1] or u8.
    #[arg(long)]
    pub images: PathBuf,
    /// Text prompt.
    #[arg(long)]
    pub prompt: String,
    /// Negative prompt ("" = the model's unconditional embedding).
    #[arg(long, default_value = "")]
    pub negative_prompt: String,
    /// RNG seed for timesteps and noise.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Stage-II weight w_II (0 skips stage II).
    #[arg(long, default_value_t = 0.0)]
    pub stage2_weight: f64,
    /// CFG scale g in ε̂ = ε_c + g(ε_c − ε_u).
    #[arg(long, default_value_t = 100.0)]
    pub guidance_scale: f32,
    /// Embedding cache directory (default: see `stylize embed`).
    #[arg(long)]
    pub cache: Option<PathBuf>,
    /// ONNX Runtime intra-op threads (default: one per core; at most 4 × the cores).
    #[arg(long, value_parser = crate::cmd::shared::thread_count)]
    pub threads: Option<usize>,
    /// Turn ONNX Runtime's CPU memory arena off.
    #[arg(long)]
    pub no_arena: bool,
    /// Turn ONNX Runtime's memory pattern off.
    #[arg(long)]
    pub no_memory_pattern: bool,
    /// Turn weight pre-packing off (`session.disable_prepacking`).
    #[arg(long)]
    pub no_prepacking: bool,
    /// Turn ONNX Runtime's graph optimizations off.
    #[arg(long)]
    pub no_graph_optimizations: bool,
    /// At most this many samples per UNet call (default: the whole 2B batch in one call).
    #[arg(long)]
    pub max_batch: Option<usize>,
    /// Let ONNX Runtime's intra-op threads spin between and after calls (its own default; off here).
    #[arg(long)]
    pub intra_op_spinning: bool,
    /// Output `.npz`.
    #[arg(long)]
    pub out: PathBuf,
}

#[cfg(feature = "text")]
/// Reads renders as (views, H, W, 3) f32 in [0, 1].
fn read_images(path: &Path) -> anyhow::Result<(usize, usize, usize, Vec<f32>)> {
    match path.extension().and_then(|e| e.to_str()) {
        Some("npy") => {}
        Some("png") => bail!(
            "{}: PNG input is not supported yet; stack the renders into a (views, H, W, 3) .npy (f32 in [0, 1] or u8)",
            path.display()
        ),
        _ => bail!(
            "{}: expected a .npy file of renders (views, H, W, 3)",
            path.display()
        ),
    }
    let bytes = std::fs::read(path).with_context(|| format!("reading {}", path.display()))?;
    let a = parse_npy(&bytes).map_err(|e| anyhow::anyhow!("{}: {e}", path.display()))?;
    let (v, h, w) = match a.shape.as_slice() {
        [v, h, w, 3] => (*v, *h, *w),
        [h, w, 3] => (1, *h, *w),
        s => bail!(
            "{}: shape {s:?}, expected (views, H, W, 3) or (H, W, 3)",
            path.display()
        ),
    };
    let data: Vec<f32> = match a.data {
        NpyData::F32(d) => d,
        NpyData::F64(d) => d.into_iter().map(|x| x as f32).collect(),
        NpyData::U8(d) => d.into_iter().map(|x| f32::from(x) / 255.0).collect(),
        _ => bail!("{}: dtype must be f32, f64 or u8", path.display()),
    };
    if let Some(bad) = data
        .iter()
        .find(|x| !x.is_finite() || **x < 0.0 || **x > 1.0)
    {
        bail!(
            "{}: image values must lie in [0, 1] (found {bad})",
            path.display()
        );
    }
    Ok((v, h, w, data))
}

#[cfg(feature = "text")]
fn f32_array(shape: &[usize], data: &[f32]) -> anyhow::Result<NpyArray> {
    NpyArray::new(shape.to_vec(), NpyData::F32(data.to_vec())).map_err(|e| anyhow::anyhow!(e))
}

#[cfg(feature = "text")]
fn tensor(w: &mut NpzWriter, key: &str, t: &csd::Tensor) -> anyhow::Result<()> {
    w.add(key, &f32_array(&t.shape, &t.data)?)
        .with_context(|| format!("writing {key}"))
}

#[cfg(feature = "text")]
fn ints(w: &mut NpzWriter, key: &str, v: &[i64]) -> anyhow::Result<()> {
    let a =
        NpyArray::new(vec![v.len()], NpyData::I64(v.to_vec())).map_err(|e| anyhow::anyhow!(e))?;
    w.add(key, &a).with_context(|| format!("writing {key}"))
}

#[cfg(feature = "text")]
fn scalar(w: &mut NpzWriter, key: &str, v: f64) -> anyhow::Result<()> {
    let a = NpyArray::new(vec![], NpyData::F64(vec![v])).map_err(|e| anyhow::anyhow!(e))?;
    w.add(key, &a).with_context(|| format!("writing {key}"))
}

#[cfg(feature = "text")]
/// Runs `stylize debug-guidance`.
pub fn run(args: Args) -> anyhow::Result<()> {
    let (views, height, width, images) = read_images(&args.images)?;
    let model = ModelDir::open(&args.model)
        .with_context(|| format!("opening model {}", args.model.display()))?;
    let options = SessionOptions {
        intra_threads: args.threads,
        cpu_memory_arena: !args.no_arena,
        memory_pattern: !args.no_memory_pattern,
        prepacking: !args.no_prepacking,
        graph_optimizations: !args.no_graph_optimizations,
        max_batch: args.max_batch,
        intra_op_spinning: args.intra_op_spinning,
        ..SessionOptions::default()
    };
    let cache = match &args.cache {
        Some(d) => Some(EmbeddingCache::new(d)),
        None => EmbeddingCache::at_default().ok(),
    };
    let (cond, uncond) = prompt_embeddings(
        &model,
        &args.prompt,
        &args.negative_prompt,
        cache.as_ref(),
        &options,
    )
    .context("preparing the prompt embeddings")?;
    let stage1: Box<dyn Denoiser> = Box::new(
        OnnxDenoiser::open(&model, Stage::One, &options).context("loading the stage-I UNet")?,
    );
    let stage2: Option<Box<dyn Denoiser>> = if args.stage2_weight > 0.0 {
        Some(Box::new(
            OnnxDenoiser::open(&model, Stage::Two, &options)
                .context("loading the stage-II UNet")?,
        ))
    } else {
        None
    };
    let config = GuidanceConfig {
        guidance_scale: args.guidance_scale,
        num_train_timesteps: model.manifest().stage1.scheduler.num_train_timesteps,
        ..GuidanceConfig::default()
    };
    let mut guidance = CascadedGuidance::new(stage1, stage2, cond.clone(), uncond.clone(), config)
        .context("setting up the guidance")?;
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(args.seed);
    let trace = guidance
        .evaluate_traced(
            &csd::Images::new(views, height, width, images)?,
            args.stage2_weight,
            &mut rng,
            &InjectedDraws::default(),
        )
        .context("evaluating the guidance")?;

    let mut w =
        NpzWriter::create(&args.out).with_context(|| format!("creating {}", args.out.display()))?;
    tensor(&mut w, "images", &trace.images)?;
    tensor(&mut w, "x", &trace.x)?;
    let s1 = &trace.stage1;
    for (k, t) in [
        ("z0", &s1.z0),
        ("noise", &s1.score.noise),
        ("z_t", &s1.z_t),
        ("eps_cond", &s1.score.eps_cond),
        ("eps_uncond", &s1.score.eps_uncond),
        ("eps_guided", &s1.score.eps_guided),
        ("grad", &s1.score.grad),
    ] {
        tensor(&mut w, &format!("stage1_{k}"), t)?;
    }
    ints(&mut w, "stage1_timesteps", &s1.score.timesteps)?;
    if let Some(s2) = &trace.stage2 {
        for (k, t) in [
            ("x0", &s2.x0),
            ("z_hat", &s2.z_hat),
            ("noise", &s2.score.noise),
            ("noise_lowres", &s2.noise_lowres),
            ("x_t", &s2.x_t),
            ("z_hat_s", &s2.z_hat_s),
            ("eps_cond", &s2.score.eps_cond),
            ("eps_uncond", &s2.score.eps_uncond),
            ("eps_guided", &s2.score.eps_guided),
            ("grad", &s2.score.grad),
        ] {
            tensor(&mut w, &format!("stage2_{k}"), t)?;
        }
        ints(&mut w, "stage2_timesteps", &s2.score.timesteps)?;
        ints(&mut w, "stage2_noise_levels", &s2.noise_levels)?;
    }
    tensor(&mut w, "grad_x", &trace.grad_x)?;
    w.add(
        "grad_images",
        &f32_array(&[views, height, width, 3], &trace.output.grad_images.rgb)?,
    )
    .context("writing grad_images")?;
    scalar(&mut w, "loss_stage1", trace.output.loss_stage1)?;
    scalar(&mut w, "loss_stage2", trace.output.loss_stage2)?;
    scalar(&mut w, "stage2_weight", args.stage2_weight)?;
    let seed = NpyArray::new(vec![], NpyData::I64(vec![args.seed as i64]))
        .map_err(|e| anyhow::anyhow!(e))?;
    w.add("seed", &seed).context("writing seed")?;
    w.add("embedding_cond", &f32_array(&cond.shape, &cond.data)?)
        .context("writing embedding_cond")?;
    w.add("embedding_uncond", &f32_array(&uncond.shape, &uncond.data)?)
        .context("writing embedding_uncond")?;
    w.finish()
        .with_context(|| format!("finishing {}", args.out.display()))?;
    outln!(
        "wrote {} (loss I {:.6e}, loss II {:.6e}, |grad| max {:.3e})",
        args.out.display(),
        trace.output.loss_stage1,
        trace.output.loss_stage2,
        trace
            .output
            .grad_images
            .rgb
            .iter()
            .fold(0.0f32, |m, v| m.max(v.abs()))
    )?;
    Ok(())
}

#[cfg(all(test, feature = "text"))]
mod tests {
    use super::*;
    use npy::npz::NpzReader;

    fn tiny() -> PathBuf {
        PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../fixtures/models/tiny-if")
    }

    fn write_images(path: &Path, views: usize, side: usize) -> anyhow::Result<()> {
        let n = views * side * side * 3;
        let data: Vec<f32> = (0..n).map(|i| ((i * 7919) % 1000) as f32 / 999.0).collect();
        let a = NpyArray::new(vec![views, side, side, 3], NpyData::F32(data))
            .map_err(|e| anyhow::anyhow!(e))?;
        std::fs::write(path, npy::write_npy(&a))?;
        Ok(())
    }

    fn args(dir: &Path, stage2_weight: f64, seed: u64, out: &str) -> Args {
        Args {
            model: tiny(),
            images: dir.join("imgs.npy"),
            prompt: "a photo of a cat".into(),
            negative_prompt: String::new(),
            seed,
            stage2_weight,
            guidance_scale: 100.0,
            cache: Some(dir.join("cache")),
            threads: Some(1),
            no_arena: false,
            no_memory_pattern: false,
            no_prepacking: false,
            no_graph_optimizations: false,
            max_batch: None,
            intra_op_spinning: false,
            out: dir.join(out),
        }
    }

    #[test]
    fn dump_has_every_intermediate_and_is_reproducible_for_a_seed() -> anyhow::Result<()> {
        let dir = tempfile::tempdir()?;
        write_images(&dir.path().join("imgs.npy"), 2, 40)?;
        run(args(dir.path(), 0.3, 7, "a.npz"))?;
        run(args(dir.path(), 0.3, 7, "b.npz"))?;
        let a = NpzReader::open(dir.path().join("a.npz"))?;
        let b = NpzReader::open(dir.path().join("b.npz"))?;
        for key in [
            "stage1_eps_cond",
            "stage2_eps_cond",
            "stage2_noise_levels",
            "grad_images",
            "grad_x",
        ] {
            let arr = a.require(key)?;
            assert_eq!(
                Some(arr),
                b.get(key),
                "{key} differs between two runs with the same seed"
            );
            let v = arr.to_f64_vec().context("numeric")?;
            assert!(
                v.iter().all(|x| x.is_finite()),
                "{key} has non-finite values"
            );
        }
        assert_eq!(a.require("grad_images")?.shape, vec![2, 40, 40, 3]);
        assert_eq!(a.require("stage1_z_t")?.shape, vec![2, 3, 64, 64]);
        assert_eq!(a.require("stage2_x_t")?.shape, vec![2, 3, 256, 256]);
        Ok(())
    }

    #[test]
    fn zero_stage2_weight_skips_stage2_and_needs_no_stage2_model() -> anyhow::Result<()> {
        let dir = tempfile::tempdir()?;
        write_images(&dir.path().join("imgs.npy"), 1, 32)?;
        run(args(dir.path(), 0.0, 1, "c.npz"))?;
        let c = NpzReader::open(dir.path().join("c.npz"))?;
        assert!(c.get("stage1_grad").is_some());
        assert!(c.get("stage2_grad").is_none());
        Ok(())
    }

    #[test]
    fn out_of_range_images_are_refused() -> anyhow::Result<()> {
        let dir = tempfile::tempdir()?;
        let a = NpyArray::new(vec![1, 4, 4, 3], NpyData::F32(vec![2.0; 48]))
            .map_err(|e| anyhow::anyhow!(e))?;
        std::fs::write(dir.path().join("imgs.npy"), npy::write_npy(&a))?;
        let msg = run(args(dir.path(), 0.0, 1, "d.npz"))
            .err()
            .map(|e| format!("{e:#}"))
            .unwrap_or_default();
        assert!(msg.contains("[0, 1]"), "{msg}");
        Ok(())
    }
}

//! `stylize eval`: identity-preservation metrics (spec §9) for run directories or mesh pairs, and the
//! CLIP similarity when a CLIP model directory is given.

use std::path::{Path, PathBuf};
#[cfg(feature = "text")]
use std::time::Instant;

#[cfg(feature = "text")]
use anyhow::Context;
use anyhow::bail;
use mesh_core::TriMesh;

use stylize::eval::{
    ClipSettings, EvalReport, Prompt, evaluate, label, load_file_pair, load_run, table,
};

/// Arguments of `stylize eval`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// Run directories (source: `deformation.npz` verts; result: `mesh.obj`; prompt: the one the run
    /// was given, recorded in `deformation.npz`).
    pub runs: Vec<PathBuf>,
    /// A source mesh and its result (same faces), repeatable: `--pair SOURCE RESULT`.
    #[arg(long, num_args = 2, value_names = ["SOURCE", "RESULT"])]
    pub pair: Vec<PathBuf>,
    /// Print JSON instead of a table.
    #[arg(long)]
    pub json: bool,
    /// CLIP model directory (from scripts/export_clip_onnx.py; the paper uses ViT-B/16): adds the
    /// CLIP similarity of source and result, the mean over views of cos(image embedding, prompt
    /// embedding).
    #[arg(long, value_name = "DIR")]
    pub clip: Option<PathBuf>,
    /// Orbit views rendered per mesh for CLIP.
    #[arg(
        long,
        default_value_t = 16,
        requires = "clip",
        allow_negative_numbers = true
    )]
    pub clip_views: usize,
    /// Side in pixels of the CLIP renders (the CLIP model then resizes them to its own size).
    #[arg(
        long,
        default_value_t = 512,
        requires = "clip",
        allow_negative_numbers = true
    )]
    pub clip_render_size: usize,
    /// Prompt for the `--pair` pairs' CLIP similarity (run directories use their own prompt).
    #[arg(long, requires = "clip")]
    pub prompt: Option<String>,
}

/// Runs `stylize eval`.
pub fn run(args: Args) -> anyhow::Result<()> {
    let mut pairs = Vec::new();
    let mut prompts = Vec::new();
    for dir in &args.runs {
        let (s, r, p) = load_run(dir)?;
        pairs.push((label(dir), s, r));
        prompts.push(p);
    }
    for two in args.pair.chunks(2) {
        let [source, result] = two else {
            bail!("--pair needs SOURCE and RESULT")
        };
        let (s, r) = load_file_pair(source, result)?;
        pairs.push((format!("{} → {}", label(source), label(result)), s, r));
        prompts.push(match &args.prompt {
            Some(t) => Prompt::Text(t.clone()),
            None => Prompt::Missing("no --prompt given for --pair".into()),
        });
    }
    if pairs.is_empty() {
        bail!("nothing to evaluate: give run directories or --pair SOURCE RESULT");
    }
    let mut report = evaluate(&pairs)?;
    if let Some(dir) = &args.clip {
        if args.clip_views == 0 {
            bail!("--clip-views must be at least 1");
        }
        if !(1..=4096).contains(&args.clip_render_size) {
            bail!("--clip-render-size must be in 1..=4096");
        }
        let settings = ClipSettings {
            views: args.clip_views,
            render_size: args.clip_render_size,
            ..ClipSettings::default()
        };
        add_clip(dir, &settings, &mut report, &pairs, &prompts)?;
    }
    if args.json {
        outln!("{}", serde_json::to_string_pretty(&report)?)?;
    } else {
        outp!("{}", table(&report))?;
    }
    Ok(())
}

/// Adds the CLIP similarity of every pair to `report` with the CLIP export in `dir`, and reports
/// where the time went on stderr.
#[cfg(feature = "text")]
fn add_clip(
    dir: &Path,
    settings: &ClipSettings,
    report: &mut EvalReport,
    pairs: &[(String, TriMesh, TriMesh)],
    prompts: &[Prompt],
) -> anyhow::Result<()> {
    let start = Instant::now();
    let mut clip = diffusion_onnx::ClipModel::open(dir, &diffusion_onnx::SessionOptions::default())
        .with_context(|| format!("--clip {}", dir.display()))?;
    let opened = start.elapsed().as_secs_f64();
    let t = stylize::eval::add_clip_scores(report, pairs, prompts, &mut clip, settings)?;
    errln!(
        "CLIP ({}): {} mesh(es) × {} views at {} px; open {opened:.3} s, render {:.3} s, \
         image embedding {:.3} s, text embedding {:.3} s",
        clip.manifest().name,
        t.meshes,
        settings.views,
        settings.render_size,
        t.render_s,
        t.embed_images_s,
        t.embed_texts_s
    );
    Ok(())
}

/// `--clip` in a build without the `text` feature: refused (no ONNX Runtime).
#[cfg(not(feature = "text"))]
fn add_clip(
    _dir: &Path,
    _settings: &ClipSettings,
    _report: &mut EvalReport,
    _pairs: &[(String, TriMesh, TriMesh)],
    _prompts: &[Prompt],
) -> anyhow::Result<()> {
    Err(crate::features::not_built("text", "--clip"))
}

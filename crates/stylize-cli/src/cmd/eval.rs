//! `stylize eval`: identity-preservation metrics (spec §9) for run directories or mesh pairs, and the
//! CLIP similarity when a CLIP model directory is given.

use std::path::{Path, PathBuf};
#[cfg(feature = "text")]
use std::time::Instant;

use anyhow::{Context, bail};
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
    /// A batch manifest (repeatable): every finished row's run directory, in manifest order
    /// (unfinished rows are listed on stderr and left out).
    #[arg(long, value_name = "FILE")]
    pub manifest: Vec<PathBuf>,
    /// Also write the report as CSV to FILE (one line per pair and a `pooled` line).
    #[arg(long, value_name = "FILE")]
    pub csv: Option<PathBuf>,
    /// Also write the report as JSON to FILE (what `--json` prints).
    #[arg(long, value_name = "FILE")]
    pub json_out: Option<PathBuf>,
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

/// The finished rows' run directories of `manifest`, in order; the unfinished ones are named on
/// stderr.
pub fn manifest_runs(manifest: &Path) -> anyhow::Result<Vec<PathBuf>> {
    let rows = crate::batch::read_manifest(manifest)?;
    let mut dirs = Vec::new();
    let mut unfinished = Vec::new();
    for (i, row) in rows.iter().enumerate() {
        if rundir::RunDir::new(&row.out).is_complete() {
            dirs.push(row.out.clone());
        } else {
            unfinished.push(format!("row {i} ({})", row.out.display()));
        }
    }
    if !unfinished.is_empty() {
        errln!(
            "{}: {} not finished, left out: {}",
            manifest.display(),
            crate::cmd::shared::count_noun(unfinished.len(), "row", "rows"),
            unfinished.join(", ")
        );
    }
    Ok(dirs)
}

/// Runs `stylize eval`.
pub fn run(args: Args) -> anyhow::Result<()> {
    let mut pairs = Vec::new();
    let mut prompts = Vec::new();
    let mut runs = Vec::new();
    for m in &args.manifest {
        runs.extend(manifest_runs(m)?);
    }
    runs.extend(args.runs.iter().cloned());
    for dir in &runs {
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
        bail!(
            "nothing to evaluate: give run directories, --manifest FILE (with finished rows) or \
             --pair SOURCE RESULT"
        );
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
    let json = serde_json::to_string_pretty(&report)?;
    if let Some(path) = &args.json_out {
        rundir::durable::replace_bytes(path, format!("{json}\n").as_bytes())
            .with_context(|| format!("cannot write {}", path.display()))?;
    }
    if let Some(path) = &args.csv {
        rundir::durable::replace_bytes(path, stylize::eval::csv(&report).as_bytes())
            .with_context(|| format!("cannot write {}", path.display()))?;
    }
    if args.json {
        outln!("{json}")?;
        for w in &report.warnings {
            errln!("warning: {w}");
        }
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

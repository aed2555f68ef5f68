//! `stylize run`: stylize one mesh into a run directory.

use std::path::PathBuf;

use anyhow::{Context, bail};

use crate::cmd::shared::RunSettings;
use crate::config::Config;
use crate::runner::execute_with;
use crate::signals::{Interrupted, shell_quote};
use stylize::runner::{RunOptions, RunRequest};
use stylize::style::Style;
use stylize::task::{ModelIdentity, Prompt, PromptTask};

/// Arguments of `stylize run`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// Input mesh (OBJ, OFF, PLY, glTF/GLB; see `stylize mesh check` for what is repaired).
    pub mesh: PathBuf,
    /// Run directory (created with its parents).
    #[arg(short, long, alias = "output", value_name = "DIR")]
    pub out: PathBuf,
    /// Model-free style: `cube`, `octahedron` or `exemplar:MESH`.
    #[arg(long, value_name = "NAME", conflicts_with = "prompt")]
    pub style: Option<String>,
    /// Text prompt (needs --model).
    #[arg(long, value_name = "TEXT")]
    pub prompt: Option<String>,
    /// Negative prompt (overrides guidance.negative_prompt).
    #[arg(long, value_name = "TEXT", allow_hyphen_values = true)]
    pub negative_prompt: Option<String>,
    // Model, configuration and progress options, shared with `stylize batch`.
    #[command(flatten)]
    pub settings: RunSettings,
    /// Seed (same as `--set run.seed=N`).
    #[arg(long, allow_negative_numbers = true)]
    pub seed: Option<u64>,
    /// Stylize only this region (repeatable: the union). `box:x0,y0,z0,x1,y1,z1` or
    /// `sphere:cx,cy,cz,r` in the normalized side-2 frame, `vertices:FILE`, `part:NAME` (OBJ
    /// group/object/material, glTF node/mesh), `property:NAME OP VALUE` (PLY), `not:SPEC`.
    /// Replaces `region.specs` of the configuration. See `stylize mesh check --regions FILE`.
    #[arg(long, value_name = "SPEC", allow_hyphen_values = true)]
    pub region: Vec<String>,
    /// Rings inside the region's boundary over which λ fades to zero (replaces `region.feather`).
    #[arg(long, value_name = "K")]
    pub region_feather: Option<u32>,
    /// Tint the region in the turntable and previews (same as `--set region.tint=true`).
    #[arg(long)]
    pub tint_region: bool,
    /// Continue an interrupted run from its checkpoint (an error when there is none). Without
    /// --config/--set/--seed/--negative-prompt, the run's own `config.toml` is used. The task
    /// (mesh, style/prompt, model, result-changing settings) must be the checkpoint's.
    #[arg(long, conflicts_with = "force")]
    pub resume: bool,
    /// Start over in an existing run directory, or write into a non-empty folder that is not a
    /// run directory. Removes only the run's own files; never replaces an input.
    #[arg(long)]
    pub force: bool,
    /// Stop after this iteration without writing outputs (to test --resume).
    #[arg(long, hide = true)]
    pub stop_after: Option<u64>,
}

/// Builds the resolved configuration: file (or defaults), then `--set`, then shortcut flags.
pub fn resolve_config(
    file: Option<&std::path::Path>,
    set: &[String],
    seed: Option<u64>,
    negative_prompt: Option<&str>,
) -> anyhow::Result<Config> {
    let base = match file {
        Some(p) => crate::config::load(p)?,
        None => Config::default(),
    };
    let mut config = base.with_overrides(set)?;
    if let Some(s) = seed {
        config.run.seed = s;
    }
    if let Some(n) = negative_prompt {
        config.guidance.negative_prompt = n.to_string();
    }
    config.validate()?;
    Ok(config)
}

/// The command that continues this run: the same mesh, run directory and objective with
/// `--resume` (the run's own `config.toml` holds the resolved settings).
pub fn resume_command(args: &Args) -> String {
    let mut parts: Vec<String> = vec![crate::open_hint::program(), "run".into()];
    parts.push(args.mesh.display().to_string());
    parts.push("--out".into());
    parts.push(args.out.display().to_string());
    if let Some(s) = &args.style {
        parts.extend(["--style".into(), s.clone()]);
    }
    if let Some(p) = &args.prompt {
        parts.extend(["--prompt".into(), p.clone()]);
    }
    if let Some(m) = &args.settings.model {
        parts.extend(["--model".into(), m.display().to_string()]);
    }
    parts.push("--resume".into());
    parts
        .iter()
        .map(|p| shell_quote(p))
        .collect::<Vec<_>>()
        .join(" ")
}

/// Runs `stylize run`.
pub fn run(args: Args) -> anyhow::Result<()> {
    // First: a stop request from now on is honoured (not the default action, which would kill).
    crate::signals::install()?;
    if args.style.is_none() && args.prompt.is_none() {
        bail!(
            "give --style NAME (model-free: cube, octahedron, exemplar:MESH) or --prompt TEXT \
             (with --model DIR)"
        );
    }
    let saved = args.out.join("config.toml");
    let no_config_flags = args.settings.config.is_none()
        && args.settings.set.is_empty()
        && args.seed.is_none()
        && args.settings.remesh.is_none()
        && args.negative_prompt.is_none();
    // `--resume` alone continues with the run's own resolved configuration.
    let config_file = if args.resume && no_config_flags && saved.is_file() {
        Some(saved)
    } else {
        args.settings.config.clone()
    };
    let config = resolve_config(
        config_file.as_deref(),
        &args.settings.set,
        args.seed,
        args.negative_prompt.as_deref(),
    )?;
    let config = args.settings.apply_remesh(config).with_region_flags(
        &args.region,
        args.region_feather,
        args.tint_region,
    )?;
    let config = crate::cmd::shared::with_view_flags(config, args.settings.view_flags())?;
    let mut options = RunOptions::default();
    if let Some(c) = &config_file {
        options.inputs.push(("config file".into(), c.clone()));
    }
    for spec in &config.region.specs {
        for file in mesh_core::region::RegionSpec::parse(spec)?.files() {
            options.inputs.push(("region vertex file".into(), file));
        }
    }
    let log = args.settings.log_mode();
    let request = RunRequest {
        mesh: args.mesh.clone(),
        out: args.out.clone(),
        config: config.clone(),
        force: args.force,
        resume: args.resume,
        halt_after: args.stop_after,
    };
    let result = match (&args.style, &args.prompt) {
        (Some(style), None) => {
            let style = Style::parse(style)?;
            if let Some(m) = &args.settings.model
                && !args.settings.quiet
            {
                errln!(
                    "warning: --model {} is not used by a --style run (model-free)",
                    m.display()
                );
            }
            execute_with(&request, log, &style, || Ok(style.clone()), &options)
        }
        (None, Some(prompt)) => {
            if !cfg!(feature = "text") {
                return Err(crate::features::not_built("text", "--prompt"));
            }
            let Some(model) = &args.settings.model else {
                bail!(
                    "--prompt needs --model DIR: an ONNX export of DeepFloyd IF (see docs/models.md for how to export it). \
                     Without models, try a model-free style: --style cube"
                );
            };
            let kind = Prompt {
                text: prompt.clone(),
                model: Some(ModelIdentity::of_dir(model)?),
            };
            options
                .inputs
                .push(("model manifest".into(), model.join("manifest.toml")));
            execute_with(
                &request,
                log,
                &kind,
                || {
                    let set = stylize::models::ModelSet::open(model, &config)?;
                    if let Some(w) = set.cpu_time_warning(&config) {
                        errln!("warning: {w}");
                    }
                    for w in set.memory_warnings() {
                        errln!("warning: {w}");
                    }
                    let warnings = set.prompt_warnings(prompt, &config)?;
                    Ok(PromptTask {
                        prompt: kind.clone(),
                        guidance: Box::new(set.into_guidance(prompt, &config)?),
                        warnings,
                    })
                },
                &options,
            )
        }
        _ => bail!("give --style NAME or --prompt TEXT, not both"),
    };
    let outcome = match result {
        Ok(o) => o,
        Err(e) => {
            if let Some(i) = e.downcast_ref::<Interrupted>()
                && i.checkpoint_iteration.is_some()
            {
                errln!("{i}");
                errln!("resume with:\n  {}", resume_command(&args));
            }
            return Err(e).with_context(|| format!("run on {}", args.mesh.display()));
        }
    };
    if !args.settings.quiet {
        for w in &outcome.warnings {
            errln!("warning: {w}");
        }
        if outcome.complete {
            errln!(
                "done: {} iterations → {}",
                outcome.iteration,
                args.out.display()
            );
            if let Some((before, after)) = outcome.alignment {
                errln!("normal alignment (area-weighted mean n·t): {before:.4} → {after:.4}");
            }
            match crate::max_safe::end_of_run(&args.out) {
                Ok(Some(line)) => errln!("{line}"),
                Ok(None) => {}
                Err(e) => errln!("warning: strongest safe λ: {e:#}"),
            }
            crate::open_hint::lines(&args.out, &crate::open_hint::program())
                .iter()
                .for_each(|l| errln!("{l}"));
        } else {
            errln!(
                "stopped after iteration {} (resume with --resume)",
                outcome.iteration
            );
        }
    }
    Ok(())
}

//! `stylize batch`: every row of a manifest (TOML or JSONL), sharded across a job array.

use std::path::PathBuf;

use anyhow::bail;

use crate::batch::{BatchOptions, RowStatus, Shard, read_manifest, run_batch_until_interrupted};
use crate::cmd::run::resolve_config;
use crate::cmd::shared::{LogFormat, RunSettings, count_noun};
use crate::signals::shell_quote;

/// Arguments of `stylize batch`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// Manifest: `.toml` with `[[run]]` tables, or JSON Lines (see docs/cli.md).
    pub manifest: PathBuf,
    /// Run only shard `i/n` (0-based). Default: from SLURM_ARRAY_TASK_ID / SLURM_ARRAY_TASK_COUNT
    /// when set, else every row.
    #[arg(long)]
    pub shard: Option<String>,
    /// Redo every row from scratch: complete rows, rows of a different task, partial rows
    /// (removes only the run directories' own files).
    #[arg(long)]
    pub force: bool,
    // Model, configuration and progress options, shared with `stylize run` (the per-row summary is
    // printed even with --quiet).
    #[command(flatten)]
    pub settings: RunSettings,
    /// Same as `--log-format jsonl` (kept for existing scripts).
    #[arg(long, hide = true)]
    pub jsonl: bool,
}

/// Runs `stylize batch`.
pub fn run(args: Args) -> anyhow::Result<()> {
    let mut settings = args.settings.clone();
    if args.jsonl {
        settings.log_format = LogFormat::Jsonl;
    }
    let config = settings.apply_remesh(resolve_config(
        settings.config.as_deref(),
        &settings.set,
        None,
        None,
    )?);
    let config = crate::cmd::shared::with_view_flags(config, settings.view_flags())?;
    let shard = match &args.shard {
        Some(s) => Shard::parse(s)?,
        None => Shard::from_env(|k| std::env::var(k).ok())?.unwrap_or(Shard::ALL),
    };
    let rows = read_manifest(&args.manifest)?;
    let log = settings.log_mode();
    let mut inputs = vec![("manifest".to_string(), args.manifest.clone())];
    if let Some(c) = &settings.config {
        inputs.push(("config file".into(), c.clone()));
    }
    let options = BatchOptions {
        config,
        shard,
        model: settings.model.clone(),
        log,
        force: args.force,
        inputs,
    };
    let (results, interrupted) = run_batch_until_interrupted(&rows, &options);
    let mut failed = 0;
    for (i, row, status, warnings) in &results {
        let what = match status {
            RowStatus::Skipped => "skipped (complete)".to_string(),
            RowStatus::Done { resumed: true } => "done (resumed)".to_string(),
            RowStatus::Done { resumed: false } => "done".to_string(),
            RowStatus::Failed(e) => {
                failed += 1;
                format!("FAILED: {e}")
            }
        };
        errln!(
            "row {i} {} → {}: {what}",
            row.mesh.display(),
            row.out.display()
        );
        for w in warnings {
            errln!("  warning: {w}");
        }
    }
    errln!(
        "shard {}/{}: {}, {} failed",
        shard.index,
        shard.count,
        count_noun(results.len(), "row", "rows"),
        failed
    );
    if let Some(i) = interrupted {
        let command: Vec<String> = std::env::args().map(|a| shell_quote(&a)).collect();
        errln!(
            "batch stopped by {}; run the same command again to resume (complete rows are \
             skipped, the interrupted row continues from its checkpoint):\n  {}",
            crate::signals::name(i.signal),
            command.join(" ")
        );
        return Err(i.into());
    }
    if failed > 0 {
        bail!(
            "{failed} of {} failed",
            count_noun(results.len(), "row", "rows")
        );
    }
    Ok(())
}

//! `stylize batch`: every row of a manifest (TOML or JSONL), sharded across a job array, and the
//! grid of its rows ([`crate::batch_grid`]).

use std::path::{Path, PathBuf};

use anyhow::bail;

use crate::batch::{
    BatchOptions, Row, RowResult, RowStatus, Shard, read_manifest, run_batch_reporting,
};
use crate::cmd::run::resolve_config;
use crate::cmd::shared::{LogFormat, RunSettings, count_noun};
use crate::runner::LogMode;
use crate::signals::{EXIT_IN_USE, Exit, shell_quote};

/// Arguments of `stylize batch`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// Manifest: `.toml` with `[[run]]` tables, or JSON Lines (see docs/cli.md).
    pub manifest: PathBuf,
    /// Run only shard `i/n` (0-based): the rows with `index % n == i`. Default: every row.
    /// Required inside a Slurm job array: `--shard "$SLURM_ARRAY_TASK_ID/N"` with
    /// `--array=0-(N-1)` (the count is never taken from the array's variables, which change when
    /// a subset is re-submitted).
    #[arg(long)]
    pub shard: Option<String>,
    /// Redo every row from scratch: complete rows, rows of a different task, partial rows
    /// (removes only the run directories' own files).
    #[arg(long)]
    pub force: bool,
    /// Where the grid of the rows goes (a PNG: one labelled tile per row, meshes × prompts/styles).
    /// Default: `MANIFEST_STEM_grid.png` beside the manifest.
    #[arg(long, value_name = "FILE")]
    pub grid: Option<PathBuf>,
    /// Run no row: only build the grid from the run directories as they stand (after the last
    /// shard of a sharded batch).
    #[arg(long, conflicts_with_all = ["shard", "force"])]
    pub grid_only: bool,
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
    // First: a stop request from now on is honoured (not the default action, which would kill).
    crate::signals::install()?;
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
    let rows = read_manifest(&args.manifest)?;
    // Before any row runs: a --grid that would replace a file of the batch is an error; the
    // default path inside a row's run directory (a manifest kept there) only means no grid.
    let grid_path = match &args.grid {
        Some(p) => {
            crate::batch_grid::check_path(p, &rows)?;
            Some(p.clone())
        }
        None if !args.grid_only && rows.len() > crate::batch_grid::DEFAULT_GRID_MAX_ROWS => {
            say(&format!(
                "grid: none ({} rows, more than the {} a batch draws unasked; pass --grid FILE, or \
                 build it later with --grid-only)",
                rows.len(),
                crate::batch_grid::DEFAULT_GRID_MAX_ROWS
            ));
            None
        }
        None => {
            let p = crate::batch_grid::default_path(&args.manifest);
            match crate::batch_grid::check_path(&p, &rows) {
                Ok(()) => Some(p),
                Err(e) if !args.grid_only => {
                    say(&format!("grid: none ({e:#}; pass --grid FILE)"));
                    None
                }
                Err(e) => return Err(e.context("pass --grid FILE")),
            }
        }
    };
    if args.grid_only {
        return match &grid_path {
            Some(p) => write_grid(p, &rows, &[]),
            None => Ok(()),
        };
    }
    let shard = Shard::resolve(args.shard.as_deref(), |k| std::env::var(k).ok())?;
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
    let jsonl = matches!(log, LogMode::Jsonl);
    let (results, interrupted) = run_batch_reporting(&rows, &options, &mut |result, took| {
        report_row(result, took, jsonl);
    });
    let count = |outcome: &str| {
        results
            .iter()
            .filter(|(_, _, s, _)| s.outcome() == outcome)
            .count()
    };
    let (failed, in_use) = (count("failed"), count("in-use"));
    let summary = format!(
        "shard {}/{}: {}, {failed} failed ({} done, {} resumed, {} skipped as complete, {in_use} in \
         use elsewhere, {} interrupted)",
        shard.index,
        shard.count,
        count_noun(results.len(), "row", "rows"),
        count("done"),
        count("resumed"),
        count("skipped"),
        count("interrupted"),
    );
    say(&summary);
    // The grid: by the batch that ran every row; a shard's end is not the batch's.
    let grid = if interrupted.is_some() {
        Ok(())
    } else if let Some(p) = grid_path.as_ref().filter(|_| shard.count == 1) {
        let known: Vec<(usize, RowStatus)> =
            results.iter().map(|(i, _, s, _)| (*i, s.clone())).collect();
        write_grid(p, &rows, &known)
    } else if grid_path.is_some() {
        say(&format!(
            "grid: not written by a shard; after the last shard, build it with: stylize batch {} \
             --grid-only{}",
            shell_quote(&args.manifest.display().to_string()),
            args.grid
                .as_ref()
                .map(|g| format!(" --grid {}", shell_quote(&g.display().to_string())))
                .unwrap_or_default()
        ));
        Ok(())
    } else {
        Ok(())
    };
    // A grid asked for (--grid) that cannot be written fails the batch; the default one is a
    // by-product, and its failure only a warning (every row's result stands).
    let grid_failed = match grid {
        Err(e) if args.grid.is_some() => {
            say(&format!("grid: not written: {e:#}"));
            true
        }
        Err(e) => {
            say(&format!("warning: grid: not written: {e:#}"));
            false
        }
        Ok(()) => false,
    };
    if let Some(i) = interrupted {
        let command: Vec<String> = std::env::args().map(|a| shell_quote(&a)).collect();
        say(&format!(
            "batch stopped by {}; run the same command again to resume (complete rows are \
             skipped, the interrupted row continues from its checkpoint):\n  {}",
            crate::signals::name(i.signal),
            command.join(" ")
        ));
        return Err(i.into());
    }
    if failed > 0 {
        bail!(
            "{failed} of {} failed",
            count_noun(results.len(), "row", "rows")
        );
    }
    if grid_failed {
        bail!("the grid could not be written (above)");
    }
    if in_use > 0 {
        return Err(Exit {
            code: EXIT_IN_USE,
            message: format!(
                "{} of {} in use by other processes (left to them; run again to check)",
                count_noun(in_use, "row", "rows"),
                results.len()
            ),
        }
        .into());
    }
    Ok(())
}

/// Writes the grid of every row ([`crate::batch_grid`]) and says so on stderr.
fn write_grid(path: &Path, rows: &[Row], known: &[(usize, RowStatus)]) -> anyhow::Result<()> {
    if rows.is_empty() {
        say("grid: none (the manifest has no rows)");
        return Ok(());
    }
    let counts = crate::batch_grid::write_grid(path, rows, known)?;
    say(&format!(
        "grid: {} ({}: {} with a result, {} without)",
        path.display(),
        count_noun(counts.results + counts.empty, "tile", "tiles"),
        counts.results,
        counts.empty
    ));
    Ok(())
}

/// A line on stderr; a log that cannot be written to (a closed terminal) is no reason to lose the
/// exit status.
fn say(line: &str) {
    use std::io::Write;
    let _ = writeln!(std::io::stderr(), "{line}");
}

/// The line of one ended row (stderr), and with `jsonl` its JSON object (stdout): `{"row": i,
/// "event": "row", "outcome": …, "seconds": …, "mesh": …, "out": …}` with `"error"` when the row
/// did not end well.
fn report_row(result: &RowResult, took: std::time::Duration, jsonl: bool) {
    let (i, row, status, warnings) = result;
    say(&format!(
        "row {i} {} → {}: {} ({:.1} s)",
        row.mesh.display(),
        row.out.display(),
        status.describe(),
        took.as_secs_f64()
    ));
    for w in warnings {
        say(&format!("  warning: {w}"));
    }
    if jsonl {
        let mut line = serde_json::json!({
            "row": i,
            "event": "row",
            "outcome": status.outcome(),
            "seconds": took.as_secs_f64(),
            "mesh": row.mesh.display().to_string(),
            "out": row.out.display().to_string(),
        });
        if let RowStatus::Failed(e) | RowStatus::InUse(e) | RowStatus::Interrupted(e) = status {
            line["error"] = e.clone().into();
        }
        // A stdout that cannot be written stops the batch like a signal (after this row).
        if crate::outln!("{line}").is_err() {
            crate::signals::output_closed();
        }
    }
}

//! `stylize eval`: identity-preservation metrics (spec §9) for run directories or mesh pairs.

use std::path::PathBuf;

use anyhow::bail;

use crate::eval::{evaluate, label, load_file_pair, load_run_pair, table};

/// Arguments of `stylize eval`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// Run directories (source: `deformation.npz` verts; result: `mesh.obj`).
    pub runs: Vec<PathBuf>,
    /// A source mesh and its result (same faces), repeatable: `--pair SOURCE RESULT`.
    #[arg(long, num_args = 2, value_names = ["SOURCE", "RESULT"])]
    pub pair: Vec<PathBuf>,
    /// Print JSON instead of a table.
    #[arg(long)]
    pub json: bool,
}

/// Runs `stylize eval`.
pub fn run(args: Args) -> anyhow::Result<()> {
    let mut pairs = Vec::new();
    for dir in &args.runs {
        let (s, r) = load_run_pair(dir)?;
        pairs.push((label(dir), s, r));
    }
    for two in args.pair.chunks(2) {
        let [source, result] = two else {
            bail!("--pair needs SOURCE and RESULT")
        };
        let (s, r) = load_file_pair(source, result)?;
        pairs.push((format!("{} → {}", label(source), label(result)), s, r));
    }
    if pairs.is_empty() {
        bail!("nothing to evaluate: give run directories or --pair SOURCE RESULT");
    }
    let report = evaluate(&pairs)?;
    if args.json {
        println!("{}", serde_json::to_string_pretty(&report)?);
    } else {
        print!("{}", table(&report));
    }
    Ok(())
}

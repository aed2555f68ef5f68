//! `stylize apply`.

/// Arguments of `stylize apply`.
#[derive(clap::Args, Debug)]
pub struct Args {}

/// Runs `stylize apply`.
pub fn run(_args: Args) -> anyhow::Result<()> {
    anyhow::bail!("`stylize apply` is not implemented yet")
}

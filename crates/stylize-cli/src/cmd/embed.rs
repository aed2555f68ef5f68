//! `stylize embed`.

/// Arguments of `stylize embed`.
#[derive(clap::Args, Debug)]
pub struct Args {}

/// Runs `stylize embed`.
pub fn run(_args: Args) -> anyhow::Result<()> {
    anyhow::bail!("`stylize embed` is not implemented yet")
}

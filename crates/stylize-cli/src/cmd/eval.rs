//! `stylize eval`.

/// Arguments of `stylize eval`.
#[derive(clap::Args, Debug)]
pub struct Args {}

/// Runs `stylize eval`.
pub fn run(_args: Args) -> anyhow::Result<()> {
    anyhow::bail!("`stylize eval` is not implemented yet")
}

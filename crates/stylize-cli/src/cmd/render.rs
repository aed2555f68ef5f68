//! `stylize render`.

/// Arguments of `stylize render`.
#[derive(clap::Args, Debug)]
pub struct Args {}

/// Runs `stylize render`.
pub fn run(_args: Args) -> anyhow::Result<()> {
    anyhow::bail!("`stylize render` is not implemented yet")
}

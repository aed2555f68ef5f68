//! `stylize mesh`.

/// Arguments of `stylize mesh`.
#[derive(clap::Args, Debug)]
pub struct Args {}

/// Runs `stylize mesh`.
pub fn run(_args: Args) -> anyhow::Result<()> {
    anyhow::bail!("`stylize mesh` is not implemented yet")
}

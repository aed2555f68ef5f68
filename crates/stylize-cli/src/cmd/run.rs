//! `stylize run`.

/// Arguments of `stylize run`.
#[derive(clap::Args, Debug)]
pub struct Args {}

/// Runs `stylize run`.
pub fn run(_args: Args) -> anyhow::Result<()> {
    anyhow::bail!("`stylize run` is not implemented yet")
}

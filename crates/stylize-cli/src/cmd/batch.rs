//! `stylize batch`.

/// Arguments of `stylize batch`.
#[derive(clap::Args, Debug)]
pub struct Args {}

/// Runs `stylize batch`.
pub fn run(_args: Args) -> anyhow::Result<()> {
    anyhow::bail!("`stylize batch` is not implemented yet")
}

//! `stylize debug-guidance` (hidden): one guidance evaluation dumped to .npz for inspection.

/// Arguments of `stylize debug-guidance`.
#[derive(clap::Args, Debug)]
pub struct Args {}

/// Runs `stylize debug-guidance`.
pub fn run(_args: Args) -> anyhow::Result<()> {
    anyhow::bail!("`stylize debug-guidance` is not implemented yet")
}

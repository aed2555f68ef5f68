//! A model-free stylization without the command line: the cube style on the Stanford bunny.
//!
//! ```sh
//! cargo run --release -p stylize --example stylize_mesh -- [MESH] [OUT_DIR]
//! ```
//! writes a complete run directory (`mesh.obj`, `deformation.npz`, `turntable.png`, …) to
//! `OUT_DIR` (default `runs/bunny-cube`).

use stylize::config::Config;
use stylize::runner::{RunRequest, execute};
use stylize::style::Style;

fn main() -> anyhow::Result<()> {
    let mut args = std::env::args().skip(1);
    let bunny = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../../fixtures/meshes/bunny.obj"
    );
    let mesh = args.next().unwrap_or_else(|| bunny.into());
    let out = args.next().unwrap_or_else(|| "runs/bunny-cube".into());
    let mut config = Config::default();
    config.style.iterations = 100;
    let request = RunRequest {
        mesh: mesh.into(),
        out: out.into(),
        config,
        force: true,
        resume: false,
        halt_after: None,
    };
    let outcome = execute(&request, Style::Cube)?;
    if let Some((before, after)) = outcome.alignment {
        println!("cube alignment {before:.3} -> {after:.3}");
    }
    println!("wrote {}", request.out.join("mesh.obj").display());
    Ok(())
}

//! `stylize`: text-guided, identity-preserving mesh stylization (Geometry in Style).

// Printing goes through `stylize_cli::output` (never panics on a closed pipe).
#![deny(clippy::print_stdout, clippy::print_stderr)]

use clap::{Parser, Subcommand};
use stylize_cli::cmd;
#[cfg(not(all(feature = "text", feature = "view")))]
use stylize_cli::features::not_built;

/// Text-guided, identity-preserving stylization of triangle meshes (Geometry in Style).
#[derive(Parser, Debug)]
#[command(name = "stylize", version, about, long_about = None)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand, Debug)]
enum Command {
    /// Re-apply a saved deformation (.npz) at one or several strengths λ.
    Apply(cmd::apply::Args),
    /// Mesh utilities (`mesh check FILE`: validation report).
    Mesh(cmd::mesh::Args),
    /// Render a mesh: turntable frames and a contact sheet.
    Render(cmd::render::Args),
    /// Remesh a mesh isotropically (even triangles of one edge length) with a quality report.
    Remesh(cmd::remesh::Args),
    /// Precompute and cache prompt embeddings with the T5 encoder.
    Embed(cmd::embed::Args),
    /// Stylize one mesh (text-guided with --model, or a model-free normal style).
    Run(cmd::run::Args),
    /// Stylize every row of a manifest (sharded across a job array).
    Batch(cmd::batch::Args),
    /// Identity metrics (per-face area ratio, volume ratio) and CLIP similarity with --clip DIR.
    Eval(cmd::eval::Args),
    /// Show runs and meshes in a local web page with a live λ slider (prints the URL).
    View(cmd::view::Args),
    /// What this machine and build can do for the text path (ONNX Runtime, CUDA, GPUs, models).
    Doctor(cmd::doctor::Args),
    /// Run one guidance evaluation with given noise/timesteps and dump every intermediate to .npz.
    #[command(hide = true, name = "debug-guidance")]
    DebugGuidance(cmd::debug_guidance::Args),
}

/// Mesa's Vulkan drivers (lavapipe) probe for a Wayland display when the GPU instance is created, and
/// libwayland prints `error: XDG_RUNTIME_DIR is invalid or not set in the environment.` when the
/// variable is unset (batch jobs, containers, ssh sessions). When it is unset or empty, the process
/// gets a private, empty runtime directory instead (created 0700, removed at exit), so the probe
/// finds no display and stays quiet; a set variable is left alone.
fn private_runtime_dir() -> Option<tempfile::TempDir> {
    if std::env::var_os("XDG_RUNTIME_DIR").is_some_and(|v| !v.is_empty()) {
        return None;
    }
    let dir = tempfile::Builder::new()
        .prefix("stylize-runtime-")
        .tempdir()
        .ok()?;
    // SAFETY: called first thing in `main`, before any other thread exists, so nothing can read
    // the environment concurrently.
    #[allow(unsafe_code)]
    unsafe {
        std::env::set_var("XDG_RUNTIME_DIR", dir.path());
    }
    Some(dir)
}

/// Parses the arguments; `--version` also names the features this binary was built with
/// (`stylize 0.1.0 (features: text, gpu, view, mp4)`).
fn parse_cli() -> Cli {
    use clap::{CommandFactory, FromArgMatches};
    // Leaked once: clap keeps a `'static` version string.
    let version: &'static str = format!(
        "{} (features: {})",
        env!("CARGO_PKG_VERSION"),
        stylize_cli::features::summary()
    )
    .leak();
    let matches = Cli::command().version(version).get_matches();
    Cli::from_arg_matches(&matches).unwrap_or_else(|e| e.exit())
}

fn main() -> std::process::ExitCode {
    // Before any thread allocates: the loop's large buffers are reused, not page-faulted in anew.
    stylize::malloc::retain_freed_buffers();
    let _runtime_dir = private_runtime_dir();
    let cli = parse_cli();
    let result = match cli.command {
        Command::Apply(a) => cmd::apply::run(a),
        Command::Mesh(a) => cmd::mesh::run(a),
        Command::Render(a) => cmd::render::run(a),
        Command::Remesh(a) => cmd::remesh::run(a),
        #[cfg(feature = "text")]
        Command::Embed(a) => cmd::embed::run(a),
        #[cfg(not(feature = "text"))]
        Command::Embed(_) => Err(not_built("text", "stylize embed")),
        Command::Run(a) => cmd::run::run(a),
        Command::Doctor(a) => cmd::doctor::run(a),
        Command::Batch(a) => cmd::batch::run(a),
        Command::Eval(a) => cmd::eval::run(a),
        #[cfg(feature = "view")]
        Command::View(a) => cmd::view::run(a),
        #[cfg(not(feature = "view"))]
        Command::View(_) => Err(not_built("view", "stylize view")),
        #[cfg(feature = "text")]
        Command::DebugGuidance(a) => cmd::debug_guidance::run(a),
        #[cfg(not(feature = "text"))]
        Command::DebugGuidance(_) => Err(not_built("text", "stylize debug-guidance")),
    };
    match result {
        Ok(()) => std::process::ExitCode::SUCCESS,
        Err(e) => {
            stylize_cli::errln!("error: {e:#}");
            // 128 + signal after SIGHUP/SIGINT/SIGTERM, 75 when a run directory is locked by
            // another process (for a batch: rows left to other processes), 141 when stdout's
            // reader hung up, else 1.
            std::process::ExitCode::from(stylize_cli::signals::exit_code(&e))
        }
    }
}

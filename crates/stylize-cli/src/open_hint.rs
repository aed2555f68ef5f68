//! The last lines of a finished `stylize run`: which files of the run directory to open, and the
//! `stylize view` command that shows the run with a live λ slider.

use std::path::{Path, PathBuf};

use crate::signals::shell_quote;

/// Files of a run directory worth opening, in that order, with what each is.
const TO_OPEN: &[(&str, &str)] = &[
    ("turntable.png", "views of the result"),
    ("before_after.png", "source and result, same views"),
    ("turntable.gif", "animated turntable"),
    ("turntable.mp4", "the same turntable as H.264 video"),
    ("mesh.obj", "the stylized mesh (also mesh.ply, mesh.glb)"),
    (
        "mesh_heat.glb",
        "the result coloured by how far each vertex moved (scale in run.json)",
    ),
    (
        "deformation.npz",
        "re-apply at another strength: stylize apply",
    ),
];

/// How to call this binary again from the current directory: `stylize` when that name on `PATH`
/// is this executable (`cargo install`), else its path (`target/release/stylize` after the
/// README's `cargo run`: the same build, so nothing is compiled again), relative to the current
/// directory when it lies below it. Not shell-quoted.
pub fn program() -> String {
    let Ok(exe) = std::env::current_exe().and_then(std::fs::canonicalize) else {
        return "stylize".to_string();
    };
    let on_path = std::env::var_os("PATH").is_some_and(|paths| {
        std::env::split_paths(&paths)
            .filter_map(|d| std::fs::canonicalize(d.join("stylize")).ok())
            .next()
            .is_some_and(|found| found == exe)
    });
    if on_path {
        return "stylize".to_string();
    }
    let shown: PathBuf = std::env::current_dir()
        .and_then(std::fs::canonicalize)
        .ok()
        .and_then(|cwd| exe.strip_prefix(cwd).ok().map(Path::to_path_buf))
        .unwrap_or(exe);
    shown.display().to_string()
}

/// The closing lines for the run directory `dir` (only files that exist are named); `program`
/// is how to call `stylize` ([`program`], quoted here).
pub fn lines(dir: &Path, program: &str) -> Vec<String> {
    let mut out = vec!["open:".to_string()];
    for (name, what) in TO_OPEN {
        let path = dir.join(name);
        if path.is_file() {
            out.push(format!("  {}  ({what})", path.display()));
        }
    }
    if !cfg!(feature = "mp4") && dir.join("turntable.gif").is_file() {
        out.push(format!(
            "  (no turntable.mp4: this binary has no H.264 encoder; `{} …` builds one with it)",
            crate::features::cargo_run_adding("mp4")
        ));
    }
    let dir = shell_quote(&dir.display().to_string());
    if cfg!(feature = "view") {
        out.push("view it, with a live λ slider:".to_string());
        out.push(format!("  {} view {dir}", shell_quote(program)));
    } else {
        // A quick-start build (docs/cli.md, "Builds and features"): this command adds the viewer
        // to the same features (axum and tokio, about 80 s after the quick-start build), then
        // opens the run.
        out.push(
            "view it, with a live λ slider (this binary has no `view`; the command adds it first):"
                .to_string(),
        );
        out.push(format!(
            "  {} view {dir}",
            crate::features::cargo_run_adding("view")
        ));
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_existing_files_and_the_view_command() {
        let dir = tempfile::tempdir().unwrap_or_else(|e| panic!("{e}"));
        let run = dir.path().join("my run");
        std::fs::create_dir_all(&run).unwrap_or_else(|e| panic!("{e}"));
        std::fs::write(run.join("turntable.png"), b"x").unwrap_or_else(|e| panic!("{e}"));
        let text = lines(&run, "stylize").join("\n");
        assert!(text.contains("turntable.png"), "{text}");
        assert!(!text.contains("mesh.obj"), "{text}");
        assert!(text.lines().last().is_some_and(|l| l.contains("my run")));
        let text = lines(&run, "target/release/stylize").join("\n");
        if cfg!(feature = "view") {
            assert!(text.contains("  target/release/stylize view '"), "{text}");
        } else {
            assert!(
                text.contains(" --features ") && text.contains("view --bin stylize -- view '"),
                "{text}"
            );
        }
    }

    #[test]
    fn program_is_this_executable() {
        // The test binary is not `stylize` on PATH: its path comes back, and it names this file.
        let p = program();
        let exe = std::env::current_exe().unwrap_or_else(|e| panic!("{e}"));
        let name = exe.file_name().map(|n| n.to_string_lossy().into_owned());
        assert!(name.is_some_and(|n| p.contains(&n)), "{p}");
    }
}

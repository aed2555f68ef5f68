//! The last lines of a finished `stylize run`: which files of the run directory to open, and the
//! `stylize view` command that shows the run with a live λ slider.

use std::path::Path;

use crate::signals::shell_quote;

/// Files of a run directory worth opening, in that order, with what each is.
const TO_OPEN: &[(&str, &str)] = &[
    ("turntable.png", "views of the result"),
    ("before_after.png", "source and result, same views"),
    ("turntable.gif", "animated turntable"),
    ("mesh.obj", "the stylized mesh (also mesh.ply, mesh.glb)"),
    (
        "deformation.npz",
        "re-apply at another strength: stylize apply",
    ),
];

/// The closing lines for the run directory `dir` (only files that exist are named).
pub fn lines(dir: &Path) -> Vec<String> {
    let mut out = vec!["open:".to_string()];
    for (name, what) in TO_OPEN {
        let path = dir.join(name);
        if path.is_file() {
            out.push(format!("  {}  ({what})", path.display()));
        }
    }
    out.push("view it, with a live λ slider:".to_string());
    out.push(format!(
        "  stylize view {}",
        shell_quote(&dir.display().to_string())
    ));
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
        let text = lines(&run).join("\n");
        assert!(text.contains("turntable.png"), "{text}");
        assert!(!text.contains("mesh.obj"), "{text}");
        assert!(text.contains("stylize view '"), "{text}");
        assert!(text.lines().last().is_some_and(|l| l.contains("my run")));
    }
}

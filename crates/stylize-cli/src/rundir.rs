//! The run directory: what a run writes, how completeness is decided, and how an existing
//! directory is treated (refuse, resume, or overwrite with `--force`).
//!
//! ```text
//! RUN_DIR/
//!   config.toml        resolved configuration (every key)
//!   metrics.jsonl      one JSON object per iteration: losses, weights, timings
//!   checkpoint.json    x, Adam moments and step, RNG state, iteration (atomic: temp + rename)
//!   previews/iter_NNNNNN.png   grid of the current views every run.preview_every iterations
//!   mesh.obj, mesh.ply, mesh.glb   deformed mesh (side-2 cube frame) with vertex normals
//!   deformation.npz    reference format (spec §8) + format_version, seed, rotation_rule
//!   turntable.png      contact sheet of an orbit around the result
//!   run.json           summary; written last — its presence marks the run complete
//! ```

use std::path::{Path, PathBuf};

use anyhow::{Context, bail};

use crate::checkpoint::Checkpoint;

/// Paths inside a run directory.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct RunDir {
    root: PathBuf,
}

/// Every file name a run writes at top level (what `--force` removes).
pub const RUN_FILES: &[&str] = &[
    "config.toml",
    "metrics.jsonl",
    "checkpoint.json",
    "checkpoint.json.tmp",
    "mesh.obj",
    "mesh.ply",
    "mesh.glb",
    "deformation.npz",
    "turntable.png",
    "run.json",
];

/// How an existing directory is to be used.
#[derive(Debug)]
pub enum Start {
    /// Nothing there (or removed with `--force`): start at iteration 1.
    Fresh,
    /// A checkpoint to continue from.
    Resume(Box<Checkpoint>),
}

impl RunDir {
    /// A run directory at `root` (nothing is touched).
    pub fn new(root: impl Into<PathBuf>) -> Self {
        Self { root: root.into() }
    }

    /// The directory.
    pub fn root(&self) -> &Path {
        &self.root
    }

    /// `root/name`.
    pub fn file(&self, name: &str) -> PathBuf {
        self.root.join(name)
    }

    /// `config.toml`.
    pub fn config(&self) -> PathBuf {
        self.file("config.toml")
    }

    /// `metrics.jsonl`.
    pub fn metrics(&self) -> PathBuf {
        self.file("metrics.jsonl")
    }

    /// `checkpoint.json`.
    pub fn checkpoint(&self) -> PathBuf {
        self.file("checkpoint.json")
    }

    /// `deformation.npz`.
    pub fn deformation(&self) -> PathBuf {
        self.file("deformation.npz")
    }

    /// `run.json` (the completion marker).
    pub fn summary(&self) -> PathBuf {
        self.file("run.json")
    }

    /// `previews/`.
    pub fn previews(&self) -> PathBuf {
        self.file("previews")
    }

    /// True when `run.json` exists (written after every other output).
    pub fn is_complete(&self) -> bool {
        self.summary().is_file()
    }

    /// True when a checkpoint exists.
    pub fn has_checkpoint(&self) -> bool {
        self.checkpoint().is_file()
    }

    /// Decides how to start, creating the directory (and its parents) when missing.
    ///
    /// - complete run: refused unless `force` (which removes the run's files, see [`RUN_FILES`]);
    /// - checkpoint present: `resume` continues from it, `force` starts over, otherwise refused;
    /// - otherwise: fresh (a `resume` without a checkpoint starts fresh too).
    pub fn prepare(&self, force: bool, resume: bool) -> anyhow::Result<Start> {
        if self.root.exists() && !self.root.is_dir() {
            bail!(
                "output {} exists and is not a directory",
                self.root.display()
            );
        }
        if force {
            self.remove_outputs()?;
        } else if self.is_complete() {
            bail!(
                "{} already holds a complete run (run.json); pass --force to overwrite it",
                self.root.display()
            );
        } else if self.has_checkpoint() {
            if !resume {
                bail!(
                    "{} holds an interrupted run (checkpoint.json); pass --resume to continue it or --force to start over",
                    self.root.display()
                );
            }
            let c = Checkpoint::load(&self.checkpoint())?;
            return Ok(Start::Resume(Box::new(c)));
        }
        std::fs::create_dir_all(&self.root)
            .with_context(|| format!("cannot create {}", self.root.display()))?;
        Ok(Start::Fresh)
    }

    fn remove_outputs(&self) -> anyhow::Result<()> {
        for name in RUN_FILES {
            let p = self.file(name);
            if p.is_file() {
                std::fs::remove_file(&p)
                    .with_context(|| format!("cannot remove {}", p.display()))?;
            }
        }
        let previews = self.previews();
        if previews.is_dir() {
            std::fs::remove_dir_all(&previews)
                .with_context(|| format!("cannot remove {}", previews.display()))?;
        }
        Ok(())
    }

    /// Keeps the `metrics.jsonl` lines of iterations `<= iteration` (after a resume, the lines a
    /// killed run wrote past its last checkpoint are dropped so the file has each iteration once).
    pub fn truncate_metrics(&self, iteration: u64) -> anyhow::Result<()> {
        let path = self.metrics();
        if !path.is_file() {
            return Ok(());
        }
        let text = std::fs::read_to_string(&path)
            .with_context(|| format!("cannot read {}", path.display()))?;
        let mut kept = String::new();
        for line in text.lines() {
            let it = serde_json::from_str::<serde_json::Value>(line)
                .ok()
                .and_then(|v| v.get("iteration").and_then(serde_json::Value::as_u64));
            if it.is_some_and(|i| i <= iteration) {
                kept.push_str(line);
                kept.push('\n');
            }
        }
        std::fs::write(&path, kept).with_context(|| format!("cannot write {}", path.display()))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn complete_run_is_refused_without_force() {
        let dir = tempfile::tempdir().unwrap_or_else(|e| panic!("{e}"));
        let run = RunDir::new(dir.path().join("a/b/run"));
        assert!(matches!(run.prepare(false, false), Ok(Start::Fresh)));
        assert!(run.root().is_dir(), "parent folders are created");
        std::fs::write(run.summary(), "{}").unwrap_or_else(|e| panic!("{e}"));
        std::fs::write(run.file("mesh.obj"), "").unwrap_or_else(|e| panic!("{e}"));
        let e = run
            .prepare(false, false)
            .err()
            .map(|e| e.to_string())
            .unwrap_or_default();
        assert!(e.contains("--force"), "{e}");
        std::fs::write(run.file("user-notes.txt"), "keep me").unwrap_or_else(|e| panic!("{e}"));
        assert!(matches!(run.prepare(true, false), Ok(Start::Fresh)));
        assert!(!run.summary().exists() && !run.file("mesh.obj").exists());
        assert!(
            run.file("user-notes.txt").exists(),
            "--force removes only the run's own files"
        );
    }

    #[test]
    fn metrics_truncation_keeps_lines_up_to_the_checkpoint() {
        let dir = tempfile::tempdir().unwrap_or_else(|e| panic!("{e}"));
        let run = RunDir::new(dir.path());
        let lines: String = (1..=7)
            .map(|i| format!("{{\"iteration\":{i}}}\n"))
            .collect();
        std::fs::write(run.metrics(), lines).unwrap_or_else(|e| panic!("{e}"));
        run.truncate_metrics(5).unwrap_or_else(|e| panic!("{e}"));
        let text = std::fs::read_to_string(run.metrics()).unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(text.lines().count(), 5);
    }
}

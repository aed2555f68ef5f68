//! The run directory: what a run writes, how completeness is decided, and how an existing
//! directory is treated (refuse, resume, or overwrite with `--force`).
//!
//! ```text
//! RUN_DIR/
//!   run.lock           held for the whole life of a run (crate::lock); absent when none runs
//!   task.json          the task's identity (crate::identity), written first: marks the folder ours
//!   config.toml        resolved configuration (every key)
//!   metrics.jsonl      one JSON object per iteration: losses, weights, timings
//!   checkpoint.json    iteration, the run's state (x, Adam moments and step, RNG state, config),
//!                      task identity (crate::checkpoint)
//!   previews/iter_NNNNNN.png   grid of the current views every run.preview_every iterations
//!   mesh.obj, mesh.ply, mesh.glb   deformed mesh (side-2 cube frame) with vertex normals
//!   deformation.npz    reference format (spec §8) + format_version, seed, rotation_rule
//!   snapshots.npz      deformed positions at iteration 0, every run.snapshot_every and the last
//!                      (stylize::snapshots; rewritten atomically while the run goes)
//!   turntable.png      contact sheet of an orbit around the result, filling its tiles
//!   turntable.gif      the same orbit animated (run.turntable_gif_frames frames, looping)
//!   turntable.mp4      the same frames as H.264 video (stylize feature mp4; a failure is a warning)
//!   before_after.png   source (top) and result (bottom), same views and crop (stylize::run_pictures)
//!   run.json           summary; written last — its presence marks the run complete
//! ```
//!
//! Every file is replaced atomically and durably ([`crate::durable`]). Rules for an existing
//! folder ([`RunDir::claim`]):
//! - an output never replaces an input (mesh, exemplar, config, mask, manifest): refused always,
//!   `--force` included (paths are compared by file identity, so links and `..` do not fool it);
//! - a non-empty folder that is not one of our run directories (no valid `task.json`,
//!   `checkpoint.json` or `run.json`) is refused unless `--force`;
//! - `--force` removes only our own files ([`RUN_FILES`], the preview grids in `previews/`, our
//!   temporary files), and `previews/` itself only when that leaves it empty;
//! - the directory lock is taken before anything in the folder is read or changed.

use std::os::unix::fs::MetadataExt;
use std::path::{Path, PathBuf};

use serde::de::DeserializeOwned;
use serde::{Deserialize, Serialize};

use crate::checkpoint::Checkpoint;
use crate::error::{Error, IoContext, Result};
use crate::identity::TaskIdentity;
use crate::lock::{RunLock, is_lock_name};

/// `return Err(Error::refused(dir, format!(…)))`.
macro_rules! run_dir_err {
    ($dir:expr, $($arg:tt)*) => {
        return Err(Error::refused($dir, format!($($arg)*)))
    };
}

/// Paths inside a run directory.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct RunDir {
    root: PathBuf,
}

/// Every file name a run writes at top level (what `--force` removes, with the preview grids).
pub const RUN_FILES: &[&str] = &[
    "task.json",
    "config.toml",
    "metrics.jsonl",
    "checkpoint.json",
    "mesh.obj",
    "mesh.ply",
    "mesh.glb",
    "mesh_heat.glb",
    "deformation.npz",
    "turntable.png",
    "turntable.gif",
    "turntable.mp4",
    "before_after.png",
    "snapshots.npz",
    "run.json",
    "source_remeshed.obj",
];

/// The `format` value of `task.json`.
const TASK_FORMAT: &str = "stylize-task";

/// How an existing directory is to be used; `S` is the state the caller keeps in its checkpoints.
#[derive(Debug)]
pub enum Start<S> {
    /// Nothing there (or removed with `--force`): start at iteration 1.
    Fresh,
    /// A checkpoint of the same task to continue from.
    Resume(Box<Checkpoint<S>>),
    /// A complete run of the same task (only when [`Claim::skip_complete`]).
    Complete,
}

/// Whether and how to continue from a checkpoint.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ResumeMode {
    /// A checkpoint is refused (`--resume` or `--force` needed).
    Never,
    /// A checkpoint must be there (`--resume`): anything else is an error.
    Required,
    /// Continue when there is a checkpoint, start fresh otherwise (batch rows).
    IfCheckpoint,
}

/// What a run asks of its directory.
#[derive(Clone, Debug)]
pub struct Claim<'a> {
    /// Start over: remove our own files first.
    pub force: bool,
    /// Checkpoint handling.
    pub resume: ResumeMode,
    /// A complete run of the same task is [`Start::Complete`] instead of an error.
    pub skip_complete: bool,
    /// The task about to run.
    pub identity: &'a TaskIdentity,
    /// The files the run reads, with their role (`input mesh`, `config file`, …).
    pub inputs: &'a [(String, PathBuf)],
}

/// `task.json`.
#[derive(Debug, Serialize, Deserialize)]
struct TaskFile {
    format: String,
    identity: TaskIdentity,
}

/// The state of a folder before a run claims it.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Existing {
    /// No such folder.
    Missing,
    /// An empty folder (or one holding only our lock or temporary files).
    Empty,
    /// One of our run directories.
    Ours,
    /// A non-empty folder that is not a run directory; a few of its entries.
    Foreign(Vec<String>),
}

/// Whether a top-level name in a run directory is one the run itself creates.
pub fn is_own_entry(name: &str) -> bool {
    RUN_FILES.contains(&name)
        || name == "previews"
        || is_lock_name(name)
        || crate::durable::is_temp_name(name)
}

/// (device, inode).
type FileId = (u64, u64);

/// Identity of a file: (device, inode) of the entry itself and of what it points to.
fn file_ids(path: &Path) -> Option<(FileId, Option<FileId>)> {
    let l = std::fs::symlink_metadata(path).ok()?;
    let followed = std::fs::metadata(path).ok().map(|m| (m.dev(), m.ino()));
    Some(((l.dev(), l.ino()), followed))
}

/// Canonical form of a path whose last component may not exist: the parent canonicalized, the
/// name kept (so a link named like an output is compared as the link, not its target).
fn canonical_entry(path: &Path) -> Option<PathBuf> {
    let name = path.file_name()?;
    let parent = match path.parent() {
        Some(p) if !p.as_os_str().is_empty() => p,
        _ => Path::new("."),
    };
    Some(std::fs::canonicalize(parent).ok()?.join(name))
}

/// Refuses when writing any of `outputs` (files replaced by rename) or removing any folder in
/// `trees` would replace or delete one of `inputs` (`(role, path)`). Files are compared by
/// identity (device and inode, links followed and not), folders by canonical path. This check
/// is not lifted by `--force`.
pub fn refuse_overwriting_inputs(
    outputs: &[PathBuf],
    trees: &[PathBuf],
    inputs: &[(String, PathBuf)],
) -> Result<()> {
    for (role, input) in inputs {
        let Some((in_entry, in_target)) = file_ids(input) else {
            continue;
        };
        for out in outputs {
            let Some((out_entry, out_target)) = file_ids(out) else {
                continue;
            };
            let same = out_entry == in_entry
                || (out_target.is_some() && out_target == in_target)
                || out_target == Some(in_entry);
            if same {
                run_dir_err!(
                    out,
                    "refusing to write {}: it is the {role} {} — an output never replaces an \
                     input (not even with --force); choose another output location",
                    out.display(),
                    input.display()
                );
            }
        }
        let entry = canonical_entry(input);
        let target = std::fs::canonicalize(input).ok();
        for tree in trees {
            let Ok(tree_c) = std::fs::canonicalize(tree) else {
                continue;
            };
            let inside = |p: &Option<PathBuf>| p.as_ref().is_some_and(|p| p.starts_with(&tree_c));
            if inside(&entry) || inside(&target) {
                run_dir_err!(
                    tree,
                    "refusing to use {}: the {role} {} lies inside it and would be removed — \
                     an output never replaces an input (not even with --force); move the input",
                    tree.display(),
                    input.display()
                );
            }
        }
    }
    Ok(())
}

/// Whether `name` is a preview grid's file name, `iter_` then digits then `.png`.
pub fn is_preview_name(name: &str) -> bool {
    name.strip_prefix("iter_")
        .and_then(|r| r.strip_suffix(".png"))
        .is_some_and(|d| !d.is_empty() && d.bytes().all(|b| b.is_ascii_digit()))
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

    /// `task.json`.
    pub fn task(&self) -> PathBuf {
        self.file("task.json")
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

    /// The identity in `task.json`, if it is there and valid.
    pub fn task_identity(&self) -> Option<TaskIdentity> {
        let text = std::fs::read_to_string(self.task()).ok()?;
        let t: TaskFile = serde_json::from_str(&text).ok()?;
        (t.format == TASK_FORMAT).then_some(t.identity)
    }

    /// Writes `task.json` (first file of a fresh run: it marks the folder as ours).
    pub fn write_task(&self, identity: &TaskIdentity) -> Result<()> {
        let t = TaskFile {
            format: TASK_FORMAT.into(),
            identity: identity.clone(),
        };
        let text = serde_json::to_string_pretty(&t)?;
        crate::durable::replace_bytes(&self.task(), text.as_bytes())
    }

    /// Whether the folder holds a valid `task.json`, a run summary or a checkpoint with a state
    /// of type `S`.
    fn has_marker<S: DeserializeOwned>(&self) -> bool {
        if self.task_identity().is_some() {
            return true;
        }
        let json = |p: PathBuf| -> Option<serde_json::Value> {
            serde_json::from_str(&std::fs::read_to_string(p).ok()?).ok()
        };
        let summary = json(self.summary());
        if summary.is_some_and(|v| v.get("status").is_some() && v.get("objective").is_some()) {
            return true;
        }
        self.has_checkpoint() && Checkpoint::<S>::load(&self.checkpoint()).is_ok()
    }

    /// What is at `root` now (a checkpoint counts as ours when its state parses as an `S`).
    pub fn inspect<S: DeserializeOwned>(&self) -> Result<Existing> {
        let entries = match std::fs::read_dir(&self.root) {
            Ok(e) => e,
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(Existing::Missing),
            Err(e) => {
                return Err(Error::io("cannot list", &self.root, e));
            }
        };
        let mut names = Vec::new();
        for e in entries {
            let e = e.io_context("cannot list", &self.root)?;
            names.push(e.file_name().to_string_lossy().into_owned());
        }
        if names
            .iter()
            .all(|n| is_lock_name(n) || crate::durable::is_temp_name(n))
        {
            return Ok(Existing::Empty);
        }
        if self.has_marker::<S>() {
            return Ok(Existing::Ours);
        }
        names.sort();
        Ok(Existing::Foreign(names))
    }

    /// Takes the directory for a run: checks inputs are not overwritten, refuses foreign folders
    /// without `--force`, takes the lock, and decides (under the lock) how to start. `S` is the
    /// state the caller's checkpoints hold ([`Checkpoint`]); a resume hands it back.
    pub fn claim<S: DeserializeOwned>(&self, claim: &Claim<'_>) -> Result<(RunLock, Start<S>)> {
        if self.root.exists() && !self.root.is_dir() {
            run_dir_err!(
                &self.root,
                "output {} exists and is not a directory",
                self.root.display()
            );
        }
        if claim.force && claim.resume == ResumeMode::Required {
            run_dir_err!(
                &self.root,
                "--resume and --force contradict each other: --force starts over"
            );
        }
        if claim.resume == ResumeMode::Required && !self.root.is_dir() {
            run_dir_err!(
                &self.root,
                "--resume: {} does not exist, so there is nothing to resume (start the run \
                 without --resume)",
                self.root.display()
            );
        }
        // A resume never rewrites task.json or config.toml (`--resume` alone reads the latter).
        let outputs: Vec<PathBuf> = RUN_FILES
            .iter()
            .filter(|n| {
                claim.resume != ResumeMode::Required || !matches!(**n, "task.json" | "config.toml")
            })
            .map(|n| self.file(n))
            .collect();
        refuse_overwriting_inputs(&outputs, &[self.previews()], claim.inputs)?;
        match self.inspect::<S>()? {
            Existing::Foreign(names) if !claim.force => {
                let shown: Vec<&str> = names.iter().take(6).map(String::as_str).collect();
                run_dir_err!(
                    &self.root,
                    "{} is not empty and is not a stylize run directory (it holds {}{}); choose \
                     a new or empty folder, or pass --force to write into it anyway (--force \
                     replaces only files named like the run's own: {}, previews/)",
                    self.root.display(),
                    shown.join(", "),
                    if names.len() > shown.len() {
                        ", …"
                    } else {
                        ""
                    },
                    RUN_FILES.join(", ")
                );
            }
            _ => {}
        }
        std::fs::create_dir_all(&self.root).io_context("cannot create", &self.root)?;
        let lock = RunLock::acquire(&self.root)?;
        self.remove_temporaries();
        let start = self.decide(claim)?;
        Ok((lock, start))
    }

    fn decide<S: DeserializeOwned>(&self, claim: &Claim<'_>) -> Result<Start<S>> {
        let dir = self.root.display();
        if claim.force {
            self.remove_outputs()?;
            return Ok(Start::Fresh);
        }
        let recorded = || -> Result<Option<TaskIdentity>> {
            if self.has_checkpoint() {
                return Ok(Checkpoint::<S>::load(&self.checkpoint())?.identity);
            }
            Ok(self.task_identity())
        };
        if self.is_complete() {
            if claim.skip_complete {
                return match recorded()? {
                    Some(id) if id == *claim.identity => Ok(Start::Complete),
                    Some(id) => {
                        let differences = id.differences(claim.identity);
                        Err(Error::DifferentTask {
                            dir: self.root.clone(),
                            message: format!(
                                "{dir} holds a complete run of a different task:\n  {}\nchange \
                                 the row's `out`, restore its settings, or pass --force to redo it",
                                differences.join("\n  ")
                            ),
                            differences,
                        })
                    }
                    None => run_dir_err!(
                        &self.root,
                        "{dir} holds a complete run written by an older stylize without a task \
                         identity, so it cannot be told whether it is this task; pass --force \
                         to redo it"
                    ),
                };
            }
            run_dir_err!(
                &self.root,
                "{dir} already holds a complete run (run.json){}; pass --force to overwrite it",
                if claim.resume == ResumeMode::Required {
                    ": there is nothing to resume"
                } else {
                    ""
                }
            );
        }
        if self.has_checkpoint() {
            if claim.resume == ResumeMode::Never {
                run_dir_err!(
                    &self.root,
                    "{dir} holds an interrupted run (checkpoint.json); pass --resume to continue \
                     it or --force to start over"
                );
            }
            let c = Checkpoint::<S>::load(&self.checkpoint())?;
            let Some(id) = &c.identity else {
                run_dir_err!(
                    &self.root,
                    "the checkpoint in {dir} was written by an older stylize (checkpoint version \
                     {}) without a task identity, so it cannot be verified to belong to this \
                     task; pass --force to start over",
                    c.version
                );
            };
            let diffs = id.differences(claim.identity);
            if !diffs.is_empty() {
                return Err(Error::DifferentTask {
                    dir: self.root.clone(),
                    message: format!(
                        "refusing to resume: the checkpoint in {dir} belongs to a different task \
                     ({} {}):\n  {}\nresume with the run's own settings (see its \
                     config.toml and task.json), or pass --force to start over",
                        diffs.len(),
                        if diffs.len() == 1 {
                            "field differs"
                        } else {
                            "fields differ"
                        },
                        diffs.join("\n  ")
                    ),
                    differences: diffs,
                });
            }
            return Ok(Start::Resume(Box::new(c)));
        }
        if claim.resume == ResumeMode::Required {
            run_dir_err!(
                &self.root,
                "--resume: {dir} holds no checkpoint, so there is nothing to resume (a run \
                 writes its first checkpoint after run.checkpoint_every iterations); start it \
                 again without --resume"
            );
        }
        // Ours without a checkpoint: an attempt that died before its first checkpoint.
        self.remove_outputs()?;
        Ok(Start::Fresh)
    }

    fn remove_temporaries(&self) {
        if let Ok(entries) = std::fs::read_dir(&self.root) {
            for e in entries.flatten() {
                let name = e.file_name().to_string_lossy().into_owned();
                if crate::durable::is_temp_name(&name) {
                    let _ = std::fs::remove_file(e.path());
                }
            }
        }
    }

    fn remove_outputs(&self) -> Result<()> {
        for name in RUN_FILES {
            let p = self.file(name);
            if p.is_file() {
                std::fs::remove_file(&p).io_context("cannot remove", &p)?;
            }
        }
        self.remove_previews()?;
        self.remove_temporaries();
        Ok(())
    }

    /// Removes the preview grids (`previews/iter_NNNNNN.png`) and our temporary files there, then
    /// the folder if that left it empty. Anything else in it is kept — another run directory
    /// placed there, say — so starting over never deletes what this run did not write.
    fn remove_previews(&self) -> Result<()> {
        let previews = self.previews();
        let Ok(entries) = std::fs::read_dir(&previews) else {
            return Ok(());
        };
        for e in entries.flatten() {
            let name = e.file_name().to_string_lossy().into_owned();
            let is_file = e.file_type().is_ok_and(|t| t.is_file());
            if is_file && (is_preview_name(&name) || crate::durable::is_temp_name(&name)) {
                let p = e.path();
                std::fs::remove_file(&p).io_context("cannot remove", &p)?;
            }
        }
        // Not empty (someone else's files): kept.
        let _ = std::fs::remove_dir(&previews);
        Ok(())
    }

    /// Keeps the `metrics.jsonl` lines of iterations `<= iteration`, each once and in increasing
    /// order (after a resume, the lines a killed run wrote past its last checkpoint, and a
    /// partial last line, are dropped). Replaced atomically.
    pub fn truncate_metrics(&self, iteration: u64) -> Result<()> {
        let path = self.metrics();
        if !path.is_file() {
            return crate::durable::replace_bytes(&path, b"");
        }
        let text = std::fs::read_to_string(&path).io_context("cannot read", &path)?;
        let mut kept = String::new();
        let mut last = 0;
        for line in text.split_inclusive('\n') {
            if !line.ends_with('\n') {
                continue;
            }
            let it = serde_json::from_str::<serde_json::Value>(line)
                .ok()
                .and_then(|v| v.get("iteration").and_then(serde_json::Value::as_u64));
            if let Some(i) = it
                && i <= iteration
                && i > last
            {
                kept.push_str(line);
                last = i;
            }
        }
        crate::durable::replace_bytes(&path, kept.as_bytes())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ok<T, E: std::fmt::Debug>(r: Result<T, E>) -> T {
        r.unwrap_or_else(|e| panic!("{e:?}"))
    }

    /// A caller's checkpoint state.
    #[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
    struct State {
        x: Vec<f64>,
    }

    fn identity(v: &str) -> TaskIdentity {
        TaskIdentity {
            fields: [("style".to_string(), v.to_string())].into(),
        }
    }

    fn claim<'a>(
        id: &'a TaskIdentity,
        inputs: &'a [(String, PathBuf)],
        force: bool,
        resume: ResumeMode,
    ) -> Claim<'a> {
        Claim {
            force,
            resume,
            skip_complete: false,
            identity: id,
            inputs,
        }
    }

    /// The error's whole chain on one line.
    fn err<T>(r: Result<T>) -> String {
        let Err(e) = r else {
            return String::new();
        };
        let mut out = e.to_string();
        let mut cur = std::error::Error::source(&e);
        while let Some(s) = cur {
            out.push_str(": ");
            out.push_str(&s.to_string());
            cur = s.source();
        }
        out
    }

    #[test]
    fn complete_run_is_refused_without_force_and_force_keeps_foreign_files() {
        let dir = ok(tempfile::tempdir());
        let run = RunDir::new(dir.path().join("a/b/run"));
        let id = identity("cube");
        let (lock, start) = ok(run.claim::<State>(&claim(&id, &[], false, ResumeMode::Never)));
        assert!(matches!(start, Start::Fresh));
        assert!(run.root().is_dir(), "parent folders are created");
        assert!(run.file(crate::lock::LOCK_FILE).is_file());
        ok(run.write_task(&id));
        drop(lock);
        assert!(
            !run.file(crate::lock::LOCK_FILE).exists(),
            "released on drop"
        );
        ok(std::fs::write(
            run.summary(),
            r#"{"status":"complete","objective":"x"}"#,
        ));
        ok(std::fs::write(run.file("mesh.obj"), ""));
        let e = err(run.claim::<State>(&claim(&id, &[], false, ResumeMode::Never)));
        assert!(e.contains("--force"), "{e}");
        ok(std::fs::write(run.file("user-notes.txt"), "keep me"));
        let (forced, start) = ok(run.claim::<State>(&claim(&id, &[], true, ResumeMode::Never)));
        assert!(matches!(start, Start::Fresh));
        assert!(!run.summary().exists() && !run.file("mesh.obj").exists());
        assert!(
            run.file("user-notes.txt").exists(),
            "--force removes only the run's own files"
        );
        // previews/: the grids go; another run directory placed there stays.
        drop(forced);
        let nested = run.previews().join("previews");
        ok(std::fs::create_dir_all(&nested));
        ok(std::fs::write(run.previews().join("iter_000004.png"), ""));
        ok(std::fs::write(run.previews().join("run.json"), "{}"));
        ok(std::fs::write(nested.join("iter_000002.png"), ""));
        let (lock, _) = ok(run.claim::<State>(&claim(&id, &[], true, ResumeMode::Never)));
        assert!(!run.previews().join("iter_000004.png").exists());
        assert!(
            run.previews().join("run.json").exists() && nested.join("iter_000002.png").exists()
        );
        drop(lock);
        ok(std::fs::remove_file(run.previews().join("run.json")));
        ok(std::fs::remove_dir_all(&nested));
        ok(std::fs::write(run.previews().join("iter_000006.png"), ""));
        let _ = ok(run.claim::<State>(&claim(&id, &[], true, ResumeMode::Never)));
        assert!(!run.previews().exists(), "an emptied previews/ is removed");
    }

    #[test]
    fn preview_names() {
        assert!(is_preview_name("iter_000012.png") && is_preview_name("iter_1234567.png"));
        for n in [
            "iter_.png",
            "iter_12.PNG",
            "iter_1a.png",
            "x_000001.png",
            "iter_000001.png~",
        ] {
            assert!(!is_preview_name(n), "{n}");
        }
    }

    #[test]
    fn foreign_folder_is_refused_without_force_and_inputs_always() {
        let dir = ok(tempfile::tempdir());
        let proj = dir.path().join("proj");
        ok(std::fs::create_dir_all(&proj));
        ok(std::fs::write(proj.join("mesh.obj"), "v 0 0 0"));
        ok(std::fs::write(proj.join("config.toml"), "# mine"));
        let run = RunDir::new(&proj);
        let id = identity("cube");
        let e = err(run.claim::<State>(&claim(&id, &[], false, ResumeMode::Never)));
        assert!(
            e.contains("not a stylize run directory") && e.contains("config.toml"),
            "{e}"
        );
        // The input mesh is one of the outputs' names: refused even with --force.
        let inputs = vec![("input mesh".to_string(), proj.join("../proj/./mesh.obj"))];
        let e = err(run.claim::<State>(&claim(&id, &inputs, true, ResumeMode::Never)));
        assert!(e.contains("input mesh") && e.contains("--force"), "{e}");
        // A hard link of the input under an output's name is the same file.
        let other = dir.path().join("other");
        ok(std::fs::create_dir_all(&other));
        ok(std::fs::hard_link(
            proj.join("mesh.obj"),
            other.join("mesh.ply"),
        ));
        let e =
            err(RunDir::new(&other).claim::<State>(&claim(&id, &inputs, true, ResumeMode::Never)));
        assert!(e.contains("mesh.ply"), "{e}");
        // An input inside previews/ would be removed by --force.
        let prev = dir.path().join("r2/previews");
        ok(std::fs::create_dir_all(&prev));
        ok(std::fs::write(prev.join("x.obj"), ""));
        let inputs = vec![("exemplar mesh".to_string(), prev.join("x.obj"))];
        let e = err(RunDir::new(dir.path().join("r2")).claim::<State>(&claim(
            &id,
            &inputs,
            true,
            ResumeMode::Never,
        )));
        assert!(e.contains("exemplar mesh"), "{e}");
        assert!(prev.join("x.obj").exists() && proj.join("config.toml").exists());
    }

    #[test]
    fn resume_needs_a_checkpoint_of_the_same_task() {
        let dir = ok(tempfile::tempdir());
        let run = RunDir::new(dir.path().join("r"));
        let id = identity("cube");
        let e = err(run.claim::<State>(&claim(&id, &[], false, ResumeMode::Required)));
        assert!(e.contains("does not exist") && !run.root().exists(), "{e}");
        ok(std::fs::create_dir_all(run.root()));
        let e = err(run.claim::<State>(&claim(&id, &[], false, ResumeMode::Required)));
        assert!(e.contains("no checkpoint"), "{e}");
        let c = Checkpoint {
            version: crate::CHECKPOINT_VERSION,
            iteration: 4,
            state: State { x: vec![0.1, -2.5] },
            identity: Some(id.clone()),
        };
        ok(run.write_task(&id));
        ok(c.save_atomic(&run.checkpoint()));
        let e = err(run.claim::<State>(&claim(&id, &[], false, ResumeMode::Never)));
        assert!(e.contains("--resume"), "{e}");
        let (lock, start) = ok(run.claim::<State>(&claim(&id, &[], false, ResumeMode::Required)));
        assert!(
            matches!(start, Start::Resume(ref r) if **r == c),
            "{start:?}"
        );
        drop(lock);
        let other = identity("octahedron");
        let r = run.claim::<State>(&claim(&other, &[], false, ResumeMode::IfCheckpoint));
        assert!(
            matches!(&r, Err(Error::DifferentTask { differences, .. })
                if differences == &["style: was cube, now octahedron"]),
            "{r:?}"
        );
        // A checkpoint whose state is not an `S` does not make the folder ours.
        ok(std::fs::write(
            run.checkpoint(),
            r#"{"version":2,"iteration":1,"identity":{"fields":{}}}"#,
        ));
        ok(std::fs::remove_file(run.task()));
        assert!(matches!(ok(run.inspect::<State>()), Existing::Foreign(_)));
    }

    #[test]
    fn a_locked_directory_is_refused() {
        let dir = ok(tempfile::tempdir());
        let run = RunDir::new(dir.path());
        let id = identity("cube");
        let (_lock, _) = ok(run.claim::<State>(&claim(&id, &[], false, ResumeMode::Never)));
        let e = err(run.claim::<State>(&claim(&id, &[], false, ResumeMode::Never)));
        assert!(e.contains("in use") && e.contains("pid"), "{e}");
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
        // A duplicated line and a partial last line (a killed writer) are dropped.
        std::fs::write(
            run.metrics(),
            "{\"iteration\":1}\n{\"iteration\":2}\n{\"iteration\":2}\n{\"iteration\":3}\n{\"itera",
        )
        .unwrap_or_else(|e| panic!("{e}"));
        run.truncate_metrics(9).unwrap_or_else(|e| panic!("{e}"));
        let text = std::fs::read_to_string(run.metrics()).unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(
            text,
            "{\"iteration\":1}\n{\"iteration\":2}\n{\"iteration\":3}\n"
        );
    }
}

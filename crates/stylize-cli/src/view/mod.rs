//! `stylize view`: a local web page showing runs and meshes, with a live λ slider.
//!
//! The server ([`server`]) is read-only except for one computation: re-applying a run's saved
//! deformation (`deformation.npz`, spec §8) at a strength λ chosen on the page. This module holds
//! what it serves:
//! - [`Item`]: one thing named on the command line — a run directory ([`RunItem`]) or a mesh file
//!   (shown as is, normalized to the side-2 cube);
//! - [`RunItem`] keeps one prefactored dARAP layer per run ([`ReadyLayer`], built on first use
//!   by [`SavedDeformation::ready_layer_as_saved`], rebuilt when the run's `deformation.npz`
//!   changes, e.g. a run that was still being written completes) and re-solves it at each λ with
//!   [`ReadyLayer::at_lambda`] (the factorization does not depend on λ).
//!
//! λ is accepted when finite and within `[0, LAMBDA_MAX]`.

pub mod assets;
pub mod metrics;
pub mod replay;
#[cfg(feature = "view")]
pub mod server;

use std::path::{Component, Path, PathBuf};
use std::sync::{Arc, Mutex, OnceLock};
use std::time::SystemTime;

use anyhow::{Context, bail, ensure};
use mesh_core::TriMesh;
use mesh_core::io::Format;
use serde::Serialize;
use stylize::saved::{ReadyLayer, SavedDeformation};

use crate::sanity::LambdaSanity;
use replay::{ReplayState, SNAPSHOTS_FILE, Snapshots};

/// The largest λ the server computes (the slider goes to ~20; the reference's values are 5–10).
pub const LAMBDA_MAX: f64 = 100.0;

/// Why a request for an item failed; the server maps each kind to an HTTP status.
#[derive(Debug, thiserror::Error)]
pub enum ViewError {
    /// The request is malformed (bad λ, bad path): 400.
    #[error("{0}")]
    BadRequest(String),
    /// No such item or file: 404.
    #[error("{0}")]
    NotFound(String),
    /// The run has no result yet (still being written): 409.
    #[error("{0}")]
    NotReady(String),
    /// A file of the run cannot be read or the computation failed: 500.
    #[error("{0:#}")]
    Failed(anyhow::Error),
}

/// Checks a strength λ from a request: finite, within `[0, LAMBDA_MAX]`.
pub fn validate_lambda(lambda: f64) -> Result<f64, ViewError> {
    if !lambda.is_finite() {
        return Err(ViewError::BadRequest(format!(
            "λ must be a finite number, got {lambda}"
        )));
    }
    if !(0.0..=LAMBDA_MAX).contains(&lambda) {
        return Err(ViewError::BadRequest(format!(
            "λ must be within [0, {LAMBDA_MAX}], got {lambda}"
        )));
    }
    Ok(lambda)
}

/// Checks a strength of the strength control (`?strength=S`): finite, in
/// `[1, `[`crate::cmd::apply::MAX_STRENGTH`]`]`, as `apply --strength`.
pub fn validate_strength(strength: f64) -> Result<f64, ViewError> {
    let max = crate::cmd::apply::MAX_STRENGTH;
    if !(strength.is_finite() && (1.0..=max).contains(&strength)) {
        return Err(ViewError::BadRequest(format!(
            "strength must be a number within [1, {max}], got {strength}"
        )));
    }
    Ok(strength)
}

/// What the page needs to know about an item (`GET api/items`).
#[derive(Clone, Debug, Serialize)]
pub struct ItemInfo {
    /// Index in the command line's order (the `{id}` of every item URL).
    pub id: usize,
    /// The path as given on the command line.
    pub name: String,
    /// `run` or `mesh`.
    pub kind: &'static str,
    /// `complete` (run.json present), `running` (`run.lock` is there: a run is writing it, or one
    /// was killed), `incomplete` (`task.json` but no result: an interrupted run), `not started`
    /// (no such directory yet, or none of those files: a batch row not reached) or `mesh`.
    pub status: &'static str,
    /// The run's saved λ (None for meshes and runs without a result yet).
    pub lambda: Option<f64>,
    /// The largest λ the server accepts.
    pub lambda_max: f64,
    /// Whether λ can be changed (a run with `deformation.npz`).
    pub has_deformation: bool,
    /// Image files of the run the page can show (`turntable.png`, …), relative to the run.
    pub images: Vec<String>,
    /// The gallery's picture: `turntable.png`, else `before_after.png`, else the newest
    /// `previews/iter_*.png` (relative to the run; None when there is none yet).
    pub thumbnail: Option<String>,
    /// The text prompt (manifest row, else the run's `task.json`).
    pub prompt: Option<String>,
    /// The model-free style (manifest row, else the run's `task.json`).
    pub style: Option<String>,
    /// The input mesh (manifest row, else the run's `run.json`).
    pub mesh: Option<String>,
    /// The manifest and row index this run comes from.
    pub manifest: Option<String>,
    /// 0-based row of the manifest.
    pub row: Option<usize>,
}

/// What a batch manifest row says about its run (shown before the run exists).
#[derive(Clone, Debug, Default)]
pub struct RunLabel {
    /// Text prompt.
    pub prompt: Option<String>,
    /// Model-free style.
    pub style: Option<String>,
    /// Input mesh, as resolved by the manifest reader.
    pub mesh: Option<String>,
    /// The manifest's path as given.
    pub manifest: Option<String>,
    /// 0-based row.
    pub row: Option<usize>,
}

/// A run's saved deformation, loaded and prefactored.
struct LoadedRun {
    /// (modification time, length) of `deformation.npz` when it was read.
    stamp: (SystemTime, u64),
    /// The rest mesh (side-2 cube frame, the frame of every result), the saved target normals
    /// and the layer, as the run saved them.
    ready: ReadyLayer,
    /// The saved `to_input_frame` (None: the file does not record it).
    to_input: Option<stylize::frame::InputFrame>,
    /// The rest mesh's self-intersections and a checker refitted at each λ.
    source: stylize::intersections::SourceIntersections,
    /// The strongest safe λ up to the slider's end, once asked for (`api/items/ID/max-safe`).
    max_safe: Option<(f64, crate::max_safe::SafeLambda)>,
}

/// A run directory named on the command line.
pub struct RunItem {
    /// The path as given.
    pub name: String,
    /// The run directory: canonical when it existed when the viewer started; a batch row's
    /// directory that did not exist yet is kept as the manifest resolved it.
    pub root: PathBuf,
    /// The canonical run directory (every file served lies inside it), known once it exists.
    canonical: OnceLock<PathBuf>,
    /// From the batch manifest, when the run comes from one.
    pub label: RunLabel,
    loaded: Mutex<Option<Box<LoadedRun>>>,
    /// The last valid `snapshots.npz` read (reused while its stamp is unchanged).
    snapshots: Mutex<Option<Arc<Snapshots>>>,
    /// The saved λ with the stamp of the `deformation.npz` it was read from.
    saved_lambda: Mutex<Option<StampedLambda>>,
}

impl std::fmt::Debug for RunItem {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("RunItem")
            .field("name", &self.name)
            .field("root", &self.root)
            .finish_non_exhaustive()
    }
}

/// A mesh at one λ, ready to send.
#[derive(Clone, Debug)]
pub struct Shape {
    /// Positions (side-2 cube frame).
    pub positions: Vec<[f64; 3]>,
    /// Faces.
    pub faces: Vec<[u32; 3]>,
    /// Diagnostics (None for the source itself).
    pub sanity: Option<LambdaSanity>,
}

/// A saved λ with the (modification time, length) of the file it was read from.
type StampedLambda = ((SystemTime, u64), Option<f64>);

fn stamp(path: &Path) -> std::io::Result<(SystemTime, u64)> {
    let m = std::fs::metadata(path)?;
    Ok((m.modified()?, m.len()))
}

impl RunItem {
    /// A run directory (it must exist; its files may still be missing).
    pub fn new(name: String, dir: &Path) -> anyhow::Result<Self> {
        let root = std::fs::canonicalize(dir)
            .with_context(|| format!("cannot open run directory {}", dir.display()))?;
        ensure!(root.is_dir(), "{} is not a directory", dir.display());
        Ok(Self {
            name,
            canonical: OnceLock::from(root.clone()),
            root,
            label: RunLabel::default(),
            loaded: Mutex::new(None),
            snapshots: Mutex::new(None),
            saved_lambda: Mutex::new(None),
        })
    }

    /// A batch row's run directory, which may not exist yet (the row is not started).
    pub fn planned(name: String, dir: &Path, label: RunLabel) -> anyhow::Result<Self> {
        let canonical = OnceLock::new();
        let root = match std::fs::canonicalize(dir) {
            Ok(c) => {
                ensure!(c.is_dir(), "{} is not a directory", dir.display());
                let _ = canonical.set(c.clone());
                c
            }
            Err(_) => std::path::absolute(dir)
                .with_context(|| format!("cannot resolve run directory {}", dir.display()))?,
        };
        Ok(Self {
            name,
            root,
            canonical,
            label,
            loaded: Mutex::new(None),
            snapshots: Mutex::new(None),
            saved_lambda: Mutex::new(None),
        })
    }

    /// The canonical run directory, once it exists.
    fn canonical_root(&self) -> Option<&Path> {
        if let Some(c) = self.canonical.get() {
            return Some(c);
        }
        let c = std::fs::canonicalize(&self.root).ok()?;
        if !c.is_dir() {
            return None;
        }
        Some(self.canonical.get_or_init(|| c))
    }

    fn npz(&self) -> PathBuf {
        self.root.join("deformation.npz")
    }

    /// The run's status (see [`ItemInfo::status`]).
    pub fn status(&self) -> &'static str {
        if self.root.join("run.json").is_file() {
            "complete"
        } else if self.root.join(rundir::lock::LOCK_FILE).exists() {
            "running"
        } else if self.root.join("task.json").is_file() {
            "incomplete"
        } else {
            "not started"
        }
    }

    /// Runs `f` on the loaded run, loading (or reloading, when `deformation.npz` changed) first.
    fn with_loaded<T>(
        &self,
        f: impl FnOnce(&mut LoadedRun) -> Result<T, ViewError>,
    ) -> Result<T, ViewError> {
        let npz = self.npz();
        let now = match stamp(&npz) {
            Ok(s) => s,
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => {
                return Err(ViewError::NotReady(format!(
                    "run {} has no deformation.npz yet (status: {}); its result appears when the run completes",
                    self.name,
                    self.status()
                )));
            }
            Err(e) => {
                return Err(ViewError::Failed(
                    anyhow::Error::from(e).context(format!("cannot read {}", npz.display())),
                ));
            }
        };
        let mut guard = self
            .loaded
            .lock()
            .map_err(|_| ViewError::Failed(anyhow::anyhow!("a previous computation panicked")))?;
        if guard.as_ref().is_none_or(|l| l.stamp != now) {
            *guard = None;
            *guard = Some(Box::new(load_run(&npz, now).map_err(ViewError::Failed)?));
        }
        match guard.as_mut() {
            Some(l) => f(l),
            None => Err(ViewError::Failed(anyhow::anyhow!("run not loaded"))),
        }
    }

    /// The saved λ (None when the run has no `deformation.npz` or it records none).
    ///
    /// Read without building the dARAP layer (a gallery lists many runs; only the one opened is
    /// factored), and cached while the file is unchanged.
    pub fn saved_lambda(&self) -> Option<f64> {
        let npz = self.npz();
        let now = stamp(&npz).ok()?;
        let mut cache = self
            .saved_lambda
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner);
        if let Some((s, l)) = *cache
            && s == now
        {
            return l;
        }
        let lambda = SavedDeformation::read(&npz).ok()?.lambda();
        *cache = Some((now, lambda));
        lambda
    }

    /// The rest mesh (side-2 cube frame).
    pub fn source(&self) -> Result<Shape, ViewError> {
        self.with_loaded(|l| {
            Ok(Shape {
                positions: l.ready.rest.positions.clone(),
                faces: l.ready.rest.faces.clone(),
                sanity: None,
            })
        })
    }

    /// The saved target normals, one per rest vertex, scaled to unit length (the layer normalizes
    /// them too; a zero vector stays zero).
    pub fn target_normals(&self) -> Result<Vec<[f64; 3]>, ViewError> {
        self.with_loaded(|l| {
            Ok(l.ready
                .targets
                .iter()
                .map(|n| {
                    let len = (n[0] * n[0] + n[1] * n[1] + n[2] * n[2]).sqrt();
                    if len > 0.0 && len.is_finite() {
                        n.map(|c| c / len)
                    } else {
                        [0.0; 3]
                    }
                })
                .collect())
        })
    }

    /// The saved deformation re-applied at `lambda` (validated here).
    pub fn at_lambda(&self, lambda: f64) -> Result<Shape, ViewError> {
        self.at(lambda, None)
    }

    /// The saved deformation re-applied at `lambda`, and with `Some(s)` pushed `s` times as far by
    /// the strength control (`apply --strength`; [`validate_strength`]). Both validated here.
    pub fn at(&self, lambda: f64, strength: Option<f64>) -> Result<Shape, ViewError> {
        let lambda = validate_lambda(lambda)?;
        let strength = strength.map(validate_strength).transpose()?;
        self.with_loaded(|l| {
            let deformed = match strength {
                None => l.ready.at_lambda(lambda),
                Some(s) => l.ready.at_strength(lambda, s),
            };
            let deformation = deformed.map_err(|e| {
                ViewError::Failed(
                    anyhow::Error::from(e).context(format!("dARAP forward failed at λ = {lambda}")),
                )
            })?;
            let mut sanity =
                LambdaSanity::assess(&l.ready.rest, &mut l.source, &deformation, lambda)
                    .map_err(ViewError::Failed)?;
            if let Some(s) = strength {
                sanity = sanity.with_strength(s);
            }
            Ok(Shape {
                positions: deformation.positions,
                faces: l.ready.rest.faces.clone(),
                sanity: Some(sanity),
            })
        })
    }

    /// A result `shape` of [`Self::at_lambda`] in the frame `frame` (None: the input's when the
    /// run recorded it, else the normalized one), placed as the run placed its `mesh.*`
    /// (`stylize::frame`): what downloads hold. `Some(Input)` on a run that does not record its
    /// input frame is a bad request.
    pub fn in_frame(
        &self,
        shape: Shape,
        frame: Option<stylize::frame::OutputFrame>,
    ) -> Result<Shape, ViewError> {
        use stylize::frame::OutputFrame;
        if frame == Some(OutputFrame::Normalized) {
            return Ok(shape);
        }
        self.with_loaded(|l| match (&l.to_input, frame) {
            (Some(to_input), _) => Ok(Shape {
                positions: to_input.place_result(&shape.positions, &l.ready.rest.positions, true),
                ..shape
            }),
            (None, Some(OutputFrame::Input)) => Err(ViewError::BadRequest(format!(
                "run {} does not record its input's frame (deformation.npz has no \
                 to_input_frame); ask for frame=normalized",
                self.name
            ))),
            (None, _) => Ok(shape),
        })
    }

    /// The strongest safe λ in `(0, upper]` ([`crate::max_safe::search`], `upper` validated as a
    /// λ), computed once per `upper` while `deformation.npz` is unchanged.
    pub fn max_safe(&self, upper: f64) -> Result<crate::max_safe::SafeLambda, ViewError> {
        let upper = validate_lambda(upper)?;
        if upper == 0.0 {
            return Err(ViewError::BadRequest(
                "max-safe needs an upper end λ > 0".into(),
            ));
        }
        self.with_loaded(|l| {
            if let Some((u, found)) = &l.max_safe
                && *u == upper
            {
                return Ok(found.clone());
            }
            let LoadedRun { ready, source, .. } = l;
            let found = crate::max_safe::search_assessed(upper, |lambda| {
                let d = ready
                    .at_lambda(lambda)
                    .with_context(|| format!("dARAP forward failed at λ = {lambda}"))?;
                LambdaSanity::assess(&ready.rest, source, &d, lambda)
            })
            .map_err(ViewError::Failed)?
            .found;
            l.max_safe = Some((upper, found.clone()));
            Ok(found)
        })
    }

    /// The canonical path of a file inside the run, from a request path relative to it.
    ///
    /// Refused: absolute paths, `.` and `..` components, empty paths, and anything that resolves
    /// (symbolic links followed) outside the run directory or to something other than a regular
    /// file.
    pub fn resolve_file(&self, rel: &str) -> Result<PathBuf, ViewError> {
        let bad = || ViewError::BadRequest(format!("not a file path inside the run: {rel:?}"));
        let rel_path = Path::new(rel);
        if rel.is_empty()
            || rel.contains('\0')
            || rel_path
                .components()
                .any(|c| !matches!(c, Component::Normal(_)))
        {
            return Err(bad());
        }
        let not_found = || ViewError::NotFound(format!("run {} has no file {rel}", self.name));
        let root = self.canonical_root().ok_or_else(|| {
            ViewError::NotFound(format!(
                "run {} has not started (no directory yet)",
                self.name
            ))
        })?;
        let path = std::fs::canonicalize(root.join(rel_path)).map_err(|_| not_found())?;
        if !path.starts_with(root) {
            return Err(ViewError::BadRequest(format!(
                "{rel} leads outside the run directory"
            )));
        }
        if !std::fs::metadata(&path).is_ok_and(|m| m.is_file()) {
            return Err(not_found());
        }
        Ok(path)
    }

    /// The run's replay (`snapshots.npz`, see [`replay`]): read again whenever the file changes; a
    /// missing or unusable file is [`ReplayState::Unavailable`] with the reason, never an error.
    pub fn replay(&self) -> ReplayState {
        let path = match self.resolve_file(SNAPSHOTS_FILE) {
            Ok(p) => p,
            Err(ViewError::NotFound(_)) => {
                return ReplayState::Unavailable(format!("the run has no {SNAPSHOTS_FILE} (yet)"));
            }
            Err(e) => return ReplayState::Unavailable(e.to_string()),
        };
        let now = match stamp(&path) {
            Ok(s) => s,
            Err(e) => {
                return ReplayState::Unavailable(format!("cannot read {SNAPSHOTS_FILE}: {e}"));
            }
        };
        let mut guard = self
            .snapshots
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner);
        if let Some(s) = guard.as_ref().filter(|s| s.stamp == now) {
            return ReplayState::Available(Arc::clone(s));
        }
        match Snapshots::read(&path, now) {
            Ok(s) => {
                let s = Arc::new(s);
                *guard = Some(Arc::clone(&s));
                ReplayState::Available(s)
            }
            Err(e) => {
                *guard = None;
                ReplayState::Unavailable(format!("{SNAPSHOTS_FILE} is not usable: {e:#}"))
            }
        }
    }

    /// The faces to draw `snapshots` with: the file's own, else the saved deformation's when its
    /// vertex count matches, else none (the page draws points).
    pub fn replay_faces(&self, snapshots: &Snapshots) -> Option<(Vec<[u32; 3]>, &'static str)> {
        if let Some(f) = &snapshots.faces {
            return Some((f.clone(), SNAPSHOTS_FILE));
        }
        self.with_loaded(|l| {
            let rest = &l.ready.rest;
            Ok((rest.positions.len() == snapshots.vertices).then(|| rest.faces.clone()))
        })
        .ok()
        .flatten()
        .map(|f| (f, "deformation.npz"))
    }

    /// The run's `metrics.jsonl` as columns (None when the run has none yet; malformed lines are
    /// skipped, see [`metrics`]).
    pub fn metrics(&self) -> Result<Option<metrics::MetricsTable>, ViewError> {
        let path = match self.resolve_file("metrics.jsonl") {
            Ok(p) => p,
            Err(ViewError::NotFound(_)) => return Ok(None),
            Err(e) => return Err(e),
        };
        let bytes = std::fs::read(&path).map_err(|e| {
            ViewError::Failed(
                anyhow::Error::from(e).context(format!("cannot read {}", path.display())),
            )
        })?;
        Ok(Some(metrics::MetricsTable::parse(
            &String::from_utf8_lossy(&bytes),
        )))
    }

    /// The gallery's picture (see [`ItemInfo::thumbnail`]).
    pub fn thumbnail(&self) -> Option<String> {
        for name in ["turntable.png", "before_after.png"] {
            if self.resolve_file(name).is_ok() {
                return Some(name.to_string());
            }
        }
        // Preview names carry zero-padded iterations: the largest name is the newest.
        let newest = std::fs::read_dir(self.root.join("previews"))
            .ok()?
            .filter_map(|e| e.ok()?.file_name().into_string().ok())
            .filter(|n| n.starts_with("iter_") && n.ends_with(".png"))
            .max()?;
        let rel = format!("previews/{newest}");
        self.resolve_file(&rel).ok().map(|_| rel)
    }

    /// Prompt, style and mesh: the manifest's when given, else read from `task.json` (prompt,
    /// style) and `run.json` (mesh); unreadable files leave them None.
    pub fn describe(&self) -> (Option<String>, Option<String>, Option<String>) {
        let read_json = |name: &str| -> Option<serde_json::Value> {
            let path = self.resolve_file(name).ok()?;
            let meta = std::fs::metadata(&path).ok()?;
            // These files are small; anything large is not ours.
            if meta.len() > 1 << 20 {
                return None;
            }
            serde_json::from_slice(&std::fs::read(path).ok()?).ok()
        };
        let mut prompt = self.label.prompt.clone();
        let mut style = self.label.style.clone();
        let mut mesh = self.label.mesh.clone();
        if prompt.is_none()
            && style.is_none()
            && let Some(task) = read_json("task.json")
        {
            let fields = &task["identity"]["fields"];
            // Values are canonical text: the prompt is JSON-quoted, the style is not.
            prompt = fields["prompt"]
                .as_str()
                .map(|p| serde_json::from_str::<String>(p).unwrap_or_else(|_| p.to_string()));
            style = fields["style"].as_str().map(str::to_string);
        }
        if mesh.is_none() {
            mesh = read_json("run.json").and_then(|r| r["mesh"].as_str().map(str::to_string));
        }
        (prompt, style, mesh)
    }

    /// Image files of the run the page offers (present ones only).
    pub fn images(&self) -> Vec<String> {
        ["turntable.png", "before_after.png", "turntable.gif"]
            .iter()
            .filter(|n| self.root.join(n).is_file())
            .map(|n| n.to_string())
            .collect()
    }
}

fn load_run(npz: &Path, stamp: (SystemTime, u64)) -> anyhow::Result<LoadedRun> {
    let saved = SavedDeformation::read(npz)
        .with_context(|| format!("cannot read saved deformation {}", npz.display()))?;
    // A localized run is shown with its saved region, as `apply` re-applies it.
    let ready = saved.ready_layer_as_saved(npz)?;
    let to_input = saved
        .input_frame()
        .with_context(|| format!("{}", npz.display()))?;
    let mut source = stylize::intersections::SourceIntersections::new(&ready.rest)
        .context("self-intersection check of the saved rest mesh")?;
    // Every slider move checks the result: on up to 2 threads (the server's 2 cores; the
    // answer does not depend on it).
    source.set_threads(
        std::thread::available_parallelism()
            .map(|n| n.get())
            .unwrap_or(1)
            .min(2),
    );
    Ok(LoadedRun {
        stamp,
        ready,
        to_input,
        source,
        max_safe: None,
    })
}

/// A mesh file named on the command line (shown as is).
#[derive(Debug)]
pub struct MeshItem {
    /// The path as given.
    pub name: String,
    /// The mesh normalized to the side-2 cube.
    pub mesh: TriMesh,
}

/// One thing named on the command line.
#[derive(Debug)]
pub enum Item {
    /// A run directory.
    Run(RunItem),
    /// A mesh file.
    Mesh(MeshItem),
}

/// Whether `path` names a mesh file the readers take (by extension, case-insensitive).
fn is_mesh_path(path: &Path) -> bool {
    Format::from_path(path).is_some_and(Format::can_read)
}

/// `not a run directory, a mesh (.obj, …) or a batch manifest (…)`: what a command-line argument
/// may be, naming every readable mesh format.
fn what_an_item_is(manifests: &str) -> String {
    let readable: Vec<Format> = Format::ALL.into_iter().filter(|f| f.can_read()).collect();
    format!(
        "not a run directory, a mesh ({}) or a batch manifest ({manifests})",
        Format::list(&readable, ".", ", ")
    )
}

impl Item {
    /// Opens a command-line argument: a directory is a run, a mesh file a mesh, and a batch
    /// manifest (`.toml`, `.jsonl`/`.json`) one run per row — rows not started yet included.
    pub fn open_all(path: &Path) -> anyhow::Result<Vec<Self>> {
        let name = path.display().to_string();
        let meta = std::fs::metadata(path).with_context(|| format!("cannot open {name}"))?;
        if meta.is_dir() {
            return Ok(vec![Item::Run(RunItem::new(name, path)?)]);
        }
        if !is_mesh_path(path) {
            // Anything else is read as a batch manifest (`.toml`, else JSON Lines).
            let rows = crate::batch::read_manifest(path)
                .with_context(|| format!("{name}: {}", what_an_item_is(".toml, JSON Lines")))?;
            return rows
                .iter()
                .enumerate()
                .map(|(i, row)| {
                    let label = RunLabel {
                        prompt: row.prompt.clone(),
                        style: row.style.clone(),
                        mesh: Some(row.mesh.display().to_string()),
                        manifest: Some(name.clone()),
                        row: Some(i),
                    };
                    // Named as the manifest names it (relative to the manifest's folder).
                    let base = path.parent().unwrap_or(Path::new(""));
                    let shown = row.out.strip_prefix(base).unwrap_or(&row.out);
                    let run = RunItem::planned(shown.display().to_string(), &row.out, label)
                        .with_context(|| format!("{name} row {i}"))?;
                    Ok(Item::Run(run))
                })
                .collect();
        }
        Ok(vec![Self::open_mesh(path)?])
    }

    /// Opens a mesh file (shown as is).
    pub fn open_mesh(path: &Path) -> anyhow::Result<Self> {
        let name = path.display().to_string();
        if !is_mesh_path(path) {
            bail!("{name}: {}", what_an_item_is(".toml, .jsonl"));
        }
        let mut mesh =
            mesh_core::io::read_mesh(path).with_context(|| format!("cannot read mesh {name}"))?;
        ensure!(!mesh.faces.is_empty(), "{name}: the mesh has no faces");
        mesh_core::normalize::side2_cube(&mut mesh.positions);
        Ok(Item::Mesh(MeshItem { name, mesh }))
    }

    /// The description the page lists.
    pub fn info(&self, id: usize) -> ItemInfo {
        match self {
            Item::Run(r) => {
                let lambda = r.saved_lambda();
                let (prompt, style, mesh) = r.describe();
                ItemInfo {
                    thumbnail: r.thumbnail(),
                    prompt,
                    style,
                    mesh,
                    manifest: r.label.manifest.clone(),
                    row: r.label.row,
                    id,
                    name: r.name.clone(),
                    kind: "run",
                    status: r.status(),
                    lambda,
                    lambda_max: LAMBDA_MAX,
                    has_deformation: r.npz().is_file(),
                    images: r.images(),
                }
            }
            Item::Mesh(m) => ItemInfo {
                id,
                name: m.name.clone(),
                kind: "mesh",
                status: "mesh",
                lambda: None,
                lambda_max: LAMBDA_MAX,
                has_deformation: false,
                images: Vec::new(),
                thumbnail: None,
                prompt: None,
                style: None,
                mesh: Some(m.name.clone()),
                manifest: None,
                row: None,
            },
        }
    }

    /// The source shape (a run's rest mesh, or the mesh itself).
    pub fn source(&self) -> Result<Shape, ViewError> {
        match self {
            Item::Run(r) => r.source(),
            Item::Mesh(m) => Ok(Shape {
                positions: m.mesh.positions.clone(),
                faces: m.mesh.faces.clone(),
                sanity: None,
            }),
        }
    }

    /// The run's target normals (runs only; see [`RunItem::target_normals`]).
    pub fn target_normals(&self) -> Result<Vec<[f64; 3]>, ViewError> {
        match self {
            Item::Run(r) => r.target_normals(),
            Item::Mesh(m) => Err(ViewError::NotFound(format!(
                "{} is a mesh, not a run: it has no target normals",
                m.name
            ))),
        }
    }

    /// The strongest safe λ up to `upper` (runs only; see [`RunItem::max_safe`]).
    pub fn max_safe(&self, upper: f64) -> Result<crate::max_safe::SafeLambda, ViewError> {
        match self {
            Item::Run(r) => r.max_safe(upper),
            Item::Mesh(m) => Err(ViewError::NotFound(format!(
                "{} is a mesh, not a run: it has no λ",
                m.name
            ))),
        }
    }

    /// The result at `lambda` (runs only).
    pub fn at_lambda(&self, lambda: f64) -> Result<Shape, ViewError> {
        self.at(lambda, None)
    }

    /// The result at `lambda`, pushed `strength` times as far when given (runs only;
    /// [`RunItem::at`]).
    pub fn at(&self, lambda: f64, strength: Option<f64>) -> Result<Shape, ViewError> {
        match self {
            Item::Run(r) => r.at(lambda, strength),
            Item::Mesh(m) => Err(ViewError::BadRequest(format!(
                "{} is a mesh, not a run: it has no deformation to re-apply",
                m.name
            ))),
        }
    }

    /// [`RunItem::in_frame`] (runs only; a mesh item has no results).
    pub fn in_frame(
        &self,
        shape: Shape,
        frame: Option<stylize::frame::OutputFrame>,
    ) -> Result<Shape, ViewError> {
        match self {
            Item::Run(r) => r.in_frame(shape, frame),
            Item::Mesh(_) => Ok(shape),
        }
    }

    /// The file name stem used for downloads.
    pub fn stem(&self) -> String {
        let name = match self {
            Item::Run(r) => &r.root,
            Item::Mesh(m) => Path::new(&m.name),
        };
        let stem = name
            .file_stem()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_else(|| "mesh".into());
        stem.chars()
            .map(|c| {
                if c.is_ascii_alphanumeric() || c == '-' || c == '_' {
                    c
                } else {
                    '_'
                }
            })
            .collect()
    }
}

/// Everything the server serves.
#[derive(Debug)]
pub struct Viewer {
    /// The items, in command-line order.
    pub items: Vec<Item>,
    /// The secret every request must carry as its first path segment.
    pub token: String,
}

impl Viewer {
    /// Opens every command-line argument.
    pub fn open(paths: &[PathBuf], token: String) -> anyhow::Result<Self> {
        ensure!(!paths.is_empty(), "name at least one run directory or mesh");
        let mut items = Vec::new();
        for p in paths {
            items.extend(Item::open_all(p)?);
        }
        ensure!(!items.is_empty(), "the manifest names no runs");
        Ok(Self { items, token })
    }

    /// The item with index `id`.
    pub fn item(&self, id: usize) -> Result<&Item, ViewError> {
        self.items
            .get(id)
            .ok_or_else(|| ViewError::NotFound(format!("no item {id}")))
    }
}

/// A fresh random token: 128 bits from the operating system's generator, as 32 hex digits.
pub fn random_token() -> String {
    use rand::TryRngCore;
    let mut bytes = [0u8; 16];
    let mut rng = rand::rngs::OsRng;
    if rng.try_fill_bytes(&mut bytes).is_err() {
        // The thread RNG is seeded from the OS as well; used only if the direct read fails.
        rand::Rng::fill(&mut rand::rng(), &mut bytes);
    }
    bytes.iter().map(|b| format!("{b:02x}")).collect()
}

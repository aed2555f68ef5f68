//! `stylize view`: a local web page showing runs and meshes, with a live λ slider.
//!
//! The server ([`server`]) is read-only except for one computation: re-applying a run's saved
//! deformation (`deformation.npz`, spec §8) at a strength λ chosen on the page. This module holds
//! what it serves:
//! - [`Item`]: one thing named on the command line — a run directory ([`RunItem`]) or a mesh file
//!   (shown as is, normalized to the side-2 cube);
//! - [`RunItem`] keeps one prefactored [`Darap`] per run (built on first use, rebuilt when the
//!   run's `deformation.npz` changes, e.g. a run that was still being written completes) and
//!   re-solves it at each λ with [`Darap::set_lambda`] (the factorization does not depend on λ).
//!
//! λ is accepted when finite and within `[0, LAMBDA_MAX]`.

pub mod assets;
pub mod server;

use std::path::{Component, Path, PathBuf};
use std::sync::Mutex;
use std::time::SystemTime;

use anyhow::{Context, bail, ensure};
use darap::{Darap, DarapOptions, PostProcess};
use mesh_core::TriMesh;
use serde::Serialize;
use stylize::saved::SavedDeformation;

use crate::sanity::LambdaSanity;

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

/// What the page needs to know about an item (`GET api/items`).
#[derive(Clone, Debug, Serialize)]
pub struct ItemInfo {
    /// Index in the command line's order (the `{id}` of every item URL).
    pub id: usize,
    /// The path as given on the command line.
    pub name: String,
    /// `run` or `mesh`.
    pub kind: &'static str,
    /// `complete` (run.json present), `running` (`run.lock` is there: a run is writing it, or one was killed), `incomplete` (no result
    /// yet or an interrupted run) or `mesh`.
    pub status: &'static str,
    /// The run's saved λ (None for meshes and runs without a result yet).
    pub lambda: Option<f64>,
    /// The largest λ the server accepts.
    pub lambda_max: f64,
    /// Whether λ can be changed (a run with `deformation.npz`).
    pub has_deformation: bool,
    /// Image files of the run the page can show (`turntable.png`, …), relative to the run.
    pub images: Vec<String>,
}

/// A run's saved deformation, loaded and prefactored.
struct LoadedRun {
    /// (modification time, length) of `deformation.npz` when it was read.
    stamp: (SystemTime, u64),
    /// The rest mesh, normalized to the side-2 cube (the frame of every result).
    rest: TriMesh,
    /// The saved target normals.
    targets: Vec<[f64; 3]>,
    /// The saved λ.
    lambda: Option<f64>,
    layer: Darap,
}

/// A run directory named on the command line.
pub struct RunItem {
    /// The path as given.
    pub name: String,
    /// The canonical path of the run directory (every file served lies inside it).
    pub root: PathBuf,
    loaded: Mutex<Option<Box<LoadedRun>>>,
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
            root,
            loaded: Mutex::new(None),
        })
    }

    fn npz(&self) -> PathBuf {
        self.root.join("deformation.npz")
    }

    /// The run's status (see [`ItemInfo::status`]).
    pub fn status(&self) -> &'static str {
        if self.root.join("run.json").is_file() {
            "complete"
        } else if self.root.join(crate::lock::LOCK_FILE).exists() {
            "running"
        } else {
            "incomplete"
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
    pub fn saved_lambda(&self) -> Option<f64> {
        self.with_loaded(|l| Ok(l.lambda)).ok().flatten()
    }

    /// The rest mesh (side-2 cube frame).
    pub fn source(&self) -> Result<Shape, ViewError> {
        self.with_loaded(|l| {
            Ok(Shape {
                positions: l.rest.positions.clone(),
                faces: l.rest.faces.clone(),
                sanity: None,
            })
        })
    }

    /// The saved deformation re-applied at `lambda` (validated here).
    pub fn at_lambda(&self, lambda: f64) -> Result<Shape, ViewError> {
        let lambda = validate_lambda(lambda)?;
        self.with_loaded(|l| {
            l.layer.set_lambda(lambda);
            let deformation = l.layer.forward(&l.targets).map_err(|e| {
                ViewError::Failed(
                    anyhow::Error::from(e).context(format!("dARAP forward failed at λ = {lambda}")),
                )
            })?;
            let sanity =
                LambdaSanity::assess(&l.rest, &deformation, lambda).map_err(ViewError::Failed)?;
            Ok(Shape {
                positions: deformation.positions,
                faces: l.rest.faces.clone(),
                sanity: Some(sanity),
            })
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
        let path = std::fs::canonicalize(self.root.join(rel_path)).map_err(|_| not_found())?;
        if !path.starts_with(&self.root) {
            return Err(ViewError::BadRequest(format!(
                "{rel} leads outside the run directory"
            )));
        }
        if !std::fs::metadata(&path).is_ok_and(|m| m.is_file()) {
            return Err(not_found());
        }
        Ok(path)
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
    ensure!(
        saved.normalize_target_normals(),
        "{}: `normalize_target_normals` is false; only normalized target normals are supported",
        npz.display()
    );
    let rule = crate::cmd::apply::saved_rotation_rule(&saved)?.unwrap_or_default();
    let lambda = saved.lambda();
    let mut rest = saved.verts_f64();
    mesh_core::normalize::side2_cube(&mut rest);
    let targets = saved.verts_normals_f64();
    let options = DarapOptions {
        lambda: lambda.unwrap_or(0.0),
        rotation_rule: rule,
        post_process: PostProcess::RecenterRescale,
    };
    let mut layer = Darap::new(&rest, &saved.faces, options)
        .with_context(|| format!("cannot build the dARAP layer for {}", npz.display()))?;
    // A localized run is shown with its saved region, as `apply` re-applies it.
    if let Some(weights) = crate::cmd::apply::saved_region_weights(&saved, npz)? {
        layer
            .set_region_weights(Some(weights))
            .with_context(|| format!("{}: invalid region_weights", npz.display()))?;
    }
    Ok(LoadedRun {
        stamp,
        rest: TriMesh::new(rest, saved.faces.clone()),
        targets,
        lambda,
        layer,
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

impl Item {
    /// Opens a command-line argument: a directory is a run, a file a mesh.
    pub fn open(path: &Path) -> anyhow::Result<Self> {
        let name = path.display().to_string();
        let meta = std::fs::metadata(path).with_context(|| format!("cannot open {name}"))?;
        if meta.is_dir() {
            return Ok(Item::Run(RunItem::new(name, path)?));
        }
        let ext = path
            .extension()
            .and_then(|e| e.to_str())
            .map(str::to_ascii_lowercase)
            .unwrap_or_default();
        if !matches!(ext.as_str(), "obj" | "off" | "ply" | "gltf" | "glb") {
            bail!(
                "{name}: not a run directory or a mesh (.obj, .off, .ply, .gltf, .glb); \
                 batch manifests are not supported yet — pass their run directories"
            );
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
                ItemInfo {
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

    /// The result at `lambda` (runs only).
    pub fn at_lambda(&self, lambda: f64) -> Result<Shape, ViewError> {
        match self {
            Item::Run(r) => r.at_lambda(lambda),
            Item::Mesh(m) => Err(ViewError::BadRequest(format!(
                "{} is a mesh, not a run: it has no deformation to re-apply",
                m.name
            ))),
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
        let items = paths
            .iter()
            .map(|p| Item::open(p))
            .collect::<anyhow::Result<Vec<_>>>()?;
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

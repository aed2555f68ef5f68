//! One run from mesh file to complete run directory: prepare the mesh, build dARAP, run the loop
//! ([`crate::pipeline`]) with checkpoints, previews and metrics, then write the outputs.

use std::io::Write;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Instant;

use crate::error::{Context, Error, IoContext, Result, Stopped, invalid};
use darap::Darap;
use mesh_core::TriMesh;
use mesh_core::region::{RegionInput, RegionSpec};
use npy::{NpyArray, NpyData};
use optim::{Adam, AdamConfig};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use raster_diff::Images;
use rundir::{Claim, ResumeMode, RunDir, RunLock, Start};

use crate::checkpoint::{CHECKPOINT_VERSION, Checkpoint, CheckpointState};
use crate::config::Config;
use crate::identity::{TaskIdentity, TaskIdentityExt};
use crate::pipeline::{IterationRecord, LoopSpec, LoopState, Objective, Observer, run_loop};
use crate::remeshing::{RemeshReport, RemeshSetting};
use crate::run_pictures::{tint_region, turntable, write_grid};
use crate::saved::SavedDeformation;
use crate::task::{BuiltTask, Figure, Task, TaskKind};

/// Format version of our extra keys in `deformation.npz`.
pub const NPZ_FORMAT_VERSION: i64 = crate::saved::FORMAT_VERSION;

/// Receives a run's progress. Every method has a default that does nothing; the command line
/// draws a progress bar, prints plain lines or JSON.
pub trait Progress {
    /// The loop is about to run iterations `at + 1 ..= total`; `headline` describes the run (what
    /// is optimized on which mesh, the renderer chosen).
    fn start(&mut self, _total: u64, _at: u64, _headline: &[String]) {}
    /// An iteration finished; `json` is its `metrics.jsonl` line.
    fn iteration(&mut self, _record: &IterationRecord, _json: &str) {}
    /// A warning that does not stop the run.
    fn warning(&mut self, _message: &str) {}
    /// The loop ended (finished, halted, stopped or failed).
    fn finish(&mut self) {}
}

/// A [`Progress`] that reports nothing.
#[derive(Clone, Copy, Debug, Default)]
pub struct NoProgress;

impl Progress for NoProgress {}

/// What a caller plugs into [`execute_with`]: where progress goes, and a cancellation flag.
pub struct RunHooks<'a> {
    /// Progress reporting.
    pub progress: &'a mut dyn Progress,
    /// Set it (from a signal handler, another thread, a UI) to stop the run: the loop finishes the
    /// current iteration, writes a checkpoint and returns [`Stopped`]. Polled after every iteration
    /// and before expensive loading.
    pub cancel: &'a AtomicBool,
}

impl std::fmt::Debug for RunHooks<'_> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("RunHooks")
            .field("cancel", &self.cancel)
            .finish_non_exhaustive()
    }
}

/// A run request.
#[derive(Clone, Debug)]
pub struct RunRequest {
    /// Input mesh file.
    pub mesh: PathBuf,
    /// Run directory.
    pub out: PathBuf,
    /// Resolved configuration.
    pub config: Config,
    /// Overwrite a complete or partial run.
    pub force: bool,
    /// Continue from a checkpoint if there is one.
    pub resume: bool,
    /// Stop after this iteration without final outputs (tests of `--resume`).
    pub halt_after: Option<u64>,
}

/// What a run did.
#[derive(Clone, Debug, PartialEq)]
pub struct RunOutcome {
    /// Last finished iteration.
    pub iteration: u64,
    /// Whether the outputs were written (false when halted early).
    pub complete: bool,
    /// For the style path: area-weighted mean alignment before and after.
    pub alignment: Option<(f64, f64)>,
    /// Warnings (e.g. an output format the mesh writer does not support).
    pub warnings: Vec<String>,
    /// Nothing was done: the directory already held a complete run of the same task (only with
    /// [`RunOptions::skip_complete`]).
    pub already_complete: bool,
}

/// The run-directory file of a remeshed input: the rest mesh as optimized (side-2 frame; also
/// the `verts`/`faces` of `deformation.npz`).
pub const REMESHED_SOURCE: &str = "source_remeshed.obj";

/// A mesh prepared as the reference does: repaired, side-2 cube normalized, rounded to the f32
/// values `deformation.npz` stores and normalized again in f64 — so `stylize apply` on the saved
/// file rebuilds exactly this rest mesh.
pub fn prepare_mesh(path: &Path) -> Result<(TriMesh, Vec<String>)> {
    prepare_mesh_with_region(path, &crate::config::RegionSection::default()).map(|(m, w, _)| (m, w))
}

/// A resolved region of a prepared mesh.
#[derive(Clone, Debug, PartialEq)]
pub struct ResolvedRegion {
    /// Vertices that may rotate (prepared mesh's numbering).
    pub free: Vec<bool>,
    /// Per-vertex weights for `Darap::set_region_weights` (feathered).
    pub weights: Vec<f64>,
}

/// Region specs parsed, with vertex files read (relative paths as given: from the working
/// directory; a batch manifest rebases them on its folder).
pub fn parse_region_specs(specs: &[String]) -> Result<Vec<RegionSpec>> {
    specs
        .iter()
        .map(|s| {
            RegionSpec::parse(s)?.with_indices(&mut |path: &Path| -> Result<Vec<usize>> {
                use std::io::Read;
                let mut text = String::new();
                mesh_core::io::open_regular(path)
                    .with_context(|| format!("cannot read vertex file {}", path.display()))?
                    .read_to_string(&mut text)
                    .io_context("cannot read vertex file", path)?;
                mesh_core::region::parse_index_list(&text)
                    .map_err(|e| Error::Invalid(format!("vertex file {}: {e}", path.display())))
            })
        })
        .collect()
}

/// Resolves `section` on a prepared mesh (`Ok(None)` when no spec is given). Warnings (a spec
/// that selects nothing, a region covering everything) are appended to `warnings`.
pub fn resolve_region(
    section: &crate::config::RegionSection,
    input: &RegionInput<'_>,
    warnings: &mut Vec<String>,
) -> Result<Option<ResolvedRegion>> {
    if section.specs.is_empty() {
        return Ok(None);
    }
    let specs = parse_region_specs(&section.specs)?;
    let region = mesh_core::region::select(&specs, input)?;
    warnings.extend(region.warnings.iter().cloned());
    let weights =
        mesh_core::region::feather_weights(&region.free, input.faces, section.feather as usize);
    Ok(Some(ResolvedRegion {
        free: region.free,
        weights,
    }))
}

/// [`prepare_mesh`] and the region of `section` on it (parts of the file and repair maps
/// followed; boxes and spheres evaluated on the prepared, normalized positions). The input is
/// never remeshed (`[mesh] remesh = "off"`); [`prepare_run_mesh`] applies the setting.
pub fn prepare_mesh_with_region(
    path: &Path,
    section: &crate::config::RegionSection,
) -> Result<(TriMesh, Vec<String>, Option<ResolvedRegion>)> {
    let p = prepare_run_mesh(
        path,
        RemeshSetting::Off,
        crate::frame::UpAxis::PosY,
        section,
    )?;
    Ok((p.mesh, p.warnings, p.region))
}

/// A run's input as it is optimized ([`prepare_run_mesh`]).
#[derive(Clone, Debug)]
pub struct PreparedMesh {
    /// Repaired, turned so that its up axis is +y, side-2 normalized (f32-exact), remeshed when
    /// the setting said so.
    pub mesh: TriMesh,
    /// What the repair did.
    pub warnings: Vec<String>,
    /// The region on `mesh`.
    pub region: Option<ResolvedRegion>,
    /// What `[mesh] remesh` decided and did.
    pub remesh: RemeshReport,
    /// The map from the normalized frame of `mesh` back to the file's coordinates
    /// ([`crate::frame`]).
    pub frame: crate::frame::InputFrame,
}

/// Side-2 normalization, rounded to the f32 values `deformation.npz` stores and normalized again
/// in f64 (so a saved rest mesh rebuilds exactly). Returns `(c, s)` with
/// `q = (p − c)·s` up to the f32 rounding between the two passes:
/// `((p − c1)·s1 − c2)·s2 = (p − (c1 + c2/s1))·(s1·s2)`.
fn normalize_f32_exact(positions: &mut [[f64; 3]]) -> ([f64; 3], f64) {
    let first = mesh_core::normalize::side2_cube(positions);
    for p in positions.iter_mut() {
        *p = p.map(|c| f64::from(c as f32));
    }
    let second = mesh_core::normalize::side2_cube(positions);
    (
        std::array::from_fn(|k| first.centre[k] + second.centre[k] / first.scale),
        first.scale * second.scale,
    )
}

/// A run's input from `path`: read, repaired, turned so that `up` is +y, normalized
/// ([`prepare_mesh`]), then remeshed as `remesh` says ([`crate::remeshing`]; the remeshed mesh
/// is normalized again and the two normalizations compose into the recorded frame) and the
/// region of `section` resolved on the result. After a remesh, the file's parts and properties
/// follow the faces they came from ([`mesh_core::remesh::transfer_parts`]); `vertices:` specs
/// name input vertex numbers that remeshing replaces, and are refused then.
pub fn prepare_run_mesh(
    path: &Path,
    remesh: RemeshSetting,
    up: crate::frame::UpAxis,
    section: &crate::config::RegionSection,
) -> Result<PreparedMesh> {
    let (mesh, parts) = mesh_core::io::read_mesh_with_parts(path)
        .with_context(|| format!("cannot read mesh {}", path.display()))?;
    let repaired =
        mesh_core::validate::repair(&mesh, &mesh_core::validate::RepairOptions::default())
            .with_context(|| format!("mesh {} cannot be used", path.display()))?;
    let mut warnings: Vec<String> = repaired
        .report
        .issues
        .iter()
        .map(|i| i.message.clone())
        .collect();
    let mut m = repaired.mesh.clone();
    up.turn(&mut m.positions);
    let (mut centre, mut scale) = normalize_f32_exact(&mut m.positions);
    let (remeshed, report) = crate::remeshing::remesh_input(&m.positions, &m.faces, remesh)
        .with_context(|| format!("mesh {}", path.display()))?;
    warnings.extend(report.warning());
    let region = match remeshed {
        None => {
            let input = RegionInput {
                positions: &m.positions,
                faces: &m.faces,
                vertex_map: &repaired.vertex_map,
                face_map: &repaired.face_map,
                parts: &parts,
            };
            resolve_region(section, &input, &mut warnings)
                .with_context(|| format!("region of {}", path.display()))?
        }
        Some(r) => {
            for spec in &section.specs {
                if !RegionSpec::parse(spec)?.files().is_empty() {
                    return Err(Error::Invalid(format!(
                        "region `{spec}` names vertices of the input file, which remeshing \
                         replaces ({}); use `--remesh off`, or a part:, property:, box: or \
                         sphere: region",
                        report.reason
                    )));
                }
            }
            let source = mesh_core::remesh::TransferSource {
                positions: &m.positions,
                faces: &m.faces,
                vertex_map: &repaired.vertex_map,
                face_map: &repaired.face_map,
            };
            let moved = mesh_core::remesh::transfer_parts(
                &parts,
                &source,
                &r.positions,
                &r.faces,
                &r.source_faces,
            )
            .map_err(|e| Error::Invalid(e.to_string()))?;
            // The input's needle faces are gone: its advice to remesh is moot.
            warnings = repaired
                .report
                .issues
                .iter()
                .filter(|i| i.kind != mesh_core::validate::IssueKind::NeedleFaces)
                .map(|i| i.message.clone())
                .collect();
            m = TriMesh::new(r.positions, r.faces);
            // q = ((R·p − c)·s − c')·s' = (R·p − (c + c'/s))·(s·s').
            let (c2, s2) = normalize_f32_exact(&mut m.positions);
            centre = std::array::from_fn(|k| centre[k] + c2[k] / scale);
            scale *= s2;
            let input = RegionInput::unrepaired(&m.positions, &m.faces, &moved);
            resolve_region(section, &input, &mut warnings)
                .with_context(|| format!("region of {} (remeshed)", path.display()))?
        }
    };
    let frame = crate::frame::InputFrame::from_normalization(up, centre, scale);
    Ok(PreparedMesh {
        mesh: m,
        warnings,
        region,
        remesh: report,
        frame,
    })
}

/// dARAP options from the configuration (the `[darap]` section is darap's own options).
pub fn darap_options(config: &Config) -> darap::DarapOptions {
    config.darap
}

struct RunObserver<'a> {
    dir: &'a RunDir,
    lock: &'a RunLock,
    identity: TaskIdentity,
    metrics: std::fs::File,
    progress: &'a mut dyn Progress,
    cancel: &'a AtomicBool,
    config_toml: String,
    preview_size: usize,
    fov: f64,
    faces: Vec<[u32; 3]>,
    preview_renderer: raster_diff::CpuRenderer,
    /// Region to tint in model-free previews (`region.tint`).
    tint: Option<Vec<bool>>,
    /// `snapshots.npz` (`run.snapshot_every`; `None` when off).
    snapshots: Option<crate::snapshots::SnapshotRecorder<'a>>,
}

fn record_json(r: &IterationRecord) -> serde_json::Value {
    let mut obj = serde_json::Map::new();
    obj.insert("iteration".into(), r.iteration.into());
    for &(k, v) in &r.terms {
        obj.insert(k.into(), v.into());
    }
    obj.insert("grad_norm".into(), r.grad_norm.into());
    let timings: serde_json::Map<String, serde_json::Value> = r
        .timings
        .iter()
        .map(|&(k, v)| (k.to_string(), v.into()))
        .collect();
    obj.insert("seconds".into(), timings.into());
    obj.into()
}

impl Observer for RunObserver<'_> {
    fn iteration(&mut self, record: &IterationRecord) -> Result<()> {
        let line = record_json(record).to_string();
        writeln!(self.metrics, "{line}").io_context("cannot write", &self.dir.metrics())?;
        self.progress.iteration(record, &line);
        if self.cancel.load(Ordering::SeqCst) {
            // The loop was asked to stop after a full iteration; `execute_with` writes the
            // checkpoint and returns the `Stopped` with its iteration.
            return Err(Error::Stopped(Stopped {
                dir: self.dir.root().to_path_buf(),
                checkpoint_iteration: None,
            }));
        }
        Ok(())
    }

    fn warning(&mut self, message: &str) {
        self.progress.warning(message);
    }

    fn after_iteration(&mut self, state: &LoopState) -> Result<()> {
        match &mut self.snapshots {
            Some(s) => {
                self.lock.ensure_held()?;
                s.after_iteration(state.iteration, &state.x)
            }
            None => Ok(()),
        }
    }

    fn checkpoint(&mut self, state: &LoopState) -> Result<()> {
        self.lock.ensure_held()?;
        let metrics = self.dir.metrics();
        self.metrics.flush().io_context("cannot flush", &metrics)?;
        // The checkpoint must not be durable before the metrics lines it accounts for.
        self.metrics
            .sync_data()
            .io_context("cannot sync", &metrics)?;
        Ok(Checkpoint {
            version: CHECKPOINT_VERSION,
            iteration: state.iteration,
            state: CheckpointState {
                x: state.x.clone(),
                adam: state.adam.state().clone(),
                rng: state.rng.clone(),
                config_toml: self.config_toml.clone(),
            },
            identity: Some(self.identity.clone()),
        }
        .save_atomic(&self.dir.checkpoint())?)
    }

    fn preview(
        &mut self,
        iteration: u64,
        deformed: &[[f64; 3]],
        images: Option<&Images>,
    ) -> Result<()> {
        let path = self.dir.previews().join(format!("iter_{iteration:06}.png"));
        match images {
            Some(images) => write_grid(&path, images),
            None => {
                let mut images = turntable(
                    &mut self.preview_renderer,
                    deformed,
                    &self.faces,
                    8,
                    self.preview_size,
                    self.fov,
                )?;
                if let (Some(free), Some(ids)) = (&self.tint, self.preview_renderer.triangle_ids())
                {
                    tint_region(&mut images, &ids, &self.faces, free);
                }
                write_grid(&path, &images)
            }
        }
    }
}

/// Options of [`execute_with`] beyond the request (what the commands know and the library
/// entry point [`execute`] does not).
#[derive(Clone, Debug, Default)]
pub struct RunOptions {
    /// Continue from a checkpoint when there is one, start fresh otherwise (batch rows; overrides
    /// `RunRequest::resume`).
    pub resume_if_checkpoint: bool,
    /// A complete run of the same task is an [`RunOutcome::already_complete`] success instead of
    /// an error (batch rows).
    pub skip_complete: bool,
    /// Further files the run reads, with their role (config file, manifest, model manifest); the
    /// input mesh and the task's own ([`TaskKind::inputs`], an exemplar) are added by the runner.
    /// No output may replace any of them.
    pub inputs: Vec<(String, PathBuf)>,
}

/// Runs one request to completion (or to `halt_after`), reporting nothing and never cancelled.
pub fn execute<'g>(request: &RunRequest, task: impl Task<'g> + 'g) -> Result<RunOutcome> {
    let never = AtomicBool::new(false);
    let hooks = RunHooks {
        progress: &mut NoProgress,
        cancel: &never,
    };
    execute_task(request, task, &RunOptions::default(), hooks)
}

/// [`execute_with`] for a task that is ready at once (nothing to load): its identity is its own
/// ([`Task`] is a [`TaskKind`]).
pub fn execute_task<'g>(
    request: &RunRequest,
    task: impl Task<'g> + 'g,
    options: &RunOptions,
    hooks: RunHooks<'_>,
) -> Result<RunOutcome> {
    let prepared = prepare(request, &task)?;
    let unread = crate::identity::unread_settings_warning(&request.config, &task)?;
    execute_prepared(
        request,
        prepared,
        task.inputs(),
        unread,
        || Ok(task),
        options,
        hooks,
    )
}

/// Stage 1 of a run: what [`prepare`] checked and computed before the run directory is touched.
#[derive(Debug)]
pub struct Prepared {
    /// The mesh as optimized ([`prepare_mesh`]).
    pub mesh: TriMesh,
    /// Repairs made to the input mesh, and later output warnings.
    pub warnings: Vec<String>,
    /// The task's identity (what a resume must match).
    pub identity: TaskIdentity,
    /// The dARAP layer on the prepared mesh.
    pub darap: Darap,
    /// The resolved configuration as written to `config.toml`.
    pub config_toml: String,
    /// Seconds spent in the dARAP precomputation.
    pub setup_seconds: f64,
    /// The region of a localized run (`[region]`), already set on `darap`.
    pub region: Option<ResolvedRegion>,
    /// What `[mesh] remesh` decided and did.
    pub remesh: RemeshReport,
    /// The map from the normalized frame back to the input file's coordinates.
    pub frame: crate::frame::InputFrame,
    /// The configuration the run uses: the request's with `camera.preset` resolved
    /// ([`Config::with_camera_resolved`]); `config_toml` is its text.
    pub config: Config,
    /// What `camera.preset = auto` chose, and why (printed when the loop starts).
    pub camera_choice: Option<String>,
    /// The scale of `mesh_heat.glb` (its largest displacement, [`crate::heat`]) once written.
    pub heat_max_displacement: Option<f64>,
    /// `run.json`'s `turntable_mp4`: what `turntable.mp4` holds once written, or why it was not
    /// (`None` when no turntable animation was asked for, `run.turntable_gif_frames = 0`).
    pub turntable_mp4: Option<serde_json::Value>,
}

/// Stage 1: validates the configuration, prepares the mesh, computes the identity of a task of
/// `kind` and precomputes dARAP — everything that can fail on bad input, before anything is
/// written.
pub fn prepare(request: &RunRequest, kind: &dyn TaskKind) -> Result<Prepared> {
    request.config.validate()?;
    let PreparedMesh {
        mesh,
        warnings,
        region,
        remesh,
        frame,
    } = prepare_run_mesh(
        &request.mesh,
        request.config.mesh.remesh,
        request.config.mesh.up,
        &request.config.region,
    )?;
    let (config, camera_choice) = request.config.clone().with_camera_resolved(&mesh.positions);
    let config_toml = config.to_toml_string()?;
    let config = &config;
    let mut identity = TaskIdentity::new(&mesh.positions, &mesh.faces, kind, config)?;
    crate::identity::insert_unless_default(
        &mut identity.fields,
        "mesh.remeshed",
        &remesh.identity_value().unwrap_or_default(),
        &String::new(),
    );
    if let Some(r) = &region {
        identity = identity.with_region(&config.region.specs, config.region.feather, &r.weights);
    }
    let setup = Instant::now();
    let mut darap = Darap::new(&mesh.positions, &mesh.faces, darap_options(config))
        .context("dARAP precomputation")?;
    if let Some(r) = &region {
        darap
            .set_region_weights(Some(r.weights.clone()))
            .context("region weights")?;
    }
    Ok(Prepared {
        config: config.clone(),
        camera_choice,
        region,
        remesh,
        frame,
        mesh,
        warnings,
        identity,
        darap,
        config_toml,
        setup_seconds: setup.elapsed().as_secs_f64(),
        heat_max_displacement: None,
        turntable_mp4: None,
    })
}

/// What `deformation.npz` records of a task beside the mesh: its label in `dataset_cfg` and its
/// optimizer's iterations and learning rate in `deform_by_csd_cfg`.
#[derive(Clone, Debug, PartialEq)]
pub struct TaskRecord {
    /// `("style", name)` or `("prompt", text)` ([`Task::label`]).
    pub label: (&'static str, String),
    /// Iterations of the task's schedule.
    pub iterations: u64,
    /// Adam's learning rate of the task's schedule.
    pub lr: f64,
}

/// Stage 2: the objective a task optimizes, with its loop and Adam settings.
pub struct BuiltObjective<'g> {
    /// The objective the loop evaluates.
    pub objective: Box<dyn Objective + 'g>,
    /// Iterations, sub-steps, checkpoint and preview cadence.
    pub spec: LoopSpec,
    /// Adam's settings (the style path has its own learning rate).
    pub adam: AdamConfig,
    /// The task's summary figure (the style path's alignment), reported before and after.
    pub alignment: Option<Figure<'g>>,
    /// The renderer chosen for a text run, and why.
    pub renderer_choice: Option<String>,
    /// Warnings about the task on this mesh (a weak style), reported when the loop starts.
    pub warnings: Vec<String>,
    /// What `deformation.npz` records of the task.
    pub record: TaskRecord,
}

impl std::fmt::Debug for BuiltObjective<'_> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("BuiltObjective")
            .field("objective", &self.objective.describe())
            .field("spec", &self.spec)
            .field("record", &self.record)
            .finish_non_exhaustive()
    }
}

/// Stage 2: builds the objective of `task` on the prepared mesh (the text path picks its renderer
/// here).
pub fn build_objective<'g>(
    task: Box<dyn Task<'g> + 'g>,
    mesh: &TriMesh,
    config: &Config,
    halt_after: Option<u64>,
) -> Result<BuiltObjective<'g>> {
    let schedule = task.schedule(config);
    let record = TaskRecord {
        label: task.label(),
        iterations: schedule.iterations,
        lr: schedule.lr,
    };
    let BuiltTask {
        objective,
        renderer_choice,
        warnings,
        alignment,
    } = task.build(mesh, config)?;
    Ok(BuiltObjective {
        objective,
        spec: LoopSpec {
            iterations: schedule.iterations,
            steps_per_batch: schedule.steps_per_batch,
            checkpoint_every: config.run.checkpoint_every,
            preview_every: config.run.preview_every,
            halt_after,
        },
        adam: AdamConfig {
            lr: schedule.lr,
            beta1: config.optim.beta1,
            beta2: config.optim.beta2,
            eps: config.optim.eps,
        },
        alignment,
        renderer_choice,
        warnings,
        record,
    })
}

/// Stage 3: the loop's initial state. A fresh start writes `task.json`, `config.toml` and an empty
/// `metrics.jsonl` and starts at the rest normals; a resume checks the checkpoint against the mesh
/// and cuts `metrics.jsonl` back to its iteration.
pub fn initial_state(
    start: Start<CheckpointState>,
    dir: &RunDir,
    prepared: &Prepared,
    config: &Config,
    adam: AdamConfig,
) -> Result<LoopState> {
    let n = prepared.mesh.positions.len();
    Ok(match start {
        Start::Fresh | Start::Complete => {
            dir.write_task(&prepared.identity)?;
            rundir::durable::replace_bytes(&dir.config(), prepared.config_toml.as_bytes())?;
            rundir::durable::replace_bytes(&dir.metrics(), b"")?;
            LoopState {
                iteration: 0,
                x: prepared.darap.rest_normals().to_vec(),
                adam: Adam::new(3 * n, adam)?,
                rng: ChaCha8Rng::seed_from_u64(config.run.seed),
            }
        }
        Start::Resume(c) => {
            let CheckpointState {
                x,
                adam: moments,
                rng,
                ..
            } = c.state;
            if x.len() != n {
                invalid!(
                    "the checkpoint has {} vertices, the mesh {n}: not the same mesh",
                    x.len()
                );
            }
            dir.truncate_metrics(c.iteration)?;
            LoopState {
                iteration: c.iteration,
                x,
                adam: Adam::from_state(adam, moments)?,
                rng,
            }
        }
    })
}

/// Stage 5: the final outputs of a finished loop — `mesh.obj/.ply/.glb` (formats this build cannot
/// write become warnings), `deformation.npz`, `turntable.png`, `turntable.gif` and
/// `before_after.png`. Returns the deformed mesh.
///
/// The outputs are the deformation of x as saved (f32), so re-applying `deformation.npz`
/// reproduces `mesh.*` exactly.
pub fn write_outputs(
    dir: &RunDir,
    lock: &RunLock,
    prepared: &mut Prepared,
    x: &[[f64; 3]],
    config: &Config,
    source: &Path,
    record: &TaskRecord,
) -> Result<TriMesh> {
    let mesh = &prepared.mesh;
    let x_saved: Vec<[f64; 3]> = x.iter().map(|p| p.map(|c| f64::from(c as f32))).collect();
    let result = prepared
        .darap
        .forward(&x_saved)
        .context("final dARAP forward")?;
    let deformed = TriMesh::new(result.positions.clone(), mesh.faces.clone());
    // The files are written in the output frame; the pictures below use the normalized frame.
    let written_mesh = match config.run.output_frame {
        crate::frame::OutputFrame::Normalized => deformed.clone(),
        crate::frame::OutputFrame::Input => TriMesh::new(
            prepared.frame.place_result(
                &deformed.positions,
                &mesh.positions,
                crate::frame::recentres(config.darap.post_process),
            ),
            mesh.faces.clone(),
        ),
    };
    lock.ensure_held()?;
    if prepared.remesh.remeshed.is_some() {
        // The rest mesh the run optimized (side-2 frame, as `deformation.npz`'s `verts`): what
        // apply, eval and view use.
        let path = dir.file(REMESHED_SOURCE);
        rundir::durable::replace_with(&path, |tmp| {
            mesh_core::io::write_mesh(tmp, mesh, None).map_err(Error::from)
        })
        .with_context(|| format!("cannot write {}", path.display()))?;
    }
    prepared.heat_max_displacement = Some(write_mesh_outputs(
        dir,
        &mesh.positions,
        &deformed.positions,
        &written_mesh,
        &mut prepared.warnings,
    )?);
    let region = prepared.region.as_ref();
    write_deformation(
        dir,
        mesh,
        x,
        config,
        source,
        record,
        region,
        &prepared.frame,
    )?;
    let free = region
        .filter(|_| config.region.tint)
        .map(|r| r.free.as_slice());
    let tt = crate::run_pictures::filled_orbit(
        &deformed.positions,
        &deformed.faces,
        config.run.turntable_views,
        config.run.turntable_size,
        config.camera.sampler.fov_y_deg,
        free,
    )?;
    write_grid(&dir.file("turntable.png"), &tt)?;
    if config.run.turntable_gif_frames > 0 {
        let frames = crate::run_pictures::filled_orbit(
            &deformed.positions,
            &deformed.faces,
            config.run.turntable_gif_frames,
            config.run.turntable_size,
            config.camera.sampler.fov_y_deg,
            free,
        )?;
        crate::run_pictures::write_turntable_gif(
            &dir.file("turntable.gif"),
            &frames,
            crate::run_pictures::GIF_FRAME_DELAY_CS,
        )?;
        prepared.turntable_mp4 = Some(write_turntable_mp4(dir, &frames, &mut prepared.warnings));
    }
    crate::run_pictures::write_before_after(
        &dir.file("before_after.png"),
        &mesh.positions,
        &deformed.positions,
        &deformed.faces,
        config.run.turntable_views,
        config.run.turntable_size,
        config.camera.sampler.fov_y_deg,
    )?;
    Ok(deformed)
}

/// Writes `turntable.mp4` from the GIF's frames (feature `mp4`, [`crate::turntable_mp4`]) and
/// returns `run.json`'s `turntable_mp4`. A failure never fails the finished run: it becomes a
/// warning (a build without the encoder only `run.json`'s `not_written`), the GIF stays, and an MP4
/// an earlier attempt left is removed (it would not show this result).
fn write_turntable_mp4(
    dir: &RunDir,
    frames: &raster_diff::Images,
    warnings: &mut Vec<String>,
) -> serde_json::Value {
    let path = dir.file("turntable.mp4");
    #[cfg(feature = "mp4")]
    let written = crate::turntable_mp4::write_turntable_mp4(
        &path,
        frames,
        crate::run_pictures::GIF_FRAME_DELAY_CS,
    )
    .map(|s| {
        serde_json::json!({
            "file": "turntable.mp4",
            "frames": s.frames,
            "width": s.width,
            "height": s.height,
            "frame_seconds": f64::from(crate::run_pictures::GIF_FRAME_DELAY_CS) / 100.0,
            "codec": "H.264 (OpenH264), 4:2:0, BT.709 limited range",
            "bytes": s.bytes,
        })
    });
    #[cfg(not(feature = "mp4"))]
    let written: Result<serde_json::Value> = {
        let _ = frames;
        Err(Error::NotBuilt {
            feature: "mp4",
            what: "turntable.mp4".into(),
        })
    };
    match written {
        Ok(summary) => summary,
        Err(e) => {
            let why = e.full_message();
            // A build without the encoder is no problem of this run: run.json and the CLI's
            // closing lines say so, the warnings do not.
            if !matches!(e.kind(), Error::NotBuilt { .. }) {
                warnings.push(format!(
                    "turntable.mp4 not written ({why}); turntable.gif has the same frames"
                ));
            }
            if path.is_file()
                && let Err(e) = std::fs::remove_file(&path)
            {
                warnings.push(format!("cannot remove the earlier {}: {e}", path.display()));
            }
            serde_json::json!({ "file": null, "not_written": why })
        }
    }
}

/// Writes `mesh.obj/.ply/.glb` and `mesh_heat.glb` of `written` (the result in the output frame)
/// with area-weighted vertex normals computed in that frame; the heat map's colours measure the
/// displacement from `rest` to `result` (both in the normalized frame, [`crate::heat`]). A mesh
/// format this build's writer does not support becomes a warning. Returns the heat map's scale.
fn write_mesh_outputs(
    dir: &RunDir,
    rest: &[[f64; 3]],
    result: &[[f64; 3]],
    written: &TriMesh,
    warnings: &mut Vec<String>,
) -> Result<f64> {
    let normals = write_mesh_files(dir, written, warnings)?;
    // The displacement heat map (crate::heat), beside the plain mesh files.
    let heat_path = dir.file("mesh_heat.glb");
    let mut heat_max = 0.0;
    rundir::durable::replace_with(&heat_path, |tmp| {
        heat_max = crate::heat::write_heat_glb(tmp, rest, result, written, Some(&normals))?;
        Ok::<(), Error>(())
    })
    .with_context(|| format!("cannot write {}", heat_path.display()))?;
    Ok(heat_max)
}

/// Writes `mesh.obj/.ply/.glb` with area-weighted vertex normals computed in the frame written
/// (returned); a format this build's writer does not support becomes a warning.
fn write_mesh_files(
    dir: &RunDir,
    mesh: &TriMesh,
    warnings: &mut Vec<String>,
) -> Result<Vec<[f64; 3]>> {
    let normals = mesh_core::normals::vertex_normals_area_weighted(&mesh.positions, &mesh.faces);
    for ext in mesh_core::io::Format::WITH_NORMALS.map(mesh_core::io::Format::extension) {
        let path = dir.file(&format!("mesh.{ext}"));
        let written = rundir::durable::replace_with(&path, |tmp| {
            mesh_core::io::write_mesh(tmp, mesh, Some(&normals)).map_err(Error::from)
        });
        match written {
            Ok(()) => {}
            Err(e)
                if matches!(
                    e.kind(),
                    Error::Mesh(mesh_core::MeshError::UnsupportedFormat { .. })
                ) =>
            {
                warnings.push(format!(
                    "mesh.{ext} not written: this build's mesh writer does not support .{ext}"
                ));
            }
            Err(e) => return Err(e).with_context(|| format!("cannot write {}", path.display())),
        }
    }
    Ok(normals)
}

/// A complete run of the same task met again (a batch row) with another `run.output_frame`: its
/// mesh files are rewritten in the asked frame (the frame is presentation, so the task is the
/// same): dARAP is applied to the saved targets as [`write_outputs`] did — the same numbers — and
/// placed in the asked frame; then `deformation.npz`'s and `run.json`'s `output_frame` are
/// updated. Returns what was done, or why it could not be (a run made before output frames
/// records no `output_frame`: its files stay as they are; `--force` redoes it).
fn reframe_complete_run(
    dir: &RunDir,
    lock: &RunLock,
    prepared: &mut Prepared,
) -> Result<Option<String>> {
    use crate::frame::OutputFrame;
    let npz = dir.deformation();
    let mut saved =
        SavedDeformation::read(&npz).with_context(|| format!("cannot read {}", npz.display()))?;
    let want = prepared.config.run.output_frame;
    let was = saved.output_frame()?;
    if was == want {
        return Ok(None);
    }
    if saved.input_frame()?.is_none() {
        return Ok(Some(format!(
            "the complete run's mesh files are in the {was} frame, not the {want} frame asked \
             for: it was made before output frames existed (redo it with --force)"
        )));
    }
    if saved.verts_normals.len() != prepared.mesh.positions.len() {
        invalid!(
            "{} does not match the prepared mesh: cannot rewrite the run's mesh files",
            npz.display()
        );
    }
    let x_saved: Vec<[f64; 3]> = saved.verts_normals_f64();
    let result = prepared
        .darap
        .forward(&x_saved)
        .context("dARAP forward of the saved targets")?;
    let positions = match want {
        OutputFrame::Normalized => result.positions.clone(),
        OutputFrame::Input => prepared.frame.place_result(
            &result.positions,
            &prepared.mesh.positions,
            crate::frame::recentres(prepared.config.darap.post_process),
        ),
    };
    lock.ensure_held()?;
    let mesh = TriMesh::new(positions, prepared.mesh.faces.clone());
    write_mesh_outputs(
        dir,
        &prepared.mesh.positions,
        &result.positions,
        &mesh,
        &mut prepared.warnings,
    )?;
    saved.set_extra("output_frame", NpyArray::scalar_str(want.name()))?;
    rundir::durable::replace_with(&npz, |tmp| saved.write(tmp).map_err(Error::from))
        .with_context(|| format!("cannot write {}", npz.display()))?;
    let summary_path = dir.summary();
    let mut summary: serde_json::Value = serde_json::from_slice(
        &std::fs::read(&summary_path).io_context("cannot read", &summary_path)?,
    )?;
    summary["output_frame"] = want.name().into();
    rundir::durable::replace_bytes(
        &summary_path,
        serde_json::to_string_pretty(&summary)?.as_bytes(),
    )
    .context("cannot write run.json")?;
    Ok(Some(format!(
        "the complete run's mesh files were rewritten from the {was} frame into the {want} frame"
    )))
}

/// Runs one request: `kind` gives the task's identity, `make_task` builds the task (e.g. loads
/// the models) — called only once the run directory is claimed, so refusals come before any
/// expensive loading.
///
/// The stages: [`prepare`] (nothing written yet), claim the run directory, [`build_objective`],
/// [`initial_state`], the loop ([`run_loop`] with checkpoints, previews and metrics), then
/// [`write_outputs`] and `run.json`.
pub fn execute_with<'g, T: Task<'g> + 'g>(
    request: &RunRequest,
    kind: &dyn TaskKind,
    make_task: impl FnOnce() -> Result<T>,
    options: &RunOptions,
    hooks: RunHooks<'_>,
) -> Result<RunOutcome> {
    let prepared = prepare(request, kind)?;
    let unread = crate::identity::unread_settings_warning(&request.config, kind)?;
    execute_prepared(
        request,
        prepared,
        kind.inputs(),
        unread,
        make_task,
        options,
        hooks,
    )
}

/// [`execute_with`] from stage 2 on: `task_inputs` are the kind's inputs, `unread` the warning
/// about settings the kind does not read.
fn execute_prepared<'g, T: Task<'g> + 'g>(
    request: &RunRequest,
    mut prepared: Prepared,
    task_inputs: Vec<(String, PathBuf)>,
    unread: Option<String>,
    make_task: impl FnOnce() -> Result<T>,
    options: &RunOptions,
    hooks: RunHooks<'_>,
) -> Result<RunOutcome> {
    let RunHooks { progress, cancel } = hooks;
    let config = &prepared.config.clone();
    let dir = RunDir::new(&request.out);
    let mut inputs = vec![("input mesh".to_string(), request.mesh.clone())];
    inputs.extend(options.inputs.iter().cloned());
    inputs.extend(task_inputs);
    let (lock, start) = claim_run_dir(&dir, request, options, &prepared, &inputs)?;
    if matches!(start, Start::Complete) {
        if let Some(note) = reframe_complete_run(&dir, &lock, &mut prepared)? {
            progress.warning(&format!("note: {note}"));
            prepared.warnings.push(note);
        }
        return Ok(RunOutcome {
            iteration: 0,
            complete: true,
            alignment: None,
            warnings: prepared.warnings,
            already_complete: true,
        });
    }
    if matches!(start, Start::Resume(_))
        && let Ok(previous) = std::fs::read_to_string(dir.config())
        && let Some(w) = config.guidance.device_change_note(&previous)
    {
        progress.warning(&format!("warning: {w}"));
        prepared.warnings.push(w);
    }
    let task = make_task_unless_stopped(&dir, &start, cancel, make_task, &mut inputs)?;
    for w in task.warnings() {
        progress.warning(&format!("warning: {w}"));
        prepared.warnings.push(w);
    }
    if config.darap.lambda == 0.0 {
        let w = "darap.lambda = 0: the target normals have no effect, so the optimization cannot \
                 change the mesh (the result is the input, normalized); λ 8 is the reference's";
        progress.warning(&format!("warning: {w}"));
        prepared.warnings.push(w.to_string());
    }
    if let Some(w) = unread {
        progress.warning(&format!("warning: {w}"));
        prepared.warnings.push(w);
    }
    let BuiltObjective {
        mut objective,
        spec,
        adam,
        alignment: figure,
        renderer_choice,
        warnings: task_warnings,
        record,
    } = build_objective(Box::new(task), &prepared.mesh, config, request.halt_after)?;
    let mut state = initial_state(start, &dir, &prepared, config, adam)?;
    for w in task_warnings {
        progress.warning(&format!("warning: {w}"));
        prepared.warnings.push(w);
    }
    let (snapshots, snapshot_warning) = crate::snapshots::SnapshotRecorder::start(
        dir.file(crate::snapshots::FILE_NAME),
        &prepared.darap,
        &prepared.mesh.faces,
        config.run.snapshot_every,
        state.iteration,
        &state.x,
        spec.iterations,
    )?;
    if let Some(w) = snapshot_warning {
        progress.warning(&format!("warning: {w}"));
        prepared.warnings.push(w);
    }
    let alignment_before = figure.as_ref().map(|f| f(&prepared.mesh.positions));
    let looped = ObservedLoop {
        dir: &dir,
        lock: &lock,
        prepared: &prepared,
        config,
        progress,
        cancel,
        snapshots,
    }
    .run(
        request,
        objective.as_mut(),
        &spec,
        &mut state,
        renderer_choice.as_deref(),
    )?;
    if state.iteration < spec.iterations {
        return Ok(RunOutcome {
            iteration: state.iteration,
            complete: false,
            alignment: None,
            warnings: prepared.warnings,
            already_complete: false,
        });
    }
    if cancel.load(Ordering::SeqCst) {
        // The final checkpoint is written; the outputs are left to the resume.
        return Err(Stopped {
            dir: request.out.clone(),
            checkpoint_iteration: Some(state.iteration),
        }
        .into());
    }
    let deformed = write_outputs(
        &dir,
        &lock,
        &mut prepared,
        &state.x,
        config,
        &request.mesh,
        &record,
    )?;
    let alignment = match (&figure, alignment_before) {
        (Some(f), Some(before)) => Some((before, f(&deformed.positions))),
        _ => None,
    };
    let intersections = new_self_intersections(&prepared.mesh, &deformed, &mut prepared.warnings);
    lock.ensure_held()?;
    write_summary(
        &dir,
        request,
        &prepared,
        &objective.describe(),
        &state,
        alignment,
        renderer_choice.as_deref(),
        looped.loop_seconds,
        intersections.as_ref(),
    )?;
    drop(lock);
    Ok(RunOutcome {
        iteration: state.iteration,
        complete: true,
        alignment,
        warnings: prepared.warnings,
        already_complete: false,
    })
}

/// Stage 2 of [`execute_with`]: the run directory taken (inputs protected, the lock held) and
/// how to start in it.
fn claim_run_dir(
    dir: &RunDir,
    request: &RunRequest,
    options: &RunOptions,
    prepared: &Prepared,
    inputs: &[(String, PathBuf)],
) -> Result<(RunLock, Start<CheckpointState>)> {
    let resume = if options.resume_if_checkpoint {
        ResumeMode::IfCheckpoint
    } else if request.resume {
        ResumeMode::Required
    } else {
        ResumeMode::Never
    };
    Ok(dir.claim(&Claim {
        force: request.force,
        resume,
        skip_complete: options.skip_complete,
        identity: &prepared.identity,
        inputs,
    })?)
}

/// Stage 3 of [`execute_with`]: the caller's task (models load here), unless the run was
/// cancelled before or while it loaded; the task's inputs ([`TaskKind::inputs`], an exemplar)
/// become inputs no output may replace.
fn make_task_unless_stopped<'g, T: Task<'g>>(
    dir: &RunDir,
    start: &Start<CheckpointState>,
    cancel: &AtomicBool,
    make_task: impl FnOnce() -> Result<T>,
    inputs: &mut Vec<(String, PathBuf)>,
) -> Result<T> {
    let stopped_before = || {
        cancel.load(Ordering::SeqCst).then(|| Stopped {
            dir: dir.root().to_path_buf(),
            checkpoint_iteration: match start {
                Start::Resume(c) => Some(c.iteration),
                _ => None,
            },
        })
    };
    if let Some(s) = stopped_before() {
        return Err(s.into());
    }
    let task = make_task()?;
    if let Some(s) = stopped_before() {
        return Err(s.into());
    }
    let task_inputs = task.inputs();
    if !task_inputs.is_empty() {
        inputs.extend(task_inputs);
        rundir::refuse_overwriting_inputs(
            &rundir::RUN_FILES
                .iter()
                .map(|n| dir.file(n))
                .collect::<Vec<_>>(),
            &[dir.previews()],
            inputs,
        )?;
    }
    Ok(task)
}

/// Stage 4 of [`execute_with`]: the loop with its observer (metrics, checkpoints, previews,
/// progress, cancellation).
struct ObservedLoop<'a> {
    dir: &'a RunDir,
    lock: &'a RunLock,
    prepared: &'a Prepared,
    config: &'a Config,
    progress: &'a mut dyn Progress,
    cancel: &'a AtomicBool,
    /// `snapshots.npz` (`run.snapshot_every`; `None` when off).
    snapshots: Option<crate::snapshots::SnapshotRecorder<'a>>,
}

/// What [`ObservedLoop::run`] measured.
struct Looped {
    loop_seconds: f64,
}

impl ObservedLoop<'_> {
    /// Runs the loop from `state`; a cancellation writes a checkpoint of the last complete
    /// iteration and returns [`Stopped`].
    fn run(
        self,
        request: &RunRequest,
        objective: &mut dyn Objective,
        spec: &LoopSpec,
        state: &mut LoopState,
        renderer_choice: Option<&str>,
    ) -> Result<Looped> {
        let Self {
            dir,
            lock,
            prepared,
            config,
            progress,
            cancel,
            snapshots,
        } = self;
        let mesh = &prepared.mesh;
        let metrics = std::fs::OpenOptions::new()
            .append(true)
            .create(true)
            .open(dir.metrics())
            .io_context("cannot open", &dir.metrics())?;
        let mut headline = vec![format!(
            "{} on {} ({} vertices)",
            objective.describe(),
            request.mesh.display(),
            mesh.positions.len()
        )];
        if prepared.remesh.remeshed.is_some() {
            headline.extend(prepared.remesh.lines());
        }
        if let Some(why) = renderer_choice {
            headline.push(format!("renderer: {why}"));
        }
        if let Some(why) = &prepared.camera_choice {
            headline.push(why.clone());
        }
        progress.start(spec.iterations, state.iteration, &headline);
        let mut observer = RunObserver {
            dir,
            lock,
            identity: prepared.identity.clone(),
            metrics,
            progress,
            cancel,
            config_toml: prepared.config_toml.clone(),
            preview_size: config.run.turntable_size,
            fov: config.camera.sampler.fov_y_deg,
            faces: mesh.faces.clone(),
            preview_renderer: raster_diff::CpuRenderer::default(),
            tint: prepared
                .region
                .as_ref()
                .filter(|_| config.region.tint)
                .map(|r| r.free.clone()),
            snapshots,
        };
        let loop_start = Instant::now();
        let looped = run_loop(&prepared.darap, spec, state, objective, &mut observer);
        observer.progress.finish();
        match looped {
            Ok(()) => Ok(Looped {
                loop_seconds: loop_start.elapsed().as_secs_f64(),
            }),
            Err(e) if matches!(e.kind(), Error::Stopped(_)) => {
                // The iteration is complete (state is consistent): keep it.
                observer.checkpoint(state)?;
                Err(Stopped {
                    dir: request.out.clone(),
                    checkpoint_iteration: Some(state.iteration),
                }
                .into())
            }
            Err(e) => Err(e),
        }
    }
}

/// The end of a run's check for self-intersections the result has and the source does not
/// ([`crate::intersections`]): when there are any, a warning (pushed to `warnings`) and the figures
/// (returned, for `run.json`'s `self_intersections`). A check that cannot run becomes a warning —
/// never a failure of a finished run.
pub fn new_self_intersections(
    source: &TriMesh,
    result: &TriMesh,
    warnings: &mut Vec<String>,
) -> Option<crate::intersections::IntersectionFigures> {
    match crate::intersections::compare(source, result) {
        Ok(f) => {
            let w = f.warning()?;
            warnings.push(format!(
                "the result has {w}: a self-intersecting mesh breaks printing, booleans and \
                 simulation; try a smaller λ (`stylize apply deformation.npz --lambda max-safe`)"
            ));
            Some(f)
        }
        Err(e) => {
            warnings.push(format!(
                "the self-intersection check of the result failed: {e}"
            ));
            None
        }
    }
}

/// Stage 6 of [`execute_with`]: `run.json`, the run's summary (written last: it marks the run
/// complete). `intersections`: the result's new self-intersections, recorded as
/// `self_intersections` when there are any.
#[allow(clippy::too_many_arguments)]
fn write_summary(
    dir: &RunDir,
    request: &RunRequest,
    prepared: &Prepared,
    objective: &str,
    state: &LoopState,
    alignment: Option<(f64, f64)>,
    renderer_choice: Option<&str>,
    loop_seconds: f64,
    intersections: Option<&crate::intersections::IntersectionFigures>,
) -> Result<()> {
    let config = &prepared.config;
    let mesh = &prepared.mesh;
    let mut summary = serde_json::json!({
        "status": "complete",
        "mesh": request.mesh.display().to_string(),
        "objective": objective,
        "iterations": state.iteration,
        "adam_steps": state.adam.state().step,
        "seed": config.run.seed,
        "lambda": config.darap.lambda,
        "rotation_rule": config.darap.rotation_rule.name(),
        "snapshot_every": config.run.snapshot_every,
        "output_frame": config.run.output_frame.name(),
        "up": config.mesh.up.name(),
        "camera_preset": config.camera.preset.name(),
        "vertices": mesh.positions.len(),
        "faces": mesh.faces.len(),
        "alignment_before": alignment.map(|a| a.0),
        "alignment_after": alignment.map(|a| a.1),
        "renderer": renderer_choice,
        "seconds": { "setup": prepared.setup_seconds, "loop": loop_seconds },
        "warnings": prepared.warnings,
        "heat": prepared.heat_max_displacement.map(|max| serde_json::json!({
            "file": "mesh_heat.glb",
            "quantity": "displacement magnitude |p - (r - centroid(r))|, normalized side-2 frame",
            "colormap": "viridis, 5 stops, piecewise linear in sRGB; COLOR_0 linear RGB",
            "max_displacement": max,
        })),
        "turntable_mp4": prepared.turntable_mp4,
        "region": prepared.region.as_ref().map(|r| serde_json::json!({
            "specs": config.region.specs,
            "feather": config.region.feather,
            "vertices": r.free.iter().filter(|&&f| f).count(),
        })),
        "task": prepared.identity.fields,
        "remesh": prepared.remesh.to_json(),
    });
    if let Some(x) = intersections {
        summary["self_intersections"] = serde_json::to_value(x)?;
    }
    rundir::durable::replace_bytes(
        &dir.summary(),
        serde_json::to_string_pretty(&summary)?.as_bytes(),
    )
    .context("cannot write run.json")
}

/// Writes `deformation.npz` in the reference format plus our keys: `to_input_frame` (the 4×4 map
/// from the frame of `verts` to the input file's coordinates, [`crate::frame`]),
/// `output_frame` (the frame of the run's `mesh.*`), `up` (the input's up axis) and, for a
/// localized run, `region_weights` (one f64 per vertex), `region_specs` (newline separated) and
/// `region_feather`.
#[allow(clippy::too_many_arguments)]
fn write_deformation(
    dir: &RunDir,
    mesh: &TriMesh,
    x: &[[f64; 3]],
    config: &Config,
    source: &Path,
    record: &TaskRecord,
    region: Option<&ResolvedRegion>,
    frame: &crate::frame::InputFrame,
) -> Result<()> {
    // The optimizer settings this run used (`[style]`'s on the model-free path).
    let (n_iters, lr) = (record.iterations, record.lr);
    let (task_key, task_value) = (record.label.0, &record.label.1);
    let csd_cfg = serde_json::json!({
        "local_step_procrustes": { "lamb": config.darap.lambda, "normalize_target_normals": true },
        "arap_energy_type": "spokes_and_rims_mine",
        "solve_method": "arap",
        "pin_first_vertex": true,
        "lr": lr,
        "n_iters": n_iters,
    });
    let dataset_cfg =
        serde_json::json!({ "mesh": source.display().to_string(), task_key: task_value });
    let mut saved = SavedDeformation {
        verts: mesh.positions.iter().map(|p| p.map(|c| c as f32)).collect(),
        faces: mesh.faces.clone(),
        verts_normals: x.iter().map(|p| p.map(|c| c as f32)).collect(),
        deform_by_csd_cfg: csd_cfg.to_string(),
        dataset_cfg: dataset_cfg.to_string(),
        extra: Vec::new(),
    };
    let scalar_i64 = |v: i64| NpyArray::new(vec![], NpyData::I64(vec![v])).map_err(Error::Invalid);
    saved.set_extra("format_version", scalar_i64(NPZ_FORMAT_VERSION)?)?;
    // The seed as i64 bits (NumPy has no portable u64 scalar in our reader).
    saved.set_extra("seed", scalar_i64(config.run.seed as i64)?)?;
    saved.set_extra(
        "rotation_rule",
        NpyArray::scalar_str(config.darap.rotation_rule.name()),
    )?;
    saved.set_input_frame(frame, config.run.output_frame, config.mesh.up)?;
    if let Some(r) = region {
        saved.set_extra(
            "region_weights",
            NpyArray::new(vec![r.weights.len()], NpyData::F64(r.weights.clone()))
                .map_err(Error::Invalid)?,
        )?;
        saved.set_extra(
            "region_specs",
            NpyArray::scalar_str(&config.region.specs.join("\n")),
        )?;
        saved.set_extra(
            "region_feather",
            scalar_i64(i64::from(config.region.feather))?,
        )?;
    }
    rundir::durable::replace_with(&dir.deformation(), |tmp| {
        saved.write(tmp).map_err(Error::from)
    })
    .with_context(|| format!("cannot write {}", dir.deformation().display()))
}

#[cfg(all(test, feature = "mp4"))]
mod mp4_tests {
    use super::*;

    #[test]
    fn turntable_mp4_failure_is_a_warning_that_removes_an_earlier_file() {
        let tmp = tempfile::tempdir().unwrap_or_else(|e| panic!("{e}"));
        let dir = RunDir::new(tmp.path());
        std::fs::write(dir.file("turntable.mp4"), b"an earlier attempt's")
            .unwrap_or_else(|e| panic!("{e}"));
        // No frames: the encoder refuses, the run goes on.
        let nothing = raster_diff::Images {
            count: 0,
            height: 8,
            width: 8,
            channels: 3,
            rgb: Vec::new(),
        };
        let mut warnings = Vec::new();
        let json = write_turntable_mp4(&dir, &nothing, &mut warnings);
        assert!(json["file"].is_null(), "{json}");
        assert!(json["not_written"].as_str().is_some(), "{json}");
        assert_eq!(warnings.len(), 1, "{warnings:?}");
        assert!(
            warnings[0].starts_with("turntable.mp4 not written (")
                && warnings[0].contains("turntable.gif has the same frames"),
            "{warnings:?}"
        );
        assert!(!dir.file("turntable.mp4").exists());
        // Frames: written, and described.
        let frames = raster_diff::Images {
            count: 2,
            height: 8,
            width: 8,
            channels: 3,
            rgb: vec![0.5; 2 * 8 * 8 * 3],
        };
        let mut warnings = Vec::new();
        let json = write_turntable_mp4(&dir, &frames, &mut warnings);
        assert!(warnings.is_empty(), "{warnings:?}");
        assert_eq!(json["file"], "turntable.mp4");
        // 8×8 frames make a 16×16 video (OpenH264's smallest; turntable_mp4::video_size).
        assert_eq!(
            (json["frames"].as_u64(), json["width"].as_u64()),
            (Some(2), Some(16))
        );
        assert!(dir.file("turntable.mp4").is_file());
    }
}

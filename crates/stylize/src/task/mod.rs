//! Kinds of task: what a run optimizes, behind two traits so that the runner, the task identity
//! and the command line's run/batch plumbing never name a kind.
//!
//! - [`TaskKind`] is what is known before anything loads: the kind's fields of the task identity
//!   (`objective` and what it optimizes), which settings it reads, and the files it reads. The
//!   runner computes the identity from it before the run directory is claimed.
//! - [`Task`] is a task ready to run (its models loaded, if any): its optimizer settings
//!   ([`Schedule`]), its [`crate::pipeline::Objective`] on the prepared mesh ([`BuiltTask`]), the
//!   label `deformation.npz` records, warnings found while loading or building, and its summary
//!   figure (the style path's normal alignment before and after).
//!
//! Two kinds are built in: the model-free styles ([`crate::style::Style`] implements both traits)
//! and a text prompt ([`Prompt`] as the kind, [`PromptTask`] with its guidance). A new kind (another
//! guidance model, an image prompt) implements the two traits and is run with
//! [`crate::runner::execute_with`] (or [`crate::runner::execute`] when it is ready at once);
//! `crates/stylize/tests/custom_task.rs` adds one outside the crate.

mod prompt;
mod style;

pub use prompt::{ModelIdentity, Prompt, PromptTask};

use std::path::PathBuf;

use mesh_core::TriMesh;

use crate::config::Config;
use crate::error::Result;
use crate::pipeline::Objective;

/// What a kind of task is, as far as it is known before anything loads (see the module
/// documentation). The runner combines it with the mesh and the configuration into the task
/// identity ([`crate::identity::TaskIdentity::new`]).
pub trait TaskKind {
    /// The kind's fields of the task identity, as canonical text: `objective` (the kind's name,
    /// `style` or `prompt`) and what it optimizes (`style`, `style.exemplar_sha256`; `prompt`,
    /// `model.name`, `model.manifest_sha256`). Field names must not start with `mesh.`,
    /// `config.` or `region.` (the runner's). Follow the identity rule of [`crate::identity`]:
    /// a field added later appears only when its value is not the default.
    fn identity_fields(&self) -> Vec<(String, String)>;

    /// Whether a run of this kind reads the result-changing setting `name` (`section.key`) of
    /// `[section]`, beyond what every run reads ([`crate::identity::COMMON_KEYS`]: `[darap]`,
    /// `[region]`, `run.seed`, Adam's `optim.beta1/beta2/eps`). Settings read join the identity
    /// as `config.NAME`; settings set away from their default and read by nobody are warned about.
    fn reads(&self, section: &str, name: &str) -> bool;

    /// What a run of this kind reads, for the warning about settings it does not read: the end of
    /// "… is not used by WHAT" (`a prompt run ([style] is the model-free path's)`).
    fn reads_summary(&self) -> String;

    /// Files the task reads, with their role (`exemplar mesh`): no output may replace them. The
    /// runner adds them to the inputs it protects when it claims the run directory.
    fn inputs(&self) -> Vec<(String, PathBuf)> {
        Vec::new()
    }
}

/// The optimizer settings of a task: how many iterations, Adam's learning rate, and Adam steps
/// per iteration (sub-steps with the same deformed mesh).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Schedule {
    /// Iterations (Adam steps are `iterations × steps_per_batch`).
    pub iterations: u64,
    /// Adam's learning rate.
    pub lr: f64,
    /// Adam steps per iteration.
    pub steps_per_batch: u32,
}

/// A summary figure of a mesh: a number of its positions (on the prepared mesh's faces), such as
/// the style path's area-weighted mean normal alignment.
pub type Figure<'g> = Box<dyn Fn(&[[f64; 3]]) -> f64 + 'g>;

/// A task's objective on the prepared mesh, with what it reports besides.
pub struct BuiltTask<'g> {
    /// The objective the loop evaluates.
    pub objective: Box<dyn Objective + 'g>,
    /// The renderer chosen and why (reported and kept in `run.json`; `None`: the task renders
    /// nothing).
    pub renderer_choice: Option<String>,
    /// Warnings about the task on this mesh (a style whose targets are close to the mesh's own
    /// normals), reported at the start of the loop and kept in `run.json`.
    pub warnings: Vec<String>,
    /// The task's summary figure of a mesh (positions on the prepared mesh's faces), reported
    /// before and after the run as `alignment_before`/`alignment_after` in `run.json` and
    /// [`crate::runner::RunOutcome::alignment`]: the style path's area-weighted mean alignment
    /// n·t. `None`: no figure.
    pub alignment: Option<Figure<'g>>,
}

impl std::fmt::Debug for BuiltTask<'_> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("BuiltTask")
            .field("objective", &self.objective.describe())
            .field("renderer_choice", &self.renderer_choice)
            .field("warnings", &self.warnings)
            .finish_non_exhaustive()
    }
}

/// A task ready to run: its kind ([`TaskKind`]) with everything loaded. The guidance it holds may
/// borrow models that outlive the run (`'g`).
pub trait Task<'g>: TaskKind {
    /// The entry `deformation.npz` records in `dataset_cfg` beside the mesh: `("style", name)`,
    /// `("prompt", text)`.
    fn label(&self) -> (&'static str, String);

    /// Warnings found while loading (a prompt longer than the text encoder reads); reported at
    /// the start and kept in `run.json`.
    fn warnings(&self) -> Vec<String> {
        Vec::new()
    }

    /// The optimizer settings this task uses from `config` (recorded in `deformation.npz`).
    fn schedule(&self, config: &Config) -> Schedule;

    /// The objective on the prepared (repaired, normalized) mesh.
    fn build(self: Box<Self>, mesh: &TriMesh, config: &Config) -> Result<BuiltTask<'g>>;
}

/// Lower-case hexadecimal of `bytes`: how the kinds record digests in their identity fields
/// (the same text as [`crate::identity`]'s mesh digest).
pub(crate) fn hex(bytes: &[u8]) -> String {
    bytes.iter().map(|b| format!("{b:02x}")).collect()
}

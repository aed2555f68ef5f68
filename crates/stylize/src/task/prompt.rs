//! The text kind: a prompt ([`Prompt`], known before the models load) and its guidance
//! ([`PromptTask`], ready).

use std::path::Path;

use csd::Guidance;
use mesh_core::TriMesh;
use serde::{Deserialize, Serialize};
use sha2::{Digest, Sha256};

use super::{BuiltTask, Schedule, Task, TaskKind};
use crate::config::Config;
use crate::error::{IoContext, Result};
use crate::pipeline::{TextObjective, ViewSettings};

/// A text prompt and the model that guides it (the text kind before the models load).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Prompt {
    /// The prompt (recorded).
    pub text: String,
    /// The model, when known (part of the task identity).
    pub model: Option<ModelIdentity>,
}

impl Prompt {
    /// `text` with no model recorded.
    pub fn new(text: impl Into<String>) -> Self {
        Self {
            text: text.into(),
            model: None,
        }
    }
}

impl TaskKind for Prompt {
    /// `objective = prompt`, `prompt` (JSON-quoted) and, with a model, `model.name` (JSON-quoted)
    /// and `model.manifest_sha256`.
    fn identity_fields(&self) -> Vec<(String, String)> {
        let quote = |s: &str| serde_json::Value::from(s).to_string();
        let mut fields = vec![
            ("objective".to_string(), "prompt".to_string()),
            ("prompt".to_string(), quote(&self.text)),
        ];
        if let Some(m) = &self.model {
            fields.push(("model.name".into(), quote(&m.name)));
            fields.push(("model.manifest_sha256".into(), m.manifest_sha256.clone()));
        }
        fields
    }

    /// Everything but `[style]` (the model-free path's).
    fn reads(&self, section: &str, _name: &str) -> bool {
        section != "style"
    }

    fn reads_summary(&self) -> String {
        "a prompt run ([style] is the model-free path's)".into()
    }
}

/// The text kind ready to run: a prompt and its guidance (models loaded by the caller).
pub struct PromptTask<'g> {
    /// The prompt and its model.
    pub prompt: Prompt,
    /// The guidance (it may borrow models that outlive the run, `'g`).
    pub guidance: Box<dyn Guidance + 'g>,
    /// Warnings found while loading (a prompt longer than the text encoder reads:
    /// [`crate::models::ModelSet::prompt_warnings`]); reported and kept in `run.json`.
    pub warnings: Vec<String>,
}

impl std::fmt::Debug for PromptTask<'_> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("PromptTask")
            .field("prompt", &self.prompt)
            .field("warnings", &self.warnings)
            .finish_non_exhaustive()
    }
}

impl TaskKind for PromptTask<'_> {
    fn identity_fields(&self) -> Vec<(String, String)> {
        self.prompt.identity_fields()
    }

    fn reads(&self, section: &str, name: &str) -> bool {
        self.prompt.reads(section, name)
    }

    fn reads_summary(&self) -> String {
        self.prompt.reads_summary()
    }
}

impl<'g> Task<'g> for PromptTask<'g> {
    fn label(&self) -> (&'static str, String) {
        ("prompt", self.prompt.text.clone())
    }

    fn warnings(&self) -> Vec<String> {
        self.warnings.clone()
    }

    /// `optim.iterations`, `optim.lr`, `optim.steps_per_batch`.
    fn schedule(&self, config: &Config) -> Schedule {
        Schedule {
            iterations: config.optim.iterations,
            lr: config.optim.lr,
            steps_per_batch: config.optim.steps_per_batch,
        }
    }

    /// The text objective with the configured renderer (chosen here) and views.
    fn build(self: Box<Self>, mesh: &TriMesh, config: &Config) -> Result<BuiltTask<'g>> {
        let (renderer, why) = raster_diff::select_renderer(config.render.backend)?;
        let views = ViewSettings {
            camera: config.camera.sampler.clone(),
            views: config.camera.views,
            width: config.render.width,
            height: config.render.height,
            adapt_distance: config.camera.adapt_distance,
        };
        let objective = TextObjective::new(renderer, self.guidance, &mesh.faces, views);
        Ok(BuiltTask {
            objective: Box::new(objective),
            renderer_choice: Some(why),
            warnings: Vec::new(),
            alignment: None,
        })
    }
}

/// The model a text run uses, as recorded.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct ModelIdentity {
    /// The manifest's `name` (or the folder's name).
    pub name: String,
    /// SHA-256 of `manifest.toml`.
    pub manifest_sha256: String,
}

impl ModelIdentity {
    /// Reads `DIR/manifest.toml` of a model directory.
    pub fn of_dir(dir: &Path) -> Result<Self> {
        let path = dir.join("manifest.toml");
        let bytes = mesh_core::io::ensure_regular_file(&path)
            .and_then(|()| std::fs::read(&path))
            .io_context("cannot read", &path)?;
        let name = std::str::from_utf8(&bytes)
            .ok()
            .and_then(|t| toml::from_str::<toml::Table>(t).ok())
            .and_then(|t| t.get("name").and_then(|v| v.as_str()).map(str::to_string))
            .unwrap_or_else(|| {
                dir.file_name()
                    .map(|n| n.to_string_lossy().into_owned())
                    .unwrap_or_default()
            });
        Ok(Self {
            name,
            manifest_sha256: super::hex(&Sha256::digest(&bytes)),
        })
    }
}

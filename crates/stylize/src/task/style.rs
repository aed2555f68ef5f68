//! The model-free kind: a [`Style`] is both the kind and the ready task (nothing loads).

use std::path::PathBuf;

use mesh_core::TriMesh;
use sha2::{Digest, Sha256};

use super::{BuiltTask, Schedule, Task, TaskKind};
use crate::config::Config;
use crate::error::Result;
use crate::pipeline::StyleObjective;
use crate::style::Style;

impl TaskKind for Style {
    /// `objective = style`, `style` (`cube`, `octahedron`, `exemplar`) and for exemplars
    /// `style.exemplar_sha256`: the SHA-256 of the exemplar's normals (count as u64 LE, then the
    /// components as f64 LE), its content, not its path.
    fn identity_fields(&self) -> Vec<(String, String)> {
        let (style, exemplar_sha256) = match self {
            Style::Cube => ("cube", None),
            Style::Octahedron => ("octahedron", None),
            Style::Exemplar { normals, .. } => {
                let mut h = Sha256::new();
                h.update((normals.len() as u64).to_le_bytes());
                for n in normals {
                    for c in n {
                        h.update(c.to_le_bytes());
                    }
                }
                ("exemplar", Some(super::hex(&h.finalize())))
            }
        };
        let mut fields = vec![
            ("objective".to_string(), "style".to_string()),
            ("style".to_string(), style.to_string()),
        ];
        if let Some(h) = exemplar_sha256 {
            fields.push(("style.exemplar_sha256".into(), h));
        }
        fields
    }

    /// `[style]` (its own iterations and learning rate).
    fn reads(&self, section: &str, _name: &str) -> bool {
        section == "style"
    }

    fn reads_summary(&self) -> String {
        "a model-free style run, which reads [style] (its own iterations and lr), [darap], \
         run.seed and optim.beta1/beta2/eps"
            .into()
    }

    fn inputs(&self) -> Vec<(String, PathBuf)> {
        match self {
            Style::Exemplar { path, .. } => vec![("exemplar mesh".into(), path.clone())],
            Style::Cube | Style::Octahedron => Vec::new(),
        }
    }
}

impl Task<'_> for Style {
    fn label(&self) -> (&'static str, String) {
        ("style", self.name())
    }

    /// `style.iterations`, `style.lr`, one Adam step per iteration.
    fn schedule(&self, config: &Config) -> Schedule {
        Schedule {
            iterations: config.style.iterations,
            lr: config.style.lr,
            steps_per_batch: 1,
        }
    }

    /// The alignment objective, the weak-style warning, and the mean alignment as the summary
    /// figure.
    fn build(self: Box<Self>, mesh: &TriMesh, _config: &Config) -> Result<BuiltTask<'static>> {
        let objective = StyleObjective::new(&self, &mesh.positions, &mesh.faces);
        let warnings = crate::style::target_angle::weak_style_warning(
            &self,
            &mesh.positions,
            &mesh.faces,
            objective.targets(),
        )
        .into_iter()
        .collect();
        let figure = objective.clone();
        Ok(BuiltTask {
            objective: Box::new(objective),
            renderer_choice: None,
            warnings,
            alignment: Some(Box::new(move |positions| figure.mean_alignment(positions))),
        })
    }
}

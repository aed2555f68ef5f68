//! The identity of a run's task: what must be equal for a checkpoint to be continued (or a
//! complete run to count as done) — the input mesh, the objective and every configuration value
//! that changes the result.
//!
//! - `mesh`: SHA-256 of the prepared mesh (repaired, normalized: exactly what is optimized) over
//!   the vertex and face counts (u64 LE), the positions (f64 LE) and the faces (u32 LE); two meshes
//!   with the same vertex count but different geometry or connectivity differ.
//! - `objective`: `style` or `prompt`; `style` (`cube`, `octahedron`, `exemplar`) and for exemplars
//!   the SHA-256 of the exemplar's target normals (its content, not its path); `prompt`; the model
//!   name and the SHA-256 of the model directory's `manifest.toml` (the weights themselves are not
//!   hashed).
//! - `config.<section>.<key>`: every resolved configuration value the chosen path reads, except
//!   those that only change cadence or presentation ([`PRESENTATION_KEYS`]). The model-free path
//!   reads `[darap]`, `[style]`, `run.seed` and Adam's `optim.beta1/beta2/eps`; the text path reads
//!   everything except `[style]`.
//!
//! - `region.*` (only for a localized run, so that unlocalized identities are unchanged): the
//!   specs, the feather rings and `region.weights_sha256`, the SHA-256 of the resolved per-vertex
//!   weights (f64 LE) — a vertex file edited between a run and its resume changes it.
//!
//! The record itself, [`TaskIdentity`] (field name → value text, with
//! [`TaskIdentity::differences`], which names each differing field with its old and new value),
//! is the run directory's ([`rundir::identity`]), which stores and compares it without looking
//! inside; how it is computed is this module's: [`TaskIdentityExt::new`] and
//! [`TaskIdentityExt::with_region`].

use std::collections::BTreeMap;
use std::path::Path;

use crate::error::{IoContext, Result};
use serde::{Deserialize, Serialize};
use sha2::{Digest, Sha256};

use crate::config::Config;
use crate::style::Style;

pub use rundir::TaskIdentity;

/// Configuration keys that do not change the optimized result (cadence, presentation, memory):
/// they may differ between a run and its resume.
pub const PRESENTATION_KEYS: &[&str] = &[
    "run.checkpoint_every",
    "run.preview_every",
    "run.turntable_views",
    "run.turntable_size",
    "run.turntable_gif_frames",
    "run.snapshot_every",
    "guidance.onnx_memory_arena",
    "guidance.onnx_low_memory",
    "region.tint",
];

/// Keys of the text path's sections that the model-free path reads as well.
const STYLE_PATH_OPTIM_KEYS: &[&str] = &["optim.beta1", "optim.beta2", "optim.eps"];

/// Whether a run on the model-free path (`style_path`) or the text path reads the result-changing
/// key `name` (`section.key`). Presentation keys and `[region]` are read by both.
fn path_reads(section: &str, name: &str, style_path: bool) -> bool {
    if !style_path {
        return section != "style";
    }
    match section {
        "darap" | "style" | "region" => true,
        "run" => name == "run.seed" || PRESENTATION_KEYS.contains(&name),
        _ => STYLE_PATH_OPTIM_KEYS.contains(&name),
    }
}

/// Keys the model-free path reads only for its pictures (previews, turntable, before/after), so
/// they are not in its identity yet are used.
const STYLE_PATH_PICTURE_KEYS: &[&str] = &["camera.fov_deg"];

/// The settings of `config` that differ from their defaults although the chosen path
/// (`style_path`: model-free) never reads them, as `section.key = value` — a `--set
/// optim.iterations=…` on a `--style` run, a negative prompt without a prompt. Presentation and
/// memory keys ([`PRESENTATION_KEYS`]) are not listed.
pub fn unread_settings(config: &Config, style_path: bool) -> Result<Vec<String>> {
    let table = toml::Table::try_from(config)?;
    let defaults = toml::Table::try_from(Config::default())?;
    let mut unread = Vec::new();
    for (section, keys) in &table {
        let Some(keys) = keys.as_table() else {
            continue;
        };
        let default_keys = defaults.get(section).and_then(|d| d.as_table());
        for (key, value) in keys {
            let name = format!("{section}.{key}");
            if PRESENTATION_KEYS.contains(&name.as_str())
                || path_reads(section, &name, style_path)
                || (style_path && STYLE_PATH_PICTURE_KEYS.contains(&name.as_str()))
            {
                continue;
            }
            if default_keys.and_then(|d| d.get(key)) != Some(value) {
                unread.push(format!("{name} = {value}"));
            }
        }
    }
    Ok(unread)
}

/// The warning for [`unread_settings`] (`None` when there are none).
pub fn unread_settings_warning(config: &Config, style_path: bool) -> Result<Option<String>> {
    let unread = unread_settings(config, style_path)?;
    if unread.is_empty() {
        return Ok(None);
    }
    let what = if style_path {
        "a model-free style run, which reads [style] (its own iterations and lr), [darap], \
         run.seed and optim.beta1/beta2/eps"
    } else {
        "a prompt run ([style] is the model-free path's)"
    };
    Ok(Some(format!(
        "{} {} not used by {what}",
        unread.join(", "),
        if unread.len() == 1 { "is" } else { "are" }
    )))
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
            manifest_sha256: hex(&Sha256::digest(&bytes)),
        })
    }
}

/// What is optimized, as recorded.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum ObjectiveIdentity {
    /// The model-free path.
    Style {
        /// `cube`, `octahedron` or `exemplar`.
        style: String,
        /// For exemplars: SHA-256 of the target normals.
        exemplar_sha256: Option<String>,
    },
    /// The text path.
    Prompt {
        /// The prompt.
        prompt: String,
        /// The model, when known.
        model: Option<ModelIdentity>,
    },
}

impl ObjectiveIdentity {
    /// The identity of a style.
    pub fn of_style(style: &Style) -> Self {
        match style {
            Style::Cube => Self::Style {
                style: "cube".into(),
                exemplar_sha256: None,
            },
            Style::Octahedron => Self::Style {
                style: "octahedron".into(),
                exemplar_sha256: None,
            },
            Style::Exemplar { normals, .. } => {
                let mut h = Sha256::new();
                h.update((normals.len() as u64).to_le_bytes());
                for n in normals {
                    for c in n {
                        h.update(c.to_le_bytes());
                    }
                }
                Self::Style {
                    style: "exemplar".into(),
                    exemplar_sha256: Some(hex(&h.finalize())),
                }
            }
        }
    }
}

fn hex(bytes: &[u8]) -> String {
    bytes.iter().map(|b| format!("{b:02x}")).collect()
}

/// SHA-256 of a prepared mesh (see the module documentation).
pub fn mesh_sha256(positions: &[[f64; 3]], faces: &[[u32; 3]]) -> String {
    let mut h = Sha256::new();
    h.update((positions.len() as u64).to_le_bytes());
    h.update((faces.len() as u64).to_le_bytes());
    for p in positions {
        for c in p {
            h.update(c.to_le_bytes());
        }
    }
    for f in faces {
        for v in f {
            h.update(v.to_le_bytes());
        }
    }
    hex(&h.finalize())
}

/// How a run's [`TaskIdentity`] is computed (see the module documentation): the record is
/// [`rundir`]'s, its fields are stylize's.
pub trait TaskIdentityExt: Sized {
    /// The identity of optimizing `objective` on the prepared mesh with `config`.
    fn new(
        positions: &[[f64; 3]],
        faces: &[[u32; 3]],
        objective: &ObjectiveIdentity,
        config: &Config,
    ) -> Result<Self>;

    /// Adds a localized run's region: its specs, feather rings and resolved weights.
    fn with_region(self, specs: &[String], feather: u32, weights: &[f64]) -> Self;
}

impl TaskIdentityExt for TaskIdentity {
    fn new(
        positions: &[[f64; 3]],
        faces: &[[u32; 3]],
        objective: &ObjectiveIdentity,
        config: &Config,
    ) -> Result<Self> {
        let mut fields = BTreeMap::new();
        fields.insert("mesh.sha256".to_string(), mesh_sha256(positions, faces));
        fields.insert("mesh.vertices".to_string(), positions.len().to_string());
        fields.insert("mesh.faces".to_string(), faces.len().to_string());
        let quote = |s: &str| serde_json::Value::from(s).to_string();
        let style_path = match objective {
            ObjectiveIdentity::Style {
                style,
                exemplar_sha256,
            } => {
                fields.insert("objective".into(), "style".into());
                fields.insert("style".into(), style.clone());
                if let Some(h) = exemplar_sha256 {
                    fields.insert("style.exemplar_sha256".into(), h.clone());
                }
                true
            }
            ObjectiveIdentity::Prompt { prompt, model } => {
                fields.insert("objective".into(), "prompt".into());
                fields.insert("prompt".into(), quote(prompt));
                if let Some(m) = model {
                    fields.insert("model.name".into(), quote(&m.name));
                    fields.insert("model.manifest_sha256".into(), m.manifest_sha256.clone());
                }
                false
            }
        };
        let table = toml::Table::try_from(config)?;
        for (section, keys) in &table {
            let Some(keys) = keys.as_table() else {
                continue;
            };
            if section == "region" {
                // Recorded by `with_region`, only for localized runs.
                continue;
            }
            for (key, value) in keys {
                let name = format!("{section}.{key}");
                if PRESENTATION_KEYS.contains(&name.as_str()) {
                    continue;
                }
                if path_reads(section, &name, style_path) {
                    fields.insert(format!("config.{name}"), value.to_string());
                }
            }
        }
        Ok(Self { fields })
    }

    fn with_region(mut self, specs: &[String], feather: u32, weights: &[f64]) -> Self {
        let mut h = Sha256::new();
        h.update((weights.len() as u64).to_le_bytes());
        for w in weights {
            h.update(w.to_le_bytes());
        }
        self.fields.insert(
            "region.specs".into(),
            serde_json::Value::from(specs.to_vec()).to_string(),
        );
        self.fields
            .insert("region.feather".into(), feather.to_string());
        self.fields
            .insert("region.weights_sha256".into(), hex(&h.finalize()));
        self
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn tri() -> (Vec<[f64; 3]>, Vec<[u32; 3]>) {
        (
            vec![[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]],
            vec![[0, 1, 2]],
        )
    }

    fn id(objective: &ObjectiveIdentity, config: &Config) -> TaskIdentity {
        let (p, f) = tri();
        TaskIdentity::new(&p, &f, objective, config).unwrap_or_else(|e| panic!("{e:#}"))
    }

    #[test]
    fn settings_the_chosen_path_never_reads_are_named() {
        let c = Config::default()
            .with_overrides(&[
                "optim.iterations=2000",
                "guidance.negative_prompt=blurry",
                "style.lr=0.05",
                "camera.fov_deg=60",
                "run.turntable_views=3",
            ])
            .unwrap_or_else(|e| panic!("{e}"));
        let style = unread_settings(&c, true).unwrap_or_default();
        assert_eq!(
            style,
            [
                "guidance.negative_prompt = \"blurry\"",
                "optim.iterations = 2000"
            ]
        );
        let text = unread_settings(&c, false).unwrap_or_default();
        assert_eq!(text, ["style.lr = 0.05"]);
        let w = unread_settings_warning(&c, true)
            .ok()
            .flatten()
            .unwrap_or_default();
        assert!(w.contains("are not used by a model-free style run"), "{w}");
        assert!(unread_settings(&Config::default(), true).is_ok_and(|u| u.is_empty()));
        assert!(unread_settings(&Config::default(), false).is_ok_and(|u| u.is_empty()));
    }

    #[test]
    fn differences_name_each_field_and_presentation_keys_are_ignored() {
        let cube = ObjectiveIdentity::of_style(&Style::Cube);
        let octa = ObjectiveIdentity::of_style(&Style::Octahedron);
        let base = Config::default();
        let a = id(&cube, &base);
        assert!(a.differences(&a).is_empty());
        let mut c = base.clone();
        c.run.seed = 3;
        c.darap.lambda = 5.0;
        c.run.checkpoint_every = 7;
        c.run.turntable_size = 64;
        let d = a.differences(&id(&octa, &c));
        assert_eq!(d.len(), 3, "{d:?}");
        assert!(
            d.iter()
                .any(|m| m.starts_with("style: was cube, now octahedron"))
        );
        assert!(
            d.iter()
                .any(|m| m.starts_with("config.run.seed: was 0, now 3"))
        );
        assert!(d.iter().any(|m| m.starts_with("config.darap.lambda")));
        // The model-free path does not read the text path's settings.
        let mut t = base.clone();
        t.guidance.scale = 7.5;
        assert!(a.differences(&id(&cube, &t)).is_empty());
        let p = |s: &str| ObjectiveIdentity::Prompt {
            prompt: s.into(),
            model: None,
        };
        let d = id(&p("a cat"), &base).differences(&id(&p("a dog"), &t));
        assert_eq!(d.len(), 2, "{d:?}");
        assert!(
            d.iter()
                .any(|m| m.contains("\"a cat\"") && m.contains("\"a dog\""))
        );
    }

    #[test]
    fn mesh_hash_sees_geometry_not_just_counts() {
        let (p, f) = tri();
        let mut q = p.clone();
        q[2][2] = 1e-12;
        assert_ne!(mesh_sha256(&p, &f), mesh_sha256(&q, &f));
        assert_ne!(mesh_sha256(&p, &f), mesh_sha256(&p, &[[0, 2, 1]]));
    }
}

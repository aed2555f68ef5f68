//! The identity of a run's task: what must be equal for a checkpoint to be continued (or a
//! complete run to count as done) — the input mesh, the objective and every configuration value
//! that changes the result.
//!
//! - `mesh`: SHA-256 of the prepared mesh (repaired, normalized: exactly what is optimized) over
//!   the vertex and face counts (u64 LE), the positions (f64 LE) and the faces (u32 LE); two meshes
//!   with the same vertex count but different geometry or connectivity differ.
//! - `mesh.remeshed` (only when `[mesh] remesh` remeshed the input, so identities of kept meshes
//!   are unchanged): the target edge length, rounds and feature angle
//!   ([`crate::remeshing::RemeshReport::identity_value`]); the setting itself is never a
//!   `config.` field ([`RECORDED_BY_THE_PREPARED_MESH`]).
//! - the task kind's own fields ([`TaskKind::identity_fields`]): `objective` (`style` or
//!   `prompt`); for a style, `style` (`cube`, `octahedron`, `exemplar`) and for exemplars the
//!   SHA-256 of the exemplar's target normals (its content, not its path); for a prompt, `prompt`,
//!   the model name and the SHA-256 of the model directory's `manifest.toml` (the weights
//!   themselves are not hashed).
//! - `config.<section>.<key>`: every resolved configuration value the run reads, except those
//!   that only change cadence or presentation ([`PRESENTATION_KEYS`]). Every run reads
//!   [`COMMON_SECTIONS`] and [`COMMON_KEYS`] (`[darap]`, `run.seed` and Adam's
//!   `optim.beta1/beta2/eps`); the kind says
//!   what else it reads ([`TaskKind::reads`]): the model-free path `[style]`, the text path
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
//!
//! # The rule for new settings
//!
//! A resume (and a batch row that skips a complete run) compares the identity recorded in
//! `task.json` with today's, field by field, so every field added to the identity would refuse to
//! continue every run made before it. Hence:
//!
//! - A new setting joins the identity only when it changes the result, and only when it is set
//!   away from its default: at its default it is absent, so identities of runs made before it
//!   are unchanged (as the `region.*` fields are absent from unlocalized runs). A new
//!   configuration key is listed in [`RECORDED_UNLESS_DEFAULT`]; a field written by hand goes
//!   through [`insert_unless_default`]. (The test `identity_keys_of_default_runs_are_frozen`
//!   fails when a new key would join the identity at its default.)
//! - Settings that change speed or memory but not the result (devices, threads, memory limits,
//!   cadences) are recorded in `run.json` and the checkpoint's `config.toml`, never in the
//!   identity ([`PRESENTATION_KEYS`]).

use std::collections::BTreeMap;

use crate::error::Result;
use sha2::{Digest, Sha256};

use crate::config::Config;
use crate::task::TaskKind;

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
    "guidance.onnx_io_binding",
    "guidance.stage1_device",
    "guidance.stage2_device",
    "guidance.text_encoder_device",
    "guidance.cuda_conv_search",
    "guidance.cuda_arena_growth",
    "guidance.cuda_memory_limit_gib",
    "guidance.cuda_tf32",
    "region.tint",
    "run.output_frame",
];

/// Keys every run reads whose whole effect is on the prepared mesh, which the identity records
/// already (`mesh.sha256`): they are never `config.*` fields. `mesh.remesh` at `auto` keeps an
/// even mesh exactly, so the identities of runs made before it are unchanged; when a run's input
/// is remeshed, the runner adds the field `mesh.remeshed` (edge length, iterations, feature
/// angle: [`crate::remeshing::RemeshReport::identity_value`]) beside the remeshed mesh's hash, so
/// a resume with settings that remesh differently (or not at all) is refused by name.
pub const RECORDED_BY_THE_PREPARED_MESH: &[&str] = &["mesh.remesh"];

/// Sections every run reads whatever its kind: the runner builds dARAP from `[darap]` and
/// `[region]` (the region is recorded by [`TaskIdentity::with_region`]), and turns the input by
/// `[mesh]` (`mesh.up`).
pub const COMMON_SECTIONS: &[&str] = &["darap", "region", "mesh"];

/// Keys every run reads whatever its kind: the runner seeds the generator from `run.seed` and runs
/// Adam with `optim.beta1/beta2/eps`.
pub const COMMON_KEYS: &[&str] = &["run.seed", "optim.beta1", "optim.beta2", "optim.eps"];

/// Keys every run reads only for its pictures (previews, turntable, before/after): they are in
/// the identity only when the kind reads them for its result, and never named as unread.
const PICTURE_KEYS: &[&str] = &["camera.fov_deg"];

/// Configuration keys added after identities were first written that change the result: they
/// join the identity only when set away from their default (see the module documentation), so
/// the identities of runs made before them are unchanged.
pub const RECORDED_UNLESS_DEFAULT: &[&str] = &["mesh.up", "camera.preset"];

/// Inserts `name = value` into identity `fields` unless `value` is `default` (the rule for new
/// settings of the module documentation). Returns whether it was inserted.
pub fn insert_unless_default<T: PartialEq + std::fmt::Display>(
    fields: &mut BTreeMap<String, String>,
    name: &str,
    value: &T,
    default: &T,
) -> bool {
    if value == default {
        return false;
    }
    fields.insert(name.to_string(), value.to_string());
    true
}

/// Whether a run of `kind` reads the result-changing key `name` (`section.key`): every run reads
/// [`COMMON_SECTIONS`] and [`COMMON_KEYS`], the kind says what else. Presentation keys are read by
/// every run.
fn run_reads(kind: &dyn TaskKind, section: &str, name: &str) -> bool {
    COMMON_SECTIONS.contains(&section) || COMMON_KEYS.contains(&name) || kind.reads(section, name)
}

/// The settings of `config` that differ from their defaults although a run of `kind` never
/// reads them, as `section.key = value` — a `--set optim.iterations=…` on a `--style` run, a
/// negative prompt without a prompt. Presentation and memory keys ([`PRESENTATION_KEYS`]) are not
/// listed.
pub fn unread_settings(config: &Config, kind: &dyn TaskKind) -> Result<Vec<String>> {
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
                || RECORDED_BY_THE_PREPARED_MESH.contains(&name.as_str())
                || run_reads(kind, section, &name)
                || PICTURE_KEYS.contains(&name.as_str())
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
pub fn unread_settings_warning(config: &Config, kind: &dyn TaskKind) -> Result<Option<String>> {
    let unread = unread_settings(config, kind)?;
    if unread.is_empty() {
        return Ok(None);
    }
    Ok(Some(format!(
        "{} {} not used by {}",
        unread.join(", "),
        if unread.len() == 1 { "is" } else { "are" },
        kind.reads_summary()
    )))
}

/// Lower-case hexadecimal of `bytes` (how digests are recorded; [`crate::task::hex`] is the task
/// kinds' own copy, so that `task` needs nothing of this module).
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
    /// The identity of optimizing a task of `kind` on the prepared mesh with `config`.
    fn new(
        positions: &[[f64; 3]],
        faces: &[[u32; 3]],
        kind: &dyn TaskKind,
        config: &Config,
    ) -> Result<Self>;

    /// Adds a localized run's region: its specs, feather rings and resolved weights.
    fn with_region(self, specs: &[String], feather: u32, weights: &[f64]) -> Self;
}

impl TaskIdentityExt for TaskIdentity {
    fn new(
        positions: &[[f64; 3]],
        faces: &[[u32; 3]],
        kind: &dyn TaskKind,
        config: &Config,
    ) -> Result<Self> {
        let mut fields = BTreeMap::new();
        fields.insert("mesh.sha256".to_string(), mesh_sha256(positions, faces));
        fields.insert("mesh.vertices".to_string(), positions.len().to_string());
        fields.insert("mesh.faces".to_string(), faces.len().to_string());
        fields.extend(kind.identity_fields());
        let table = toml::Table::try_from(config)?;
        let defaults = toml::Table::try_from(Config::default())?;
        for (section, keys) in &table {
            let Some(keys) = keys.as_table() else {
                continue;
            };
            if section == "region" {
                // Recorded by `with_region`, only for localized runs.
                continue;
            }
            let default_keys = defaults.get(section).and_then(|d| d.as_table());
            for (key, value) in keys {
                let name = format!("{section}.{key}");
                if PRESENTATION_KEYS.contains(&name.as_str())
                    || RECORDED_BY_THE_PREPARED_MESH.contains(&name.as_str())
                {
                    continue;
                }
                if RECORDED_UNLESS_DEFAULT.contains(&name.as_str())
                    && default_keys.and_then(|d| d.get(key)) == Some(value)
                {
                    continue;
                }
                if run_reads(kind, section, &name) {
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
    use crate::style::Style;
    use crate::task::Prompt;

    fn tri() -> (Vec<[f64; 3]>, Vec<[u32; 3]>) {
        (
            vec![[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]],
            vec![[0, 1, 2]],
        )
    }

    fn id(objective: &dyn TaskKind, config: &Config) -> TaskIdentity {
        let (p, f) = tri();
        TaskIdentity::new(&p, &f, objective, config).unwrap_or_else(|e| panic!("{e:#}"))
    }

    #[test]
    fn devices_and_provider_options_never_change_the_identity() {
        let base = id(&Prompt::new("a cat"), &Config::default());
        let moved = Config::default()
            .with_overrides(&[
                "guidance.stage1_device=cuda:0",
                "guidance.stage2_device=cuda:1",
                "guidance.text_encoder_device=cuda:0",
                "guidance.onnx_io_binding=false",
                "guidance.cuda_conv_search=heuristic",
                "guidance.cuda_arena_growth=same_as_requested",
                "guidance.cuda_memory_limit_gib=20",
                "guidance.cuda_tf32=false",
            ])
            .unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(id(&Prompt::new("a cat"), &moved), base);
        assert_eq!(
            unread_settings(&moved, &Style::Cube).unwrap_or_default(),
            Vec::<String>::new()
        );
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
        let style = unread_settings(&c, &Style::Cube).unwrap_or_default();
        assert_eq!(
            style,
            [
                "guidance.negative_prompt = \"blurry\"",
                "optim.iterations = 2000"
            ]
        );
        let text = unread_settings(&c, &Prompt::new("a cat")).unwrap_or_default();
        assert_eq!(text, ["style.lr = 0.05"]);
        let w = unread_settings_warning(&c, &Style::Cube)
            .ok()
            .flatten()
            .unwrap_or_default();
        assert!(w.contains("are not used by a model-free style run"), "{w}");
        assert!(unread_settings(&Config::default(), &Style::Cube).is_ok_and(|u| u.is_empty()));
        assert!(
            unread_settings(&Config::default(), &Prompt::new("a cat")).is_ok_and(|u| u.is_empty())
        );
        let w = unread_settings_warning(&c, &Prompt::new("a cat"))
            .ok()
            .flatten()
            .unwrap_or_default();
        assert_eq!(
            w,
            "style.lr = 0.05 is not used by a prompt run ([style] is the model-free path's)"
        );
    }

    #[test]
    fn differences_name_each_field_and_presentation_keys_are_ignored() {
        let cube = Style::Cube;
        let octa = Style::Octahedron;
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
        let p = Prompt::new;
        let d = id(&p("a cat"), &base).differences(&id(&p("a dog"), &t));
        assert_eq!(d.len(), 2, "{d:?}");
        assert!(
            d.iter()
                .any(|m| m.contains("\"a cat\"") && m.contains("\"a dog\""))
        );
    }

    /// The identity rule for new settings (module documentation): the fields of a run at the
    /// default configuration are exactly those identities have had so far, so a new key that
    /// would join every identity at its default (refusing to resume every earlier run) fails here.
    /// Such a key belongs in `RECORDED_UNLESS_DEFAULT` (or `PRESENTATION_KEYS` when it does not
    /// change the result).
    #[test]
    fn identity_keys_of_default_runs_are_frozen() {
        let names = |kind: &dyn TaskKind| -> Vec<String> {
            id(kind, &Config::default()).fields.into_keys().collect()
        };
        let common = [
            "mesh.faces",
            "mesh.sha256",
            "mesh.vertices",
            "objective",
            "config.darap.lambda",
            "config.darap.post_process",
            "config.darap.rotation_rule",
            "config.optim.beta1",
            "config.optim.beta2",
            "config.optim.eps",
            "config.run.seed",
        ];
        let sorted = |own: &[&str]| {
            let mut all: Vec<String> = common.iter().chain(own).map(|s| s.to_string()).collect();
            all.sort();
            all
        };
        let style = sorted(&[
            "style",
            "config.style.iterations",
            "config.style.lr",
            "config.style.objective",
        ]);
        assert_eq!(names(&Style::Cube), style);
        let text = sorted(&[
            "prompt",
            "config.camera.adapt_distance",
            "config.camera.azimuth_deg",
            "config.camera.distance",
            "config.camera.elevation_deg",
            "config.camera.fov_deg",
            "config.camera.views",
            "config.guidance.grad_clip",
            "config.guidance.loss_scale",
            "config.guidance.negative_prompt",
            "config.guidance.scale",
            "config.guidance.stage1_weight",
            "config.guidance.stage2_weight",
            "config.guidance.t_max",
            "config.guidance.t_min",
            "config.optim.iterations",
            "config.optim.lr",
            "config.optim.steps_per_batch",
            "config.render.backend",
            "config.render.height",
            "config.render.width",
        ]);
        assert_eq!(names(&Prompt::new("a cat")), text);
    }

    /// `mesh.remesh` acts through the prepared mesh only: never a `config.` field, never an
    /// unread setting, whatever its value and whatever the kind.
    #[test]
    fn the_remesh_setting_is_recorded_by_the_prepared_mesh_only() {
        use crate::remeshing::RemeshSetting;
        for kind in [&Style::Cube as &dyn TaskKind, &Prompt::new("a cat")] {
            let default = id(kind, &Config::default());
            for r in [RemeshSetting::Off, RemeshSetting::On] {
                let mut c = Config::default();
                c.mesh.remesh = r;
                assert_eq!(id(kind, &c), default, "{r}");
                assert_eq!(unread_settings(&c, kind).ok(), Some(Vec::new()), "{r}");
            }
        }
    }

    #[test]
    fn orientation_and_camera_preset_join_only_away_from_their_default_and_the_frame_never() {
        let with = |sets: &[&str]| {
            let c = Config::default()
                .with_overrides(sets)
                .unwrap_or_else(|e| panic!("{e}"));
            (
                id(&Style::Cube, &c).fields,
                id(&Prompt::new("a cat"), &c).fields,
            )
        };
        let (style0, text0) = with(&[]);
        // The output frame is presentation: no identity changes.
        assert_eq!(
            with(&["run.output_frame=normalized"]),
            (style0.clone(), text0.clone())
        );
        // Explicit defaults are absent too.
        assert_eq!(
            with(&["mesh.up=+y", "camera.preset=default"]),
            (style0.clone(), text0.clone())
        );
        let (style, text) = with(&["mesh.up=+z"]);
        for f in [&style, &text] {
            assert_eq!(f.get("config.mesh.up").map(String::as_str), Some("\"+z\""));
        }
        // A resolved preset: recorded for the text path (which reads [camera]), not the style's.
        let (style, text) = with(&["camera.preset=tall"]);
        assert_eq!(style, style0);
        assert_eq!(
            text.get("config.camera.preset").map(String::as_str),
            Some("\"tall\"")
        );
    }

    #[test]
    fn new_settings_join_only_away_from_their_default() {
        let mut fields = BTreeMap::new();
        assert!(!insert_unless_default(
            &mut fields,
            "config.remesh.iterations",
            &0,
            &0
        ));
        assert!(fields.is_empty());
        assert!(insert_unless_default(
            &mut fields,
            "config.remesh.iterations",
            &3,
            &0
        ));
        assert_eq!(
            fields.get("config.remesh.iterations").map(String::as_str),
            Some("3")
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

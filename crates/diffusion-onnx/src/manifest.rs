//! The model directory: `manifest.toml` plus the `.onnx` files (and their external data) it names.
//!
//! Written by `scripts/export_if_onnx.py`; the format is documented in `docs/models.md`.

use std::path::{Path, PathBuf};

use serde::Deserialize;

use crate::npy::read_npy;
use crate::{OnnxError, builtin};

/// The manifest format version this crate reads.
pub const FORMAT_VERSION: u32 = 1;

/// The uncond value that selects IF's shipped empty-prompt T5-v1.1-XXL embedding.
pub const BUILTIN_IF_UNCOND: &str = "builtin:if-t5-v1_1-xxl-empty";
/// The most tokens per prompt a manifest may declare (IF: 77).
pub const MAX_TOKENS: usize = 4096;
/// The widest embedding a manifest may declare (IF: 4096).
pub const MAX_EMBEDDING_DIM: usize = 65_536;
/// The largest native resolution a stage may declare (IF: 64 and 256).
pub const MAX_SAMPLE_SIZE: usize = 4096;
/// The most output channels a stage may declare (IF: 6).
pub const MAX_CHANNELS: usize = 64;
/// The most training timesteps a schedule may declare (IF: 1000).
pub const MAX_TRAIN_TIMESTEPS: usize = 100_000;

/// The tokenizer value that selects the shipped T5 tokenizer.
pub const BUILTIN_T5_TOKENIZER: &str = "builtin:t5";

/// Floating-point type of a model's float inputs and outputs.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Dtype {
    /// IEEE half precision (converted from/to f32 at the session boundary).
    Fp16,
    /// Single precision.
    Fp32,
}

impl Dtype {
    /// The manifest spelling.
    pub fn as_str(self) -> &'static str {
        match self {
            Dtype::Fp16 => "fp16",
            Dtype::Fp32 => "fp32",
        }
    }
}

/// `[text_encoder]`: the T5 encoder (optional: embeddings can come from a cache instead).
#[derive(Clone, Debug, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TextEncoderManifest {
    /// `.onnx` file, relative to the directory.
    pub file: String,
    /// External data files of `file` (relative), required beside it.
    #[serde(default)]
    pub external_data: Vec<String>,
    /// Float type of the output.
    pub dtype: Dtype,
    /// Tokens per prompt (padded/truncated), 77 for IF.
    pub max_tokens: usize,
    /// Width of the output, 4096 for T5-v1.1-XXL.
    pub embedding_dim: usize,
    /// `"builtin:t5"` or a `tokenizers` JSON file in the directory.
    pub tokenizer: String,
    /// Name of the i64 `(B, max_tokens)` token id input.
    pub input_ids: String,
    /// Name of the i64 `(B, max_tokens)` attention mask input (1 = token, 0 = padding).
    pub attention_mask: String,
    /// Name of the `(B, max_tokens, embedding_dim)` output.
    pub output: String,
}

/// `[embeddings]`: the shape of prompt embeddings and the unconditional one.
#[derive(Clone, Debug, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct EmbeddingsManifest {
    /// Embedding width (4096 for IF).
    pub dim: usize,
    /// Tokens (77 for IF).
    pub tokens: usize,
    /// The unconditional (empty-prompt) embedding: a `.npy` file `(tokens, dim)` in the directory, or
    /// [`BUILTIN_IF_UNCOND`] for IF's own shipped vector.
    pub uncond: String,
}

/// `[stageN.scheduler]`: the diffusion schedule the stage was trained with.
#[derive(Clone, Debug, PartialEq, Deserialize)]
pub struct SchedulerManifest {
    /// diffusers class name (`DDPMScheduler`).
    pub name: String,
    /// T (1000).
    pub num_train_timesteps: usize,
    /// `squaredcos_cap_v2` for IF.
    pub beta_schedule: String,
    /// `epsilon` for IF.
    #[serde(default)]
    pub prediction_type: Option<String>,
    /// `learned_range` for IF (the output's extra channels).
    #[serde(default)]
    pub variance_type: Option<String>,
    /// Other recorded values (informational).
    #[serde(default)]
    pub clip_sample: Option<bool>,
    /// Other recorded values (informational).
    #[serde(default)]
    pub thresholding: Option<bool>,
    /// Only for linear schedules (informational).
    #[serde(default)]
    pub beta_start: Option<f64>,
    /// Only for linear schedules (informational).
    #[serde(default)]
    pub beta_end: Option<f64>,
}

/// `[stage1]` / `[stage2]`: one UNet.
#[derive(Clone, Debug, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct StageManifest {
    /// `.onnx` file, relative to the directory.
    pub file: String,
    /// External data files of `file` (relative), required beside it.
    #[serde(default)]
    pub external_data: Vec<String>,
    /// Float type of `sample`, `encoder_hidden_states` and the output.
    pub dtype: Dtype,
    /// Input channels (IF-I: 3; IF-II: 6 = noisy image ++ noised upsampled low-res).
    pub in_channels: usize,
    /// Output channels (IF: 6 = ε ++ learned variance).
    pub out_channels: usize,
    /// Native resolution (IF-I 64, IF-II 256).
    pub sample_size: usize,
    /// Name of the `(N, in_channels, H, W)` input.
    pub sample: String,
    /// Name of the i64 `(N,)` timestep input.
    pub timestep: String,
    /// Name of the `(N, tokens, dim)` text input.
    pub encoder_hidden_states: String,
    /// Name of the i64 `(N,)` noise-level input (stage II only).
    #[serde(default)]
    pub class_labels: Option<String>,
    /// Name of the `(N, out_channels, H, W)` output.
    pub output: String,
    /// The training schedule.
    pub scheduler: SchedulerManifest,
    /// Stage II: the schedule used to noise the upsampled low-resolution image.
    #[serde(default)]
    pub noising_scheduler: Option<SchedulerManifest>,
}

/// The whole `manifest.toml`.
#[derive(Clone, Debug, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Manifest {
    /// Must be [`FORMAT_VERSION`].
    pub format_version: u32,
    /// Model identity (part of the embedding cache key).
    pub name: String,
    /// Free text.
    #[serde(default)]
    pub description: Option<String>,
    /// The T5 encoder, if exported.
    #[serde(default)]
    pub text_encoder: Option<TextEncoderManifest>,
    /// Embedding shape and the unconditional embedding.
    pub embeddings: EmbeddingsManifest,
    /// IF stage I.
    pub stage1: StageManifest,
    /// IF stage II, if exported.
    #[serde(default)]
    pub stage2: Option<StageManifest>,
}

/// Which UNet.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Stage {
    /// IF stage I (64 px).
    One,
    /// IF stage II (256 px super-resolution, noise-level class label).
    Two,
}

impl Stage {
    /// `"stage1"` / `"stage2"`, as in the manifest.
    pub fn key(self) -> &'static str {
        match self {
            Stage::One => "stage1",
            Stage::Two => "stage2",
        }
    }
}

/// The largest `manifest.toml` read (ours are ~2 KiB).
pub const MAX_MANIFEST_BYTES: u64 = 1 << 20;

/// Reads a manifest as text: a regular file (after links) of at most [`MAX_MANIFEST_BYTES`], a
/// leading UTF-8 byte-order mark dropped.
pub(crate) fn read_bounded(path: &Path) -> std::io::Result<String> {
    use std::io::Read;
    let file = std::fs::File::open(path)?;
    let meta = file.metadata()?;
    if !meta.is_file() {
        return Err(std::io::Error::other("not a regular file"));
    }
    let mut bytes = Vec::new();
    file.take(MAX_MANIFEST_BYTES + 1).read_to_end(&mut bytes)?;
    if bytes.len() as u64 > MAX_MANIFEST_BYTES {
        return Err(std::io::Error::other(format!(
            "larger than {MAX_MANIFEST_BYTES} bytes, which no manifest is"
        )));
    }
    let text = String::from_utf8(bytes)
        .map_err(|e| std::io::Error::new(std::io::ErrorKind::InvalidData, e))?;
    Ok(match text.strip_prefix('\u{feff}') {
        Some(rest) => rest.to_string(),
        None => text,
    })
}

/// A validated model directory.
#[derive(Clone, Debug)]
pub struct ModelDir {
    root: PathBuf,
    manifest: Manifest,
}

impl ModelDir {
    /// Reads `<dir>/manifest.toml` and checks that it is complete and consistent and that every file
    /// it names (models, external data, tokenizer, uncond embedding) exists.
    pub fn open(dir: impl AsRef<Path>) -> Result<Self, OnnxError> {
        let root = dir.as_ref().to_path_buf();
        let err = |message: String| OnnxError::Manifest {
            dir: root.clone(),
            message,
        };
        if !root.is_dir() {
            return Err(err(
                "is not a directory; pass the folder written by scripts/export_if_onnx.py".into(),
            ));
        }
        let path = root.join("manifest.toml");
        let text = read_bounded(&path).map_err(|e| {
            err(format!(
                "cannot read manifest.toml ({e}); a model directory is made by scripts/export_if_onnx.py (see docs/models.md)"
            ))
        })?;
        let manifest: Manifest =
            toml::from_str(&text).map_err(|e| err(format!("manifest.toml is invalid: {e}")))?;
        let dir = Self { root, manifest };
        dir.validate()?;
        Ok(dir)
    }

    /// The directory.
    pub fn root(&self) -> &Path {
        &self.root
    }

    /// The parsed manifest.
    pub fn manifest(&self) -> &Manifest {
        &self.manifest
    }

    /// The manifest of one stage (None for a missing stage II).
    pub fn stage(&self, stage: Stage) -> Option<&StageManifest> {
        match stage {
            Stage::One => Some(&self.manifest.stage1),
            Stage::Two => self.manifest.stage2.as_ref(),
        }
    }

    /// The bytes of one stage's files (the `.onnx` and its external data) as they are on disk: about
    /// the weights' size. None for a missing stage; an unreadable file counts 0 (opening the session
    /// reports it).
    pub fn weight_bytes(&self, stage: Stage) -> Option<u64> {
        let s = self.stage(stage)?;
        Some(
            std::iter::once(&s.file)
                .chain(&s.external_data)
                .filter_map(|f| std::fs::metadata(self.path_of(f)).ok())
                .map(|m| m.len())
                .sum(),
        )
    }

    /// About how many parameters one stage's UNet has: [`Self::weight_bytes`] over the size of the
    /// manifest's float type (the graph itself is small next to the weights).
    pub fn approx_parameters(&self, stage: Stage) -> Option<u64> {
        let s = self.stage(stage)?;
        let per = match s.dtype {
            Dtype::Fp16 => 2,
            Dtype::Fp32 => 4,
        };
        Some(self.weight_bytes(stage)? / per)
    }

    /// Absolute path of a file named in the manifest.
    pub fn path_of(&self, file: &str) -> PathBuf {
        self.root.join(file)
    }

    /// The name part of the text encoder's identity for the embedding cache: the manifest `name` and
    /// the embedding shape. [`EmbeddingCache::identity`](crate::EmbeddingCache::identity) adds the
    /// digest of the encoder's files, so replaced weights under the same name are never mixed up.
    pub fn text_identity(&self) -> String {
        let m = &self.manifest;
        format!("{}|{}x{}", m.name, m.embeddings.tokens, m.embeddings.dim)
    }

    /// The files whose bytes determine the text encoder's output, as `(declared name, path)`: the
    /// `.onnx`, its external data and a tokenizer file (not the built-in tokenizer). None without
    /// `[text_encoder]`.
    pub fn text_encoder_files(&self) -> Option<Vec<(String, PathBuf)>> {
        let t = self.manifest.text_encoder.as_ref()?;
        let mut files: Vec<(String, PathBuf)> = std::iter::once(&t.file)
            .chain(&t.external_data)
            .map(|f| (f.clone(), self.path_of(f)))
            .collect();
        if t.tokenizer != BUILTIN_T5_TOKENIZER {
            files.push((t.tokenizer.clone(), self.path_of(&t.tokenizer)));
        }
        Some(files)
    }

    /// The unconditional (empty-prompt) embedding `(tokens, dim)`.
    pub fn uncond_embedding(&self) -> Result<csd::Embedding, OnnxError> {
        let e = &self.manifest.embeddings;
        if e.uncond == BUILTIN_IF_UNCOND {
            return builtin::if_empty_prompt_embedding();
        }
        let path = self.path_of(&e.uncond);
        let arr = read_npy(&path)?;
        let data = arr.to_f32().ok_or_else(|| OnnxError::Npy {
            path: path.clone(),
            message: "the unconditional embedding must be float (f16 or f32)".into(),
        })?;
        let shape = match arr.shape.as_slice() {
            [t, d] => [*t, *d],
            [1, t, d] => [*t, *d],
            s => {
                return Err(OnnxError::Npy {
                    path,
                    message: format!("expected shape ({}, {}), found {s:?}", e.tokens, e.dim),
                });
            }
        };
        if shape != [e.tokens, e.dim] {
            return Err(OnnxError::Npy {
                path,
                message: format!("expected shape ({}, {}), found {shape:?}", e.tokens, e.dim),
            });
        }
        OnnxError::check_finite(
            &data,
            || "the unconditional (empty-prompt) embedding".into(),
            &path,
            "re-export it with scripts/export_if_onnx.py (an fp16 encoder can overflow; use --dtype fp32), or \
             use uncond = \"builtin:if-t5-v1_1-xxl-empty\" for the real IF model",
        )?;
        Ok(csd::Embedding { shape, data })
    }

    fn require_file(&self, what: &str, file: &str, hint: &str) -> Result<(), OnnxError> {
        let err = |message: String| OnnxError::Manifest {
            dir: self.root.clone(),
            message,
        };
        if file.is_empty() {
            return Err(err(format!("{what}: the file name is empty")));
        }
        let rel = Path::new(file);
        if rel.is_absolute()
            || rel
                .components()
                .any(|c| matches!(c, std::path::Component::ParentDir))
        {
            return Err(err(format!(
                "{what} `{file}` must be a path inside the model directory"
            )));
        }
        let path = self.path_of(file);
        if !path.is_file() {
            return Err(OnnxError::MissingFile {
                dir: self.root.clone(),
                what: what.to_string(),
                file: file.to_string(),
                path,
                hint: hint.to_string(),
            });
        }
        Ok(())
    }

    fn validate(&self) -> Result<(), OnnxError> {
        let m = &self.manifest;
        let err = |message: String| {
            Err(OnnxError::Manifest {
                dir: self.root.clone(),
                message,
            })
        };
        if m.format_version != FORMAT_VERSION {
            return err(format!(
                "format_version = {} but this program reads version {FORMAT_VERSION}; re-export with this \
                 repository's scripts/export_if_onnx.py",
                m.format_version
            ));
        }
        if m.name.trim().is_empty() {
            return err(
                "`name` must not be empty (it identifies the model in the embedding cache)".into(),
            );
        }
        let e = &m.embeddings;
        if e.dim == 0 || e.tokens == 0 {
            return err(format!(
                "[embeddings] dim = {} and tokens = {} must be positive",
                e.dim, e.tokens
            ));
        }
        // Sizes from the file size buffers (embeddings, token ids, schedules, images): each is
        // bounded by what a model of this kind can be, so a typo cannot demand gigabytes.
        if e.tokens > MAX_TOKENS || e.dim > MAX_EMBEDDING_DIM {
            return err(format!(
                "[embeddings] tokens = {} and dim = {} must be at most {MAX_TOKENS} and \
                 {MAX_EMBEDDING_DIM} (IF: 77 and 4096)",
                e.tokens, e.dim
            ));
        }
        if let Some(t) = &m.text_encoder
            && (t.max_tokens > MAX_TOKENS || t.embedding_dim > MAX_EMBEDDING_DIM)
        {
            return err(format!(
                "[text_encoder] max_tokens = {} and embedding_dim = {} must be at most \
                 {MAX_TOKENS} and {MAX_EMBEDDING_DIM} (IF: 77 and 4096)",
                t.max_tokens, t.embedding_dim
            ));
        }
        for stage in [Stage::One, Stage::Two] {
            let Some(s) = self.stage(stage) else { continue };
            let key = stage.key();
            if !(1..=MAX_SAMPLE_SIZE).contains(&s.sample_size) {
                return err(format!(
                    "[{key}] sample_size = {} must be within 1..={MAX_SAMPLE_SIZE} (IF: 64 and 256)",
                    s.sample_size
                ));
            }
            if s.out_channels > MAX_CHANNELS {
                return err(format!(
                    "[{key}] out_channels = {} must be at most {MAX_CHANNELS} (IF: 6)",
                    s.out_channels
                ));
            }
            for (which, sch) in [
                ("scheduler", Some(&s.scheduler)),
                ("noising_scheduler", s.noising_scheduler.as_ref()),
            ] {
                if let Some(sch) = sch
                    && !(1..=MAX_TRAIN_TIMESTEPS).contains(&sch.num_train_timesteps)
                {
                    return err(format!(
                        "[{key}.{which}] num_train_timesteps = {} must be within \
                         1..={MAX_TRAIN_TIMESTEPS} (IF: 1000)",
                        sch.num_train_timesteps
                    ));
                }
            }
        }
        if e.uncond == BUILTIN_IF_UNCOND {
            if (e.tokens, e.dim) != (builtin::IF_UNCOND_TOKENS, builtin::IF_UNCOND_DIM) {
                return err(format!(
                    "[embeddings] uncond = \"{BUILTIN_IF_UNCOND}\" is IF's ({}, {}) T5-v1.1-XXL vector, but this \
                     model's embeddings are ({}, {}); export an uncond_embedding.npy for this encoder",
                    builtin::IF_UNCOND_TOKENS,
                    builtin::IF_UNCOND_DIM,
                    e.tokens,
                    e.dim
                ));
            }
        } else {
            self.require_file(
                "unconditional embedding",
                &e.uncond,
                "it is written by scripts/export_if_onnx.py next to manifest.toml",
            )?;
        }
        let model_hint = "copy the whole directory written by scripts/export_if_onnx.py";
        let data_hint = "models over 2 GB keep their weights in ONNX external data beside the .onnx; copy \
                         those files along with the .onnx";
        if let Some(t) = &m.text_encoder {
            self.require_file("text encoder model", &t.file, model_hint)?;
            for f in &t.external_data {
                self.require_file("text encoder external data", f, data_hint)?;
            }
            if t.embedding_dim != e.dim || t.max_tokens != e.tokens {
                return err(format!(
                    "[text_encoder] gives ({}, {}) embeddings but [embeddings] says ({}, {})",
                    t.max_tokens, t.embedding_dim, e.tokens, e.dim
                ));
            }
            if t.tokenizer != BUILTIN_T5_TOKENIZER {
                self.require_file(
                    "tokenizer",
                    &t.tokenizer,
                    "name a tokenizers JSON file or use \"builtin:t5\"",
                )?;
            }
            Self::distinct_names(
                "text_encoder",
                &[&t.input_ids, &t.attention_mask, &t.output],
            )
            .or_else(&err)?;
        }
        for stage in [Stage::One, Stage::Two] {
            let Some(s) = self.stage(stage) else { continue };
            let key = stage.key();
            self.require_file(&format!("{key} model"), &s.file, model_hint)?;
            for f in &s.external_data {
                self.require_file(&format!("{key} external data"), f, data_hint)?;
            }
            let (want_in, label) = match stage {
                Stage::One => (3, false),
                Stage::Two => (6, true),
            };
            if s.in_channels != want_in {
                return err(format!(
                    "[{key}] in_channels = {} but IF's {key} takes {want_in}",
                    s.in_channels
                ));
            }
            if s.out_channels < 3 {
                return err(format!(
                    "[{key}] out_channels = {} but ε needs at least 3",
                    s.out_channels
                ));
            }
            if s.class_labels.is_some() != label {
                return err(if label {
                    "[stage2] must name its noise-level input: class_labels = \"…\"".into()
                } else {
                    "[stage1] takes no class_labels (only IF stage II has a noise-level input)"
                        .into()
                });
            }
            let mut names = vec![
                s.sample.as_str(),
                &s.timestep,
                &s.encoder_hidden_states,
                &s.output,
            ];
            if let Some(c) = &s.class_labels {
                names.push(c);
            }
            Self::distinct_names(key, &names).or_else(&err)?;
            for (which, sch) in std::iter::once(("scheduler", &s.scheduler))
                .chain(s.noising_scheduler.iter().map(|n| ("noising_scheduler", n)))
            {
                if sch.beta_schedule != "squaredcos_cap_v2" || sch.num_train_timesteps == 0 {
                    return err(format!(
                        "[{key}.{which}] beta_schedule = \"{}\" with {} steps: only DeepFloyd IF's \"squaredcos_cap_v2\" \
                         is implemented",
                        sch.beta_schedule, sch.num_train_timesteps
                    ));
                }
                if let Some(p) = &sch.prediction_type
                    && p != "epsilon"
                {
                    return err(format!(
                        "[{key}.{which}] prediction_type = \"{p}\": only \"epsilon\" is supported"
                    ));
                }
            }
        }
        Ok(())
    }

    fn distinct_names(section: &str, names: &[&str]) -> Result<(), String> {
        for (i, a) in names.iter().enumerate() {
            if a.is_empty() {
                return Err(format!("[{section}] has an empty input/output name"));
            }
            if names[..i].contains(a) {
                return Err(format!("[{section}] uses the name `{a}` twice"));
            }
        }
        Ok(())
    }
}

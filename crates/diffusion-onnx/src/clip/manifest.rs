//! The CLIP model directory's `manifest.toml` (format in `docs/models.md`, section "CLIP"): reading,
//! validation, and the SHA-256 of the files it names.

use std::io::Read;
use std::path::Path;

use serde::Deserialize;
use sha2::{Digest, Sha256};

use super::BUILTIN_CLIP_TOKENIZER;
use crate::OnnxError;

/// The CLIP manifest format version this crate reads.
pub const CLIP_FORMAT_VERSION: u32 = 1;

/// `[image_encoder]` of a CLIP manifest.
#[derive(Clone, Debug, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ClipImageManifest {
    /// `.onnx` file, relative to the directory.
    pub file: String,
    /// Lower-case hex SHA-256 of `file`, checked on open.
    pub sha256: String,
    /// Name of the f32 `[B, 3, S, S]` input.
    pub input: String,
    /// Name of the f32 `[B, D]` output.
    pub output: String,
    /// S, the side the images are resized to (224 for ViT-B/16).
    pub image_size: usize,
    /// Per-channel mean subtracted after resizing (RGB).
    pub mean: [f32; 3],
    /// Per-channel standard deviation divided by after subtracting the mean (RGB).
    pub std: [f32; 3],
}

/// `[text_encoder]` of a CLIP manifest.
#[derive(Clone, Debug, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ClipTextManifest {
    /// `.onnx` file, relative to the directory.
    pub file: String,
    /// Lower-case hex SHA-256 of `file`, checked on open.
    pub sha256: String,
    /// Name of the i64 `[B, context_length]` input.
    pub input_ids: String,
    /// Name of the f32 `[B, D]` output.
    pub output: String,
    /// `"builtin:clip"` or a `tokenizers` JSON file in the directory.
    pub tokenizer: String,
    /// Tokens per prompt (77).
    pub context_length: usize,
    /// `<|startoftext|>` (49406).
    pub bos_id: i64,
    /// `<|endoftext|>` (49407).
    pub eos_id: i64,
    /// Padding after the end-of-text token (49407).
    pub pad_id: i64,
}

/// The whole CLIP `manifest.toml`.
#[derive(Clone, Debug, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ClipManifest {
    /// Must be [`CLIP_FORMAT_VERSION`].
    pub format_version: u32,
    /// Model identity.
    pub name: String,
    /// Free text.
    #[serde(default)]
    pub description: Option<String>,
    /// D, the width of both embeddings (512 for ViT-B/16).
    pub embedding_dim: usize,
    /// The image encoder.
    pub image_encoder: ClipImageManifest,
    /// The text encoder.
    pub text_encoder: ClipTextManifest,
}

/// Lower-case hex SHA-256 of a file.
pub fn sha256_file(path: &Path) -> Result<String, OnnxError> {
    let mut f = std::fs::File::open(path).map_err(|e| OnnxError::io(path, e))?;
    let mut h = Sha256::new();
    let mut buf = vec![0u8; 1 << 20];
    loop {
        let n = f.read(&mut buf).map_err(|e| OnnxError::io(path, e))?;
        if n == 0 {
            break;
        }
        h.update(&buf[..n]);
    }
    Ok(h.finalize().iter().map(|b| format!("{b:02x}")).collect())
}

/// Reads and validates `<dir>/manifest.toml` without opening any session: the format version,
/// positive sizes, file names inside the directory, every named file present with the recorded
/// SHA-256.
pub fn read_clip_manifest(dir: &Path) -> Result<ClipManifest, OnnxError> {
    let err = |message: String| OnnxError::Manifest {
        dir: dir.to_path_buf(),
        message,
    };
    if !dir.is_dir() {
        return Err(err(
            "is not a directory; pass the folder written by scripts/export_clip_onnx.py".into(),
        ));
    }
    let text = crate::manifest::read_bounded(&dir.join("manifest.toml")).map_err(|e| {
        err(format!(
            "cannot read manifest.toml ({e}); a CLIP model directory is made by scripts/export_clip_onnx.py \
             (see docs/models.md, \"CLIP\")"
        ))
    })?;
    let m: ClipManifest = toml::from_str(&text).map_err(|e| {
        err(format!(
            "manifest.toml is not a CLIP manifest: {e} (a DeepFloyd IF directory is not a CLIP model; \
             see docs/models.md, \"CLIP\")"
        ))
    })?;
    if m.format_version != CLIP_FORMAT_VERSION {
        return Err(err(format!(
            "format_version = {} but this program reads CLIP manifests of version {CLIP_FORMAT_VERSION}; \
             re-export with this repository's scripts/export_clip_onnx.py",
            m.format_version
        )));
    }
    let (i, t) = (&m.image_encoder, &m.text_encoder);
    if m.embedding_dim == 0 || i.image_size == 0 || t.context_length < 2 {
        return Err(err(format!(
            "embedding_dim = {}, [image_encoder] image_size = {} must be positive and [text_encoder] \
             context_length = {} at least 2",
            m.embedding_dim, i.image_size, t.context_length
        )));
    }
    if i.image_size > crate::manifest::MAX_SAMPLE_SIZE
        || t.context_length > crate::manifest::MAX_TOKENS
        || m.embedding_dim > crate::manifest::MAX_EMBEDDING_DIM
    {
        return Err(err(format!(
            "embedding_dim = {}, [image_encoder] image_size = {} and [text_encoder] context_length \
             = {} must be at most {}, {} and {} (ViT-B/16: 512, 224 and 77)",
            m.embedding_dim,
            i.image_size,
            t.context_length,
            crate::manifest::MAX_EMBEDDING_DIM,
            crate::manifest::MAX_SAMPLE_SIZE,
            crate::manifest::MAX_TOKENS
        )));
    }
    if i.std.iter().any(|s| !(s.is_finite() && *s > 0.0)) || i.mean.iter().any(|v| !v.is_finite()) {
        return Err(err(format!(
            "[image_encoder] std = {:?} must be positive and mean = {:?} finite",
            i.std, i.mean
        )));
    }
    let mut files = vec![
        ("image encoder model", &i.file, Some(&i.sha256)),
        ("text encoder model", &t.file, Some(&t.sha256)),
    ];
    if t.tokenizer != BUILTIN_CLIP_TOKENIZER {
        files.push(("tokenizer", &t.tokenizer, None));
    }
    for (what, file, sha) in files {
        let rel = Path::new(file.as_str());
        if file.is_empty()
            || rel.is_absolute()
            || rel
                .components()
                .any(|c| matches!(c, std::path::Component::ParentDir))
        {
            return Err(err(format!(
                "{what} `{file}` must be a file name inside the model directory"
            )));
        }
        let path = dir.join(rel);
        if !path.is_file() {
            return Err(OnnxError::MissingFile {
                dir: dir.to_path_buf(),
                what: what.to_string(),
                file: file.clone(),
                path,
                hint: "copy the whole directory written by scripts/export_clip_onnx.py".into(),
            });
        }
        if let Some(want) = sha {
            let got = sha256_file(&path)?;
            if !got.eq_ignore_ascii_case(want.trim()) {
                return Err(err(format!(
                    "{what} `{file}` has SHA-256 {got} but the manifest records {want}: the file is damaged \
                     or belongs to another export; copy it again or re-export"
                )));
            }
        }
    }
    Ok(m)
}

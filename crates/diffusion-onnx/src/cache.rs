//! On-disk cache of prompt embeddings, so the (4.7 B-parameter) T5 encoder runs once per prompt and
//! never during optimization.
//!
//! Layout: `<dir>/<key>.npy`, f32 `(tokens, dim)`, where `key` is the hex SHA-256 of
//! `"stylize-embedding-v1\0" + model identity + "\0" + preprocessed prompt` (lower-cased, stripped:
//! prompts that tokenize the same share an entry). The model identity ([`EmbeddingCache::identity`])
//! is the manifest `name`, the embedding shape **and the SHA-256 of the text encoder's files** (the
//! `.onnx`, its external data, a tokenizer file), so replacing the encoder's weights under the same
//! name never serves the old encoder's embeddings. Files are written atomically.
//!
//! `<dir>/encoders/` holds two kinds of small files:
//! - `file-<sha256(absolute path)>.txt`: a file's digest memoized with its device, inode, size,
//!   mtime and ctime, so a 9.5 GB encoder is hashed once, not on every run (any write, copy over or
//!   rename changes one of those and the file is hashed again);
//! - `latest-<sha256(name|shape)>.txt`: the encoder digest last seen under a model name. A model
//!   directory exported without its encoder (`--skip-text-encoder`) has nothing to hash and uses
//!   this digest, i.e. the embeddings of the encoder most recently used under its name in this cache.

use std::io::Read;
use std::path::{Path, PathBuf};

use sha2::{Digest, Sha256};

use crate::npy::{NpyArray, NpyData, read_npy, write_npy};
use crate::tokenizer::T5Tokenizer;
use crate::{ModelDir, OnnxError, SessionOptions, T5Encoder};

/// Environment variable overriding the default cache directory.
pub const CACHE_ENV: &str = "STYLIZE_EMBEDDING_CACHE";

/// A directory of cached embeddings.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct EmbeddingCache {
    dir: PathBuf,
}

impl EmbeddingCache {
    /// A cache in `dir` (created on first write).
    pub fn new(dir: impl Into<PathBuf>) -> Self {
        Self { dir: dir.into() }
    }

    /// `$STYLIZE_EMBEDDING_CACHE`, else `$XDG_CACHE_HOME/stylize/embeddings`, else
    /// `$HOME/.cache/stylize/embeddings`.
    pub fn default_dir() -> Result<PathBuf, OnnxError> {
        let non_empty = |k: &str| {
            std::env::var_os(k)
                .filter(|v| !v.is_empty())
                .map(PathBuf::from)
        };
        if let Some(d) = non_empty(CACHE_ENV) {
            return Ok(d);
        }
        if let Some(d) = non_empty("XDG_CACHE_HOME") {
            return Ok(d.join("stylize").join("embeddings"));
        }
        if let Some(h) = non_empty("HOME") {
            return Ok(h.join(".cache").join("stylize").join("embeddings"));
        }
        Err(OnnxError::Cache(format!(
            "no cache directory: set {CACHE_ENV} or XDG_CACHE_HOME (or HOME), or pass --cache DIR"
        )))
    }

    /// The cache at [`Self::default_dir`].
    pub fn at_default() -> Result<Self, OnnxError> {
        Ok(Self::new(Self::default_dir()?))
    }

    /// The directory.
    pub fn dir(&self) -> &Path {
        &self.dir
    }

    /// The identity of `model`'s text encoder for cache keys:
    /// `"<name>|<tokens>x<dim>|encoder-sha256:<digest>"`, the digest over the encoder's files (see
    /// the module docs). A directory without `[text_encoder]` takes the digest last recorded under
    /// its name in this cache (`encoder-sha256:unknown` when there is none: every lookup misses).
    pub fn identity(&self, model: &ModelDir) -> Result<String, OnnxError> {
        let base = model.text_identity();
        let latest = self
            .encoders_dir()
            .join(format!("latest-{}.txt", hex_sha256(base.as_bytes())));
        let digest = match model.text_encoder_files() {
            Some(files) => {
                let digest = self.files_digest(&files)?;
                // Best effort: a read-only cache still works, only the lean-directory lookup misses.
                if std::fs::read_to_string(&latest).ok().as_deref() != Some(digest.as_str()) {
                    let _ = std::fs::create_dir_all(self.encoders_dir())
                        .and_then(|()| write_atomic(&latest, digest.as_bytes()));
                }
                digest
            }
            None => std::fs::read_to_string(&latest)
                .ok()
                .map(|s| s.trim().to_string())
                .filter(|s| s.len() == 64 && s.bytes().all(|b| b.is_ascii_hexdigit()))
                .unwrap_or_else(|| "unknown".into()),
        };
        Ok(format!("{base}|encoder-sha256:{digest}"))
    }

    fn encoders_dir(&self) -> PathBuf {
        self.dir.join("encoders")
    }

    /// SHA-256 over `(declared name, SHA-256 of contents)` of each file, in order.
    fn files_digest(&self, files: &[(String, PathBuf)]) -> Result<String, OnnxError> {
        let mut h = Sha256::new();
        h.update(b"stylize-encoder-v1\0");
        for (name, path) in files {
            h.update(name.as_bytes());
            h.update(b"\0");
            h.update(self.file_digest(path)?.as_bytes());
            h.update(b"\0");
        }
        Ok(hex(&h.finalize()))
    }

    /// The SHA-256 of a file's contents, memoized under `encoders/` by (device, inode, size, mtime, ctime).
    fn file_digest(&self, path: &Path) -> Result<String, OnnxError> {
        let meta = std::fs::metadata(path).map_err(|e| OnnxError::io(path, e))?;
        let absolute = std::fs::canonicalize(path).map_err(|e| OnnxError::io(path, e))?;
        let memo = self.encoders_dir().join(format!(
            "file-{}.txt",
            hex_sha256(absolute.as_os_str().as_encoded_bytes())
        ));
        let stamp = file_stamp(&meta);
        if let Ok(text) = std::fs::read_to_string(&memo)
            && let Some((s, d)) = text.trim().rsplit_once(' ')
            && s == stamp
            && d.len() == 64
        {
            return Ok(d.to_string());
        }
        let mut file = std::fs::File::open(path).map_err(|e| OnnxError::io(path, e))?;
        let mut h = Sha256::new();
        let mut buf = vec![0u8; 1 << 20];
        loop {
            let n = file.read(&mut buf).map_err(|e| OnnxError::io(path, e))?;
            if n == 0 {
                break;
            }
            h.update(&buf[..n]);
        }
        let digest = hex(&h.finalize());
        // Best effort, as for `latest-*`: without the memo the file is hashed again next time.
        let _ = std::fs::create_dir_all(self.encoders_dir())
            .and_then(|()| write_atomic(&memo, format!("{stamp} {digest}\n").as_bytes()));
        Ok(digest)
    }

    /// The cache key of a prompt for a model identity ([`Self::identity`]).
    pub fn key(model_identity: &str, prompt: &str) -> String {
        let mut h = Sha256::new();
        h.update(b"stylize-embedding-v1\0");
        h.update(model_identity.as_bytes());
        h.update(b"\0");
        h.update(T5Tokenizer::preprocess(prompt).as_bytes());
        hex(&h.finalize())
    }

    /// The file an entry lives in.
    pub fn path(&self, model_identity: &str, prompt: &str) -> PathBuf {
        self.dir
            .join(format!("{}.npy", Self::key(model_identity, prompt)))
    }

    /// A cached embedding, if present. A present but unreadable entry is an error (delete it to
    /// recompute).
    pub fn get(
        &self,
        model_identity: &str,
        prompt: &str,
    ) -> Result<Option<csd::Embedding>, OnnxError> {
        let path = self.path(model_identity, prompt);
        if !path.is_file() {
            return Ok(None);
        }
        let arr = read_npy(&path)?;
        let (Some(data), [t, d]) = (arr.to_f32(), arr.shape.as_slice()) else {
            return Err(OnnxError::Cache(format!(
                "{} is not a (tokens, dim) float array; delete it to recompute",
                path.display()
            )));
        };
        OnnxError::check_finite(
            &data,
            || format!("the cached embedding of the prompt {prompt:?}"),
            &path,
            "delete the file to recompute it (an fp16 text encoder can overflow; an fp32 export does not)",
        )?;
        Ok(Some(csd::Embedding {
            shape: [*t, *d],
            data,
        }))
    }

    /// Stores an embedding.
    pub fn put(
        &self,
        model_identity: &str,
        prompt: &str,
        embedding: &csd::Embedding,
    ) -> Result<PathBuf, OnnxError> {
        let [t, d] = embedding.shape;
        if embedding.data.len() != t * d {
            return Err(OnnxError::Cache(format!(
                "embedding of shape {:?} has {} values",
                embedding.shape,
                embedding.data.len()
            )));
        }
        std::fs::create_dir_all(&self.dir).map_err(|e| OnnxError::io(&self.dir, e))?;
        let path = self.path(model_identity, prompt);
        write_npy(
            &path,
            &NpyArray {
                shape: vec![t, d],
                data: NpyData::F32(embedding.data.clone()),
            },
        )?;
        Ok(path)
    }
}

/// Prompt embeddings for guidance: `(cond, uncond)`.
///
/// The empty negative prompt uses the model's unconditional embedding (IF's shipped vector for the
/// real model). Other prompts come from the cache when present; otherwise the text encoder is opened
/// (once) and the result is stored in the cache when one is given.
pub fn prompt_embeddings(
    model: &ModelDir,
    prompt: &str,
    negative_prompt: &str,
    cache: Option<&EmbeddingCache>,
    options: &SessionOptions,
) -> Result<(csd::Embedding, csd::Embedding), OnnxError> {
    let mut identity: Option<String> = None;
    let mut encoder: Option<T5Encoder> = None;
    let mut one = |p: &str| -> Result<csd::Embedding, OnnxError> {
        if T5Tokenizer::preprocess(p).is_empty() {
            return model.uncond_embedding();
        }
        let Some(c) = cache else {
            return encode(&mut encoder, model, options, p);
        };
        if identity.is_none() {
            identity = Some(c.identity(model)?);
        }
        let identity = identity.as_deref().unwrap_or_default();
        if let Some(e) = c.get(identity, p)? {
            let want = [
                model.manifest().embeddings.tokens,
                model.manifest().embeddings.dim,
            ];
            if e.shape == want {
                return Ok(e);
            }
            return Err(OnnxError::Cache(format!(
                "{} has shape {:?} but this model's embeddings are {want:?}; delete it to recompute",
                c.path(identity, p).display(),
                e.shape
            )));
        }
        let e = encode(&mut encoder, model, options, p)?;
        c.put(identity, p, &e)?;
        Ok(e)
    };
    let cond = one(prompt)?;
    let uncond = one(negative_prompt)?;
    Ok((cond, uncond))
}

/// Encodes one prompt, opening the encoder on first use.
fn encode(
    encoder: &mut Option<T5Encoder>,
    model: &ModelDir,
    options: &SessionOptions,
    prompt: &str,
) -> Result<csd::Embedding, OnnxError> {
    if encoder.is_none() {
        *encoder = Some(T5Encoder::open(model, options)?);
    }
    let enc = encoder
        .as_mut()
        .ok_or_else(|| OnnxError::Cache("text encoder unavailable".into()))?;
    enc.embed_batch(&[prompt])?
        .pop()
        .ok_or_else(|| OnnxError::Cache("the text encoder returned nothing".into()))
}

fn hex(bytes: &[u8]) -> String {
    bytes.iter().map(|b| format!("{b:02x}")).collect()
}

fn hex_sha256(bytes: &[u8]) -> String {
    hex(&Sha256::digest(bytes))
}

/// What identifies a file's version without reading it: size and mtime everywhere, plus device,
/// inode and ctime on Unix (ctime changes on every write and rename and cannot be set back).
fn file_stamp(meta: &std::fs::Metadata) -> String {
    let mtime = meta
        .modified()
        .ok()
        .and_then(|t| t.duration_since(std::time::UNIX_EPOCH).ok())
        .map_or(0, |d| d.as_nanos());
    #[cfg(unix)]
    {
        use std::os::unix::fs::MetadataExt;
        format!(
            "dev{}-ino{}-len{}-mtime{mtime}-ctime{}.{}",
            meta.dev(),
            meta.ino(),
            meta.len(),
            meta.ctime(),
            meta.ctime_nsec()
        )
    }
    #[cfg(not(unix))]
    {
        format!("len{}-mtime{mtime}", meta.len())
    }
}

/// Writes a small file atomically (temporary name with the pid, then rename).
fn write_atomic(path: &Path, bytes: &[u8]) -> std::io::Result<()> {
    let tmp = path.with_extension(format!("tmp{}", std::process::id()));
    std::fs::write(&tmp, bytes)
        .and_then(|()| std::fs::rename(&tmp, path))
        .inspect_err(|_| {
            let _ = std::fs::remove_file(&tmp);
        })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cache_round_trips_an_embedding_exactly() {
        let dir = tempfile::tempdir().expect("tempdir");
        let cache = EmbeddingCache::new(dir.path().join("nested").join("cache"));
        let e = csd::Embedding {
            shape: [3, 2],
            data: vec![0.5, -1.25, 3.0e-7, 1.0e6, -0.0, 7.0],
        };
        assert_eq!(cache.get("model-a", "a cat").ok(), Some(None));
        cache.put("model-a", "a cat", &e).expect("put");
        assert_eq!(cache.get("model-a", "a cat").ok(), Some(Some(e.clone())));
        // IF's preprocessing: same tokens, same entry.
        assert_eq!(cache.get("model-a", "  A CAT ").ok(), Some(Some(e)));
    }

    #[test]
    fn key_depends_on_model_and_prompt() {
        let k = EmbeddingCache::key("m", "a cat");
        assert_eq!(k.len(), 64);
        assert_ne!(k, EmbeddingCache::key("m2", "a cat"));
        assert_ne!(k, EmbeddingCache::key("m", "a dog"));
        // The separator keeps (identity, prompt) pairs apart.
        assert_ne!(
            EmbeddingCache::key("ab", "c"),
            EmbeddingCache::key("a", "bc")
        );
    }

    #[test]
    fn corrupt_entry_is_an_error_not_a_panic() {
        let dir = tempfile::tempdir().expect("tempdir");
        let cache = EmbeddingCache::new(dir.path());
        std::fs::write(cache.path("m", "p"), b"garbage").expect("write");
        assert!(cache.get("m", "p").is_err());
    }
}

//! On-disk cache of prompt embeddings, so the (4.7 B-parameter) T5 encoder runs once per prompt and
//! never during optimization.
//!
//! Layout: `<dir>/<key>.npy`, f32 `(tokens, dim)`, where `key` is the hex SHA-256 of
//! `"stylize-embedding-v1\0" + model identity + "\0" + preprocessed prompt` (lower-cased, stripped:
//! prompts that tokenize the same share an entry). The model identity is
//! [`ModelDir::text_identity`](crate::ModelDir::text_identity). Files are written atomically.

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

    /// The cache key of a prompt for a model.
    pub fn key(model_identity: &str, prompt: &str) -> String {
        let mut h = Sha256::new();
        h.update(b"stylize-embedding-v1\0");
        h.update(model_identity.as_bytes());
        h.update(b"\0");
        h.update(T5Tokenizer::preprocess(prompt).as_bytes());
        h.finalize().iter().map(|b| format!("{b:02x}")).collect()
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
    let identity = model.text_identity();
    let mut encoder: Option<T5Encoder> = None;
    let mut one = |p: &str| -> Result<csd::Embedding, OnnxError> {
        if T5Tokenizer::preprocess(p).is_empty() {
            return model.uncond_embedding();
        }
        if let Some(c) = cache
            && let Some(e) = c.get(&identity, p)?
        {
            let want = [
                model.manifest().embeddings.tokens,
                model.manifest().embeddings.dim,
            ];
            if e.shape == want {
                return Ok(e);
            }
            return Err(OnnxError::Cache(format!(
                "{} has shape {:?} but this model's embeddings are {want:?}; delete it to recompute",
                c.path(&identity, p).display(),
                e.shape
            )));
        }
        if encoder.is_none() {
            encoder = Some(T5Encoder::open(model, options)?);
        }
        let enc = encoder
            .as_mut()
            .ok_or_else(|| OnnxError::Cache("text encoder unavailable".into()))?;
        let e = enc
            .embed_batch(&[p])?
            .pop()
            .ok_or_else(|| OnnxError::Cache("the text encoder returned nothing".into()))?;
        if let Some(c) = cache {
            c.put(&identity, p, &e)?;
        }
        Ok(e)
    };
    let cond = one(prompt)?;
    let uncond = one(negative_prompt)?;
    Ok((cond, uncond))
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

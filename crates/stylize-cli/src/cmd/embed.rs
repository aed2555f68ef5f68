//! `stylize embed`: encode prompts with the model's T5 encoder once and store the embeddings in the
//! on-disk cache, so optimization runs never load the (4.7 B-parameter) encoder.

use std::path::PathBuf;

#[cfg(feature = "text")]
use anyhow::{Context, bail};
#[cfg(feature = "text")]
use diffusion_onnx::{EmbeddingCache, ModelDir, SessionOptions, T5Encoder, T5Tokenizer};

/// Arguments of `stylize embed`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// Model directory (manifest.toml + .onnx files from scripts/export_if_onnx.py).
    #[arg(long)]
    pub model: PathBuf,
    /// Prompt to encode (repeat for several).
    #[arg(long = "prompt", required = true)]
    pub prompts: Vec<String>,
    /// Cache directory (default: $STYLIZE_EMBEDDING_CACHE, else $XDG_CACHE_HOME/stylize/embeddings,
    /// else ~/.cache/stylize/embeddings).
    #[arg(long)]
    pub cache: Option<PathBuf>,
    /// Re-encode prompts that are already cached.
    #[arg(long)]
    pub force: bool,
    /// ONNX Runtime intra-op threads (default: one per core; at most 4 × the cores).
    #[arg(long, allow_negative_numbers = true, value_parser = crate::cmd::shared::thread_count)]
    pub threads: Option<usize>,
}

#[cfg(feature = "text")]
/// Runs `stylize embed`.
pub fn run(args: Args) -> anyhow::Result<()> {
    let model = ModelDir::open(&args.model)
        .with_context(|| format!("opening model {}", args.model.display()))?;
    let cache = match &args.cache {
        Some(d) => EmbeddingCache::new(d),
        None => EmbeddingCache::at_default().context("choosing the embedding cache directory")?,
    };
    let identity = cache
        .identity(&model)
        .context("identifying the text encoder for the cache")?;
    let mut todo = Vec::new();
    for p in &args.prompts {
        if T5Tokenizer::preprocess(p).is_empty() {
            outln!("(empty prompt) uses the model's unconditional embedding; nothing to cache")?;
            continue;
        }
        let path = cache.path(&identity, p);
        if !args.force && path.is_file() {
            outln!("cached  {}  {p:?}", path.display())?;
        } else {
            todo.push(p.as_str());
        }
    }
    if todo.is_empty() {
        return Ok(());
    }
    if model.manifest().text_encoder.is_none() {
        bail!(
            "{} has no text encoder ([text_encoder] in manifest.toml) and {} prompt(s) are not cached; run \
             `stylize embed` with a model directory that includes the encoder (same `name`), or pass --cache",
            args.model.display(),
            todo.len()
        );
    }
    let options = SessionOptions {
        intra_threads: args.threads,
        ..SessionOptions::default()
    };
    let mut encoder = T5Encoder::open(&model, &options).context("loading the text encoder")?;
    let mut closed: Option<crate::output::OutputClosed> = None;
    for p in todo {
        let e = encoder
            .embed_batch(&[p])
            .with_context(|| format!("encoding {p:?}"))?;
        let e = e
            .first()
            .context("the text encoder returned no embedding")?;
        let path = cache
            .put(&identity, p, e)
            .with_context(|| format!("caching {p:?}"))?;
        // A closed stdout does not stop the encoding: every prompt is cached, then the command
        // fails with the first write error (exit 141 for a broken pipe).
        if closed.is_none() {
            closed = outln!("encoded {}  {p:?}", path.display()).err();
        }
    }
    closed.map_or(Ok(()), |e| Err(e.into()))
}

#[cfg(all(test, feature = "text"))]
mod tests {
    use super::*;

    fn tiny() -> PathBuf {
        PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../fixtures/models/tiny-if")
    }

    #[test]
    fn embed_fills_the_cache_with_the_encoders_output() -> anyhow::Result<()> {
        let dir = tempfile::tempdir()?;
        let args = |force| Args {
            model: tiny(),
            prompts: vec!["a photo of a cat".into(), "".into()],
            cache: Some(dir.path().to_path_buf()),
            force,
            threads: Some(1),
        };
        run(args(false))?;
        let model = ModelDir::open(tiny())?;
        let cache = EmbeddingCache::new(dir.path());
        let cached = cache
            .get(&cache.identity(&model)?, "a photo of a cat")?
            .context("entry written")?;
        let mut enc = T5Encoder::open(&model, &SessionOptions::default())?;
        let fresh = enc.embed_batch(&["a photo of a cat"])?;
        assert_eq!(Some(&cached), fresh.first());
        // Only the one non-empty prompt is stored (besides the encoder digests in `encoders/`).
        let npy = std::fs::read_dir(dir.path())?
            .filter(|e| {
                e.as_ref()
                    .is_ok_and(|e| e.path().extension().is_some_and(|x| x == "npy"))
            })
            .count();
        assert_eq!(npy, 1);
        run(args(true))?;
        Ok(())
    }

    #[test]
    fn missing_model_directory_is_an_error_with_its_path() {
        let r = run(Args {
            model: PathBuf::from("/nonexistent/model"),
            prompts: vec!["x".into()],
            cache: None,
            force: false,
            threads: None,
        });
        let msg = format!("{:#}", r.err().map(|e| e.to_string()).unwrap_or_default());
        assert!(msg.contains("/nonexistent/model"), "{msg}");
    }
}

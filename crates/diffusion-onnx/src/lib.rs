//! DeepFloyd IF through ONNX Runtime, behind the `csd` traits.
//!
//! - [`ModelDir`]: a directory with `manifest.toml` and the exported `.onnx` files (written by
//!   `scripts/export_if_onnx.py`; format in `docs/models.md`).
//! - [`OnnxDenoiser`]: IF stage I or II UNet, implements [`csd::Denoiser`]. Tensors are f32 NCHW
//!   outside; fp16 models are converted at the session boundary.
//! - [`T5Encoder`]: T5 tokenizer + encoder, implements [`csd::TextEmbedding`].
//! - [`EmbeddingCache`] and [`prompt_embeddings`]: encode each prompt once, reuse from disk.
//! - [`clip`]: CLIP image and text encoders ([`ClipModel`]) for the CLIP similarity of spec §9.
//! - [`runtime`]: finding the ONNX Runtime library (`$ORT_DYLIB_PATH`, else
//!   `.deps/onnxruntime/` from `scripts/setup-onnxruntime.sh`), execution providers.

mod builtin;
mod cache;
pub mod clip;
mod denoiser;
mod error;
mod manifest;
pub mod memory;
pub mod npy;
pub mod probe;
pub mod runtime;
mod session;
mod text;
mod tokenizer;

pub use builtin::{IF_UNCOND_DIM, IF_UNCOND_TOKENS, if_empty_prompt_embedding};
pub use cache::{CACHE_ENV, EmbeddingCache, prompt_embeddings};
pub use clip::{ClipManifest, ClipModel, ClipTokenizer, cosine_similarity};
pub use denoiser::OnnxDenoiser;
pub use error::OnnxError;
pub use manifest::{
    BUILTIN_IF_UNCOND, BUILTIN_T5_TOKENIZER, Dtype, EmbeddingsManifest, FORMAT_VERSION, Manifest,
    ModelDir, SchedulerManifest, Stage, StageManifest, TextEncoderManifest,
};
pub use runtime::{ArenaGrowth, ConvAlgorithmSearch, CudaOptions, Device, SessionOptions};
pub use text::T5Encoder;
pub use tokenizer::{T5Tokenizer, Tokens};

//! CLIP image and text embeddings through ONNX Runtime, for the CLIP similarity of spec §9
//! ("cosine between the image embedding of renders of the result and the text embedding of the
//! prompt", ViT-B/16 in the paper).
//!
//! A CLIP model directory holds `manifest.toml`, `image_encoder.onnx` and `text_encoder.onnx`, written
//! by `scripts/export_clip_onnx.py` (format in `docs/models.md`, section "CLIP"):
//! - image encoder: `pixel_values` f32 `[B, 3, S, S]`, already normalized with the manifest's mean/std,
//!   → `image_embeds` f32 `[B, D]`: the visual projection of the pooled output, **not** normalized;
//! - text encoder: `input_ids` i64 `[B, 77]` → `text_embeds` f32 `[B, D]`: the text projection at the
//!   first end-of-text token, **not** normalized.
//!
//! [`cosine_similarity`] normalizes, so the missing normalization does not matter for the metric.
//!
//! **Tokens** ([`ClipTokenizer`]): the OpenAI CLIP BPE vocabulary shipped in `assets/clip_tokenizer.json`
//! (normalizer: NFC, runs of white space → one space, lower case); ids are `<|startoftext|>` (49406),
//! at most 75 BPE tokens (longer prompts are truncated), `<|endoftext|>` (49407), then the pad id
//! (49407, Hugging Face's convention) up to 77. OpenAI's reference tokenizer also runs `ftfy` and HTML
//! unescaping first; plain prompts are unaffected.
//!
//! **Images** ([`ClipModel::embed_images`], [`preprocess`]): square RGB f32 images in `[0, 1]`, laid
//! out `(image, row, column, channel)` like `raster_diff::Images`. Each is resized to the model's
//! `S × S` with PIL's bicubic filter (a = −0.5; when reducing, the kernel is widened by the scale
//! factor, i.e. antialiased — the filter `CLIPImageProcessor` uses), then normalized per channel,
//! `(x − mean) / std`. Differences from `CLIPImageProcessor` (resize the shortest side to S, centre
//! crop S × S, rescale bytes by 1/255, normalize): for a square image shortest-side resize + centre
//! crop is exactly this resize; here the input is float and nothing is quantized to 8 bits (PIL
//! resizes `uint8` RGB images, rounds after each pass and clamps), so values differ by about one
//! 8-bit step before normalization (measured: at most 0.005; docs/models.md §6). An image already
//! `S × S` is not resampled.
//!
//! Submodules: [`manifest`] (reading and checking `manifest.toml`), [`tokenizer`], [`preprocess`]
//! (resize and normalization), [`model`] (the sessions).

pub mod manifest;
pub mod model;
pub mod preprocess;
pub mod tokenizer;

pub use manifest::{
    CLIP_FORMAT_VERSION, ClipImageManifest, ClipManifest, ClipTextManifest, read_clip_manifest,
    sha256_file,
};
pub use model::ClipModel;
pub use preprocess::{cosine_similarity, preprocess, resize_bicubic};
pub use tokenizer::{BUILTIN_CLIP_TOKENIZER, CLIP_TOKENIZER_JSON, ClipTokenizer};

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

use std::borrow::Cow;
use std::io::Read;
use std::path::{Path, PathBuf};

use ort::session::{Session, SessionInputValue};
use serde::Deserialize;
use sha2::{Digest, Sha256};
use tokenizers::Tokenizer;

use crate::OnnxError;
use crate::manifest::Dtype;
use crate::runtime::{SessionOptions, open_session};
use crate::session::{Kind, check_signature, float_input, float_output, int_input};

/// The OpenAI CLIP BPE `tokenizers` JSON (49,408 tokens; see `assets/README.md`).
pub const CLIP_TOKENIZER_JSON: &[u8] = include_bytes!("../assets/clip_tokenizer.json");
/// The `[text_encoder] tokenizer` value that selects the shipped CLIP tokenizer.
pub const BUILTIN_CLIP_TOKENIZER: &str = "builtin:clip";
/// The CLIP manifest format version this crate reads.
pub const CLIP_FORMAT_VERSION: u32 = 1;
/// Images per image-encoder call (bounds the session's memory; ViT-B/16 at 224 px needs ~0.5 GB for 16).
const IMAGE_BATCH: usize = 16;

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

/// CLIP tokenization to a fixed context length (see the module docs).
pub struct ClipTokenizer {
    inner: Tokenizer,
    context_length: usize,
    bos_id: i64,
    eos_id: i64,
    pad_id: i64,
}

impl std::fmt::Debug for ClipTokenizer {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("ClipTokenizer")
            .field("context_length", &self.context_length)
            .finish_non_exhaustive()
    }
}

impl ClipTokenizer {
    /// The shipped OpenAI CLIP vocabulary with OpenAI's ids and context length (77, 49406, 49407,
    /// pad 49407).
    pub fn builtin() -> Result<Self, OnnxError> {
        Self::from_json_bytes(CLIP_TOKENIZER_JSON, 77, 49406, 49407, 49407)
    }

    /// A `tokenizers` JSON with the given context length and special ids.
    pub fn from_json_bytes(
        bytes: &[u8],
        context_length: usize,
        bos_id: i64,
        eos_id: i64,
        pad_id: i64,
    ) -> Result<Self, OnnxError> {
        if context_length < 2 {
            return Err(OnnxError::Tokenizer(format!(
                "context_length = {context_length}: at least 2 (start and end tokens) are needed"
            )));
        }
        let inner = Tokenizer::from_bytes(bytes)
            .map_err(|e| OnnxError::Tokenizer(format!("cannot load the CLIP tokenizer: {e}")))?;
        Ok(Self {
            inner,
            context_length,
            bos_id,
            eos_id,
            pad_id,
        })
    }

    /// Tokens per prompt.
    pub fn context_length(&self) -> usize {
        self.context_length
    }

    /// `[bos] + BPE tokens (truncated to context_length − 2) + [eos] + [pad …]`, `context_length` ids.
    pub fn encode(&self, prompt: &str) -> Result<Vec<i64>, OnnxError> {
        let enc = self
            .inner
            .encode(prompt, false)
            .map_err(|e| OnnxError::Tokenizer(format!("cannot encode {prompt:?}: {e}")))?;
        let mut ids = Vec::with_capacity(self.context_length);
        ids.push(self.bos_id);
        ids.extend(
            enc.get_ids()
                .iter()
                .take(self.context_length - 2)
                .map(|&i| i64::from(i)),
        );
        ids.push(self.eos_id);
        ids.resize(self.context_length, self.pad_id);
        Ok(ids)
    }
}

/// Per output index: the first input index and the normalized weights of PIL's `Image.BICUBIC`
/// (`precompute_coeffs`: pixel centres at +0.5, kernel widened by the scale factor when reducing,
/// weights renormalized at the borders). This is exactly csd's antialiased Keys cubic (a = −0.5), the
/// kernel the guidance resizes with, so the two share one implementation.
fn resample_coefficients(input: usize, output: usize) -> Result<Vec<csd::resize::Taps>, OnnxError> {
    csd::Resize1d::cubic_antialias(input, output)
        .map(|r| r.rows().to_vec())
        .map_err(|e| OnnxError::Shape {
            model: "bicubic resize".into(),
            message: e.to_string(),
        })
}

/// Resizes one image `(row, column, channel)` with `channels` interleaved channels from
/// `height × width` to `out_height × out_width` with PIL's `Image.BICUBIC` on float planes: the
/// horizontal pass first (into an f32 intermediate), then the vertical one, each a normalized
/// bicubic kernel widened by the scale factor when reducing. Values are not clamped (bicubic can
/// overshoot slightly, as PIL's float mode does). Errors when a size is zero or `image` does not
/// hold `height · width · channels` values.
pub fn resize_bicubic(
    image: &[f32],
    height: usize,
    width: usize,
    channels: usize,
    out_height: usize,
    out_width: usize,
) -> Result<Vec<f32>, OnnxError> {
    if [height, width, channels, out_height, out_width].contains(&0)
        || image.len() != height * width * channels
    {
        return Err(OnnxError::Shape {
            model: "bicubic resize".into(),
            message: format!(
                "{} values for a {height}×{width}×{channels} image resized to {out_height}×{out_width} \
                 (sizes must be positive and the value count height·width·channels)",
                image.len()
            ),
        });
    }
    let horizontal = resample_coefficients(width, out_width)?;
    let mut tmp = vec![0.0f32; height * out_width * channels];
    for r in 0..height {
        for (
            o,
            csd::resize::Taps {
                start: lo,
                weights: w,
            },
        ) in horizontal.iter().enumerate()
        {
            for c in 0..channels {
                let s: f64 = w
                    .iter()
                    .enumerate()
                    .map(|(k, wk)| wk * f64::from(image[(r * width + lo + k) * channels + c]))
                    .sum();
                tmp[(r * out_width + o) * channels + c] = s as f32;
            }
        }
    }
    let vertical = resample_coefficients(height, out_height)?;
    let mut out = vec![0.0f32; out_height * out_width * channels];
    for (
        o,
        csd::resize::Taps {
            start: lo,
            weights: w,
        },
    ) in vertical.iter().enumerate()
    {
        for col in 0..out_width {
            for c in 0..channels {
                let s: f64 = w
                    .iter()
                    .enumerate()
                    .map(|(k, wk)| wk * f64::from(tmp[((lo + k) * out_width + col) * channels + c]))
                    .sum();
                out[(o * out_width + col) * channels + c] = s as f32;
            }
        }
    }
    Ok(out)
}

/// CLIP preprocessing of `count` square RGB images `(image, row, column, channel)` of side `side`,
/// values in `[0, 1]`: bicubic resize to `size` (skipped when `side == size`), then
/// `(x − mean) / std`, returned as `pixel_values` `(image, channel, row, column)`. Errors when
/// `rgb` does not hold `count · side² · 3` values or a size is zero.
pub fn preprocess(
    rgb: &[f32],
    count: usize,
    side: usize,
    size: usize,
    mean: [f32; 3],
    std: [f32; 3],
) -> Result<Vec<f32>, OnnxError> {
    let per = side * side * 3;
    if side == 0 || size == 0 || rgb.len() != count * per {
        return Err(OnnxError::Shape {
            model: "CLIP preprocessing".into(),
            message: format!(
                "{} values for {count} RGB images of side {side} (need count·side²·3 = {}), target size {size}",
                rgb.len(),
                count * per
            ),
        });
    }
    let mut out = Vec::with_capacity(count * 3 * size * size);
    for n in 0..count {
        let img = &rgb[n * per..(n + 1) * per];
        let resized: Cow<'_, [f32]> = if side == size {
            Cow::Borrowed(img)
        } else {
            Cow::Owned(resize_bicubic(img, side, side, 3, size, size)?)
        };
        for c in 0..3 {
            out.extend(resized.chunks_exact(3).map(|px| (px[c] - mean[c]) / std[c]));
        }
    }
    Ok(out)
}

/// `a·b / (|a| |b|)` in f64; 0 when either vector is zero. Slices of different lengths are compared
/// over the shorter one (callers compare embeddings of one model, which have equal lengths).
pub fn cosine_similarity(a: &[f32], b: &[f32]) -> f64 {
    let (mut ab, mut aa, mut bb) = (0.0f64, 0.0f64, 0.0f64);
    for (&x, &y) in a.iter().zip(b) {
        let (x, y) = (f64::from(x), f64::from(y));
        ab += x * y;
        aa += x * x;
        bb += y * y;
    }
    if aa == 0.0 || bb == 0.0 {
        return 0.0;
    }
    (ab / (aa.sqrt() * bb.sqrt())).clamp(-1.0, 1.0)
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

/// A CLIP model: both encoders and the tokenizer.
pub struct ClipModel {
    root: PathBuf,
    manifest: ClipManifest,
    tokenizer: ClipTokenizer,
    image: Session,
    text: Session,
}

impl std::fmt::Debug for ClipModel {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("ClipModel")
            .field("root", &self.root)
            .field("name", &self.manifest.name)
            .finish_non_exhaustive()
    }
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
    let text = std::fs::read_to_string(dir.join("manifest.toml")).map_err(|e| {
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

/// Checks the static sizes the graph states (dynamic ones, −1, pass): dimension `k` of `name` must be
/// `want[k]` where `want[k]` is `Some`.
fn check_dims(
    session: &Session,
    model: &str,
    name: &str,
    want: &[Option<usize>],
) -> Result<(), OnnxError> {
    let outlet = session
        .inputs()
        .iter()
        .chain(session.outputs().iter())
        .find(|o| o.name() == name);
    let Some(shape) = outlet.and_then(|o| o.dtype().tensor_shape()) else {
        return Ok(());
    };
    for (k, (&got, want)) in shape.iter().zip(want).enumerate() {
        if let Some(w) = want
            && got >= 0
            && got as usize != *w
        {
            return Err(OnnxError::Signature {
                model: model.to_string(),
                message: format!(
                    "`{name}` has size {got} in dimension {k} (shape {:?}) but the manifest implies {w}",
                    &**shape
                ),
            });
        }
    }
    Ok(())
}

impl ClipModel {
    /// Opens a CLIP model directory: validates the manifest and files ([`read_clip_manifest`]),
    /// loads the tokenizer, opens both sessions and checks their inputs/outputs (names, element
    /// types, ranks, and the sizes S, 77 and D where the graph states them).
    pub fn open(dir: impl AsRef<Path>, options: &SessionOptions) -> Result<Self, OnnxError> {
        let root = dir.as_ref().to_path_buf();
        let manifest = read_clip_manifest(&root)?;
        let (i, t) = (&manifest.image_encoder, &manifest.text_encoder);
        let tokenizer = if t.tokenizer == BUILTIN_CLIP_TOKENIZER {
            ClipTokenizer::from_json_bytes(
                CLIP_TOKENIZER_JSON,
                t.context_length,
                t.bos_id,
                t.eos_id,
                t.pad_id,
            )?
        } else {
            let path = root.join(&t.tokenizer);
            let bytes = std::fs::read(&path).map_err(|e| OnnxError::io(&path, e))?;
            ClipTokenizer::from_json_bytes(&bytes, t.context_length, t.bos_id, t.eos_id, t.pad_id)?
        };
        let d = manifest.embedding_dim;
        let image = open_session(&root.join(&i.file), options, "CLIP image encoder")?;
        check_signature(
            &image,
            "CLIP image encoder",
            Dtype::Fp32,
            &[(&i.input, Kind::Float, 4)],
            (&i.output, Kind::Float, 2),
        )?;
        let s = i.image_size;
        check_dims(
            &image,
            "CLIP image encoder",
            &i.input,
            &[None, Some(3), Some(s), Some(s)],
        )?;
        check_dims(&image, "CLIP image encoder", &i.output, &[None, Some(d)])?;
        let text = open_session(&root.join(&t.file), options, "CLIP text encoder")?;
        check_signature(
            &text,
            "CLIP text encoder",
            Dtype::Fp32,
            &[(&t.input_ids, Kind::Int64, 2)],
            (&t.output, Kind::Float, 2),
        )?;
        check_dims(
            &text,
            "CLIP text encoder",
            &t.input_ids,
            &[None, Some(t.context_length)],
        )?;
        check_dims(&text, "CLIP text encoder", &t.output, &[None, Some(d)])?;
        Ok(Self {
            root,
            manifest,
            tokenizer,
            image,
            text,
        })
    }

    /// The model directory.
    pub fn root(&self) -> &Path {
        &self.root
    }

    /// The parsed manifest.
    pub fn manifest(&self) -> &ClipManifest {
        &self.manifest
    }

    /// S: the side images are resized to.
    pub fn image_size(&self) -> usize {
        self.manifest.image_encoder.image_size
    }

    /// D: the embedding width.
    pub fn embedding_dim(&self) -> usize {
        self.manifest.embedding_dim
    }

    /// The tokenizer.
    pub fn tokenizer(&self) -> &ClipTokenizer {
        &self.tokenizer
    }

    fn run_single(
        session: &mut Session,
        model: &str,
        input: &str,
        value: ort::value::DynValue,
        output: &str,
        n: usize,
        d: usize,
    ) -> Result<Vec<Vec<f32>>, OnnxError> {
        let inputs: Vec<(Cow<'_, str>, SessionInputValue<'_>)> =
            vec![(Cow::from(input), value.into())];
        let outputs = session
            .run(inputs)
            .map_err(|e| OnnxError::ort(format!("running the {model}"), e))?;
        let value = outputs.get(output).ok_or_else(|| OnnxError::Signature {
            model: model.into(),
            message: format!("output `{output}` missing from the results"),
        })?;
        let (shape, data) = float_output(value, Dtype::Fp32, &format!("the {model} output"))?;
        if shape != [n, d] {
            return Err(OnnxError::Shape {
                model: model.into(),
                message: format!("output shape {shape:?}, expected [{n}, {d}]"),
            });
        }
        Ok(data.chunks_exact(d).map(<[f32]>::to_vec).collect())
    }

    /// Text embeddings `[D]` (projected, not normalized) of several prompts, one session call.
    pub fn embed_texts(&mut self, prompts: &[&str]) -> Result<Vec<Vec<f32>>, OnnxError> {
        if prompts.is_empty() {
            return Ok(Vec::new());
        }
        let l = self.tokenizer.context_length();
        let mut ids = Vec::with_capacity(prompts.len() * l);
        for p in prompts {
            ids.extend(self.tokenizer.encode(p)?);
        }
        let n = prompts.len();
        let t = &self.manifest.text_encoder;
        Self::run_single(
            &mut self.text,
            "CLIP text encoder",
            &t.input_ids,
            int_input(vec![n, l], ids)?,
            &t.output,
            n,
            self.manifest.embedding_dim,
        )
    }

    /// Image embeddings `[D]` (projected, not normalized) of `count` square RGB images of side `side`,
    /// values in `[0, 1]`, laid out `(image, row, column, channel)` (as `raster_diff::Images`).
    /// Preprocessing: see [`preprocess`] and the module docs. Runs in batches of 16.
    pub fn embed_images(
        &mut self,
        rgb: &[f32],
        count: usize,
        side: usize,
    ) -> Result<Vec<Vec<f32>>, OnnxError> {
        let model = "CLIP image encoder";
        if side == 0 || rgb.len() != count * side * side * 3 {
            return Err(OnnxError::Shape {
                model: model.into(),
                message: format!(
                    "{} values for {count} RGB images of side {side} (need count·side²·3 = {})",
                    rgb.len(),
                    count * side * side * 3
                ),
            });
        }
        if let Some(bad) = rgb.iter().find(|v| !v.is_finite()) {
            return Err(OnnxError::Shape {
                model: model.into(),
                message: format!("the images contain a non-finite value ({bad})"),
            });
        }
        let i = &self.manifest.image_encoder;
        let (size, mean, std) = (i.image_size, i.mean, i.std);
        let per = side * side * 3;
        let mut out = Vec::with_capacity(count);
        for start in (0..count).step_by(IMAGE_BATCH) {
            let n = IMAGE_BATCH.min(count - start);
            let pixels = preprocess(
                &rgb[start * per..(start + n) * per],
                n,
                side,
                size,
                mean,
                std,
            )?;
            let value = float_input(Dtype::Fp32, vec![n, 3, size, size], pixels)?;
            out.extend(Self::run_single(
                &mut self.image,
                model,
                &i.input,
                value,
                &i.output,
                n,
                self.manifest.embedding_dim,
            )?);
        }
        Ok(out)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn builtin_tokenizer_gives_openai_ids_then_padding() {
        let tok = ClipTokenizer::builtin().expect("builtin tokenizer");
        let ids = tok.encode("a photo of a cat").expect("encode");
        assert_eq!(&ids[..7], &[49406, 320, 1125, 539, 320, 2368, 49407]);
        assert_eq!(ids.len(), 77);
        assert!(ids[7..].iter().all(|&i| i == 49407));
    }

    #[test]
    fn case_and_white_space_runs_do_not_matter() {
        let tok = ClipTokenizer::builtin().expect("builtin tokenizer");
        assert_eq!(
            tok.encode("  A   Photo of a\tCAT ").ok(),
            tok.encode("a photo of a cat").ok()
        );
    }

    #[test]
    fn long_prompts_keep_start_and_end_tokens() {
        let tok = ClipTokenizer::builtin().expect("builtin tokenizer");
        let ids = tok
            .encode(&"a very ornate wooden chair ".repeat(40))
            .expect("encode");
        assert_eq!((ids.len(), ids[0], ids[76]), (77, 49406, 49407));
        assert!(ids[1..76].iter().all(|&i| i != 49407));
    }

    #[test]
    fn resize_preserves_constants_and_identity() {
        let img: Vec<f32> = (0..5 * 5 * 3).map(|i| (i % 7) as f32 / 7.0).collect();
        assert_eq!(resize_bicubic(&img, 5, 5, 3, 5, 5).ok(), Some(img));
        let flat = vec![0.25f32; 48 * 48 * 3];
        let small = resize_bicubic(&flat, 48, 48, 3, 7, 7).expect("resize");
        assert!(small.iter().all(|v| (v - 0.25).abs() < 1e-6));
        let big = resize_bicubic(&flat, 48, 48, 3, 100, 100).expect("resize");
        assert!(resize_bicubic(&flat, 48, 48, 3, 0, 7).is_err());
        assert!(resize_bicubic(&flat, 47, 48, 3, 7, 7).is_err());
        assert!(big.iter().all(|v| (v - 0.25).abs() < 1e-6));
    }

    #[test]
    fn downscaling_is_antialiased() {
        // A one-pixel checkerboard averages to its mean when reduced 4×; point sampling would alias.
        let side = 32;
        let img: Vec<f32> = (0..side * side)
            .flat_map(|k| {
                let v = ((k / side + k % side) % 2) as f32;
                [v; 3]
            })
            .collect();
        let small = resize_bicubic(&img, side, side, 3, 8, 8).expect("resize");
        assert!(
            small.iter().all(|v| (v - 0.5).abs() < 0.02),
            "{:?}",
            &small[..6]
        );
    }

    #[test]
    fn cosine_similarity_is_scale_invariant_and_bounded() {
        let a = [1.0f32, 2.0, 3.0];
        let b = [2.0f32, 4.0, 6.0];
        assert!((cosine_similarity(&a, &b) - 1.0).abs() < 1e-12);
        assert!((cosine_similarity(&a, &[-1.0, -2.0, -3.0]) + 1.0).abs() < 1e-12);
        assert!(cosine_similarity(&[1.0, 0.0], &[0.0, 1.0]).abs() < 1e-12);
        assert_eq!(cosine_similarity(&[0.0, 0.0], &[1.0, 1.0]), 0.0);
    }
}

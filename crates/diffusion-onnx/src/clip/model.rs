//! [`ClipModel`]: the two ONNX sessions (image and text encoder) with their manifest and tokenizer.

use std::borrow::Cow;
use std::path::{Path, PathBuf};

use ort::session::{Session, SessionInputValue};

use super::manifest::{ClipManifest, read_clip_manifest};
use super::preprocess::preprocess;
use super::tokenizer::{BUILTIN_CLIP_TOKENIZER, CLIP_TOKENIZER_JSON, ClipTokenizer};
use crate::OnnxError;
use crate::manifest::Dtype;
use crate::runtime::{SessionOptions, open_session};
use crate::session::{Kind, check_signature, float_input, float_output, int_input};

/// Images per image-encoder call (bounds the session's memory; ViT-B/16 at 224 px needs ~0.5 GB for 16).
const IMAGE_BATCH: usize = 16;

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

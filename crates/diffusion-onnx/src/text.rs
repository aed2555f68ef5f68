//! The T5 text encoder as an ONNX session, behind [`csd::TextEmbedding`].

use std::borrow::Cow;

use ort::session::{Session, SessionInputValue};

use crate::OnnxError;
use crate::manifest::{Dtype, ModelDir};
use crate::runtime::{SessionOptions, open_session};
use crate::session::{Kind, check_signature, float_output, int_input};
use crate::tokenizer::T5Tokenizer;

/// T5 encoder + tokenizer: prompt → `(tokens, dim)` embedding (IF: `(77, 4096)`), f32.
pub struct T5Encoder {
    session: Session,
    tokenizer: T5Tokenizer,
    input_ids: String,
    attention_mask: String,
    output: String,
    dtype: Dtype,
    shape: [usize; 2],
    file: std::path::PathBuf,
}

impl std::fmt::Debug for T5Encoder {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("T5Encoder")
            .field("shape", &self.shape)
            .field("dtype", &self.dtype)
            .finish_non_exhaustive()
    }
}

impl T5Encoder {
    /// Opens the `[text_encoder]` of a model directory and checks its signature.
    pub fn open(model: &ModelDir, options: &SessionOptions) -> Result<Self, OnnxError> {
        let m = model.manifest();
        let t = m.text_encoder.as_ref().ok_or_else(|| OnnxError::Manifest {
            dir: model.root().to_path_buf(),
            message: "this model directory has no [text_encoder]; precompute embeddings with `stylize embed` using a \
                      directory that has one, or re-export without --skip-text-encoder"
                .into(),
        })?;
        let tokenizer = T5Tokenizer::of_text_encoder(model, t)?;
        let file = model.path_of(&t.file);
        let session = open_session(&file, options, "text encoder")?;
        check_signature(
            &session,
            "text encoder",
            t.dtype,
            &[
                (&t.input_ids, Kind::Int64, 2),
                (&t.attention_mask, Kind::Int64, 2),
            ],
            (&t.output, Kind::Float, 3),
        )?;
        Ok(Self {
            session,
            tokenizer,
            input_ids: t.input_ids.clone(),
            attention_mask: t.attention_mask.clone(),
            output: t.output.clone(),
            dtype: t.dtype,
            shape: [t.max_tokens, t.embedding_dim],
            file,
        })
    }

    /// The tokenizer.
    pub fn tokenizer(&self) -> &T5Tokenizer {
        &self.tokenizer
    }

    /// Encodes several prompts in one session call.
    pub fn embed_batch(&mut self, prompts: &[&str]) -> Result<Vec<csd::Embedding>, OnnxError> {
        if prompts.is_empty() {
            return Ok(Vec::new());
        }
        let [tokens, dim] = self.shape;
        let mut ids = Vec::with_capacity(prompts.len() * tokens);
        let mut mask = Vec::with_capacity(prompts.len() * tokens);
        for p in prompts {
            let t = self.tokenizer.encode(p)?;
            ids.extend(t.input_ids);
            mask.extend(t.attention_mask);
        }
        let n = prompts.len();
        let inputs: Vec<(Cow<'_, str>, SessionInputValue<'_>)> = vec![
            (
                Cow::from(self.input_ids.as_str()),
                int_input(vec![n, tokens], ids)?.into(),
            ),
            (
                Cow::from(self.attention_mask.as_str()),
                int_input(vec![n, tokens], mask)?.into(),
            ),
        ];
        let outputs = self
            .session
            .run(inputs)
            .map_err(|e| OnnxError::ort("running the text encoder", e))?;
        let value = outputs
            .get(&self.output)
            .ok_or_else(|| OnnxError::Signature {
                model: "text encoder".into(),
                message: format!("output `{}` missing from the results", self.output),
            })?;
        let (shape, data) = float_output(value, self.dtype, "the text encoder output")?;
        if shape != [n, tokens, dim] {
            return Err(OnnxError::Shape {
                model: "text encoder".into(),
                message: format!("output shape {shape:?}, expected [{n}, {tokens}, {dim}]"),
            });
        }
        data.chunks_exact(tokens * dim)
            .zip(prompts)
            .map(|(c, p)| {
                OnnxError::check_finite(
                    c,
                    || format!("the text encoder's embedding of the prompt {p:?}"),
                    &self.file,
                    "the encoder overflowed (fp16 T5 can; export it with --dtype fp32) or its weights are broken; \
                     nothing was cached",
                )?;
                Ok(csd::Embedding {
                    shape: [tokens, dim],
                    data: c.to_vec(),
                })
            })
            .collect()
    }
}

impl csd::TextEmbedding for T5Encoder {
    fn embed(&mut self, prompt: &str) -> Result<csd::Embedding, csd::GuidanceError> {
        let mut v = self.embed_batch(&[prompt])?;
        v.pop()
            .ok_or_else(|| csd::GuidanceError::Model("the text encoder returned nothing".into()))
    }
}

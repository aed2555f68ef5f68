//! CLIP tokenization (see the [`clip`](super) module docs for the exact ids).

use tokenizers::Tokenizer;

use crate::OnnxError;

/// The OpenAI CLIP BPE `tokenizers` JSON (49,408 tokens; see `assets/README.md`).
pub const CLIP_TOKENIZER_JSON: &[u8] = include_bytes!("../../assets/clip_tokenizer.json");
/// The `[text_encoder] tokenizer` value that selects the shipped CLIP tokenizer.
pub const BUILTIN_CLIP_TOKENIZER: &str = "builtin:clip";

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
}

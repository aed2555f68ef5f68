//! T5 tokenization as DeepFloyd IF does it: lower-case and strip the prompt, encode with the T5
//! SentencePiece (Unigram) vocabulary, end with `</s>` (id 1), pad with 0 / truncate to the model's
//! token count (77). The attention mask is 1 on tokens (including `</s>`) and 0 on padding.

use tokenizers::Tokenizer;

use crate::OnnxError;
use crate::builtin::T5_TOKENIZER_JSON;
use crate::manifest::{BUILTIN_T5_TOKENIZER, ModelDir, TextEncoderManifest};

/// Id of `</s>`.
pub const EOS_ID: i64 = 1;
/// Id of `<pad>`.
pub const PAD_ID: i64 = 0;

/// Token ids and attention mask of one prompt, both of the tokenizer's length.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Tokens {
    /// Token ids, `</s>` last among the real tokens, then the pad id 0.
    pub input_ids: Vec<i64>,
    /// 1 for real tokens, 0 for padding.
    pub attention_mask: Vec<i64>,
}

/// The T5 tokenizer with IF's preprocessing and a fixed length.
pub struct T5Tokenizer {
    inner: Tokenizer,
    max_tokens: usize,
}

impl std::fmt::Debug for T5Tokenizer {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("T5Tokenizer")
            .field("max_tokens", &self.max_tokens)
            .finish_non_exhaustive()
    }
}

impl T5Tokenizer {
    /// The shipped T5 vocabulary, `max_tokens` long (77 for IF).
    pub fn builtin(max_tokens: usize) -> Result<Self, OnnxError> {
        Self::from_json_bytes(T5_TOKENIZER_JSON, max_tokens)
    }

    /// A `tokenizers` JSON file.
    pub fn from_file(path: &std::path::Path, max_tokens: usize) -> Result<Self, OnnxError> {
        let bytes = std::fs::read(path).map_err(|e| OnnxError::io(path, e))?;
        Self::from_json_bytes(&bytes, max_tokens)
    }

    fn from_json_bytes(bytes: &[u8], max_tokens: usize) -> Result<Self, OnnxError> {
        if max_tokens < 1 {
            return Err(OnnxError::Tokenizer("max_tokens must be at least 1".into()));
        }
        let inner = Tokenizer::from_bytes(bytes)
            .map_err(|e| OnnxError::Tokenizer(format!("cannot load: {e}")))?;
        Ok(Self { inner, max_tokens })
    }

    /// The tokenizer a manifest's `[text_encoder]` names (the shipped one or a file in the model
    /// directory), `max_tokens` long.
    pub fn of_text_encoder(model: &ModelDir, t: &TextEncoderManifest) -> Result<Self, OnnxError> {
        if t.tokenizer == BUILTIN_T5_TOKENIZER {
            Self::builtin(t.max_tokens)
        } else {
            Self::from_file(&model.path_of(&t.tokenizer), t.max_tokens)
        }
    }

    /// The tokenizer of a model directory's `[text_encoder]`; `None` when it has none (prompts
    /// then come from precomputed embeddings).
    pub fn of_model(model: &ModelDir) -> Result<Option<Self>, OnnxError> {
        model
            .manifest()
            .text_encoder
            .as_ref()
            .map(|t| Self::of_text_encoder(model, t))
            .transpose()
    }

    /// Tokens per prompt.
    pub fn max_tokens(&self) -> usize {
        self.max_tokens
    }

    /// IF's text preprocessing (without caption cleaning): lower-case, strip surrounding white space.
    pub fn preprocess(prompt: &str) -> String {
        prompt.trim().to_lowercase()
    }

    /// The content tokens of `prompt` (after [`Self::preprocess`], without `</s>`) that
    /// [`Self::encode`] drops: those past the first `max_tokens − 1`. 0 when the prompt fits.
    pub fn dropped_tokens(&self, prompt: &str) -> Result<usize, OnnxError> {
        Ok(self
            .content_ids(prompt)?
            .len()
            .saturating_sub(self.max_tokens - 1))
    }

    /// The content token ids of `prompt` (preprocessed, no `</s>`), not truncated.
    fn content_ids(&self, prompt: &str) -> Result<Vec<i64>, OnnxError> {
        let text = Self::preprocess(prompt);
        let enc = self
            .inner
            .encode(text.as_str(), false)
            .map_err(|e| OnnxError::Tokenizer(format!("cannot encode {prompt:?}: {e}")))?;
        let mut ids: Vec<i64> = enc.get_ids().iter().map(|&i| i64::from(i)).collect();
        // Some tokenizer files put `</s>` in the content when `add_special_tokens` is false; drop it.
        while ids.last() == Some(&EOS_ID) {
            ids.pop();
        }
        Ok(ids)
    }

    /// Encodes one prompt: content tokens truncated to `max_tokens − 1`, then `</s>`, then padding
    /// (as Hugging Face's T5 tokenizer with `truncation=True, padding="max_length"`).
    pub fn encode(&self, prompt: &str) -> Result<Tokens, OnnxError> {
        let mut ids = self.content_ids(prompt)?;
        ids.truncate(self.max_tokens - 1);
        ids.push(EOS_ID);
        let real = ids.len();
        ids.resize(self.max_tokens, PAD_ID);
        let mut attention_mask = vec![1; real];
        attention_mask.resize(self.max_tokens, 0);
        Ok(Tokens {
            input_ids: ids,
            attention_mask,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_photo_of_a_cat_gives_the_standard_t5_ids_then_padding() {
        let tok = T5Tokenizer::builtin(77).expect("builtin tokenizer");
        let t = tok.encode("a photo of a cat").expect("encode");
        assert_eq!(&t.input_ids[..8], &[3, 9, 1202, 13, 3, 9, 1712, 1]);
        assert!(t.input_ids[8..].iter().all(|&i| i == PAD_ID));
        assert_eq!(t.input_ids.len(), 77);
        assert_eq!(t.attention_mask.iter().sum::<i64>(), 8);
        assert!(t.attention_mask[..8].iter().all(|&m| m == 1));
    }

    #[test]
    fn case_and_surrounding_space_do_not_matter() {
        let tok = T5Tokenizer::builtin(77).expect("builtin tokenizer");
        assert_eq!(
            tok.encode("  A Photo of a CAT \n").ok(),
            tok.encode("a photo of a cat").ok()
        );
    }

    #[test]
    fn empty_prompt_is_just_end_of_sequence() {
        let tok = T5Tokenizer::builtin(77).expect("builtin tokenizer");
        let t = tok.encode("").expect("encode");
        assert_eq!(t.input_ids[0], EOS_ID);
        assert_eq!(t.attention_mask.iter().sum::<i64>(), 1);
    }

    #[test]
    fn long_prompts_are_truncated_and_still_end_with_eos() {
        let tok = T5Tokenizer::builtin(77).expect("builtin tokenizer");
        let long = "a very ornate wooden chair ".repeat(40);
        let t = tok.encode(&long).expect("encode");
        assert_eq!(t.input_ids.len(), 77);
        assert_eq!(t.input_ids[76], EOS_ID);
        assert!(t.attention_mask.iter().all(|&m| m == 1));
        // The dropped tokens are those past the 76 content tokens `encode` keeps.
        let dropped = tok.dropped_tokens(&long).expect("count");
        assert!(dropped > 100, "{dropped}");
        assert_eq!(tok.content_ids(&long).expect("ids").len(), dropped + 76);
        assert_eq!(tok.dropped_tokens("a photo of a cat").ok(), Some(0));
        let exact = "cat ".repeat(76);
        let n = tok.content_ids(&exact).expect("ids").len();
        assert_eq!(tok.dropped_tokens(&exact).ok(), Some(n.saturating_sub(76)));
    }
}

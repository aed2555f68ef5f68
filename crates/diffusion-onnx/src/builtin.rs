//! Assets compiled into the crate (see `assets/README.md` for provenance and licenses).

use std::path::Path;

use crate::OnnxError;
use crate::npy::parse_npy;

/// The T5 / T5-v1.1 `tokenizers` JSON (32,100 tokens, Unigram, appends `</s>` = 1, pad 0).
pub const T5_TOKENIZER_JSON: &[u8] = include_bytes!("../assets/t5_tokenizer.json");

/// DeepFloyd IF's T5-v1.1-XXL encoding of the empty prompt, f16 `(77, 4096)` `.npy`.
pub const IF_EMPTY_PROMPT_NPY: &[u8] = include_bytes!("../assets/zero_t5-v1_1-xxl_vector.npy");

/// Tokens of IF's empty-prompt embedding (77).
pub const IF_UNCOND_TOKENS: usize = 77;
/// Width of IF's empty-prompt embedding (4096, T5-v1.1-XXL).
pub const IF_UNCOND_DIM: usize = 4096;

/// IF's unconditional embedding `(77, 4096)`, widened to f32.
pub fn if_empty_prompt_embedding() -> Result<csd::Embedding, OnnxError> {
    let path = Path::new("<builtin zero_t5-v1_1-xxl_vector.npy>");
    let arr = parse_npy(IF_EMPTY_PROMPT_NPY, path)?;
    let data = arr.to_f32().ok_or_else(|| OnnxError::Npy {
        path: path.to_path_buf(),
        message: "not float data".into(),
    })?;
    if arr.shape != [IF_UNCOND_TOKENS, IF_UNCOND_DIM] {
        return Err(OnnxError::Npy {
            path: path.to_path_buf(),
            message: format!("unexpected shape {:?}", arr.shape),
        });
    }
    OnnxError::check_finite(
        &data,
        || "IF's built-in empty-prompt embedding".into(),
        path,
        "this build's copy is damaged; rebuild from a clean checkout",
    )?;
    Ok(csd::Embedding {
        shape: [IF_UNCOND_TOKENS, IF_UNCOND_DIM],
        data,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn builtin_if_uncond_is_finite_nonzero_77_by_4096() {
        let e = if_empty_prompt_embedding().expect("builtin embedding parses");
        assert_eq!(e.shape, [77, 4096]);
        assert!(e.data.iter().all(|v| v.is_finite()));
        let norm: f64 = e
            .data
            .iter()
            .map(|&v| f64::from(v) * f64::from(v))
            .sum::<f64>()
            .sqrt();
        assert!(norm > 1.0, "an encoder output, not zeros: |e| = {norm}");
    }
}

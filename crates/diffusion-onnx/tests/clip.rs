//! CLIP through ONNX Runtime against PyTorch: the tiny CLIP fixture in `fixtures/models/tiny-clip` and
//! the reference inputs/outputs written when it was exported (see fixtures/models/README.md).
//!
//! Needs the ONNX Runtime library: run `scripts/setup-onnxruntime.sh` (or set ORT_DYLIB_PATH).
//!
//! Tolerances:
//! - preprocessing (Rust bicubic resize + normalize vs PIL's float-mode BICUBIC + numpy): 1e-4 absolute
//!   on normalized values (both compute in f32/f64; differences are rounding only);
//! - embeddings: max abs difference ≤ 1e-4 + 1e-4 · max |reference| (ONNX Runtime vs PyTorch fp32;
//!   the exporter measured ~1e-6).

use std::path::{Path, PathBuf};

use diffusion_onnx::clip::{ClipModel, ClipTokenizer, preprocess, read_clip_manifest};
use diffusion_onnx::npy::read_npy;
use diffusion_onnx::{OnnxError, SessionOptions, cosine_similarity};

const TOL: (f32, f32) = (1e-4, 1e-4);

fn tiny() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../../fixtures/models/tiny-clip")
}

fn reference(name: &str) -> diffusion_onnx::npy::NpyArray {
    read_npy(tiny().join("reference").join(format!("{name}.npy"))).expect("reference array")
}

fn ref_f32(name: &str) -> (Vec<usize>, Vec<f32>) {
    let a = reference(name);
    let v = a.to_f32().expect("float reference");
    (a.shape, v)
}

fn prompts() -> Vec<String> {
    let text =
        std::fs::read_to_string(tiny().join("reference/prompts.json")).expect("prompts.json");
    // A JSON array of strings; parsed by hand to keep serde_json out of this crate's dev-dependencies.
    let inner = text.trim().trim_start_matches('[').trim_end_matches(']');
    inner
        .split("\",")
        .map(|s| {
            s.trim()
                .trim_start_matches('"')
                .trim_end_matches('"')
                .to_string()
        })
        .collect()
}

fn options() -> SessionOptions {
    SessionOptions {
        intra_threads: Some(1),
        ..SessionOptions::default()
    }
}

fn open() -> ClipModel {
    ClipModel::open(tiny(), &options()).unwrap_or_else(|e| panic!("open tiny-clip: {e}"))
}

fn assert_close(got: &[f32], want: &[f32], (atol, rtol): (f32, f32), what: &str) {
    assert_eq!(got.len(), want.len(), "{what}: length");
    let scale = want.iter().fold(0.0f32, |m, v| m.max(v.abs()));
    let err = got
        .iter()
        .zip(want)
        .fold(0.0f32, |m, (a, b)| m.max((a - b).abs()));
    let tol = atol + rtol * scale;
    assert!(
        got.iter().all(|v| v.is_finite()) && err <= tol,
        "{what}: max |rust − torch| = {err:e} > {tol:e}"
    );
}

#[test]
fn tokenizer_matches_the_reference_ids() {
    let tok = ClipTokenizer::builtin().expect("tokenizer");
    let want = reference("input_ids");
    let want = want.as_i64().expect("i64 ids");
    let prompts = prompts();
    assert_eq!(prompts.len() * 77, want.len(), "prompt count");
    for (i, p) in prompts.iter().enumerate() {
        let got = tok.encode(p).expect("encode");
        assert_eq!(got, &want[i * 77..(i + 1) * 77], "prompt {p:?}");
    }
}

#[test]
fn text_embeddings_match_pytorch() {
    let mut clip = open();
    let prompts = prompts();
    let refs: Vec<&str> = prompts.iter().map(String::as_str).collect();
    let got = clip.embed_texts(&refs).expect("embed_texts");
    let (shape, want) = ref_f32("text_embeds");
    assert_eq!(shape, [prompts.len(), clip.embedding_dim()]);
    assert_close(&got.concat(), &want, TOL, "text embeddings");
    // Batching does not change a prompt's embedding.
    let single = clip.embed_texts(&refs[1..2]).expect("one prompt");
    assert_close(&single[0], &got[1], (1e-6, 1e-6), "batch of one");
    assert!(clip.embed_texts(&[]).expect("empty").is_empty());
}

#[test]
fn preprocessing_matches_pil_bicubic_and_normalization() {
    let clip = open();
    let m = &clip.manifest().image_encoder;
    let (s_big, big) = ref_f32("images_resized");
    let (s_exact, exact) = ref_f32("images_exact");
    let (_, pixel_values) = ref_f32("pixel_values");
    let mut got =
        preprocess(&big, s_big[0], s_big[1], m.image_size, m.mean, m.std).expect("preprocess");
    assert!(
        s_big[1] != m.image_size,
        "the reference must exercise the resize"
    );
    got.extend(
        preprocess(&exact, s_exact[0], s_exact[1], m.image_size, m.mean, m.std)
            .expect("preprocess"),
    );
    assert_close(&got, &pixel_values, (1e-4, 0.0), "pixel_values");
    assert!(preprocess(&big[1..], s_big[0], s_big[1], m.image_size, m.mean, m.std).is_err());
}

#[test]
fn image_embeddings_match_pytorch_for_resized_and_exact_sizes() {
    let mut clip = open();
    let (s_big, big) = ref_f32("images_resized");
    let (s_exact, exact) = ref_f32("images_exact");
    let (shape, want) = ref_f32("image_embeds");
    assert_eq!(shape, [s_big[0] + s_exact[0], clip.embedding_dim()]);
    let mut got = clip
        .embed_images(&big, s_big[0], s_big[1])
        .expect("resized images");
    got.extend(
        clip.embed_images(&exact, s_exact[0], s_exact[1])
            .expect("exact-size image"),
    );
    assert_close(&got.concat(), &want, TOL, "image embeddings");
    // Deterministic.
    let again = clip.embed_images(&big, s_big[0], s_big[1]).expect("again");
    assert_eq!(again, got[..2].to_vec());
    // A cosine between them is a number in [−1, 1].
    let c = cosine_similarity(
        &got[0],
        &clip.embed_texts(&["a photo of a cat"]).expect("t")[0],
    );
    assert!((-1.0..=1.0).contains(&c), "{c}");
}

#[test]
fn bad_image_input_is_an_error_not_a_panic() {
    let mut clip = open();
    let err = clip
        .embed_images(&[0.5; 10], 1, 4)
        .expect_err("wrong length");
    assert!(
        matches!(err, OnnxError::Shape { .. }) && err.to_string().contains("side 4"),
        "{err}"
    );
    let mut nan = vec![0.5f32; 2 * 2 * 3];
    nan[3] = f32::NAN;
    let err = clip.embed_images(&nan, 1, 2).expect_err("NaN");
    assert!(err.to_string().contains("non-finite"), "{err}");
    assert!(clip.embed_images(&[], 0, 8).expect("no images").is_empty());
}

/// A copy of the fixture in a temporary directory, with `edit` applied to the manifest text.
fn broken_copy(edit: impl Fn(&str) -> String) -> tempfile::TempDir {
    let dir = tempfile::tempdir().expect("tempdir");
    for f in ["image_encoder.onnx", "text_encoder.onnx"] {
        std::fs::copy(tiny().join(f), dir.path().join(f)).expect("copy");
    }
    let manifest = std::fs::read_to_string(tiny().join("manifest.toml")).expect("manifest");
    std::fs::write(dir.path().join("manifest.toml"), edit(&manifest)).expect("write");
    dir
}

fn open_err(dir: &Path) -> String {
    match ClipModel::open(dir, &options()) {
        Ok(_) => panic!("{} must not open", dir.display()),
        Err(e) => e.to_string(),
    }
}

#[test]
fn a_faithful_copy_opens() {
    let dir = broken_copy(str::to_string);
    assert!(read_clip_manifest(dir.path()).is_ok());
}

#[test]
fn missing_directory_or_manifest_says_how_to_make_one() {
    let tmp = tempfile::tempdir().expect("tempdir");
    let msg = open_err(&tmp.path().join("nope"));
    assert!(
        msg.contains("not a directory") && msg.contains("export_clip_onnx.py"),
        "{msg}"
    );
    let msg = open_err(tmp.path());
    assert!(
        msg.contains("manifest.toml") && msg.contains("export_clip_onnx.py"),
        "{msg}"
    );
}

#[test]
fn an_if_model_directory_is_not_a_clip_model() {
    let if_dir = tiny().join("../tiny-if");
    let msg = open_err(&if_dir);
    assert!(msg.contains("not a CLIP manifest"), "{msg}");
}

#[test]
fn missing_model_file_is_named() {
    let dir = broken_copy(str::to_string);
    std::fs::remove_file(dir.path().join("text_encoder.onnx")).expect("rm");
    let msg = open_err(dir.path());
    assert!(
        msg.contains("text encoder model")
            && msg.contains("text_encoder.onnx")
            && msg.contains("missing"),
        "{msg}"
    );
}

#[test]
fn sha256_mismatch_is_reported() {
    let dir = broken_copy(str::to_string);
    let path = dir.path().join("image_encoder.onnx");
    let mut bytes = std::fs::read(&path).expect("read");
    let last = bytes.len() - 1;
    bytes[last] ^= 1;
    std::fs::write(&path, bytes).expect("write");
    let msg = open_err(dir.path());
    assert!(
        msg.contains("SHA-256") && msg.contains("image_encoder.onnx"),
        "{msg}"
    );
}

#[test]
fn shapes_that_disagree_with_the_graph_are_reported() {
    let dir = broken_copy(|m| m.replace("image_size = 32", "image_size = 224"));
    let msg = open_err(dir.path());
    assert!(msg.contains("pixel_values") && msg.contains("224"), "{msg}");
    let dir = broken_copy(|m| m.replace("embedding_dim = 8", "embedding_dim = 512"));
    let msg = open_err(dir.path());
    assert!(msg.contains("512") && msg.contains("embeds"), "{msg}");
    let dir = broken_copy(|m| m.replace("output = \"text_embeds\"", "output = \"pooled\""));
    let msg = open_err(dir.path());
    assert!(
        msg.contains("pooled") && msg.contains("text_embeds"),
        "{msg}"
    );
}

#[test]
fn wrong_format_version_and_bad_std_are_rejected() {
    let dir = broken_copy(|m| m.replace("format_version = 1", "format_version = 2"));
    let msg = open_err(dir.path());
    assert!(msg.contains("format_version = 2"), "{msg}");
    let dir = broken_copy(|m| m.replace("std = [0.26862954", "std = [0.0"));
    let msg = open_err(dir.path());
    assert!(msg.contains("std"), "{msg}");
}

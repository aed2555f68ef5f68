//! The ONNX path against PyTorch: the tiny IF-architecture fixtures in `fixtures/models/` and the
//! reference inputs/outputs PyTorch produced when they were exported (see fixtures/models/README.md).
//!
//! Needs the ONNX Runtime library: run `scripts/setup-onnxruntime.sh` (or set ORT_DYLIB_PATH).
//!
//! Tolerances (max abs difference ≤ atol + rtol · max |reference|):
//! - fp32 models: atol = rtol = 1e-4 (ONNX Runtime and PyTorch differ by ~3e-6 here),
//! - fp16 models (same weights rounded to half) against the fp32 reference: atol = rtol = 2e-2.

use std::path::{Path, PathBuf};

use csd::{Denoiser, Embedding, TextEmbedding};
use diffusion_onnx::npy::read_npy;
use diffusion_onnx::{
    EmbeddingCache, ModelDir, OnnxDenoiser, OnnxError, SessionOptions, Stage, T5Encoder,
    T5Tokenizer, prompt_embeddings,
};

const FP32_TOL: (f32, f32) = (1e-4, 1e-4);
const FP16_TOL: (f32, f32) = (2e-2, 2e-2);

fn fixtures() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../../fixtures/models")
}

fn tiny() -> PathBuf {
    fixtures().join("tiny-if")
}

fn reference(name: &str) -> diffusion_onnx::npy::NpyArray {
    read_npy(tiny().join("reference").join(format!("{name}.npy"))).expect("reference array")
}

fn ref_f32(name: &str) -> (Vec<usize>, Vec<f32>) {
    let a = reference(name);
    let v = a.to_f32().expect("float reference");
    (a.shape, v)
}

fn ref_i64(name: &str) -> Vec<i64> {
    reference(name).as_i64().expect("int reference").to_vec()
}

fn options() -> SessionOptions {
    SessionOptions {
        intra_threads: Some(1),
        ..SessionOptions::default()
    }
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
        got.iter().all(|v| v.is_finite()),
        "{what}: non-finite output"
    );
    assert!(
        err <= tol,
        "{what}: max |rust − pytorch| = {err:e} > {tol:e}"
    );
    // Guard against a vacuous comparison (e.g. all zeros on both sides).
    assert!(
        scale > 0.1,
        "{what}: reference is unexpectedly small ({scale})"
    );
}

fn embeddings_from(name: &str) -> Vec<Embedding> {
    let (shape, data) = ref_f32(name);
    let (t, d) = (shape[1], shape[2]);
    data.chunks_exact(t * d)
        .map(|c| Embedding {
            shape: [t, d],
            data: c.to_vec(),
        })
        .collect()
}

fn run_stage(dir: &Path, stage: Stage, tol: (f32, f32)) {
    let model = ModelDir::open(dir).expect("model dir");
    let mut unet = OnnxDenoiser::open(&model, stage, &options()).expect("open UNet");
    let key = stage.key();
    let (shape, sample) = ref_f32(&format!("{key}_sample"));
    let t = ref_i64(&format!("{key}_timestep"));
    let emb = embeddings_from(&format!("{key}_encoder_hidden_states"));
    let refs: Vec<&Embedding> = emb.iter().collect();
    let labels = (stage == Stage::Two).then(|| ref_i64("stage2_class_labels"));
    let out = unet
        .predict(
            &csd::Tensor {
                shape,
                data: sample,
            },
            &t,
            &refs,
            labels.as_deref(),
        )
        .expect("predict");
    let (want_shape, want) = ref_f32(&format!("{key}_noise_pred"));
    assert_eq!(out.shape, want_shape);
    assert_close(&out.data, &want, tol, &format!("{} {key}", dir.display()));
}

#[test]
fn stage1_fp32_reproduces_pytorch_reference() {
    run_stage(&tiny(), Stage::One, FP32_TOL);
}

#[test]
fn stage2_fp32_with_noise_level_labels_reproduces_pytorch_reference() {
    run_stage(&tiny(), Stage::Two, FP32_TOL);
}

#[test]
fn fp16_models_with_external_data_reproduce_fp32_reference_to_half_precision() {
    let dir = fixtures().join("tiny-if-fp16");
    run_stage(&dir, Stage::One, FP16_TOL);
    run_stage(&dir, Stage::Two, FP16_TOL);
    let model = ModelDir::open(&dir).expect("model dir");
    let mut t5 = T5Encoder::open(&model, &options()).expect("open encoder");
    let got = t5
        .embed_batch(&["a photo of a cat", "  A Wooden CHAIR, Ornate!  "])
        .expect("embed");
    let flat: Vec<f32> = got.iter().flat_map(|e| e.data.iter().copied()).collect();
    assert_close(
        &flat,
        &ref_f32("t5_last_hidden_state").1,
        FP16_TOL,
        "fp16 text encoder",
    );
}

#[test]
fn tokenizer_matches_the_ids_pytorch_was_fed() {
    let tok = T5Tokenizer::builtin(77).expect("tokenizer");
    let ids = ref_i64("t5_input_ids");
    let mask = ref_i64("t5_attention_mask");
    for (i, p) in ["a photo of a cat", "  A Wooden CHAIR, Ornate!  "]
        .iter()
        .enumerate()
    {
        let t = tok.encode(p).expect("encode");
        assert_eq!(t.input_ids, ids[i * 77..(i + 1) * 77], "ids of {p:?}");
        assert_eq!(
            t.attention_mask,
            mask[i * 77..(i + 1) * 77],
            "mask of {p:?}"
        );
    }
}

#[test]
fn text_encoder_fp32_reproduces_pytorch_reference() {
    let model = ModelDir::open(tiny()).expect("model dir");
    let mut t5 = T5Encoder::open(&model, &options()).expect("open encoder");
    let got = t5
        .embed_batch(&["a photo of a cat", "  A Wooden CHAIR, Ornate!  "])
        .expect("embed");
    let flat: Vec<f32> = got.iter().flat_map(|e| e.data.iter().copied()).collect();
    assert_close(
        &flat,
        &ref_f32("t5_last_hidden_state").1,
        FP32_TOL,
        "text encoder",
    );
    // The trait path gives the same as the batch path.
    let one = t5.embed("a photo of a cat").expect("embed one");
    assert_close(&one.data, &got[0].data, FP32_TOL, "single vs batch");
}

#[test]
fn uncond_embedding_is_the_encoders_empty_prompt_output() {
    let model = ModelDir::open(tiny()).expect("model dir");
    let stored = model.uncond_embedding().expect("uncond");
    let mut t5 = T5Encoder::open(&model, &options()).expect("open encoder");
    let fresh = t5.embed("").expect("embed empty");
    assert_eq!(stored.shape, fresh.shape);
    assert_close(&fresh.data, &stored.data, FP32_TOL, "uncond");
}

#[test]
fn batched_cond_and_uncond_halves_equal_separate_calls() {
    let model = ModelDir::open(tiny()).expect("model dir");
    let mut unet = OnnxDenoiser::open(&model, Stage::One, &options()).expect("open UNet");
    let (shape, sample) = ref_f32("stage1_sample");
    let emb = embeddings_from("stage1_encoder_hidden_states");
    let uncond = model.uncond_embedding().expect("uncond");
    // One 2B batch: [cond0, cond1, uncond, uncond] on [x0, x1, x0, x1], as csd sends it.
    let per = shape[1] * shape[2] * shape[3];
    let mut batch = sample.clone();
    batch.extend_from_slice(&sample);
    let t = [500i64, 30, 500, 30];
    let both = unet
        .predict(
            &csd::Tensor {
                shape: vec![4, shape[1], shape[2], shape[3]],
                data: batch,
            },
            &t,
            &[&emb[0], &emb[1], &uncond, &uncond],
            None,
        )
        .expect("batched");
    let out_per = both.data.len() / 4;
    for (i, e) in [&emb[0], &emb[1], &uncond, &uncond].iter().enumerate() {
        let x = &sample[(i % 2) * per..(i % 2 + 1) * per];
        let single = unet
            .predict(
                &csd::Tensor {
                    shape: vec![1, shape[1], shape[2], shape[3]],
                    data: x.to_vec(),
                },
                &t[i..=i],
                &[e],
                None,
            )
            .expect("single");
        assert_close(
            &both.data[i * out_per..(i + 1) * out_per],
            &single.data,
            (1e-5, 1e-5),
            &format!("sample {i}"),
        );
    }
    // Conditioning matters: cond and uncond predictions differ.
    let d: f32 = both.data[..out_per]
        .iter()
        .zip(&both.data[2 * out_per..3 * out_per])
        .map(|(a, b)| (a - b).abs())
        .sum();
    assert!(d > 1e-3, "text conditioning has no effect ({d})");
}

#[test]
fn stage2_runs_at_native_256px_on_a_batch_of_16() {
    let model = ModelDir::open(tiny()).expect("model dir");
    let mut unet = OnnxDenoiser::open(&model, Stage::Two, &options()).expect("open UNet");
    let n = 16;
    let data: Vec<f32> = (0..n * 6 * 256 * 256)
        .map(|i| ((i % 997) as f32 / 498.0) - 1.0)
        .collect();
    let e = model.uncond_embedding().expect("uncond");
    let embs = vec![&e; n];
    let t: Vec<i64> = (0..n as i64).map(|i| 20 + 60 * i).collect();
    let s: Vec<i64> = (0..n as i64).map(|i| 980 - 60 * i).collect();
    let out = unet
        .predict(
            &csd::Tensor {
                shape: vec![n, 6, 256, 256],
                data,
            },
            &t,
            &embs,
            Some(&s),
        )
        .expect("predict");
    assert_eq!(out.shape, vec![n, 6, 256, 256]);
    assert!(out.data.iter().all(|v| v.is_finite()));
}

// ---------------------------------------------------------------------------------------------
// Errors users will hit
// ---------------------------------------------------------------------------------------------

fn copy_dir(from: &Path, to: &Path) {
    std::fs::create_dir_all(to).expect("mkdir");
    for entry in std::fs::read_dir(from).expect("read_dir") {
        let entry = entry.expect("entry");
        let p = entry.path();
        if p.is_dir() {
            copy_dir(&p, &to.join(entry.file_name()));
        } else {
            std::fs::copy(&p, to.join(entry.file_name())).expect("copy");
        }
    }
}

/// A temporary copy of a fixture with `edit` applied to its manifest text.
fn edited(fixture: &str, edit: impl Fn(String) -> String) -> tempfile::TempDir {
    let tmp = tempfile::tempdir().expect("tempdir");
    copy_dir(&fixtures().join(fixture), tmp.path());
    let m = tmp.path().join("manifest.toml");
    let text = std::fs::read_to_string(&m).expect("manifest");
    std::fs::write(&m, edit(text)).expect("write manifest");
    tmp
}

fn err_text<T: std::fmt::Debug>(r: Result<T, OnnxError>) -> String {
    match r {
        Ok(v) => panic!("expected an error, got {v:?}"),
        Err(e) => e.to_string(),
    }
}

#[test]
fn missing_model_file_names_the_file_and_what_to_do() {
    let tmp = edited("tiny-if", |s| s);
    std::fs::remove_file(tmp.path().join("unet_stage2.onnx")).expect("rm");
    let msg = err_text(ModelDir::open(tmp.path()));
    assert!(
        msg.contains("unet_stage2.onnx")
            && msg.contains("stage2 model")
            && msg.contains("export_if_onnx"),
        "{msg}"
    );
}

#[test]
fn missing_manifest_says_how_model_dirs_are_made() {
    let tmp = tempfile::tempdir().expect("tempdir");
    let msg = err_text(ModelDir::open(tmp.path()));
    assert!(
        msg.contains("manifest.toml") && msg.contains("export_if_onnx.py"),
        "{msg}"
    );
}

#[test]
fn missing_declared_external_data_is_caught_before_loading() {
    let tmp = edited("tiny-if-fp16", |s| s);
    std::fs::remove_file(tmp.path().join("unet_stage1.onnx.data")).expect("rm");
    let msg = err_text(ModelDir::open(tmp.path()));
    assert!(
        msg.contains("unet_stage1.onnx.data")
            && msg.contains("external data")
            && msg.contains("2 GB"),
        "{msg}"
    );
}

#[test]
fn undeclared_missing_external_data_fails_at_load_with_a_hint() {
    let tmp = edited("tiny-if-fp16", |s| {
        s.replace(
            "external_data = [\"unet_stage1.onnx.data\"]",
            "external_data = []",
        )
    });
    std::fs::remove_file(tmp.path().join("unet_stage1.onnx.data")).expect("rm");
    let model = ModelDir::open(tmp.path()).expect("manifest itself is fine");
    let msg = err_text(OnnxDenoiser::open(&model, Stage::One, &options()));
    assert!(
        msg.contains("external data") && msg.contains("unet_stage1.onnx.data"),
        "{msg}"
    );
}

#[test]
fn wrong_input_name_lists_the_graphs_real_names() {
    let tmp = edited("tiny-if", |s| {
        s.replacen("sample = \"sample\"", "sample = \"x\"", 1)
    });
    let model = ModelDir::open(tmp.path()).expect("manifest parses");
    let msg = err_text(OnnxDenoiser::open(&model, Stage::One, &options()));
    assert!(msg.contains("`x`") && msg.contains("\"sample\""), "{msg}");
}

#[test]
fn fp16_manifest_on_fp32_graph_is_a_dtype_mismatch_with_the_fix() {
    let tmp = edited("tiny-if", |s| {
        s.replace("dtype = \"fp32\"", "dtype = \"fp16\"")
    });
    let model = ModelDir::open(tmp.path()).expect("manifest parses");
    let msg = err_text(OnnxDenoiser::open(&model, Stage::One, &options()));
    assert!(
        msg.contains("fp16") && msg.contains("dtype = \"fp32\""),
        "{msg}"
    );
    let msg = err_text(T5Encoder::open(&model, &options()));
    assert!(msg.contains("dtype = \"fp32\""), "{msg}");
}

#[test]
fn wrong_shapes_are_errors_that_say_what_was_expected() {
    let model = ModelDir::open(tiny()).expect("model dir");
    let mut s1 = OnnxDenoiser::open(&model, Stage::One, &options()).expect("open");
    let e = model.uncond_embedding().expect("uncond");
    let x = |c: usize| csd::Tensor {
        shape: vec![1, c, 8, 8],
        data: vec![0.0; c * 64],
    };
    let msg = err_text(s1.run(&x(6), &[10], &[&e], None));
    assert!(
        msg.contains("6 channels") && msg.contains("takes 3"),
        "{msg}"
    );
    let msg = err_text(s1.run(&x(3), &[10, 20], &[&e], None));
    assert!(msg.contains("timesteps"), "{msg}");
    let wrong = Embedding {
        shape: [77, 4096],
        data: vec![0.0; 77 * 4096],
    };
    let msg = err_text(s1.run(&x(3), &[10], &[&wrong], None));
    assert!(msg.contains("(77, 8)"), "{msg}");
    let msg = err_text(s1.run(&x(3), &[10], &[&e], Some(&[5])));
    assert!(msg.contains("no class labels"), "{msg}");
    let mut s2 = OnnxDenoiser::open(&model, Stage::Two, &options()).expect("open");
    let msg = err_text(s2.run(&x(6), &[10], &[&e], None));
    assert!(msg.contains("class labels"), "{msg}");
    let bad = csd::Tensor {
        shape: vec![1, 3, 8, 8],
        data: vec![0.0; 5],
    };
    assert!(s1.run(&bad, &[10], &[&e], None).is_err());
}

#[test]
fn builtin_if_uncond_on_a_non_xxl_encoder_is_refused() {
    let tmp = edited("tiny-if", |s| {
        s.replace(
            "uncond = \"uncond_embedding.npy\"",
            "uncond = \"builtin:if-t5-v1_1-xxl-empty\"",
        )
    });
    let msg = err_text(ModelDir::open(tmp.path()));
    assert!(
        msg.contains("4096") && msg.contains("uncond_embedding.npy"),
        "{msg}"
    );
}

#[test]
fn stage1_with_class_labels_or_stage2_without_is_refused() {
    let tmp = edited("tiny-if", |s| {
        s.replace("class_labels = \"class_labels\"\n", "")
    });
    let msg = err_text(ModelDir::open(tmp.path()));
    assert!(msg.contains("class_labels"), "{msg}");
}

#[test]
fn cached_embeddings_serve_a_directory_without_text_encoder() {
    let cache_dir = tempfile::tempdir().expect("tempdir");
    let cache = EmbeddingCache::new(cache_dir.path());
    let model = ModelDir::open(tiny()).expect("model dir");
    let (cond, uncond) =
        prompt_embeddings(&model, "a photo of a cat", "", Some(&cache), &options())
            .expect("embeddings");
    assert_eq!(uncond, model.uncond_embedding().expect("uncond"));
    let identity = cache.identity(&model).expect("identity");
    assert!(cache.path(&identity, "a photo of a cat").is_file());
    let want = &ref_f32("t5_last_hidden_state").1[..77 * 8];
    assert_close(&cond.data, want, FP32_TOL, "cached cond");

    // Same model name, no encoder: the cache answers, an unknown prompt is a clear error.
    let tmp = edited("tiny-if", |s| {
        let start = s.find("[text_encoder]").expect("section");
        let end = s.find("[embeddings]").expect("section");
        format!("{}{}", &s[..start], &s[end..])
    });
    std::fs::remove_file(tmp.path().join("text_encoder.onnx")).expect("rm");
    let lean = ModelDir::open(tmp.path()).expect("lean model dir");
    let (again, _) = prompt_embeddings(&lean, "A photo of a cat ", "", Some(&cache), &options())
        .expect("from cache");
    assert_eq!(again, cond);
    let msg = err_text(prompt_embeddings(
        &lean,
        "a dog",
        "",
        Some(&cache),
        &options(),
    ));
    assert!(
        msg.contains("no [text_encoder]") && msg.contains("stylize embed"),
        "{msg}"
    );
}

// ---------------------------------------------------------------------------------------------
// Non-finite embeddings and the encoder's identity in the cache
// ---------------------------------------------------------------------------------------------

fn write_f32_npy(path: &Path, shape: Vec<usize>, data: Vec<f32>) {
    diffusion_onnx::npy::write_npy(
        path,
        &diffusion_onnx::npy::NpyArray {
            shape,
            data: diffusion_onnx::npy::NpyData::F32(data),
        },
    )
    .expect("write npy");
}

#[test]
fn all_nan_unconditional_embedding_is_an_error_naming_the_file() {
    let tmp = edited("tiny-if", |s| s);
    let file = tmp.path().join("uncond_embedding.npy");
    write_f32_npy(&file, vec![77, 8], vec![f32::NAN; 77 * 8]);
    let model = ModelDir::open(tmp.path()).expect("model dir");
    let err = model
        .uncond_embedding()
        .expect_err("NaN embedding accepted");
    assert!(
        matches!(&err, OnnxError::NonFinite { count: 616, total: 616, path, .. } if *path == file),
        "{err:?}"
    );
    // The empty negative prompt goes through the same file in `prompt_embeddings`.
    let msg = err_text(prompt_embeddings(&model, "a cat", "", None, &options()));
    assert!(
        msg.contains("unconditional")
            && msg.contains("uncond_embedding.npy")
            && msg.contains("616 non-finite"),
        "{msg}"
    );
}

#[test]
fn nan_cached_embedding_is_an_error_naming_the_entry() {
    let cache_dir = tempfile::tempdir().expect("tempdir");
    let cache = EmbeddingCache::new(cache_dir.path());
    let model = ModelDir::open(tiny()).expect("model dir");
    let identity = cache.identity(&model).expect("identity");
    let mut data = vec![0.5f32; 77 * 8];
    data[10] = f32::NAN;
    data[11] = f32::INFINITY;
    cache
        .put(
            &identity,
            "a photo of a cat",
            &Embedding {
                shape: [77, 8],
                data,
            },
        )
        .expect("put");
    let msg = err_text(prompt_embeddings(
        &model,
        "a photo of a cat",
        "",
        Some(&cache),
        &options(),
    ));
    let entry = cache.path(&identity, "a photo of a cat");
    assert!(
        msg.contains("cached embedding")
            && msg.contains("a photo of a cat")
            && msg.contains(&entry.display().to_string())
            && msg.contains("2 non-finite")
            && msg.contains("delete"),
        "{msg}"
    );
}

#[test]
fn replacing_the_text_encoder_under_the_same_name_never_serves_stale_embeddings() {
    let cache_dir = tempfile::tempdir().expect("tempdir");
    let cache = EmbeddingCache::new(cache_dir.path());
    let tmp = edited("tiny-if", |s| s);
    let model = ModelDir::open(tmp.path()).expect("model dir");
    let (old, _) = prompt_embeddings(&model, "a photo of a cat", "", Some(&cache), &options())
        .expect("fp32 encoder");
    let old_identity = cache.identity(&model).expect("identity");

    // Same `name`, new weights: the fp16 export of the encoder (different bytes, close outputs).
    for f in ["text_encoder.onnx", "text_encoder.onnx.data"] {
        std::fs::copy(fixtures().join("tiny-if-fp16").join(f), tmp.path().join(f)).expect("copy");
    }
    let m = tmp.path().join("manifest.toml");
    let text = std::fs::read_to_string(&m).expect("manifest");
    let text = text.replacen(
        "external_data = []\ndtype = \"fp32\"",
        "external_data = [\"text_encoder.onnx.data\"]\ndtype = \"fp16\"",
        1,
    );
    assert!(text.contains("text_encoder.onnx.data"), "manifest edit");
    std::fs::write(&m, text).expect("write manifest");
    let model = ModelDir::open(tmp.path()).expect("model dir");
    assert_eq!(
        model.text_identity(),
        ModelDir::open(tiny()).expect("dir").text_identity()
    );
    let new_identity = cache.identity(&model).expect("identity");
    assert_ne!(new_identity, old_identity);
    let (new, _) = prompt_embeddings(&model, "a photo of a cat", "", Some(&cache), &options())
        .expect("fp16 encoder");
    let fresh = T5Encoder::open(&model, &options())
        .expect("open")
        .embed_batch(&["a photo of a cat"])
        .expect("embed");
    assert_eq!(Some(&new), fresh.first(), "the new encoder's output");
    assert_ne!(new, old, "fp16 and fp32 encoders differ in the last bits");

    // Bytes replaced in place (same size, same name): the memoized digest is not trusted.
    let onnx = tmp.path().join("text_encoder.onnx");
    let mut bytes = std::fs::read(&onnx).expect("read");
    bytes.iter_mut().for_each(|b| *b = 0);
    std::fs::write(&onnx, &bytes).expect("write");
    assert_ne!(cache.identity(&model).expect("identity"), new_identity);
    let msg = err_text(prompt_embeddings(
        &model,
        "a photo of a cat",
        "",
        Some(&cache),
        &options(),
    ));
    assert!(msg.contains("text encoder"), "{msg}");
}

#[test]
fn denoiser_describes_itself_with_its_model_file() {
    use csd::Denoiser as _;
    let model = ModelDir::open(tiny()).expect("model dir");
    let unet = OnnxDenoiser::open(&model, Stage::Two, &options()).expect("open UNet");
    let d = unet.describe();
    assert!(
        d.contains("stage2 UNet") && d.contains("unet_stage2.onnx") && d.contains("fp32"),
        "{d}"
    );
}

/// The low-memory settings (arena, memory pattern and pre-packing off, the batch split into calls
/// of `max_batch` samples) give the whole-batch result: stage II with its per-sample class labels,
/// on a batch of 5 split into 1 + … and 2 + 2 + 1 (a ragged last chunk), and the PyTorch reference.
#[test]
fn low_memory_options_and_split_batches_match_the_whole_batch_call() {
    let model = ModelDir::open(tiny()).expect("model dir");
    let (shape, sample) = ref_f32("stage2_sample");
    let emb = embeddings_from("stage2_encoder_hidden_states");
    let uncond = model.uncond_embedding().expect("uncond");
    let per = shape[1] * shape[2] * shape[3];
    // 5 samples: x0, x1, x0, x1, x0 with distinct timesteps, labels and embeddings.
    let mut data = Vec::new();
    for i in 0..5 {
        data.extend_from_slice(&sample[(i % 2) * per..(i % 2 + 1) * per]);
    }
    let x = csd::Tensor {
        shape: vec![5, shape[1], shape[2], shape[3]],
        data,
    };
    let t = [20i64, 980, 500, 30, 700];
    let labels = [250i64, 0, 100, 20, 0];
    let embs = [&emb[0], &emb[1], &uncond, &uncond, &emb[1]];
    let mut whole = OnnxDenoiser::open(&model, Stage::Two, &options()).expect("open");
    let want = whole
        .predict(&x, &t, &embs, Some(&labels))
        .expect("whole batch");
    for (max_batch, intra_op_spinning) in [(1, false), (2, true), (7, false)] {
        let opts = SessionOptions {
            intra_threads: Some(1),
            max_batch: Some(max_batch),
            intra_op_spinning,
            ..SessionOptions::low_memory()
        };
        let mut split = OnnxDenoiser::open(&model, Stage::Two, &opts).expect("open low-memory");
        let got = split
            .predict(&x, &t, &embs, Some(&labels))
            .expect("split batch");
        assert_eq!(got.shape, want.shape);
        assert_close(
            &got.data,
            &want.data,
            (1e-5, 1e-5),
            &format!("max_batch {max_batch}"),
        );
    }
    // The first two samples are the PyTorch reference's inputs.
    let (_, reference) = ref_f32("stage2_noise_pred");
    assert_close(
        &want.data[..2 * want.data.len() / 5],
        &reference,
        FP32_TOL,
        "reference",
    );
}

#[test]
fn max_batch_zero_is_refused_with_the_reason() {
    let model = ModelDir::open(tiny()).expect("model dir");
    let opts = SessionOptions {
        max_batch: Some(0),
        ..SessionOptions::default()
    };
    let msg = err_text(OnnxDenoiser::open(&model, Stage::One, &opts));
    assert!(msg.contains("max_batch = 0"), "{msg}");
}

/// Sizes that size buffers are bounded before anything is allocated from them: a manifest with a
/// huge token count, resolution or schedule is refused with the bound, not an abort.
#[test]
fn huge_sizes_in_a_manifest_are_refused_before_anything_is_allocated() {
    for (from, to, says) in [
        ("tokens = 77", "tokens = 4000000000", "must be at most 4096"),
        (
            "max_tokens = 77",
            "max_tokens = 4000000000",
            "must be at most 4096",
        ),
        ("dim = 8", "dim = 100000000", "65536"),
        ("sample_size = 256", "sample_size = 1000000", "1..=4096"),
        (
            "num_train_timesteps = 1000",
            "num_train_timesteps = 0",
            "1..=100000",
        ),
        (
            "num_train_timesteps = 1000",
            "num_train_timesteps = 10000000000",
            "1..=100000",
        ),
    ] {
        let tmp = edited("tiny-if", |s| {
            assert!(s.contains(from), "the fixture has {from}");
            // `max_tokens = 77` must not also match `tokens = 77`'s edit and vice versa.
            s.replacen(&format!("\n{from}"), &format!("\n{to}"), 1)
        });
        let msg = err_text(ModelDir::open(tmp.path()));
        assert!(msg.contains(says), "{to}: {msg}");
    }
    // A manifest.toml far larger than any manifest is refused unread.
    let tmp = edited("tiny-if", |s| s + &"#".repeat(2 << 20));
    let msg = err_text(ModelDir::open(tmp.path()));
    assert!(msg.contains("larger than"), "{msg}");
}

/// The IO-binding path (persistent bound tensors, text re-bound only when it changes, reused output)
/// against fresh tensors per call: bit-identical on the CPU provider, fp32 and fp16, both stages,
/// over a sequence of calls in which the embeddings stay, change in one sample, and the batch shape
/// changes (a ragged last chunk re-allocates the bound tensors).
#[test]
fn io_binding_is_bit_identical_to_fresh_tensors_across_calls() {
    for fixture in ["tiny-if", "tiny-if-fp16"] {
        let model = ModelDir::open(fixtures().join(fixture)).expect("model dir");
        let uncond = model.uncond_embedding().expect("uncond");
        let mut cond = uncond.clone();
        for (i, v) in cond.data.iter_mut().enumerate() {
            *v += ((i % 13) as f32 - 6.0) * 0.05;
        }
        let mut other = cond.clone();
        other.data[3] += 0.5;
        for stage in [Stage::One, Stage::Two] {
            let c_in = if stage == Stage::One { 3 } else { 6 };
            let px = 32;
            for max_batch in [None, Some(3)] {
                let open = |io_binding| {
                    let opts = SessionOptions {
                        intra_threads: Some(1),
                        max_batch,
                        io_binding,
                        ..SessionOptions::default()
                    };
                    OnnxDenoiser::open(&model, stage, &opts).expect("open")
                };
                let (mut bound, mut fresh) = (open(true), open(false));
                // Calls: (samples, embeddings) — same text twice, one sample's text changed,
                // then a smaller batch.
                let calls: Vec<Vec<&Embedding>> = vec![
                    vec![&cond, &cond, &uncond, &uncond],
                    vec![&cond, &cond, &uncond, &uncond],
                    vec![&cond, &other, &uncond, &uncond],
                    vec![&other, &uncond],
                ];
                for (k, embs) in calls.iter().enumerate() {
                    let n = embs.len();
                    let data: Vec<f32> = (0..n * c_in * px * px)
                        .map(|i| (((i * 7 + k * 31) % 211) as f32 / 105.0) - 1.0)
                        .collect();
                    let x = csd::Tensor {
                        shape: vec![n, c_in, px, px],
                        data,
                    };
                    let t: Vec<i64> = (0..n as i64).map(|i| 20 + 100 * i + 7 * k as i64).collect();
                    let s: Vec<i64> = (0..n as i64).map(|i| 900 - 50 * i).collect();
                    let labels = (stage == Stage::Two).then_some(s.as_slice());
                    let a = bound.predict(&x, &t, embs, labels).expect("bound");
                    let b = fresh.predict(&x, &t, embs, labels).expect("fresh");
                    assert_eq!(a.shape, b.shape);
                    let differ = a
                        .data
                        .iter()
                        .zip(&b.data)
                        .filter(|(p, q)| p.to_bits() != q.to_bits())
                        .count();
                    assert_eq!(
                        differ, 0,
                        "{fixture} {stage:?} max_batch {max_batch:?} call {k}: {differ} values differ"
                    );
                }
            }
        }
    }
}

/// A changed embedding after an unchanged call reaches the model through the binding (the text is
/// compared, not assumed unchanged): the output follows the new text.
#[test]
fn io_binding_picks_up_changed_text() {
    let model = ModelDir::open(tiny()).expect("model dir");
    let uncond = model.uncond_embedding().expect("uncond");
    let mut cond = uncond.clone();
    for v in &mut cond.data {
        *v += 0.3;
    }
    let mut unet = OnnxDenoiser::open(&model, Stage::One, &options()).expect("open");
    let x = csd::Tensor {
        shape: vec![1, 3, 32, 32],
        data: (0..3 * 32 * 32)
            .map(|i| (i % 17) as f32 / 8.0 - 1.0)
            .collect(),
    };
    let a = unet.predict(&x, &[500], &[&uncond], None).expect("a");
    let a2 = unet.predict(&x, &[500], &[&uncond], None).expect("a2");
    let b = unet.predict(&x, &[500], &[&cond], None).expect("b");
    assert_eq!(a.data, a2.data);
    let d: f32 = a.data.iter().zip(&b.data).map(|(p, q)| (p - q).abs()).sum();
    assert!(d > 1e-3, "the new text did not reach the model ({d})");
}

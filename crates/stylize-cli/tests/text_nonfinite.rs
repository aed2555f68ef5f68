//! The text path refuses non-finite embeddings with an error that names the tensor and its file,
//! instead of "succeeding" with a zero gradient and an unchanged mesh (the reference's `nan_to_num`
//! turns NaN guidance into zeros). Needs the ONNX Runtime library: `scripts/setup-onnxruntime.sh`.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use diffusion_onnx::npy::{NpyArray, NpyData, write_npy};
use mesh_core::TriMesh;

mod common;
use common::{ok, s};

fn stylize(args: &[&str], cache: &Path) -> Output {
    ok(Command::new(env!("CARGO_BIN_EXE_stylize"))
        .args(args)
        .env(diffusion_onnx::CACHE_ENV, cache)
        .output())
}

fn tiny_if() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../../fixtures/models/tiny-if")
}

/// A copy of the tiny fixture models (without the PyTorch reference data).
fn model_copy(to: &Path) -> PathBuf {
    let dir = to.join("model");
    ok(std::fs::create_dir_all(&dir));
    for entry in ok(std::fs::read_dir(tiny_if())) {
        let p = ok(entry).path();
        if p.is_file()
            && let Some(name) = p.file_name()
        {
            ok(std::fs::copy(&p, dir.join(name)));
        }
    }
    dir
}

fn nan_embedding(path: &Path) {
    ok(write_npy(
        path,
        &NpyArray {
            shape: vec![77, 8],
            data: NpyData::F32(vec![f32::NAN; 77 * 8]),
        },
    ));
}

/// `stylize run` of 2 iterations on a small mesh; returns (output, run directory).
fn run_text(tmp: &Path, model: &Path, cache: &Path) -> (Output, PathBuf) {
    let (p, f) = mesh_core::shapes::icosphere(2).into_parts();
    let mesh = tmp.join("blob.obj");
    ok(mesh_core::io::write_mesh(&mesh, &TriMesh::new(p, f), None));
    let run = tmp.join("text");
    let out = stylize(
        &[
            "run",
            s(&mesh),
            "--prompt",
            "a wooden chair",
            "--model",
            s(model),
            "-o",
            s(&run),
            "--quiet",
            "--set",
            "optim.iterations=2",
            "--set",
            "camera.views=1",
            "--set",
            "render.width=32",
            "--set",
            "render.height=32",
        ],
        cache,
    );
    (out, run)
}

fn assert_refused(out: &Output, run: &Path, wants: &[&str]) {
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        !out.status.success(),
        "a NaN embedding run exited 0:\n{stderr}"
    );
    for w in wants {
        assert!(stderr.contains(w), "stderr lacks {w:?}:\n{stderr}");
    }
    assert!(
        !run.join("mesh.obj").exists(),
        "an unchanged mesh was written"
    );
}

#[test]
fn all_nan_empty_prompt_embedding_fails_naming_the_file() {
    let tmp = ok(tempfile::tempdir());
    let model = model_copy(tmp.path());
    let uncond = model.join("uncond_embedding.npy");
    nan_embedding(&uncond);
    let (out, run) = run_text(tmp.path(), &model, &tmp.path().join("cache"));
    assert_refused(
        &out,
        &run,
        &["unconditional", s(&uncond), "616 non-finite values"],
    );
}

#[test]
fn nan_cached_prompt_embedding_fails_naming_the_cache_entry() {
    let tmp = ok(tempfile::tempdir());
    let cache = tmp.path().join("cache");
    let filled = stylize(
        &[
            "embed",
            "--model",
            s(&tiny_if()),
            "--prompt",
            "a wooden chair",
        ],
        &cache,
    );
    assert!(
        filled.status.success(),
        "{}",
        String::from_utf8_lossy(&filled.stderr)
    );
    let entries: Vec<PathBuf> = ok(std::fs::read_dir(&cache))
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.extension().is_some_and(|x| x == "npy"))
        .collect();
    assert_eq!(entries.len(), 1, "{entries:?}");
    nan_embedding(&entries[0]);
    let (out, run) = run_text(tmp.path(), &tiny_if(), &cache);
    assert_refused(
        &out,
        &run,
        &[
            "cached embedding",
            "a wooden chair",
            s(&entries[0]),
            "616 non-finite values",
        ],
    );
}

//! `stylize doctor` on this machine (no GPU, no NVIDIA driver): with the CPU-only ONNX Runtime, with
//! no library at all, with a damaged CUDA provider beside the library, and with a stage configured
//! on a GPU that is not there. Each runs the binary (ONNX Runtime loads once per process).

use std::path::{Path, PathBuf};
use std::process::Command;

mod common;
use common::ok;

fn repo() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../..")
}

fn doctor(args: &[&str], ort: Option<&Path>) -> (serde_json::Value, String) {
    let run = |args: &[&str]| {
        let mut c = Command::new(env!("CARGO_BIN_EXE_stylize"));
        c.arg("doctor").args(args);
        match ort {
            Some(p) => c.env(diffusion_onnx::runtime::ORT_DYLIB_ENV, p),
            None => c.env_remove(diffusion_onnx::runtime::ORT_DYLIB_ENV),
        };
        let out = ok(c.output());
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
        out.stdout
    };
    let json = run(args);
    let plain: Vec<&str> = args.iter().copied().filter(|a| *a != "--json").collect();
    let text = run(&plain);
    (
        ok(serde_json::from_slice(&json)),
        String::from_utf8_lossy(&text).into_owned(),
    )
}

fn problems(v: &serde_json::Value) -> Vec<String> {
    v["problems"]
        .as_array()
        .map(|a| {
            a.iter()
                .map(|p| format!("{} | {}", p["problem"], p["next_step"]))
                .collect()
        })
        .unwrap_or_default()
}

#[test]
fn cpu_library_no_gpu_and_the_tiny_models() {
    let model = repo().join("fixtures/models/tiny-if");
    let (v, text) = doctor(&["--json", "--model", &model.to_string_lossy()], None);
    let rt = &v["onnx_runtime"];
    assert_eq!(rt["version"], "1.31.1", "{v:#}");
    assert!(rt["error"].is_null(), "{v:#}");
    assert_eq!(rt["cuda_provider"]["state"], "absent", "{v:#}");
    assert!(
        rt["devices"].as_array().is_some_and(|d| d.iter().any(|d| d
            .as_str()
            .is_some_and(|s| s.starts_with("CPUExecutionProvider")))),
        "{v:#}"
    );
    // No NVIDIA driver on this machine: the report says why there are no GPUs.
    if v["driver"]["gpus"].as_array().is_some_and(|g| g.is_empty()) {
        assert!(v["driver"]["error"].is_string(), "{v:#}");
    }
    assert!(
        v["model"]
            .as_str()
            .is_some_and(|m| m.starts_with("ok: tiny-if")),
        "{v:#}"
    );
    assert_eq!(v["memory"][0]["device"], "cpu", "{v:#}");
    assert!(v["time"][0]["seconds_per_iteration"].is_number(), "{v:#}");
    if !cfg!(feature = "cuda") {
        assert_eq!(problems(&v), Vec::<String>::new());
    }
    assert!(
        text.contains("ONNX Runtime: ")
            && text.contains("CUDA provider: absent")
            && text.contains("problems: none"),
        "{text}"
    );
}

#[test]
fn a_missing_library_is_a_problem_with_the_fix() {
    let tmp = ok(tempfile::tempdir());
    let missing = tmp.path().join("libonnxruntime.so.1.31.1");
    let (v, text) = doctor(&["--json"], Some(&missing));
    assert!(
        v["onnx_runtime"]["error"]
            .as_str()
            .is_some_and(|e| e.contains("no such file")),
        "{v:#}"
    );
    let p = problems(&v);
    assert!(
        p.len() == 1 && p[0].contains("setup-onnxruntime.sh") && p[0].contains("onnxruntime-gpu"),
        "{p:?}"
    );
    assert!(text.contains("NOT USABLE"), "{text}");
}

#[test]
fn a_damaged_cuda_provider_beside_the_library_is_named() {
    let tmp = ok(tempfile::tempdir());
    let lib = tmp.path().join("libonnxruntime.so.1.31.1");
    ok(std::os::unix::fs::symlink(
        diffusion_onnx::runtime::default_dylib_path(),
        &lib,
    ));
    ok(std::fs::write(
        tmp.path().join("libonnxruntime_providers_cuda.so"),
        b"half a download",
    ));
    let (v, text) = doctor(&["--json"], Some(&lib));
    let cuda = &v["onnx_runtime"]["cuda_provider"];
    assert_eq!(cuda["state"], "fails", "{v:#}");
    assert!(
        cuda["advice"]
            .as_str()
            .is_some_and(|a| a.contains("damaged")),
        "{v:#}"
    );
    assert!(
        problems(&v).iter().any(|p| p.contains("does not load")),
        "{v:#}"
    );
    assert!(text.contains("CUDA provider: does not load"), "{text}");
}

#[test]
fn a_stage_on_a_gpu_that_is_not_there_is_a_problem() {
    let model = repo().join("fixtures/models/tiny-if");
    let (v, _) = doctor(
        &[
            "--json",
            "--model",
            &model.to_string_lossy(),
            "--set",
            "guidance.stage2_device=cuda:3",
        ],
        None,
    );
    let p = problems(&v);
    assert!(
        p.iter()
            .any(|p| p.contains("cuda:3 is configured but the driver lists no such GPU")),
        "{p:?}"
    );
    if !cfg!(feature = "cuda") {
        assert!(p.iter().any(|p| p.contains("--features cuda")), "{p:?}");
    }
    assert!(v["time"][0]["seconds_per_iteration"].is_null(), "{v:#}");
    assert!(
        v["time"][0]["basis"]
            .as_str()
            .is_some_and(|b| b.contains("gpu_check.sh")),
        "{v:#}"
    );
}

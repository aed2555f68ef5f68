//! The `stylize` binary: run → apply → eval on a small mesh, clear errors, and the text path with
//! the tiny IF fixture models (needs the ONNX Runtime library: `scripts/setup-onnxruntime.sh`).

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use mesh_core::TriMesh;

mod common;
use common::{ok, s};

fn stylize(args: &[&str], cache: &Path) -> Output {
    ok(Command::new(env!("CARGO_BIN_EXE_stylize"))
        .args(args)
        .env(diffusion_onnx::CACHE_ENV, cache)
        .output())
}

fn must(out: &Output) {
    assert!(
        out.status.success(),
        "stylize failed:\n{}\n{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
}

fn small_mesh(dir: &Path) -> PathBuf {
    let (p, f) = mesh_core::shapes::icosphere(2).into_parts();
    let p: Vec<[f64; 3]> = p.iter().map(|v| [1.4 * v[0], v[1], 0.7 * v[2]]).collect();
    let path = dir.join("blob.obj");
    ok(mesh_core::io::write_mesh(&path, &TriMesh::new(p, f), None));
    path
}

#[test]
fn run_then_apply_reproduces_the_saved_mesh_and_eval_reports_it() {
    let tmp = ok(tempfile::tempdir());
    let mesh = small_mesh(tmp.path());
    let run = tmp.path().join("out/run");
    must(&stylize(
        &[
            "run",
            s(&mesh),
            "--style",
            "octahedron",
            "-o",
            s(&run),
            "--set",
            "style.iterations=8",
            "--set",
            "run.turntable_size=24",
            "--quiet",
        ],
        tmp.path(),
    ));
    let applied = tmp.path().join("applied.obj");
    must(&stylize(
        &["apply", s(&run.join("deformation.npz")), "-o", s(&applied)],
        tmp.path(),
    ));
    let a = ok(mesh_core::io::read_mesh(&applied));
    let b = ok(mesh_core::io::read_mesh(run.join("mesh.obj")));
    assert_eq!(a.faces, b.faces);
    let worst = a
        .positions
        .iter()
        .zip(&b.positions)
        .flat_map(|(p, q)| (0..3).map(move |k| (p[k] - q[k]).abs()))
        .fold(0.0, f64::max);
    assert!(
        worst < 1e-9,
        "stylize apply differs from the run's mesh by {worst}"
    );

    let out = stylize(&["eval", s(&run), "--json"], tmp.path());
    must(&out);
    let report: serde_json::Value = ok(serde_json::from_slice(&out.stdout));
    let mean = report["area_ratio_mean"].as_f64().unwrap_or(f64::NAN);
    assert!(mean.is_finite() && mean > 0.0, "{report}");
}

#[test]
fn prompt_without_model_points_to_the_model_docs() {
    let tmp = ok(tempfile::tempdir());
    let mesh = small_mesh(tmp.path());
    let out = stylize(
        &[
            "run",
            s(&mesh),
            "--prompt",
            "a chair",
            "-o",
            s(&tmp.path().join("r")),
        ],
        tmp.path(),
    );
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("--model") && err.contains("docs/models.md"),
        "{err}"
    );
}

#[test]
fn unknown_config_key_is_rejected_before_any_work() {
    let tmp = ok(tempfile::tempdir());
    let mesh = small_mesh(tmp.path());
    let run = tmp.path().join("r");
    let out = stylize(
        &[
            "run",
            s(&mesh),
            "--style",
            "cube",
            "-o",
            s(&run),
            "--set",
            "darap.lamda=5",
        ],
        tmp.path(),
    );
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("darap.lamda") && err.contains("lambda"),
        "{err}"
    );
    assert!(!run.exists(), "nothing is written for a bad config");
}

#[test]
fn text_path_runs_with_the_tiny_fixture_models() {
    let tmp = ok(tempfile::tempdir());
    let mesh = small_mesh(tmp.path());
    let run = tmp.path().join("text");
    let model = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../fixtures/models/tiny-if");
    must(&stylize(
        &[
            "run",
            s(&mesh),
            "--prompt",
            "a wooden chair",
            "--model",
            s(&model),
            "-o",
            s(&run),
            "--quiet",
            "--set",
            "optim.iterations=2",
            "--set",
            "camera.views=1",
            "--set",
            "render.width=64",
            "--set",
            "render.height=64",
            "--set",
            "run.turntable_size=24",
            "--set",
            "run.preview_every=1",
        ],
        tmp.path(),
    ));
    let metrics = ok(std::fs::read_to_string(run.join("metrics.jsonl")));
    assert_eq!(metrics.lines().count(), 2);
    for line in metrics.lines() {
        let v: serde_json::Value = ok(serde_json::from_str(line));
        let g = v["grad_norm"].as_f64().unwrap_or(f64::NAN);
        assert!(g.is_finite() && g > 0.0, "no gradient reached x: {line}");
    }
    assert!(run.join("previews/iter_000002.png").is_file());
    let summary: serde_json::Value = ok(serde_json::from_str(&ok(std::fs::read_to_string(
        run.join("run.json"),
    ))));
    assert_eq!(summary["adam_steps"], 4, "two Adam steps per iteration");
}

#[test]
fn resume_alone_continues_with_the_runs_own_config() {
    let tmp = ok(tempfile::tempdir());
    let mesh = small_mesh(tmp.path());
    let run = tmp.path().join("run");
    let first = [
        "run",
        s(&mesh),
        "--style",
        "cube",
        "-o",
        s(&run),
        "--quiet",
        "--set",
        "style.iterations=9",
        "--set",
        "run.checkpoint_every=4",
        "--set",
        "run.turntable_size=16",
        "--stop-after",
        "6",
    ];
    must(&stylize(&first, tmp.path()));
    assert!(!run.join("run.json").exists());
    let out = stylize(
        &["run", s(&mesh), "--style", "cube", "-o", s(&run), "--quiet"],
        tmp.path(),
    );
    assert!(
        !out.status.success(),
        "an interrupted run needs --resume or --force"
    );
    must(&stylize(
        &[
            "run",
            s(&mesh),
            "--style",
            "cube",
            "-o",
            s(&run),
            "--quiet",
            "--resume",
        ],
        tmp.path(),
    ));
    let summary: serde_json::Value = ok(serde_json::from_str(&ok(std::fs::read_to_string(
        run.join("run.json"),
    ))));
    assert_eq!(summary["iterations"], 9);
    let out = stylize(
        &[
            "run",
            s(&mesh),
            "--style",
            "cube",
            "-o",
            s(&run),
            "--quiet",
            "--resume",
            "--seed",
            "3",
        ],
        tmp.path(),
    );
    assert!(
        !out.status.success(),
        "a complete run is not redone by --resume"
    );
}

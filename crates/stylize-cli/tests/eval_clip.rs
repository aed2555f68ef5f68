//! `stylize eval --clip` with the tiny CLIP fixture (`fixtures/models/tiny-clip`, random weights: the
//! similarities are meaningless numbers, so these tests check structure, determinism, range, the
//! source/result columns, where the prompt comes from, and the error paths). Needs the ONNX Runtime
//! library (`scripts/setup-onnxruntime.sh`).

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use mesh_core::TriMesh;
use stylize::saved::SavedDeformation;

mod common;
use common::{ok, s, stylize};

fn must(out: &Output) -> serde_json::Value {
    assert!(
        out.status.success(),
        "stylize failed:\n{}\n{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    serde_json::from_slice(&out.stdout).unwrap_or(serde_json::Value::Null)
}

fn fails(out: &Output) -> String {
    assert!(
        !out.status.success(),
        "stylize should have failed:\n{}",
        String::from_utf8_lossy(&out.stdout)
    );
    String::from_utf8_lossy(&out.stderr).into_owned()
}

fn fixtures() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../../fixtures/models")
}

fn tiny_clip() -> PathBuf {
    fixtures().join("tiny-clip")
}

/// Source and result meshes on disk, and a run directory holding the same pair with a prompt (as the
/// text path writes it: `deformation.npz` with `dataset_cfg.prompt`, `mesh.obj`).
struct Setup {
    _tmp: tempfile::TempDir,
    source: PathBuf,
    result: PathBuf,
    text_run: PathBuf,
    root: PathBuf,
}

fn setup() -> Setup {
    let tmp = ok(tempfile::tempdir());
    let root = tmp.path().to_path_buf();
    let (p, f) = mesh_core::shapes::icosphere(2).into_parts();
    let src: Vec<[f64; 3]> = p.iter().map(|v| [v[0], 0.8 * v[1], 0.9 * v[2]]).collect();
    let res: Vec<[f64; 3]> = src
        .iter()
        .map(|v| [1.5 * v[0], v[1] + 0.3 * v[0] * v[0], 0.7 * v[2]])
        .collect();
    let source = root.join("source.obj");
    let result = root.join("result.obj");
    ok(mesh_core::io::write_mesh(
        &source,
        &TriMesh::new(src.clone(), f.clone()),
        None,
    ));
    ok(mesh_core::io::write_mesh(
        &result,
        &TriMesh::new(res.clone(), f.clone()),
        None,
    ));
    let text_run = root.join("text_run");
    ok(std::fs::create_dir_all(&text_run));
    let saved = SavedDeformation {
        verts: src.iter().map(|p| p.map(|c| c as f32)).collect(),
        faces: f.clone(),
        verts_normals: vec![[0.0; 3]; src.len()],
        deform_by_csd_cfg: "{}".into(),
        dataset_cfg: r#"{"mesh": "source.obj", "prompt": "a wooden chair"}"#.into(),
        extra: Vec::new(),
    };
    ok(saved.write(text_run.join("deformation.npz")));
    ok(mesh_core::io::write_mesh(
        text_run.join("mesh.obj"),
        &TriMesh::new(res, f),
        None,
    ));
    Setup {
        _tmp: tmp,
        source,
        result,
        text_run,
        root,
    }
}

fn clip_args<'a>(extra: &[&'a str], clip: &'a str) -> Vec<&'a str> {
    let mut a = vec![
        "eval",
        "--clip",
        clip,
        "--clip-views",
        "4",
        "--clip-render-size",
        "48",
    ];
    a.extend_from_slice(extra);
    a
}

fn num(v: &serde_json::Value) -> f64 {
    v.as_f64().unwrap_or(f64::NAN)
}

#[test]
fn run_dir_and_pair_get_source_and_result_scores_from_their_prompts() {
    let st = setup();
    let clip = tiny_clip();
    let args = clip_args(
        &[
            s(&st.text_run),
            "--pair",
            s(&st.source),
            s(&st.result),
            "--prompt",
            "a wooden chair",
            "--json",
        ],
        s(&clip),
    );
    let report = must(&stylize(&args));
    let pairs = report["pairs"].as_array().cloned().unwrap_or_default();
    assert_eq!(pairs.len(), 2, "{report}");
    for p in &pairs {
        let c = &p["clip"];
        assert_eq!(c["prompt"], "a wooden chair", "{report}");
        assert_eq!(c["views"], 4);
        for which in ["source", "result"] {
            let v = num(&c[which]);
            assert!((-1.0..=1.0).contains(&v), "{which} = {v}: {report}");
        }
        assert!(c.get("skipped").is_none(), "{report}");
    }
    // The run directory holds the same meshes as the pair (its source rounded to f32): same scores.
    for which in ["source", "result"] {
        let (a, b) = (num(&pairs[0]["clip"][which]), num(&pairs[1]["clip"][which]));
        assert!((a - b).abs() < 1e-4, "{which}: run {a} vs pair {b}");
    }
    // Source and result are different shapes, so their renders and scores differ.
    let (src, res) = (
        num(&pairs[0]["clip"]["source"]),
        num(&pairs[0]["clip"]["result"]),
    );
    assert!(src != res, "source and result scored the same: {src}");
    let mean = num(&report["clip_result_mean"]);
    let want = (num(&pairs[0]["clip"]["result"]) + num(&pairs[1]["clip"]["result"])) / 2.0;
    assert!((mean - want).abs() < 1e-12, "{mean} vs {want}");
    assert!(num(&report["clip_source_mean"]).is_finite());
    // The identity metrics are still there.
    assert!(num(&report["area_ratio_mean"]) > 0.0);
}

#[test]
fn scores_are_deterministic_and_depend_on_the_prompt() {
    let st = setup();
    let clip = tiny_clip();
    let run = |prompt: &str| {
        let args = clip_args(
            &[
                "--pair",
                s(&st.source),
                s(&st.result),
                "--prompt",
                prompt,
                "--json",
            ],
            s(&clip),
        );
        let out = stylize(&args);
        must(&out);
        out.stdout
    };
    let a = run("a wooden chair");
    assert_eq!(a, run("a wooden chair"), "two runs differ");
    assert_ne!(
        a,
        run("a marble statue of a horse"),
        "the prompt is ignored"
    );
}

#[test]
fn model_free_run_and_pair_without_prompt_have_empty_clip_columns_with_reasons() {
    let st = setup();
    let style_run = st.root.join("style_run");
    must(&stylize(&[
        "run",
        s(&st.source),
        "--style",
        "octahedron",
        "-o",
        s(&style_run),
        "--set",
        "style.iterations=4",
        "--set",
        "run.turntable_size=16",
        "--quiet",
    ]));
    let clip = tiny_clip();
    let args = clip_args(
        &[
            s(&style_run),
            "--pair",
            s(&st.source),
            s(&st.result),
            "--json",
        ],
        s(&clip),
    );
    let report = must(&stylize(&args));
    let why0 = report["pairs"][0]["clip"]["skipped"]
        .as_str()
        .unwrap_or_default()
        .to_string();
    assert!(
        why0.contains("model-free") && why0.contains("octahedron"),
        "{report}"
    );
    let why1 = report["pairs"][1]["clip"]["skipped"]
        .as_str()
        .unwrap_or_default();
    assert!(why1.contains("--prompt"), "{report}");
    for p in [0, 1] {
        assert!(report["pairs"][p]["clip"]["source"].is_null(), "{report}");
        assert!(report["pairs"][p]["clip"]["result"].is_null(), "{report}");
    }
    assert!(report.get("clip_result_mean").is_none(), "{report}");

    // The table says the same in words.
    let args = clip_args(&[s(&style_run)], s(&clip));
    let out = stylize(&args);
    must(&out);
    let table = String::from_utf8_lossy(&out.stdout);
    assert!(
        table.contains("CLIP src") && table.contains("CLIP res") && table.contains("model-free"),
        "{table}"
    );
}

#[test]
fn table_has_clip_columns_only_with_clip() {
    let st = setup();
    let clip = tiny_clip();
    let plain = stylize(&["eval", s(&st.text_run)]);
    must(&plain);
    assert!(!String::from_utf8_lossy(&plain.stdout).contains("CLIP"));
    let args = clip_args(&[s(&st.text_run)], s(&clip));
    let out = stylize(&args);
    must(&out);
    let table = String::from_utf8_lossy(&out.stdout);
    assert!(
        table.contains("CLIP src") && table.contains("\"a wooden chair\", 4 views"),
        "{table}"
    );
    let plain_json = must(&stylize(&["eval", s(&st.text_run), "--json"]));
    assert!(plain_json["pairs"][0].get("clip").is_none(), "{plain_json}");
}

#[test]
fn bad_clip_arguments_are_clear_errors() {
    let st = setup();
    let run = s(&st.text_run);
    let missing = st.root.join("no-such-model");
    let err = fails(&stylize(&["eval", run, "--clip", s(&missing)]));
    assert!(
        err.contains("--clip") && err.contains("export_clip_onnx.py"),
        "{err}"
    );
    let tiny_if = fixtures().join("tiny-if");
    let err = fails(&stylize(&["eval", run, "--clip", s(&tiny_if)]));
    assert!(err.contains("not a CLIP manifest"), "{err}");
    let clip = tiny_clip();
    let err = fails(&stylize(&[
        "eval",
        run,
        "--clip",
        s(&clip),
        "--clip-views",
        "0",
    ]));
    assert!(err.contains("--clip-views"), "{err}");
    let err = fails(&stylize(&["eval", run, "--prompt", "a chair"]));
    assert!(err.contains("--clip"), "{err}");
}

#[test]
fn a_real_text_path_run_is_scored_against_its_own_prompt() {
    let st = setup();
    let run = st.root.join("text_path_run");
    let model = fixtures().join("tiny-if");
    let out = ok(Command::new(env!("CARGO_BIN_EXE_stylize"))
        .args([
            "run",
            s(&st.source),
            "--prompt",
            "a marble bust",
            "--model",
            s(&model),
            "-o",
            s(&run),
            "--quiet",
            "--set",
            "optim.iterations=1",
            "--set",
            "camera.views=1",
            "--set",
            "render.width=32",
            "--set",
            "render.height=32",
            "--set",
            "run.turntable_size=16",
        ])
        .env(diffusion_onnx::CACHE_ENV, st.root.join("cache"))
        .output());
    must(&out);
    let clip = tiny_clip();
    let report = must(&stylize(&clip_args(&[s(&run), "--json"], s(&clip))));
    let c = &report["pairs"][0]["clip"];
    assert_eq!(c["prompt"], "a marble bust", "{report}");
    assert!((-1.0..=1.0).contains(&num(&c["result"])), "{report}");
    assert!((-1.0..=1.0).contains(&num(&c["source"])), "{report}");
}

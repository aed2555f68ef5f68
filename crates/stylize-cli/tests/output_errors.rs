//! A standard output that cannot be written (`stylize … | head -1`: the reader hung up) ends a
//! command with a clear error and status 141 (128 + SIGPIPE), never a panic; a run writing
//! `--log-format jsonl` lines stops the way a signal stops it (checkpoint, how to resume), and
//! the resumed run equals an uninterrupted one. Each command gets a pipe whose reader is closed
//! before it starts, so its first write fails (deterministically, no race with a reader).

use std::path::{Path, PathBuf};
use std::process::{Command, Output, Stdio};

mod common;
use common::{ok, s, stderr};

fn fixture(name: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../../fixtures/meshes")
        .join(name)
}

/// Runs `stylize args` with stdout a pipe nobody reads (its read end closed).
fn with_closed_stdout(args: &[&str]) -> Output {
    let (reader, writer) = ok(std::io::pipe());
    drop(reader);
    ok(Command::new(env!("CARGO_BIN_EXE_stylize"))
        .args(args)
        .stdin(Stdio::null())
        .stdout(writer)
        .stderr(Stdio::piped())
        .output())
}

fn assert_clear_exit(out: &Output, what: &str) {
    let err = stderr(out);
    assert!(!err.contains("panicked"), "{what} panicked: {err}");
    assert_eq!(out.status.code(), Some(141), "{what}: {err}");
}

#[test]
fn reports_on_a_closed_stdout_end_with_141_and_a_message_not_a_panic() {
    let bunny = fixture("bunny.obj");
    for args in [
        vec!["mesh", "check", "--json", s(&bunny)],
        vec!["mesh", "check", s(&bunny)],
        vec!["mesh", "check", "--regions", s(&bunny)],
    ] {
        let out = with_closed_stdout(&args);
        assert_clear_exit(&out, &args.join(" "));
        assert!(
            stderr(&out).contains("cannot write to standard output"),
            "{}",
            stderr(&out)
        );
    }
}

/// A small ellipsoid (icosphere, 162 vertices) as an OBJ file.
fn small_mesh(dir: &Path) -> PathBuf {
    let (p, f) = mesh_core::shapes::icosphere(2).into_parts();
    let p: Vec<[f64; 3]> = p.iter().map(|v| [1.5 * v[0], v[1], 0.8 * v[2]]).collect();
    let path = dir.join("ellipsoid.obj");
    ok(mesh_core::io::write_mesh(
        &path,
        &mesh_core::TriMesh::new(p, f),
        None,
    ));
    path
}

const SETTINGS: [&str; 10] = [
    "--set",
    "style.iterations=12",
    "--set",
    "run.checkpoint_every=0",
    "--set",
    "run.preview_every=0",
    "--set",
    "run.turntable_views=1",
    "--set",
    "run.turntable_size=16",
];

#[test]
fn jsonl_on_a_closed_stdout_stops_the_run_like_a_signal_and_the_resume_loses_nothing() {
    let tmp = ok(tempfile::tempdir());
    let mesh = small_mesh(tmp.path());
    let (cut, whole) = (tmp.path().join("cut"), tmp.path().join("whole"));
    let run_args = |out: &Path| -> Vec<String> {
        let mut a: Vec<String> = ["run", s(&mesh), "--style", "cube", "--out", s(out)]
            .iter()
            .map(|x| x.to_string())
            .collect();
        a.extend(SETTINGS.iter().map(|x| x.to_string()));
        a
    };
    let mut args = run_args(&cut);
    args.extend(["--log-format".into(), "jsonl".into()]);
    let refs: Vec<&str> = args.iter().map(String::as_str).collect();
    let out = with_closed_stdout(&refs);
    assert_clear_exit(&out, "run --log-format jsonl");
    let err = stderr(&out);
    assert!(
        err.contains("closed standard output") && err.contains("checkpoint written"),
        "{err}"
    );
    assert!(err.contains("--resume"), "says how to resume: {err}");
    assert!(cut.join("checkpoint.json").is_file());
    assert!(!cut.join("run.json").exists(), "stopped before the end");

    let mut resume = run_args(&cut);
    resume.extend(["--resume".into(), "-q".into()]);
    let refs: Vec<&str> = resume.iter().map(String::as_str).collect();
    let resumed = common::stylize(&refs);
    assert!(resumed.status.success(), "{}", stderr(&resumed));
    let mut plain = run_args(&whole);
    plain.push("-q".into());
    let refs: Vec<&str> = plain.iter().map(String::as_str).collect();
    let uninterrupted = common::stylize(&refs);
    assert!(uninterrupted.status.success(), "{}", stderr(&uninterrupted));
    assert_eq!(
        ok(std::fs::read(cut.join("mesh.obj"))),
        ok(std::fs::read(whole.join("mesh.obj"))),
        "the interrupted and resumed run's mesh equals the uninterrupted one's"
    );
    let normals = |d: &Path| {
        ok(stylize::saved::SavedDeformation::read(
            d.join("deformation.npz"),
        ))
        .verts_normals
    };
    assert_eq!(normals(&cut), normals(&whole), "the optimized targets too");
}

#[test]
fn apply_on_a_closed_stdout_writes_every_output_then_exits_141() {
    let tmp = ok(tempfile::tempdir());
    let out = tmp.path().join("bunny.obj");
    let o = with_closed_stdout(&[
        "apply",
        s(&fixture("bunny_targets.npz")),
        "--lambda",
        "3,5",
        "-o",
        s(&out),
    ]);
    assert_clear_exit(&o, "apply");
    for l in [3, 5] {
        assert!(
            tmp.path().join(format!("bunny_lambda{l}.obj")).is_file(),
            "λ = {l} written: {}",
            stderr(&o)
        );
    }
}

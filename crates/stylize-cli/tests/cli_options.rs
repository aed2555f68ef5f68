//! The `stylize` binary as a user meets it: one `--out` everywhere, one `--log-format`, errors that
//! point at the right fix (negative numbers, a missing style, a missing file stated once), and the
//! batch summary (singular "1 row", each row's repair warnings).

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

mod common;
use common::{ok, s, stderr, stylize};

fn must(out: &Output) {
    assert!(
        out.status.success(),
        "stylize failed:\n{}\n{}",
        String::from_utf8_lossy(&out.stdout),
        stderr(out)
    );
}

/// An octahedron; with `stray`, one extra vertex no face uses (repair drops it, with a warning).
fn octahedron(dir: &Path, name: &str, stray: bool) -> PathBuf {
    let mut mesh = mesh_core::shapes::octahedron();
    if stray {
        mesh.positions.push([3.0, 3.0, 3.0]);
    }
    let path = dir.join(name);
    ok(mesh_core::io::write_mesh(&path, &mesh, None));
    path
}

/// A finished style run (tiny) in `dir/run`; returns its `deformation.npz`.
fn saved_run(dir: &Path) -> PathBuf {
    let mesh = octahedron(dir, "oct.obj", false);
    let run = dir.join("run");
    must(&stylize(&[
        "run",
        s(&mesh),
        "--style",
        "cube",
        "--out",
        s(&run),
        "--set",
        "style.iterations=3",
        "--set",
        "run.turntable_views=1",
        "--set",
        "run.turntable_size=16",
        "--quiet",
    ]));
    run.join("deformation.npz")
}

#[test]
fn apply_takes_out_and_keeps_output_as_an_alias() {
    let tmp = ok(tempfile::tempdir());
    let saved = saved_run(tmp.path());
    for flag in ["--out", "--output", "-o"] {
        let target = tmp.path().join(format!("applied{}.obj", flag.len()));
        must(&stylize(&["apply", s(&saved), flag, s(&target)]));
        assert!(target.is_file(), "{flag} wrote nothing");
    }
    let help = String::from_utf8_lossy(&stylize(&["apply", "--help"]).stdout).into_owned();
    assert!(help.contains("--out <FILE>"), "{help}");
    // `--output-frame` is another flag; the alias `--output` itself must not be listed.
    assert!(
        !help.replace("--output-frame", "").contains("--output"),
        "the alias is hidden: {help}"
    );
}

#[test]
fn render_takes_out_and_keeps_output_as_an_alias() {
    let tmp = ok(tempfile::tempdir());
    let mesh = octahedron(tmp.path(), "oct.obj", false);
    for flag in ["--out", "--output"] {
        let dir = tmp.path().join(&flag[2..]);
        let args = [
            "render",
            s(&mesh),
            "--turntable",
            "1",
            "--size",
            "16",
            "--cpu",
            flag,
            s(&dir),
        ];
        must(&stylize(&args));
        assert!(dir.join("contact_sheet.png").is_file(), "{flag}");
    }
}

#[test]
fn render_leaves_no_xdg_runtime_dir_complaint_when_the_variable_is_unset() {
    let tmp = ok(tempfile::tempdir());
    let mesh = octahedron(tmp.path(), "oct.obj", false);
    let dir = tmp.path().join("frames");
    // Without --cpu: the GPU adapter is probed (lavapipe's Wayland probe printed the complaint).
    let out = ok(Command::new(env!("CARGO_BIN_EXE_stylize"))
        .args([
            "render",
            s(&mesh),
            "--turntable",
            "1",
            "--size",
            "16",
            "--out",
            s(&dir),
        ])
        .env_remove("XDG_RUNTIME_DIR")
        .output());
    must(&out);
    let err = stderr(&out);
    assert!(!err.contains("XDG_RUNTIME_DIR"), "{err}");
}

#[test]
fn a_negative_lambda_is_read_as_a_number_and_refused_clearly() {
    let tmp = ok(tempfile::tempdir());
    let saved = saved_run(tmp.path());
    let target = tmp.path().join("neg.obj");
    let out = stylize(&["apply", s(&saved), "--out", s(&target), "--lambda", "-1"]);
    assert!(!out.status.success());
    let err = stderr(&out);
    assert!(!err.contains("'-- -1'"), "clap took -1 for a flag: {err}");
    assert!(err.contains("--lambda -1") && err.contains("≥ 0"), "{err}");
    assert!(!target.exists());
}

#[test]
fn run_without_a_style_names_both_style_and_prompt() {
    let tmp = ok(tempfile::tempdir());
    let mesh = octahedron(tmp.path(), "oct.obj", false);
    let out = stylize(&["run", s(&mesh), "--out", s(&tmp.path().join("r"))]);
    assert!(!out.status.success());
    let err = stderr(&out);
    assert!(
        err.contains("--style NAME") && err.contains("--prompt TEXT"),
        "{err}"
    );
}

#[test]
fn a_missing_file_states_the_os_error_once() {
    let tmp = ok(tempfile::tempdir());
    let missing = tmp.path().join("nonexist.obj");
    let manifest = tmp.path().join("m.toml");
    ok(std::fs::write(
        &manifest,
        format!(
            "[[run]]\nmesh = {:?}\nout = {:?}\nstyle = \"cube\"\n",
            s(&missing),
            s(&tmp.path().join("b"))
        ),
    ));
    let cases: Vec<Vec<String>> = vec![
        vec![
            "run".into(),
            s(&missing).into(),
            "--style".into(),
            "cube".into(),
            "--out".into(),
            s(&tmp.path().join("r")).into(),
        ],
        vec![
            "apply".into(),
            s(&tmp.path().join("nonexist.npz")).into(),
            "--out".into(),
            s(&tmp.path().join("a.obj")).into(),
        ],
        vec![
            "render".into(),
            s(&missing).into(),
            "--out".into(),
            s(&tmp.path().join("f")).into(),
        ],
        vec!["mesh".into(), "check".into(), s(&missing).into()],
        vec!["batch".into(), s(&manifest).into()],
        vec!["batch".into(), s(&tmp.path().join("nonexist.toml")).into()],
    ];
    for args in cases {
        let args: Vec<&str> = args.iter().map(String::as_str).collect();
        let out = stylize(&args);
        assert!(!out.status.success(), "{args:?}");
        let err = stderr(&out);
        assert_eq!(
            err.matches("No such file or directory").count(),
            1,
            "{args:?}:\n{err}"
        );
    }
}

#[test]
fn batch_says_one_row_prints_repair_warnings_and_takes_log_format() {
    let tmp = ok(tempfile::tempdir());
    let mesh = octahedron(tmp.path(), "stray.obj", true);
    let manifest = tmp.path().join("m.toml");
    ok(std::fs::write(
        &manifest,
        format!(
            "[[run]]\nmesh = {:?}\nout = {:?}\nstyle = \"cube\"\n",
            s(&mesh),
            s(&tmp.path().join("b"))
        ),
    ));
    let settings = [
        "--set",
        "style.iterations=3",
        "--set",
        "run.turntable_views=1",
        "--set",
        "run.turntable_size=16",
    ];
    let mut args = vec!["batch", s(&manifest), "--log-format", "jsonl"];
    args.extend(settings);
    let out = stylize(&args);
    must(&out);
    let err = stderr(&out);
    assert!(err.contains(": 1 row, 0 failed"), "{err}");
    assert!(!err.contains("1 rows"), "{err}");
    // The repair of the stray vertex, as run.json records it, now also on the terminal.
    let run_json: serde_json::Value = ok(serde_json::from_str(&ok(std::fs::read_to_string(
        tmp.path().join("b/run.json"),
    ))));
    let recorded = run_json["warnings"].as_array().cloned().unwrap_or_default();
    assert!(
        !recorded.is_empty(),
        "no repair warning recorded: {run_json}"
    );
    for w in recorded {
        let w = w.as_str().unwrap_or_default();
        assert!(
            err.contains(&format!("warning: {w}")),
            "{w:?} not in:\n{err}"
        );
    }
    // --log-format jsonl: one JSON object per iteration on stdout.
    let stdout = String::from_utf8_lossy(&out.stdout).into_owned();
    let lines: Vec<&str> = stdout.lines().collect();
    assert_eq!(lines.len(), 3, "{stdout}");
    for l in lines {
        let v: serde_json::Value = ok(serde_json::from_str(l));
        assert!(v.get("iteration").is_some(), "{l}");
    }
    // The old `--jsonl` flag still works (hidden), `--force` to run the row again.
    let mut args = vec!["batch", s(&manifest), "--jsonl", "--force"];
    args.extend(settings);
    let out = stylize(&args);
    must(&out);
    assert_eq!(String::from_utf8_lossy(&out.stdout).lines().count(), 3);
}

#[test]
fn help_texts_name_no_spec_sections_or_crates() {
    for sub in [
        vec!["--help"],
        vec!["run", "--help"],
        vec!["batch", "--help"],
        vec!["apply", "--help"],
        vec!["render", "--help"],
        vec!["eval", "--help"],
        vec!["embed", "--help"],
        vec!["mesh", "check", "--help"],
    ] {
        let out = stylize(&sub);
        must(&out);
        let help = String::from_utf8_lossy(&out.stdout).into_owned();
        for bad in [
            "§",
            "mesh_core",
            "raster_diff",
            "csd",
            "diffusion_onnx",
            "darap::",
        ] {
            assert!(!help.contains(bad), "{sub:?} mentions {bad}:\n{help}");
        }
    }
    let run_help = String::from_utf8_lossy(&stylize(&["run", "--help"]).stdout).into_owned();
    let batch_help = String::from_utf8_lossy(&stylize(&["batch", "--help"]).stdout).into_owned();
    for shared in [
        "--model <DIR>",
        "--config <FILE>",
        "--set <KEY=VALUE>",
        "--log-format <FORMAT>",
        "--quiet",
    ] {
        assert!(
            run_help.contains(shared) && batch_help.contains(shared),
            "{shared}"
        );
    }
    assert!(!batch_help.contains("--jsonl"), "the old flag is hidden");
}

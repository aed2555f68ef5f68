//! The binary's build features (`text`, `gpu`, `view`, `mp4`; docs/cli.md, "Builds and features"):
//! `--version` names them, and in a build without one (the README's quick-start build, CI's
//! `cargo test -p stylize-cli --no-default-features --test features`) whatever
//! needs it fails at once, with the command that builds the full binary, before it touches the
//! output directory, while the model-free path still runs.

use std::path::PathBuf;

mod common;
use common::{ok, s, stderr, stylize};

fn repo() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../..")
}

#[test]
fn version_names_the_features_of_this_build() {
    let out = stylize(&["--version"]);
    assert!(out.status.success(), "{}", stderr(&out));
    let text = String::from_utf8_lossy(&out.stdout);
    let on: Vec<&str> = [
        ("text", cfg!(feature = "text")),
        ("gpu", cfg!(feature = "gpu")),
        ("view", cfg!(feature = "view")),
        ("mp4", cfg!(feature = "mp4")),
    ]
    .iter()
    .filter_map(|&(n, on)| on.then_some(n))
    .collect();
    let want = if on.is_empty() {
        "none".to_owned()
    } else {
        on.join(", ")
    };
    assert!(
        text.trim_end()
            .ends_with(&format!("{} (features: {want})", env!("CARGO_PKG_VERSION"))),
        "{text}"
    );
}

/// Asserts that `out` failed with the missing-feature message for `feature`.
#[cfg(not(all(feature = "text", feature = "view")))]
fn refused_for(out: &std::process::Output, feature: &str) {
    let e = stderr(out);
    assert_eq!(out.status.code(), Some(1), "{e}");
    assert!(
        e.contains(&format!("needs the `{feature}` feature"))
            && e.contains("cargo install --locked --path crates/stylize-cli")
            && !e.contains("panicked"),
        "{e}"
    );
}

#[cfg(not(feature = "text"))]
#[test]
fn without_text_every_text_command_is_refused_before_any_work() {
    let tmp = ok(tempfile::tempdir());
    let model = repo().join("fixtures/models/tiny-if");
    let mesh = repo().join("fixtures/meshes/bunny.obj");
    let out_dir = tmp.path().join("run");
    let run = stylize(&[
        "run",
        s(&mesh),
        "--prompt",
        "a lego bunny",
        "--model",
        s(&model),
        "--out",
        s(&out_dir),
    ]);
    refused_for(&run, "text");
    assert!(!out_dir.exists(), "nothing was written");
    // Without --model the missing feature, not the missing model, is what the user learns.
    refused_for(
        &stylize(&["run", s(&mesh), "--prompt", "x", "--out", s(&out_dir)]),
        "text",
    );
    refused_for(
        &stylize(&["embed", "--model", s(&model), "--prompt", "a chair"]),
        "text",
    );
    refused_for(
        &stylize(&[
            "debug-guidance",
            "--model",
            s(&model),
            "--images",
            s(&tmp.path().join("x.npy")),
            "--prompt",
            "x",
            "--out",
            s(&tmp.path().join("y.npz")),
        ]),
        "text",
    );
    refused_for(
        &stylize(&[
            "eval",
            "--pair",
            s(&mesh),
            s(&mesh),
            "--clip",
            s(&tmp.path().join("clip")),
        ]),
        "text",
    );
    let manifest = tmp.path().join("batch.toml");
    ok(std::fs::write(
        &manifest,
        format!(
            "[[run]]\nmesh = {:?}\nprompt = \"a chair\"\nout = {:?}\n",
            s(&mesh),
            s(&tmp.path().join("row"))
        ),
    ));
    let batch = stylize(&["batch", s(&manifest), "--model", s(&model)]);
    assert!(!batch.status.success(), "{}", stderr(&batch));
    assert!(
        stderr(&batch).contains("needs the `text` feature"),
        "{}",
        stderr(&batch)
    );
}

#[cfg(not(feature = "view"))]
#[test]
fn without_view_the_viewer_is_refused() {
    let out = stylize(&["view", "--port", "0", "."]);
    refused_for(&out, "view");
    // … and names the command that adds just the viewer to this build.
    let e = stderr(&out);
    assert!(
        e.contains("cargo run --release --no-default-features --features ")
            && e.contains("view --bin stylize -- …"),
        "{e}"
    );
}

/// What the quick-start build is for: the README's first command (fewer iterations) runs and
/// writes the pictures; its closing hint calls this very binary for `view` when it has the
/// feature, else the command that builds the full one.
#[test]
fn the_model_free_demo_runs_and_points_at_this_binary() {
    let tmp = ok(tempfile::tempdir());
    let out_dir = tmp.path().join("demo");
    let mesh = repo().join("fixtures/meshes/bunny.obj");
    let out = stylize(&[
        "run",
        s(&mesh),
        "--style",
        "cube",
        "--out",
        s(&out_dir),
        "--set",
        "style.iterations=4",
    ]);
    let e = stderr(&out);
    assert!(out.status.success(), "{e}");
    for f in ["mesh.obj", "mesh.glb", "before_after.png", "turntable.png"] {
        assert!(out_dir.join(f).is_file(), "{f} missing: {e}");
    }
    // The closing lines name the heat map beside the mesh it colours.
    assert!(
        out_dir.join("mesh_heat.glb").is_file()
            && e.contains("mesh_heat.glb  (the result coloured"),
        "{e}"
    );
    // The H.264 turntable: written with `mp4`, else named as missing (run.json, closing lines),
    // never a warning or a failure.
    let summary: serde_json::Value = ok(serde_json::from_str(&ok(std::fs::read_to_string(
        out_dir.join("run.json"),
    ))));
    let mp4 = &summary["turntable_mp4"];
    if cfg!(feature = "mp4") {
        assert!(out_dir.join("turntable.mp4").is_file(), "{e}");
        assert_eq!(mp4["file"], "turntable.mp4", "{mp4}");
        assert_eq!(mp4["frames"], 36, "{mp4}");
        assert!(
            e.contains("turntable.mp4  (the same turntable as H.264 video)"),
            "{e}"
        );
        // It decodes to the GIF's 36 frames of run.turntable_size (256) pixels, 8/100 s each.
        #[cfg(feature = "mp4")]
        {
            let bytes = ok(std::fs::read(out_dir.join("turntable.mp4")));
            let video = ok(stylize::turntable_mp4::decode_mp4(&bytes));
            assert_eq!((video.width, video.height), (256, 256));
            assert_eq!(video.frames.len(), 36);
            assert_eq!(video.durations, [8; 36]);
        }
    } else {
        assert!(!out_dir.join("turntable.mp4").exists());
        assert!(mp4["file"].is_null(), "{mp4}");
        assert!(
            mp4["not_written"]
                .as_str()
                .is_some_and(|w| w.contains("`mp4` feature")),
            "{mp4}"
        );
        assert!(
            e.contains("no turntable.mp4: this binary has no H.264 encoder"),
            "{e}"
        );
        assert!(!e.contains("turntable.mp4 not written"), "{e}");
    }
    let view_line = e
        .lines()
        .skip_while(|l| !l.starts_with("view it"))
        .nth(1)
        .unwrap_or_default()
        .trim()
        .to_string();
    let program = view_line.rsplit_once(" view ").map_or("", |(p, _)| p);
    if cfg!(feature = "view") {
        let exe = ok(std::fs::canonicalize(env!("CARGO_BIN_EXE_stylize")));
        let called = ok(std::fs::canonicalize(program.trim_matches('\'')));
        assert_eq!(called, exe, "{view_line}");
    } else {
        // The quick-start build's features plus `view` (none + view for the README's).
        assert!(
            program.starts_with("cargo run --release --no-default-features --features ")
                && program.ends_with("view --bin stylize --"),
            "{view_line}"
        );
    }
}

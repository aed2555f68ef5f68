//! A style that can barely move the input is reported: the fandisk as exemplar on the bunny warns
//! (in the outcome and in `run.json`), the cube style does not.

use std::path::{Path, PathBuf};

use stylize::config::Config;
use stylize::runner::{RunRequest, execute};
use stylize::style::Style;

fn ok<T, E: std::fmt::Debug>(r: Result<T, E>) -> T {
    r.unwrap_or_else(|e| panic!("{e:?}"))
}

fn fixture(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../fixtures/meshes")
        .join(name)
}

fn run_warnings(style: Style, out: &Path) -> Vec<String> {
    let mut config = Config::default();
    config.style.iterations = 1;
    config.run.preview_every = 0;
    config.run.turntable_views = 1;
    config.run.turntable_size = 16;
    config.run.turntable_gif_frames = 0;
    config.run.snapshot_every = 0;
    let request = RunRequest {
        mesh: fixture("bunny.obj"),
        out: out.to_path_buf(),
        config,
        force: false,
        resume: false,
        halt_after: None,
    };
    let outcome = ok(execute(&request, style));
    let summary: serde_json::Value = ok(serde_json::from_slice(&ok(std::fs::read(
        out.join("run.json"),
    ))));
    let recorded: Vec<String> = summary["warnings"]
        .as_array()
        .map(|a| {
            a.iter()
                .filter_map(|w| w.as_str().map(String::from))
                .collect()
        })
        .unwrap_or_default();
    assert_eq!(recorded, outcome.warnings);
    outcome.warnings
}

#[test]
fn a_weak_exemplar_is_warned_about_and_the_cube_style_is_not() {
    let tmp = ok(tempfile::tempdir());
    let fandisk = ok(Style::parse(&format!(
        "exemplar:{}",
        fixture("fandisk.off").display()
    )));
    let warnings = run_warnings(fandisk, &tmp.path().join("fandisk"));
    assert!(
        warnings
            .iter()
            .any(|w| w.contains("fandisk.off") && w.contains("° from their targets")),
        "{warnings:?}"
    );
    let warnings = run_warnings(Style::Cube, &tmp.path().join("cube"));
    assert!(
        !warnings.iter().any(|w| w.contains("from their targets")),
        "{warnings:?}"
    );
}

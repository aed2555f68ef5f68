//! The authors' own example (issue 41): their text-optimized chair normals,
//! `example-run/nrmls-expected-cuteanimalthemedchair.npz` of `threedle/geometry-in-style` (MIT; the
//! chair itself is a ShapeNet model, so the file is not redistributed here), re-applied with the
//! reference rule at the λ values of the issue's table.
//!
//! **Opt-in** (`#[ignore]`: CI has no copy of the file and no network to fetch it):
//!
//! ```text
//! GIS_AUTHORS_CHAIR_NPZ=/path/to/nrmls-expected-cuteanimalthemedchair.npz \
//!     cargo test -p stylize-cli --test authors_chair -- --ignored
//! ```
//!
//! The expected figures are not ours: the faces in self-intersecting pairs are the issue author's
//! pymeshlab counts (`compute_selection_by_self_intersections_per_face`), and the volume ratios and
//! flipped shares the issue's table. `docs/strength.md` has the face-by-face comparison.

#![allow(clippy::unwrap_used)]

use std::path::PathBuf;

mod common;
use common::stylize_text as stylize;

fn chair() -> PathBuf {
    let p = std::env::var_os("GIS_AUTHORS_CHAIR_NPZ").expect(
        "set GIS_AUTHORS_CHAIR_NPZ to the authors' nrmls-expected-cuteanimalthemedchair.npz",
    );
    let p = PathBuf::from(p);
    assert!(p.is_file(), "{} is not a file", p.display());
    p
}

/// `stylize apply CHAIR -o OUT ARGS…`: (success, stdout, stderr).
fn apply_chair(out: &std::path::Path, args: &[&str]) -> (bool, String, String) {
    common::apply_text(&chair(), out, args)
}

/// The number after `key` in `line` (`"volume ratio 0.906,"` → 0.906).
fn figure(line: &str, key: &str) -> f64 {
    let at = line
        .find(key)
        .unwrap_or_else(|| panic!("no `{key}` in {line}"));
    line[at + key.len()..]
        .trim_start()
        .split(|c: char| !(c.is_ascii_digit() || c == '.'))
        .next()
        .unwrap()
        .parse()
        .unwrap_or_else(|e| panic!("`{key}` in {line}: {e}"))
}

#[test]
#[ignore = "needs the authors' chair: GIS_AUTHORS_CHAIR_NPZ=… (see the file's doc comment)"]
fn the_issue_table_under_the_reference_rule() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("chair.obj");
    let (ok, stdout, stderr) = apply_chair(
        &out,
        &["--lambda", "5,8,10,12,15,20", "--rotation-rule", "gis"],
    );
    assert!(ok, "{stderr}");
    // (λ, volume ratio, % flipped, faces in intersecting pairs): the issue's table.
    let table = [
        (5, 1.021, 0.0, 4),
        (8, 1.009, 0.0, 4),
        (10, 0.906, 0.2, 77),
        (12, 0.681, 10.4, 398),
        (15, 0.385, 69.0, 3202),
        (20, 0.254, 95.0, 5503),
    ];
    for (lambda, volume, flipped, faces) in table {
        let head = format!("  λ = {lambda}: volume ratio");
        let line = stdout
            .lines()
            .find(|l| l.starts_with(&head))
            .unwrap_or_else(|| panic!("no line for λ = {lambda}: {stdout}"));
        assert!(
            (figure(line, "volume ratio") - volume).abs() < 1e-3,
            "{line}"
        );
        // The issue rounds 69.2 and 95.4 to whole per cent.
        let at = line.find("% of vertices flipped").unwrap();
        let pct: f64 = line[..at].rsplit(' ').next().unwrap().parse().unwrap();
        assert!((pct - flipped).abs() <= 0.5, "{line}");
        let at = line.find("self-intersections:").unwrap();
        let got = figure(&line[at..], "pairs (");
        assert_eq!(got as usize, faces, "{line}");
    }
    // The source's own pairs (4 faces) are not new; λ = 5 and 8 add none, λ = 10 does.
    assert!(
        !stderr.contains("warning: λ = 5:") && !stderr.contains("warning: λ = 8:"),
        "{stderr}"
    );
    assert!(stderr.contains("λ = 10: 76 new"), "{stderr}");
}

#[test]
#[ignore = "needs the authors' chair: GIS_AUTHORS_CHAIR_NPZ=… (see the file's doc comment)"]
fn max_safe_stops_between_the_saved_lambda_and_the_first_intersection() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("safe.obj");
    let (ok, stdout, stderr) = apply_chair(&out, &["--lambda", "max-safe:20"]);
    assert!(ok, "{stderr}");
    let line = stdout
        .lines()
        .find(|l| l.starts_with("max-safe: λ = "))
        .unwrap_or_else(|| panic!("{stdout}"));
    let lambda = figure(line, "max-safe: λ =");
    // λ = 8 (the saved one) has no new pair, λ = 10 has 76 (the test above).
    assert!((8.0..10.0).contains(&lambda), "{line}");
    for (l, safe) in [(lambda, true), (lambda * 1.01, false)] {
        let o = dir.path().join(format!("at{l}.obj"));
        let (ok, so, se) = apply_chair(&o, &["--lambda", &format!("{l}")]);
        assert!(ok, "{se}");
        assert_eq!(!se.contains("warning"), safe, "λ = {l}: {so}{se}");
    }
}

#[test]
#[ignore = "needs the authors' chair: GIS_AUTHORS_CHAIR_NPZ=… (see the file's doc comment)"]
fn remesh_auto_leaves_the_chair_alone() {
    // The chair is the paper's example of an isotropic input (edge std/mean 0.15): `--remesh auto`
    // must keep it. Its rest mesh, written as an OBJ, through `mesh check`.
    let saved = stylize::saved::SavedDeformation::read(chair()).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let obj = dir.path().join("chair.obj");
    let mut text = String::new();
    for v in &saved.verts {
        text += &format!("v {} {} {}\n", v[0], v[1], v[2]);
    }
    for f in &saved.faces {
        text += &format!("f {} {} {}\n", f[0] + 1, f[1] + 1, f[2] + 1);
    }
    std::fs::write(&obj, text).unwrap();
    let (ok, stdout, stderr) = stylize(&["mesh", "check", obj.to_str().unwrap()]);
    assert!(ok, "{stderr}");
    assert!(
        stdout.contains("`stylize run` keeps them as they are"),
        "{stdout}"
    );
    assert!(stdout.contains("std/mean 0.150"), "{stdout}");
}

//! `stylize apply --lambda max-safe[:UPPER]` end to end: the λ it returns is safe (no warning when
//! applied) and 1 % above it is not, on a case that crosses once (the golden bunny under the
//! reference rule: flips past 1 %) and on one built to cross twice (a slab swinging through a
//! plate and out again, under the `procrustes` rule: new self-intersections on a middle band of λ only).

#![allow(clippy::unwrap_used)]

use std::path::{Path, PathBuf};

mod common;
use common::stylize_text as stylize;

use stylize::saved::SavedDeformation;

/// Runs max-safe, then applies at the answer and at 1 % above; returns (λ, max-safe's stderr).
fn max_safe_then_check(saved: &Path, upper: f64, extra: &[&str], dir: &Path) -> (f64, String) {
    let s = saved.to_str().unwrap();
    let out = dir.join("safe.obj");
    let spec = format!("max-safe:{upper}");
    let mut args = vec!["apply", s, "-o", out.to_str().unwrap(), "--lambda", &spec];
    args.extend_from_slice(extra);
    let (ok, stdout, stderr) = stylize(&args);
    assert!(ok, "{stderr}");
    assert!(out.is_file(), "the mesh at the safe λ is written");
    let line = stdout
        .lines()
        .find(|l| l.starts_with("max-safe: λ = "))
        .unwrap_or_else(|| panic!("{stdout}"));
    let lambda: f64 = line["max-safe: λ = ".len()..]
        .split_whitespace()
        .next()
        .unwrap()
        .parse()
        .unwrap();
    assert!(lambda > 0.0 && lambda < upper, "{stdout}");
    assert!(stdout.contains("self-intersections"), "{stdout}");

    let at = |l: f64, name: &str| {
        let o = dir.join(name);
        let l = format!("{l}");
        let mut args = vec!["apply", s, "-o", o.to_str().unwrap(), "--lambda", &l];
        args.extend_from_slice(extra);
        let (ok, stdout, stderr) = stylize(&args);
        assert!(ok, "{stderr}");
        (stdout, stderr)
    };
    let (so, se) = at(lambda, "at.obj");
    assert!(!se.contains("warning"), "λ = {lambda} is safe: {so}{se}");
    let (so, se) = at(lambda * 1.01, "above.obj");
    assert!(
        se.contains("warning"),
        "1 % above λ = {lambda} is not safe: {so}{se}"
    );
    (lambda, stderr)
}

#[test]
fn max_safe_crossing_once_bunny_flips() {
    let dir = tempfile::tempdir().unwrap();
    let saved =
        PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../fixtures/golden/bunny_targets.npz");
    let (lambda, stderr) = max_safe_then_check(&saved, 20.0, &[], dir.path());
    // λ = 8 is safe and λ = 10 is not (docs/cli.md, "λ sanity").
    assert!((8.0..10.0).contains(&lambda), "{lambda}");
    assert!(!stderr.contains("not monotone"), "{stderr}");
}

/// A closed box: the 8 corners `lo + (i·dx, j·dy, k·dz)` and 12 outward triangles, appended.
fn push_box(
    verts: &mut Vec<[f64; 3]>,
    faces: &mut Vec<[u32; 3]>,
    corner: impl Fn(usize, usize, usize) -> [f64; 3],
) {
    let b = verts.len() as u32;
    for k in 0..2 {
        for j in 0..2 {
            for i in 0..2 {
                verts.push(corner(i, j, k));
            }
        }
    }
    let c = |i: u32, j: u32, k: u32| b + i + 2 * j + 4 * k;
    let quads = [
        [c(0, 0, 0), c(0, 1, 0), c(1, 1, 0), c(1, 0, 0)], // k = 0
        [c(0, 0, 1), c(1, 0, 1), c(1, 1, 1), c(0, 1, 1)], // k = 1
        [c(0, 0, 0), c(1, 0, 0), c(1, 0, 1), c(0, 0, 1)], // j = 0
        [c(0, 1, 0), c(0, 1, 1), c(1, 1, 1), c(1, 1, 0)], // j = 1
        [c(0, 0, 0), c(0, 0, 1), c(0, 1, 1), c(0, 1, 0)], // i = 0
        [c(1, 0, 0), c(1, 1, 0), c(1, 1, 1), c(1, 0, 1)], // i = 1
    ];
    for [p, q, r, s] in quads {
        faces.push([p, q, r]);
        faces.push([p, r, s]);
    }
}

/// Two closed components (boxes, so that `R = I` reproduces the rest mesh exactly): a slab B
/// `[0, 1] × [−0.1, 0.1] × [0, 0.02]` whose first vertex `(0, −0.1, 0)` (pinned) lies on the hinge
/// (the y axis), with target normals asking it to turn about y by `ALPHA` (its far end going down,
/// −z); and a thin plate A around the plane y = 0 covering the angles [25°, 40°] below the x axis
/// at radii [0.45, 0.9], whose targets are its own normals (it stays). As λ grows the slab's angle
/// grows from 0 towards `ALPHA`: it passes through A (unsafe: new self-intersections) and out again
/// (safe).
fn swinging_slab(path: &Path) {
    const ALPHA: f64 = 80.0;
    let mut verts = Vec::new();
    let mut faces = Vec::new();
    push_box(&mut verts, &mut faces, |i, j, k| {
        [i as f64, if j == 0 { -0.1 } else { 0.1 }, 0.02 * k as f64]
    });
    let slab = verts.len();
    push_box(&mut verts, &mut faces, |i, j, k| {
        let t = (25.0f64 + 15.0 * k as f64).to_radians();
        let r = [0.45, 0.9][i];
        [r * t.cos(), if j == 0 { -0.01 } else { 0.01 }, -r * t.sin()]
    });
    let mut normals = mesh_core::normals::vertex_normals_area_weighted(&verts, &faces);
    let (s, c) = ALPHA.to_radians().sin_cos();
    for n in &mut normals[..slab] {
        // R_y(α) n: x → (cos α, 0, −sin α), z → (sin α, 0, cos α).
        *n = [c * n[0] + s * n[2], n[1], -s * n[0] + c * n[2]];
    }
    let base_file = SavedDeformation::read(
        PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../fixtures/golden/bunny_targets.npz"),
    )
    .unwrap();
    let f32s = |v: &[[f64; 3]]| v.iter().map(|p| p.map(|x| x as f32)).collect::<Vec<_>>();
    let saved = SavedDeformation {
        verts: f32s(&verts),
        faces,
        verts_normals: f32s(&normals),
        ..base_file
    };
    saved.write(path).unwrap();
}

#[test]
fn max_safe_crossing_twice_slab_through_plate() {
    let dir = tempfile::tempdir().unwrap();
    let saved = dir.path().join("slab.npz");
    swinging_slab(&saved);
    let extra = ["--rotation-rule", "procrustes"];
    // Sanity of the construction: safe at small λ, unsafe in the middle, safe again at the top.
    let (_, scan, _) = stylize(&[
        "apply",
        saved.to_str().unwrap(),
        "-o",
        dir.path().join("scan.obj").to_str().unwrap(),
        "--lambda",
        "1,2,4,8,16,32,64",
        "--rotation-rule",
        "procrustes",
    ]);
    let new_pairs = |l: &str| -> usize {
        let line = scan
            .lines()
            .find(|x| x.trim_start().starts_with(&format!("λ = {l}: volume")))
            .unwrap_or_else(|| panic!("{scan}"));
        line.rsplit(", ")
            .next()
            .unwrap()
            .trim_end_matches(" new")
            .parse()
            .unwrap()
    };
    assert_eq!(new_pairs("1"), 0, "{scan}");
    assert!(new_pairs("8") > 0, "{scan}");
    assert_eq!(new_pairs("32"), 0, "{scan}");
    let (lambda, stderr) = max_safe_then_check(&saved, 64.0, &extra, dir.path());
    assert!((1.0..8.0).contains(&lambda), "{lambda}");
    assert!(stderr.contains("not monotone"), "{stderr}");
}

#[test]
fn bad_max_safe_arguments_are_clear_errors() {
    let dir = tempfile::tempdir().unwrap();
    let saved =
        PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../fixtures/golden/bunny_targets.npz");
    let out = dir.path().join("x.obj");
    for (spec, says) in [
        ("max-safe:0", "upper end"),
        ("max-safe:-3", "upper end"),
        ("max-safe:NaN", "upper end"),
        ("max-safe:inf", "upper end"),
        ("max-safe:1e9", "upper end"),
        ("max-safe:abc", "not a number"),
        ("max-safe12", "max-safe:UPPER"),
        ("max-safe,5", "stands alone"),
        ("fast", "neither a number nor max-safe"),
    ] {
        let (ok, _, stderr) = stylize(&[
            "apply",
            saved.to_str().unwrap(),
            "-o",
            out.to_str().unwrap(),
            "--lambda",
            spec,
        ]);
        assert!(!ok, "{spec} accepted");
        assert!(stderr.contains(says), "{spec}: {stderr}");
        assert!(!stderr.contains("panicked"), "{spec}: {stderr}");
        assert!(!out.exists(), "{spec} wrote a file");
    }
}

/// The end of a run: a result with new self-intersections warns, records the figures in
/// `run.json` and names the strongest safe λ below the run's; a safe one stays quiet. (20
/// iterations of the cube style on the bunny: about 3 s each in the dev profile.)
#[test]
fn the_end_of_a_run_reports_new_intersections_and_the_strongest_safe_lambda() {
    let dir = tempfile::tempdir().unwrap();
    let mesh = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../fixtures/meshes/bunny.obj");
    let run = |lambda: &str, name: &str| {
        let out = dir.path().join(name);
        let (ok, _, stderr) = stylize(&[
            "run",
            mesh.to_str().unwrap(),
            "--style",
            "cube",
            "-o",
            out.to_str().unwrap(),
            "--set",
            &format!("darap.lambda={lambda}"),
            "--set",
            "style.iterations=20",
        ]);
        assert!(ok, "{stderr}");
        let summary: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(out.join("run.json")).unwrap()).unwrap();
        (stderr, summary)
    };
    let (stderr, summary) = run("30", "strong");
    let x = &summary["self_intersections"];
    assert!(x["new_pairs"].as_u64().unwrap() > 0, "{summary}");
    assert!(
        summary["warnings"]
            .as_array()
            .unwrap()
            .iter()
            .any(|w| w.as_str().unwrap().contains("new self-intersecting")),
        "{summary}"
    );
    let line = stderr
        .lines()
        .find(|l| l.contains("the strongest safe λ up to it is "))
        .unwrap_or_else(|| panic!("{stderr}"));
    let safe: f64 = line
        .split("up to it is ")
        .nth(1)
        .unwrap()
        .split_whitespace()
        .next()
        .unwrap()
        .parse()
        .unwrap();
    assert!(safe > 0.0 && safe < 30.0, "{line}");
    let (stderr, summary) = run("5", "gentle");
    assert!(summary.get("self_intersections").is_none(), "{summary}");
    assert!(!stderr.contains("strongest safe"), "{stderr}");
}

/// `apply --strength`: the strength control (docs/strength.md).
fn apply_out(args: &[&str]) -> (String, String) {
    let (ok, stdout, stderr) = stylize(args);
    assert!(ok, "{args:?}: {stderr}");
    (stdout, stderr)
}

#[test]
fn strength_one_writes_the_result_at_lambda_byte_for_byte() {
    let dir = tempfile::tempdir().unwrap();
    let saved =
        PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../fixtures/golden/bunny_targets.npz");
    let s = saved.to_str().unwrap();
    let plain = dir.path().join("plain.obj");
    let one = dir.path().join("one.obj");
    apply_out(&["apply", s, "-o", plain.to_str().unwrap()]);
    let (stdout, _) = apply_out(&["apply", s, "-o", one.to_str().unwrap(), "--strength", "1"]);
    assert!(stdout.contains("strength 1 (λ = 8): wrote"), "{stdout}");
    assert_eq!(std::fs::read(&plain).unwrap(), std::fs::read(&one).unwrap());
}

#[test]
fn strength_keeps_the_bunny_sane_where_the_larger_lambda_collapses_it() {
    // 3 × λ₀ both ways: the reference rule at λ = 24 flips most rotations (docs/strength.md: 92 %
    // at 3 λ₀); the strength control at 3 keeps the rotations and the volume.
    let dir = tempfile::tempdir().unwrap();
    let saved =
        PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../fixtures/golden/bunny_targets.npz");
    let s = saved.to_str().unwrap();
    let (_, big_lambda) = apply_out(&[
        "apply",
        s,
        "-o",
        dir.path().join("l24.obj").to_str().unwrap(),
        "--lambda",
        "24",
    ]);
    assert!(big_lambda.contains("flipped"), "{big_lambda}");
    let strong = dir.path().join("s3.obj");
    let (stdout, stderr) = apply_out(&[
        "apply",
        s,
        "-o",
        strong.to_str().unwrap(),
        "--strength",
        "3",
    ]);
    assert!(!stderr.contains("warning"), "{stdout}{stderr}");
    assert!(
        stdout.contains("strength 3 (λ = 8): volume ratio"),
        "{stdout}"
    );
    // … and it is another mesh than the saved result.
    let plain = dir.path().join("plain.obj");
    apply_out(&["apply", s, "-o", plain.to_str().unwrap()]);
    assert_ne!(
        std::fs::read(&plain).unwrap(),
        std::fs::read(&strong).unwrap()
    );
}

/// On the slab of [`max_safe_crossing_twice_slab_through_plate`] under the `procrustes` rule the
/// strength control at s from λ = 1 is the rule at λ = s: safe at 1, unsafe at 8, safe again at 32.
/// `--strength max-safe:64` finds the first crossing; the answer is safe and 1 % above it is not.
#[test]
fn strength_max_safe_finds_the_first_crossing_of_the_slab() {
    let dir = tempfile::tempdir().unwrap();
    let saved = dir.path().join("slab.npz");
    swinging_slab(&saved);
    let s = saved.to_str().unwrap();
    let base = ["--rotation-rule", "procrustes", "--lambda", "1"];
    let out = dir.path().join("safe.obj");
    let mut args = vec![
        "apply",
        s,
        "-o",
        out.to_str().unwrap(),
        "--strength",
        "max-safe:64",
    ];
    args.extend_from_slice(&base);
    let (stdout, stderr) = apply_out(&args);
    let line = stdout
        .lines()
        .find(|l| l.starts_with("max-safe: strength "))
        .unwrap_or_else(|| panic!("{stdout}"));
    let strength: f64 = line["max-safe: strength ".len()..]
        .split_whitespace()
        .next()
        .unwrap()
        .parse()
        .unwrap();
    assert!((1.0..8.0).contains(&strength), "{stdout}");
    assert!(stderr.contains("not monotone"), "{stderr}");
    for (value, safe) in [(strength, true), (strength * 1.01, false)] {
        let o = dir.path().join(format!("at{value}.obj"));
        let v = format!("{value}");
        let mut args = vec!["apply", s, "-o", o.to_str().unwrap(), "--strength", &v];
        args.extend_from_slice(&base);
        let (so, se) = apply_out(&args);
        assert_eq!(!se.contains("warning"), safe, "strength {value}: {so}{se}");
    }
}

#[test]
fn bad_strength_arguments_are_clear_errors() {
    let dir = tempfile::tempdir().unwrap();
    let saved =
        PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../fixtures/golden/bunny_targets.npz");
    let out = dir.path().join("x.obj");
    for (extra, says) in [
        (&["--strength", "0.5"][..], "[1, 100]"),
        (&["--strength", "0"][..], "[1, 100]"),
        (&["--strength", "NaN"][..], "[1, 100]"),
        (&["--strength", "1e9"][..], "[1, 100]"),
        (&["--strength", "max-safe:1"][..], "upper end"),
        (&["--strength", "max-safe:1e9"][..], "upper end"),
        (&["--strength", "max-safe,2"][..], "stands alone"),
        (&["--strength", "2", "--lambda", "5,8"][..], "one λ"),
        (&["--strength", "2", "--lambda", "max-safe"][..], "one λ"),
        (&["--strength", "fast"][..], "neither a number"),
    ] {
        let (ok, _, stderr) = common::apply_text(&saved, &out, extra);
        assert!(!ok, "{extra:?} accepted");
        assert!(stderr.contains(says), "{extra:?}: {stderr}");
        assert!(!out.exists(), "{extra:?} wrote a file");
    }
}

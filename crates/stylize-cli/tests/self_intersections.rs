//! Self-intersections where users see them: `mesh check` (the source), `eval` (pairs, faces and
//! new ones against the source, table and JSON) and `apply` (the sanity line and its warning),
//! agreeing with each other on the same meshes.

#![allow(clippy::unwrap_used)]

use std::path::PathBuf;

mod common;
use common::{s, stylize_text as stylize};

fn fixture(rel: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../../fixtures")
        .join(rel)
}

#[test]
fn mesh_check_reports_the_sources_self_intersections() {
    // The cow intersects itself as shipped (docs/self_intersections.md: 101 pairs, 89 faces);
    // the bunny does not.
    let (ok, out, err) = stylize(&["mesh", "check", s(&fixture("meshes/cow.off")), "--json"]);
    assert!(ok, "{err}");
    let j: serde_json::Value = serde_json::from_str(&out).unwrap();
    let x = &j["self_intersections"];
    let repaired = mesh_core::validate::repair(
        &mesh_core::io::read_mesh(fixture("meshes/cow.off")).unwrap(),
        &mesh_core::validate::RepairOptions::default(),
    )
    .unwrap()
    .mesh;
    let lib =
        mesh_core::intersect::self_intersections(&repaired.positions, &repaired.faces).unwrap();
    assert!(x["pairs"].as_u64().unwrap() > 0, "{x}");
    assert_eq!(x["pairs"].as_u64().unwrap() as usize, lib.pairs.len());
    assert_eq!(x["faces"].as_u64().unwrap() as usize, lib.faces.len());
    assert!(!x["example_pairs"].as_array().unwrap().is_empty());
    let (ok, table, _) = stylize(&["mesh", "check", s(&fixture("meshes/cow.off"))]);
    assert!(ok);
    assert!(
        table.contains(&format!("self-intersections: {} pairs", lib.pairs.len())),
        "{table}"
    );
    let (ok, table, _) = stylize(&["mesh", "check", s(&fixture("meshes/bunny.obj"))]);
    assert!(ok);
    assert!(table.contains("self-intersections: none"), "{table}");
}

#[test]
fn eval_and_apply_agree_on_new_self_intersections() {
    let dir = tempfile::tempdir().unwrap();
    let saved = fixture("golden/bunny_targets.npz");
    let out = dir.path().join("b.obj");
    let (ok, stdout, stderr) = stylize(&["apply", s(&saved), "-o", s(&out), "--lambda", "5,20"]);
    assert!(ok, "{stderr}");
    // apply's own count at λ = 20, from its sanity line.
    let line = stdout
        .lines()
        .find(|l| l.contains("λ = 20: volume"))
        .unwrap();
    let new: u64 = line
        .rsplit(", ")
        .next()
        .unwrap()
        .trim_end_matches(" new")
        .parse()
        .unwrap();
    assert!(new > 0, "{line}");
    assert!(
        stderr.contains("new self-intersecting face pairs"),
        "{stderr}"
    );
    let source = dir.path().join("source.obj");
    let (ok, _, err) = stylize(&["apply", s(&saved), "-o", s(&source), "--lambda", "0"]);
    assert!(ok, "{err}");
    // eval of the λ = 0 result (the rest mesh) against λ = 20 and λ = 5.
    let at20 = dir.path().join("b_lambda20.obj");
    let at5 = dir.path().join("b_lambda5.obj");
    let (ok, json, err) = stylize(&[
        "eval",
        "--json",
        "--pair",
        s(&source),
        s(&at20),
        "--pair",
        s(&source),
        s(&at5),
    ]);
    assert!(ok, "{err}");
    let j: serde_json::Value = serde_json::from_str(&json).unwrap();
    let x20 = &j["pairs"][0]["intersections"];
    assert_eq!(x20["new_pairs"].as_u64().unwrap(), new, "{x20}");
    assert_eq!(x20["source_pairs"], 0);
    assert!(x20["new_faces"].as_u64().unwrap() > 0);
    assert_eq!(j["pairs"][1]["intersections"]["new_pairs"], 0);
    let (ok, table, _) = stylize(&["eval", "--pair", s(&source), s(&at20)]);
    assert!(ok);
    assert!(table.contains("self-∩ faces (new)"), "{table}");
}

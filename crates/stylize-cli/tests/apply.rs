//! `stylize apply` end to end on the golden bunny: outputs equal the independent golden results.

#![allow(clippy::unwrap_used)]

use std::path::PathBuf;

use darap::RotationRule;
use stylize_cli::cmd::apply::{Args, run};

fn golden(name: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../../fixtures/golden")
        .join(name)
}

fn max_diff(a: &str, b: &PathBuf) -> f64 {
    let a = mesh_core::io::read_mesh(a).unwrap();
    let b = mesh_core::io::read_mesh(b).unwrap();
    assert_eq!(a.faces, b.faces);
    a.positions
        .iter()
        .zip(&b.positions)
        .flat_map(|(p, q)| (0..3).map(move |c| (p[c] - q[c]).abs()))
        .fold(0.0, f64::max)
}

fn args(out: PathBuf) -> Args {
    Args {
        saved: golden("bunny_targets.npz"),
        output: out,
        lambda: vec![],
        rotation_rule: None,
        mask: None,
        region: vec![],
        region_feather: None,
        no_region: false,
        force: false,
    }
}

#[test]
fn default_lambda_reproduces_golden_result() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("nested/folder/bunny.obj");
    run(args(out.clone())).unwrap();
    assert!(max_diff(out.to_str().unwrap(), &golden("bunny_lambda8_gis.obj")) < 1e-9);
}

#[test]
fn several_lambdas_write_one_file_each_and_match_golden() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("bunny.obj");
    run(Args {
        lambda: vec![5.0, 8.0],
        ..args(out)
    })
    .unwrap();
    let p5 = dir.path().join("bunny_lambda5.obj");
    let p8 = dir.path().join("bunny_lambda8.obj");
    assert!(max_diff(p5.to_str().unwrap(), &golden("bunny_lambda5_gis.obj")) < 1e-9);
    assert!(max_diff(p8.to_str().unwrap(), &golden("bunny_lambda8_gis.obj")) < 1e-9);
}

#[test]
fn procrustes_rule_matches_golden() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("bunny.obj");
    run(Args {
        lambda: vec![40.0],
        rotation_rule: Some(RotationRule::Procrustes),
        ..args(out.clone())
    })
    .unwrap();
    assert!(
        max_diff(
            out.to_str().unwrap(),
            &golden("bunny_lambda40_procrustes.obj")
        ) < 1e-9
    );
}

#[test]
fn existing_outputs_are_refused_without_force_and_nothing_is_written() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("bunny.obj");
    std::fs::write(dir.path().join("bunny_lambda8.obj"), "keep me").unwrap();
    let err = run(Args {
        lambda: vec![5.0, 8.0],
        ..args(out.clone())
    })
    .unwrap_err();
    assert!(format!("{err:#}").contains("--force"));
    assert!(
        !dir.path().join("bunny_lambda5.obj").exists(),
        "no output may be written before all are checked"
    );
    assert_eq!(
        std::fs::read_to_string(dir.path().join("bunny_lambda8.obj")).unwrap(),
        "keep me"
    );
    run(Args {
        lambda: vec![5.0, 8.0],
        force: true,
        ..args(out)
    })
    .unwrap();
    assert!(dir.path().join("bunny_lambda5.obj").exists());
}

#[test]
fn empty_mask_file_keeps_rest_shape() {
    let dir = tempfile::tempdir().unwrap();
    let mask = dir.path().join("mask.txt");
    std::fs::write(&mask, "# no vertex may rotate\n\n").unwrap();
    let out = dir.path().join("bunny.obj");
    run(Args {
        mask: Some(mask),
        ..args(out.clone())
    })
    .unwrap();
    // R = I everywhere on a closed mesh: the rest shape, recentred (same bbox diagonal).
    let saved = stylize::saved::SavedDeformation::read(golden("bunny_targets.npz")).unwrap();
    let mut rest = saved.verts_f64();
    mesh_core::normalize::side2_cube(&mut rest);
    let n = rest.len() as f64;
    let mean: [f64; 3] = std::array::from_fn(|c| rest.iter().map(|p| p[c]).sum::<f64>() / n);
    let expected: Vec<[f64; 3]> = rest
        .iter()
        .map(|p| std::array::from_fn(|c| p[c] - mean[c]))
        .collect();
    let got = mesh_core::io::read_mesh(&out).unwrap().positions;
    let d = got
        .iter()
        .zip(&expected)
        .flat_map(|(p, q)| (0..3).map(move |c| (p[c] - q[c]).abs()))
        .fold(0.0, f64::max);
    assert!(d < 1e-10, "{d}");
}

#[test]
fn bad_inputs_give_clear_errors() {
    let dir = tempfile::tempdir().unwrap();
    let bad_ext = run(args(dir.path().join("bunny.stl"))).unwrap_err();
    assert!(format!("{bad_ext:#}").contains(".obj, .ply or .glb"));
    let missing = run(Args {
        saved: dir.path().join("nope.npz"),
        ..args(dir.path().join("a.obj"))
    })
    .unwrap_err();
    assert!(format!("{missing:#}").contains("nope.npz"));
    let mask = dir.path().join("mask.txt");
    std::fs::write(&mask, "0\n99999\n").unwrap();
    let bad_mask = run(Args {
        mask: Some(mask),
        ..args(dir.path().join("b.obj"))
    })
    .unwrap_err();
    assert!(format!("{bad_mask:#}").contains("line 2"));
    let neg = run(Args {
        lambda: vec![-1.0],
        ..args(dir.path().join("c.obj"))
    })
    .unwrap_err();
    assert!(format!("{neg:#}").contains("λ"));
}

#[test]
fn a_region_vertex_file_is_never_overwritten_even_with_force() {
    let dir = tempfile::tempdir().unwrap();
    let verts = dir.path().join("region.obj");
    std::fs::write(&verts, "0\n1\n2\n").unwrap();
    let e = run(Args {
        region: vec![format!("vertices:{}", verts.display())],
        force: true,
        ..args(verts.clone())
    })
    .unwrap_err();
    assert!(format!("{e:#}").contains("region vertex file"), "{e:#}");
    assert_eq!(std::fs::read_to_string(&verts).unwrap(), "0\n1\n2\n");
}

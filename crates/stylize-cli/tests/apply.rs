//! `stylize apply` end to end on the golden bunny: outputs equal the independent golden results.

#![allow(clippy::unwrap_used)]

use std::path::PathBuf;

use darap::RotationRule;
use stylize_cli::cmd::apply::{Args, LambdaArg, run};

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
        strength: vec![],
        rotation_rule: None,
        mask: None,
        region: vec![],
        region_feather: None,
        no_region: false,
        output_frame: None,
        force: false,
    }
}

#[test]
fn a_file_without_a_recorded_frame_is_written_normalized_and_refuses_the_input_frame() {
    let dir = tempfile::tempdir().unwrap();
    // The golden file (the reference's keys only): the default writes the normalized frame (the
    // golden result, checked below), an explicit input frame is an error naming the key.
    let e = run(Args {
        output_frame: Some(stylize::frame::OutputFrame::Input),
        ..args(dir.path().join("x.obj"))
    })
    .expect_err("no to_input_frame");
    assert!(format!("{e:#}").contains("to_input_frame"), "{e:#}");
    assert!(!dir.path().join("x.obj").exists());
    run(Args {
        output_frame: Some(stylize::frame::OutputFrame::Normalized),
        ..args(dir.path().join("n.obj"))
    })
    .unwrap();
    run(args(dir.path().join("d.obj"))).unwrap();
    assert_eq!(
        std::fs::read(dir.path().join("n.obj")).unwrap(),
        std::fs::read(dir.path().join("d.obj")).unwrap()
    );
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
        lambda: vec![LambdaArg::Value(5.0), LambdaArg::Value(8.0)],
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
        lambda: vec![LambdaArg::Value(40.0)],
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
        lambda: vec![LambdaArg::Value(5.0), LambdaArg::Value(8.0)],
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
        lambda: vec![LambdaArg::Value(5.0), LambdaArg::Value(8.0)],
        force: true,
        ..args(out)
    })
    .unwrap();
    assert!(dir.path().join("bunny_lambda5.obj").exists());
}

#[test]
fn mask_file_listing_no_vertex_is_an_error_and_writes_nothing() {
    // (R = I everywhere giving the rest shape is darap's own test,
    // `all_false_mask_gives_rest_shape_and_zero_gradient`.)
    let dir = tempfile::tempdir().unwrap();
    let mask = dir.path().join("mask.txt");
    let out = dir.path().join("bunny.obj");
    for text in ["", "# no vertex may rotate\n\n"] {
        std::fs::write(&mask, text).unwrap();
        let e = run(Args {
            mask: Some(mask.clone()),
            ..args(out.clone())
        })
        .expect_err("an empty mask is refused");
        let e = format!("{e:#}");
        assert!(
            e.contains("mask.txt") && e.contains("lists no vertex"),
            "{e}"
        );
        assert!(!out.exists());
    }
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
        lambda: vec![LambdaArg::Value(-1.0)],
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

#[test]
fn a_missing_or_malformed_recorded_lambda_is_named_as_the_files() {
    let dir = tempfile::tempdir().unwrap();
    let mut saved = stylize::saved::SavedDeformation::read(golden("bunny_targets.npz")).unwrap();
    let path = dir.path().join("edited.npz");
    let cases = [
        (r#"{"local_step_procrustes": {"lamb": -3}}"#, "lamb = -3"),
        (
            r#"{"local_step_procrustes": {"lamb": "eight"}}"#,
            "lamb = \"eight\"",
        ),
        (
            r#"{"local_step_procrustes": {"lamb": NaN}}"#,
            "not valid JSON",
        ),
        (r#"{"local_step_procrustes": {}}"#, "records no λ"),
    ];
    for (cfg, needle) in cases {
        saved.deform_by_csd_cfg = cfg.to_string();
        saved.write(&path).unwrap();
        let e = run(Args {
            saved: path.clone(),
            ..args(dir.path().join("out.obj"))
        })
        .expect_err("refused");
        let e = format!("{e:#}");
        assert!(
            e.contains(needle) && e.contains("edited.npz") && !e.contains("--lambda -"),
            "{cfg}: {e}"
        );
    }
    // --lambda overrides what the file records.
    run(Args {
        saved: path,
        lambda: vec![LambdaArg::Value(5.0)],
        ..args(dir.path().join("out.obj"))
    })
    .unwrap();
}

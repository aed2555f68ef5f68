//! Agreement with the independent NumPy/SciPy golden data in `fixtures/golden` (see its README).

#![allow(clippy::unwrap_used)]

use darap::{Darap, DarapOptions, RotationRule};
use npy::NpyData;
use npy::npz::NpzReader;
use std::path::PathBuf;

fn golden(name: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../../fixtures/golden")
        .join(name)
}

const CASES: [(&str, f64, RotationRule); 4] = [
    ("bunny_lambda8_gis", 8.0, RotationRule::Gis),
    ("bunny_lambda5_gis", 5.0, RotationRule::Gis),
    ("bunny_lambda8_procrustes", 8.0, RotationRule::Procrustes),
    ("bunny_lambda40_procrustes", 40.0, RotationRule::Procrustes),
];

type Rows = Vec<[f64; 3]>;

/// The saved deformation's rest mesh normalized to the side-2 cube in f64, and its raw targets.
/// (Read with the npy crate directly: the saved-deformation type lives in `stylize`, above darap.)
fn inputs() -> (Rows, Vec<[u32; 3]>, Rows) {
    let saved = NpzReader::open(golden("bunny_targets.npz")).unwrap();
    let widen = |rows: Vec<[f32; 3]>| -> Rows { rows.iter().map(|p| p.map(f64::from)).collect() };
    let mut verts = widen(saved.rows3_f32("verts").unwrap());
    mesh_core::normalize::side2_cube(&mut verts);
    let faces = saved.rows3_u32("faces").unwrap();
    (
        verts,
        faces,
        widen(saved.rows3_f32("verts_normals").unwrap()),
    )
}

/// `local_step_procrustes.lamb` of the saved configuration.
fn saved_lambda() -> Option<f64> {
    let saved = NpzReader::open(golden("bunny_targets.npz")).unwrap();
    let cfg: serde_json::Value =
        serde_json::from_str(&saved.string("deform_by_csd_cfg").unwrap()).unwrap();
    cfg.get("local_step_procrustes")?.get("lamb")?.as_f64()
}

#[test]
fn positions_match_golden_for_all_four_cases() {
    let (verts, faces, x) = inputs();
    assert_eq!(saved_lambda(), Some(8.0));
    for (case, lambda, rule) in CASES {
        let opts = DarapOptions {
            lambda,
            rotation_rule: rule,
            ..Default::default()
        };
        let layer = Darap::new(&verts, &faces, opts).unwrap();
        let out = layer.forward(&x).unwrap();
        let expected = mesh_core::io::read_mesh(golden(&format!("{case}.obj"))).unwrap();
        assert_eq!(expected.faces, faces, "{case}: faces differ");
        let err = out
            .positions
            .iter()
            .zip(&expected.positions)
            .flat_map(|(a, b)| (0..3).map(move |c| (a[c] - b[c]).abs()))
            .fold(0.0, f64::max);
        eprintln!("{case}: max |Δposition| = {err:.2e}");
        assert!(err < 1e-9, "{case}: max |Δposition| = {err:e}");
    }
}

#[test]
fn vjp_directional_derivatives_match_golden() {
    let (verts, faces, x) = inputs();
    let vjp = NpzReader::open(golden("bunny_vjp.npz")).unwrap();
    let cot = vjp.rows3_f64("golden_cotangent").unwrap();
    let dirs: Vec<Vec<[f64; 3]>> = (0..3)
        .map(|k| vjp.rows3_f64(&format!("direction_{k}")).unwrap())
        .collect();
    for (case, lambda, rule) in CASES {
        let expected = match &vjp.require(&format!("{case}_directional")).unwrap().data {
            NpyData::F64(v) => v.clone(),
            other => panic!("unexpected dtype {}", other.descr()),
        };
        let opts = DarapOptions {
            lambda,
            rotation_rule: rule,
            ..Default::default()
        };
        let layer = Darap::new(&verts, &faces, opts).unwrap();
        let state = layer.forward(&x).unwrap();
        let g = layer.backward(&state, &cot);
        for (k, d) in dirs.iter().enumerate() {
            let an: f64 = g
                .iter()
                .zip(d)
                .map(|(a, b)| a[0] * b[0] + a[1] * b[1] + a[2] * b[2])
                .sum();
            let rel = (an - expected[k]).abs() / expected[k].abs().max(1e-12);
            eprintln!("{case} direction {k}: rel. error {rel:.2e}");
            assert!(
                rel < 1e-6,
                "{case} direction {k}: adjoint {an:.12e} vs golden {:.12e} (rel {rel:e})",
                expected[k]
            );
        }
    }
}

#[test]
fn rotation_at_vertex0_and_max_angle_match_golden_summary() {
    let (verts, faces, x) = inputs();
    let text = std::fs::read_to_string(golden("summary.json")).unwrap();
    let summary: serde_json::Value = serde_json::from_str(&text).unwrap();
    for case in summary["cases"].as_array().unwrap() {
        let lambda = case["lambda"].as_f64().unwrap();
        let rule = match case["rotation_rule"].as_str().unwrap() {
            "gis" => RotationRule::Gis,
            _ => RotationRule::Procrustes,
        };
        let layer = Darap::new(
            &verts,
            &faces,
            DarapOptions {
                lambda,
                rotation_rule: rule,
                ..Default::default()
            },
        )
        .unwrap();
        let out = layer.forward(&x).unwrap();
        let r0 = &out.rotations[0];
        for i in 0..3 {
            for j in 0..3 {
                let e = case["R_vertex0"][i][j].as_f64().unwrap();
                assert!(
                    (r0[i][j] - e).abs() < 1e-9,
                    "{}: R0[{i}][{j}] {} vs {e}",
                    case["file"],
                    r0[i][j]
                );
            }
        }
        // Rotation angle from the trace: θ = acos((tr R − 1)/2).
        let max_angle = out
            .rotations
            .iter()
            .map(|r| {
                ((r[0][0] + r[1][1] + r[2][2] - 1.0) / 2.0)
                    .clamp(-1.0, 1.0)
                    .acos()
                    .to_degrees()
            })
            .fold(0.0, f64::max);
        let expected = case["rotation_angle_deg_max"].as_f64().unwrap();
        assert!(
            (max_angle - expected).abs() < 1e-6,
            "{}: max angle {max_angle} vs {expected}",
            case["file"]
        );
    }
}

//! End-to-end tests of the model-free path through the library entry point (`runner::execute`):
//! the shape moves toward its style, the run directory is complete, `--resume` after an
//! interruption equals an uninterrupted run, and `deformation.npz` re-applies (spec §8) to the
//! saved mesh.

use std::path::{Path, PathBuf};

use mesh_core::TriMesh;
use stylize::runner::{RunOutcome, RunRequest};
use stylize::saved::SavedDeformation;
use stylize::style::Style;
use stylize_cli::config::Config;
use stylize_cli::runner::{LogMode, execute};

mod common;
use common::ok;

/// An icosphere (2 subdivisions, 162 vertices) stretched into an ellipsoid, as an OBJ file.
fn small_mesh(dir: &Path) -> PathBuf {
    let (p, f) = mesh_core::shapes::icosphere(2).into_parts();
    let p: Vec<[f64; 3]> = p.iter().map(|v| [1.5 * v[0], v[1], 0.8 * v[2]]).collect();
    let path = dir.join("ellipsoid.obj");
    ok(mesh_core::io::write_mesh(&path, &TriMesh::new(p, f), None));
    path
}

fn config(iterations: u64, checkpoint_every: u64) -> Config {
    let mut c = Config::default();
    c.style.iterations = iterations;
    c.run.checkpoint_every = checkpoint_every;
    c.run.preview_every = 0;
    c.run.turntable_views = 2;
    c.run.turntable_size = 32;
    c
}

fn run(
    mesh: &Path,
    out: &Path,
    config: Config,
    resume: bool,
    halt_after: Option<u64>,
) -> anyhow::Result<RunOutcome> {
    let request = RunRequest {
        mesh: mesh.to_path_buf(),
        out: out.to_path_buf(),
        config,
        force: false,
        resume,
        halt_after,
    };
    execute(&request, LogMode::Quiet, Style::Cube)
}

#[test]
fn cube_style_increases_face_alignment_with_the_cube_gauss_map() {
    let tmp = ok(tempfile::tempdir());
    let mesh = small_mesh(tmp.path());
    let outcome = ok(run(
        &mesh,
        &tmp.path().join("run"),
        config(40, 0),
        false,
        None,
    ));
    let (before, after) = outcome.alignment.unwrap_or((0.0, 0.0));
    assert!(outcome.complete);
    assert!(before > 0.5 && before < 0.95, "before {before}");
    // Measured independently of the loop: re-read the written mesh and score it.
    let written = ok(mesh_core::io::read_mesh(tmp.path().join("run/mesh.obj")));
    let rest = ok(stylize::runner::prepare_mesh(&mesh)).0;
    let targets = Style::Cube.face_targets(&rest.positions, &rest.faces);
    let measured =
        stylize::style::alignment::mean_alignment(&written.positions, &written.faces, &targets);
    assert!((measured - after).abs() < 1e-9, "{measured} vs {after}");
    assert!(after > before + 0.03, "alignment {before} → {after}");
}

#[test]
fn run_directory_is_complete_and_refuses_overwrite() {
    let tmp = ok(tempfile::tempdir());
    let mesh = small_mesh(tmp.path());
    let out = tmp.path().join("nested/dirs/run");
    let mut cfg = config(6, 4);
    // A text-path setting: not used, so warned about and not recorded as the run's.
    cfg.optim.iterations = 2000;
    let outcome = ok(run(&mesh, &out, cfg.clone(), false, None));
    assert!(
        outcome
            .warnings
            .iter()
            .any(|w| w.contains("optim.iterations = 2000")
                && w.contains("not used by a model-free style run")),
        "{:?}",
        outcome.warnings
    );
    for f in [
        "config.toml",
        "metrics.jsonl",
        "checkpoint.json",
        "mesh.obj",
        "mesh.ply",
        "mesh.glb",
        "mesh_heat.glb",
        "deformation.npz",
        "turntable.png",
        "run.json",
    ] {
        assert!(out.join(f).is_file(), "{f} missing");
    }
    check_heat_map(&mesh, &out);
    assert_eq!(ok(stylize_cli::config::load(&out.join("config.toml"))), cfg);
    let metrics = ok(std::fs::read_to_string(out.join("metrics.jsonl")));
    let iterations: Vec<u64> = metrics
        .lines()
        .map(|l| {
            ok(serde_json::from_str::<serde_json::Value>(l))["iteration"]
                .as_u64()
                .unwrap_or(0)
        })
        .collect();
    assert_eq!(iterations, vec![1, 2, 3, 4, 5, 6]);
    let summary: serde_json::Value = ok(serde_json::from_str(&ok(std::fs::read_to_string(
        out.join("run.json"),
    ))));
    assert_eq!(summary["status"], "complete");
    let saved = ok(SavedDeformation::read(out.join("deformation.npz")));
    assert_eq!(saved.lambda(), Some(8.0));
    let recorded = saved.csd_cfg();
    assert_eq!(
        (recorded["n_iters"].as_u64(), recorded["lr"].as_f64()),
        (Some(6), Some(cfg.style.lr)),
        "the optimizer settings the run used"
    );
    assert!(saved.extra("seed").is_some() && saved.extra("rotation_rule").is_some());
    assert!(saved.extra("format_version").is_some());
    let e = run(&mesh, &out, cfg, false, None)
        .err()
        .map(|e| format!("{e:#}"))
        .unwrap_or_default();
    assert!(e.contains("--force"), "{e}");
}

#[test]
fn resume_after_interruption_equals_uninterrupted_run() {
    let tmp = ok(tempfile::tempdir());
    let mesh = small_mesh(tmp.path());
    let cfg = config(12, 5);
    let a = tmp.path().join("a");
    ok(run(&mesh, &a, cfg.clone(), false, None));
    // "Killed" after iteration 8: the last checkpoint is at 5, iterations 6–8 are lost.
    let b = tmp.path().join("b");
    let halted = ok(run(&mesh, &b, cfg.clone(), false, Some(8)));
    assert!(!halted.complete && halted.iteration == 8);
    let e = run(&mesh, &b, cfg.clone(), false, None)
        .err()
        .map(|e| format!("{e:#}"))
        .unwrap_or_default();
    assert!(e.contains("--resume"), "{e}");
    let resumed = ok(run(&mesh, &b, cfg, true, None));
    assert!(resumed.complete && resumed.iteration == 12);
    let xa = ok(SavedDeformation::read(a.join("deformation.npz"))).verts_normals;
    let xb = ok(SavedDeformation::read(b.join("deformation.npz"))).verts_normals;
    assert_eq!(xa, xb, "resumed run differs from the uninterrupted one");
    let ca = ok(stylize::checkpoint::Checkpoint::load(
        &a.join("checkpoint.json"),
    ));
    let cb = ok(stylize::checkpoint::Checkpoint::load(
        &b.join("checkpoint.json"),
    ));
    assert_eq!(ca.iteration, cb.iteration);
    assert!(ca.state.x == cb.state.x, "x differs after resume");
    assert!(
        ca.state.adam == cb.state.adam,
        "Adam state differs after resume"
    );
    let lines = |d: &Path| {
        ok(std::fs::read_to_string(d.join("metrics.jsonl")))
            .lines()
            .count()
    };
    assert_eq!(lines(&b), 12);
    assert_eq!(lines(&a), 12);
}

#[test]
fn saved_deformation_reapplies_to_the_saved_mesh() {
    let tmp = ok(tempfile::tempdir());
    let mesh = small_mesh(tmp.path());
    let out = tmp.path().join("run");
    ok(run(&mesh, &out, config(10, 0), false, None));
    // Spec §8 "apply": normalize `verts` to the side-2 cube, dARAP with the saved λ, forward.
    let saved = ok(SavedDeformation::read(out.join("deformation.npz")));
    let mut rest = saved.verts_f64();
    mesh_core::normalize::side2_cube(&mut rest);
    let lambda = saved.lambda().unwrap_or(f64::NAN);
    let layer = ok(darap::Darap::new(
        &rest,
        &saved.faces,
        darap::DarapOptions {
            lambda,
            ..Default::default()
        },
    ));
    let applied = ok(layer.forward(&saved.verts_normals_f64())).positions;
    // mesh.obj is in the input's frame (the default): placed by the recorded map.
    let frame = ok(saved.input_frame()).unwrap_or_else(|| panic!("no to_input_frame"));
    let applied = frame.place_result(&applied, &rest, true);
    let written = ok(mesh_core::io::read_mesh(out.join("mesh.obj")));
    assert_eq!(written.faces, saved.faces);
    let worst = applied
        .iter()
        .zip(&written.positions)
        .flat_map(|(a, b)| (0..3).map(move |k| (a[k] - b[k]).abs()))
        .fold(0.0, f64::max);
    assert!(
        worst < 1e-12,
        "re-applied mesh differs from mesh.obj by {worst}"
    );
}

#[test]
fn unknown_style_and_missing_mesh_are_clear_errors() {
    assert!(Style::parse("dodecahedron").is_err());
    let tmp = ok(tempfile::tempdir());
    let e = run(
        &tmp.path().join("nope.obj"),
        &tmp.path().join("r"),
        config(1, 0),
        false,
        None,
    )
    .err()
    .map(|e| format!("{e:#}"))
    .unwrap_or_default();
    assert!(e.contains("nope.obj"), "{e}");
    assert!(
        !tmp.path().join("r").exists(),
        "no run directory for an unreadable mesh"
    );
}

#[test]
fn lambda_zero_is_warned_about_up_front() {
    let tmp = ok(tempfile::tempdir());
    let mesh = small_mesh(tmp.path());
    let mut cfg = config(2, 0);
    cfg.darap.lambda = 0.0;
    let outcome = ok(run(&mesh, &tmp.path().join("run"), cfg, false, None));
    assert!(
        outcome
            .warnings
            .iter()
            .any(|w| w.starts_with("darap.lambda = 0") && w.contains("no effect")),
        "{:?}",
        outcome.warnings
    );
}

/// The `(count, 3)` f32 rows of a GLB attribute (our writer's layout: one buffer, tight VEC3).
fn glb_vec3(path: &Path, attribute: &str) -> Vec<[f32; 3]> {
    let bytes = ok(std::fs::read(path));
    let u32_at = |i: usize| {
        u32::from_le_bytes([bytes[i], bytes[i + 1], bytes[i + 2], bytes[i + 3]]) as usize
    };
    assert_eq!(&bytes[0..4], b"glTF");
    let json_len = u32_at(12);
    let json: serde_json::Value = ok(serde_json::from_slice(&bytes[20..20 + json_len]));
    let bin = &bytes[20 + json_len + 8..];
    let accessor = &json["accessors"][json["meshes"][0]["primitives"][0]["attributes"][attribute]
        .as_u64()
        .unwrap_or(u64::MAX) as usize];
    assert_eq!(accessor["componentType"], 5126, "{attribute}: f32");
    assert_eq!(accessor["type"], "VEC3");
    let view = &json["bufferViews"][accessor["bufferView"].as_u64().unwrap_or(u64::MAX) as usize];
    let offset = view["byteOffset"].as_u64().unwrap_or(0) as usize;
    let count = accessor["count"].as_u64().unwrap_or(0) as usize;
    (0..count)
        .map(|v| {
            [0, 1, 2].map(|k| {
                let i = offset + 12 * v + 4 * k;
                f32::from_le_bytes([bin[i], bin[i + 1], bin[i + 2], bin[i + 3]])
            })
        })
        .collect()
}

/// `mesh_heat.glb`: the result's positions, and colours that encode the displacement from the
/// rest mesh (at its vertex centroid) through the documented colormap, with the scale in run.json.
fn check_heat_map(mesh: &Path, out: &Path) {
    let rest = ok(stylize::runner::prepare_mesh(mesh)).0.positions;
    // mesh.obj (and the heat map's positions) are in the input's frame (the default); the
    // displacement is measured in the normalized frame: mesh.obj mapped back by the saved map.
    let written = ok(mesh_core::io::read_mesh(out.join("mesh.obj"))).positions;
    let saved = ok(SavedDeformation::read(out.join("deformation.npz")));
    let frame = ok(saved.input_frame()).unwrap_or_else(|| panic!("no to_input_frame"));
    let result = ok(frame.unplace_result(&written, &rest, true));
    let heat = out.join("mesh_heat.glb");
    // A valid glTF for the reader too, with the result's geometry.
    let read = ok(mesh_core::io::read_mesh(&heat));
    assert_eq!(read.positions.len(), result.len());
    for (g, r) in glb_vec3(&heat, "POSITION").iter().zip(&written) {
        for k in 0..3 {
            assert_eq!(g[k], r[k] as f32);
        }
    }
    let n = rest.len() as f64;
    let centroid = [0, 1, 2].map(|k| rest.iter().map(|r| r[k]).sum::<f64>() / n);
    let d: Vec<f64> = rest
        .iter()
        .zip(&result)
        .map(|(r, p)| {
            [0, 1, 2]
                .map(|k| (p[k] - (r[k] - centroid[k])).powi(2))
                .iter()
                .sum::<f64>()
                .sqrt()
        })
        .collect();
    let max = d.iter().copied().fold(0.0, f64::max);
    assert!(max > 1e-4, "the run should move the surface ({max})");
    let summary: serde_json::Value = ok(serde_json::from_str(&ok(std::fs::read_to_string(
        out.join("run.json"),
    ))));
    let recorded = summary["heat"]["max_displacement"]
        .as_f64()
        .unwrap_or(f64::NAN);
    assert!((recorded - max).abs() <= 1e-12 * max, "{recorded} vs {max}");
    assert_eq!(summary["heat"]["file"], "mesh_heat.glb");
    let colors = glb_vec3(&heat, "COLOR_0");
    assert_eq!(colors.len(), d.len());
    let mut most = 0;
    for (v, (c, &dv)) in colors.iter().zip(&d).enumerate() {
        let want = stylize::heat::colormap(dv / max).map(stylize::heat::srgb_to_linear);
        for k in 0..3 {
            assert!(
                (f64::from(c[k]) - want[k]).abs() < 1e-6,
                "vertex {v}: {c:?} vs {want:?}"
            );
        }
        if dv > d[most] {
            most = v;
        }
    }
    // The vertex that moved most is the colormap's last stop (yellow).
    let top = stylize::heat::VIRIDIS_STOPS[4].map(stylize::heat::srgb_to_linear);
    for k in 0..3 {
        assert!((f64::from(colors[most][k]) - top[k]).abs() < 1e-6);
    }
}

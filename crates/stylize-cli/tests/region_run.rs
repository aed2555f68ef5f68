//! Localized stylization end to end (issue 13): the cube style on one half of the bunny.
//!
//! Outside the region the rotations are exactly the identity and Adam leaves the targets at their
//! rest values; far from the region the surface moves only rigidly (through the global solve);
//! the region itself changes. The run directory, the task identity and `deformation.npz` carry
//! the region, and `stylize apply` re-applies it by default.

use std::path::{Path, PathBuf};
use std::process::Command;

use darap::Darap;
/// The 3×3 identity (row-major, as `darap::Mat3`).
const IDENTITY: darap::Mat3 = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];
use npy::NpyData;
use stylize::runner::{RunOutcome, RunRequest, darap_options, prepare_mesh_with_region};
use stylize::saved::SavedDeformation;
use stylize::style::Style;
use stylize_cli::config::{Config, RegionSection};
use stylize_cli::runner::{LogMode, execute};

mod common;
use common::ok;

fn bunny() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../fixtures/meshes/bunny.obj")
}

/// The half of the normalized bunny with x ≤ 0.
const LEFT_HALF: &str = "box:-1,-1,-1,0,1,1";

fn config(iterations: u64, specs: &[&str], feather: u32) -> Config {
    let mut c = Config::default();
    c.style.iterations = iterations;
    c.run.checkpoint_every = 0;
    c.run.preview_every = 0;
    c.run.turntable_views = 2;
    c.run.turntable_size = 32;
    c.region = RegionSection {
        specs: specs.iter().map(|s| s.to_string()).collect(),
        feather,
        tint: true,
    };
    c
}

fn run(out: &Path, config: Config, resume: bool, halt: Option<u64>) -> anyhow::Result<RunOutcome> {
    execute(
        &RunRequest {
            mesh: bunny(),
            out: out.to_path_buf(),
            config,
            force: false,
            resume,
            halt_after: halt,
        },
        LogMode::Quiet,
        Style::Cube,
    )
}

/// Per vertex, the largest relative change of an incident edge's length, after dividing out the
/// median ratio over the whole mesh (post-processing rescales the mesh uniformly).
fn edge_distortion(rest: &[[f64; 3]], deformed: &[[f64; 3]], faces: &[[u32; 3]]) -> Vec<f64> {
    let len = |p: &[[f64; 3]], a: u32, b: u32| {
        let (x, y) = (p[a as usize], p[b as usize]);
        ((x[0] - y[0]).powi(2) + (x[1] - y[1]).powi(2) + (x[2] - y[2]).powi(2)).sqrt()
    };
    let edges = mesh_core::topology::edges(faces);
    let ratios: Vec<f64> = edges
        .iter()
        .map(|e| len(deformed, e[0], e[1]) / len(rest, e[0], e[1]))
        .collect();
    let mut sorted = ratios.clone();
    sorted.sort_by(f64::total_cmp);
    let median = sorted[sorted.len() / 2];
    let mut out = vec![0.0f64; rest.len()];
    for (e, r) in edges.iter().zip(&ratios) {
        let d = (r / median - 1.0).abs();
        for &v in e {
            out[v as usize] = out[v as usize].max(d);
        }
    }
    out
}

fn mean_over(values: &[f64], pick: impl Fn(usize) -> bool) -> f64 {
    let chosen: Vec<f64> = (0..values.len())
        .filter(|&v| pick(v))
        .map(|v| values[v])
        .collect();
    chosen.iter().sum::<f64>() / chosen.len().max(1) as f64
}

#[test]
fn cube_style_on_half_the_bunny_leaves_the_other_half_rigid() {
    let tmp = ok(tempfile::tempdir());
    let out = tmp.path().join("run");
    let cfg = config(60, &[LEFT_HALF], 0);
    let outcome = ok(run(&out, cfg.clone(), false, None));
    assert!(outcome.complete);

    // The region as the run resolved it, independently: prepared mesh + selection.
    let (mesh, _, region) = ok(prepare_mesh_with_region(&bunny(), &cfg.region));
    let region = region.expect("a region");
    let n = mesh.positions.len();
    let inside = region.free.iter().filter(|&&f| f).count();
    assert!(inside > n / 5 && inside < 4 * n / 5, "{inside} of {n}");
    for (v, p) in mesh.positions.iter().enumerate() {
        assert_eq!(region.free[v], p[0] <= 0.0, "vertex {v} at {p:?}");
    }

    // deformation.npz records the region; the targets outside it never moved (zero gradient, so
    // Adam's moments stay zero and its step is exactly zero).
    let saved = ok(SavedDeformation::read(out.join("deformation.npz")));
    let Some(NpyData::F64(w)) = saved.extra("region_weights").map(|a| a.data.clone()) else {
        panic!("region_weights missing")
    };
    assert_eq!(w, region.weights);
    let mut layer = ok(Darap::new(
        &mesh.positions,
        &mesh.faces,
        darap_options(&cfg),
    ));
    let rest_normals = layer.rest_normals().to_vec();
    let x = saved.verts_normals_f64();
    let mut moved_inside = 0;
    for v in 0..n {
        let rest_f32 = rest_normals[v].map(|c| f64::from(c as f32));
        if region.free[v] {
            moved_inside += usize::from(x[v] != rest_f32);
        } else {
            assert_eq!(x[v], rest_f32, "target {v} outside the region moved");
        }
    }
    assert!(
        moved_inside > inside / 2,
        "{moved_inside} of {inside} targets moved"
    );

    // Outside the region every rotation is exactly the identity.
    ok(layer.set_region_weights(Some(region.weights.clone())));
    let state = ok(layer.forward(&x));
    for v in (0..n).filter(|&v| !region.free[v]) {
        assert_eq!(state.rotations[v], IDENTITY, "vertex {v}");
    }
    // mesh.obj is in the input's frame (the default): the result placed by the recorded map.
    let written = ok(mesh_core::io::read_mesh(out.join("mesh.obj")));
    let saved = ok(SavedDeformation::read(out.join("deformation.npz")));
    let frame = ok(saved.input_frame()).unwrap_or_else(|| panic!("no to_input_frame"));
    assert_eq!(
        written.positions,
        frame.place_result(&state.positions, &mesh.positions, true)
    );

    // Far from the region (≥ 6 rings away) the surface moves only through the global solve: its
    // edge lengths keep their proportions, while the region's change several times more.
    let outside: Vec<bool> = region.free.iter().map(|f| !f).collect();
    let depth = mesh_core::region::feather_weights(&outside, &mesh.faces, 5);
    let far = |v: usize| depth[v] == 1.0;
    assert!((0..n).filter(|&v| far(v)).count() > n / 10);
    let distortion = edge_distortion(&mesh.positions, &state.positions, &mesh.faces);
    let d_far = mean_over(&distortion, far);
    let d_region = mean_over(&distortion, |v| region.free[v]);
    assert!(d_region > 4.0 * d_far, "region {d_region} vs far {d_far}");
    // The region moved toward the style.
    let region_faces: Vec<[u32; 3]> = mesh
        .faces
        .iter()
        .copied()
        .filter(|f| f.iter().all(|&v| region.free[v as usize]))
        .collect();
    let region_targets = Style::Cube.face_targets(&mesh.positions, &region_faces);
    let align = |p: &[[f64; 3]]| {
        stylize::style::alignment::mean_alignment(p, &region_faces, &region_targets)
    };
    assert!(
        align(&state.positions) > align(&mesh.positions) + 0.02,
        "region alignment {} → {}",
        align(&mesh.positions),
        align(&state.positions)
    );

    // The run directory records the region.
    let summary: serde_json::Value = ok(serde_json::from_str(&ok(std::fs::read_to_string(
        out.join("run.json"),
    ))));
    assert_eq!(summary["region"]["specs"][0], LEFT_HALF);
    assert_eq!(summary["region"]["vertices"], inside);
    assert_eq!(
        ok(stylize_cli::config::load(&out.join("config.toml"))).region,
        cfg.region
    );

    // `stylize apply` re-applies with the saved region by default; --no-region does not.
    let apply = |extra: &[&str], name: &str| -> Vec<[f64; 3]> {
        let target = tmp.path().join(name);
        let status = ok(Command::new(env!("CARGO_BIN_EXE_stylize"))
            .arg("apply")
            .arg(out.join("deformation.npz"))
            .arg("-o")
            .arg(&target)
            .args(extra)
            .status());
        assert!(status.success(), "apply {extra:?}");
        ok(mesh_core::io::read_mesh(&target)).positions
    };
    assert_eq!(apply(&[], "default.obj"), written.positions);
    assert_ne!(apply(&["--no-region"], "whole.obj"), written.positions);
    assert_eq!(
        apply(&["--region", LEFT_HALF], "again.obj"),
        written.positions
    );
}

#[test]
fn resume_with_another_region_is_refused_and_an_empty_region_is_an_error() {
    let tmp = ok(tempfile::tempdir());
    let out = tmp.path().join("run");
    let with_checkpoints = |specs: &[&str], feather| {
        let mut c = config(6, specs, feather);
        c.run.checkpoint_every = 1;
        c
    };
    let halted = ok(run(&out, with_checkpoints(&[LEFT_HALF], 0), false, Some(3)));
    assert!(!halted.complete);
    let e = run(&out, with_checkpoints(&[LEFT_HALF], 2), true, None).expect_err("an error");
    let msg = format!("{e:#}");
    assert!(
        msg.contains("region.feather") && msg.contains("region.weights_sha256"),
        "{msg}"
    );
    let e = run(
        &out,
        with_checkpoints(&["not:box:-1,-1,-1,0,1,1"], 0),
        true,
        None,
    )
    .expect_err("an error");
    assert!(format!("{e:#}").contains("region.specs"), "{e:#}");
    // The same region resumes.
    assert!(ok(run(&out, with_checkpoints(&[LEFT_HALF], 0), true, None)).complete);

    let empty = tmp.path().join("empty");
    let e = run(&empty, config(6, &["sphere:5,5,5,0.5"], 0), false, None).expect_err("an error");
    let msg = format!("{e:#}");
    assert!(
        msg.contains("selects no vertex") && msg.contains("sphere:5,5,5,0.5"),
        "{msg}"
    );
    assert!(!empty.exists(), "nothing is written for a refused region");
    let e = run(&empty, config(6, &["part:head"], 0), false, None).expect_err("an error");
    assert!(format!("{e:#}").contains("no part named `head`"), "{e:#}");
}

/// An icosphere OBJ with groups `top` (faces whose centroid has z > 0) and `bottom`.
fn grouped_sphere(dir: &Path) -> PathBuf {
    let (p, f) = mesh_core::shapes::icosphere(2).into_parts();
    let mut text = String::new();
    for q in &p {
        text.push_str(&format!("v {} {} {}\n", q[0], 1.2 * q[1], q[2]));
    }
    for (name, top) in [("top", true), ("bottom", false)] {
        text.push_str(&format!("g {name}\n"));
        for t in &f {
            let z: f64 = t.iter().map(|&v| p[v as usize][2]).sum();
            if (z > 0.0) == top {
                text.push_str(&format!("f {} {} {}\n", t[0] + 1, t[1] + 1, t[2] + 1));
            }
        }
    }
    let path = dir.join("grouped.obj");
    ok(std::fs::write(&path, text));
    path
}

#[test]
fn the_binary_lists_parts_and_stylizes_a_named_part() {
    let tmp = ok(tempfile::tempdir());
    let mesh = grouped_sphere(tmp.path());
    let stylize = |args: &[&str]| {
        ok(Command::new(env!("CARGO_BIN_EXE_stylize"))
            .args(args)
            .output())
    };
    let m = mesh.to_str().unwrap_or_default();
    let listed = stylize(&["mesh", "check", m, "--regions"]);
    assert!(listed.status.success());
    let text = String::from_utf8_lossy(&listed.stdout);
    assert!(
        text.contains("part:top") && text.contains("part:bottom"),
        "{text}"
    );
    let out = tmp.path().join("run");
    let o = out.to_str().unwrap_or_default();
    let ran = stylize(&[
        "run",
        m,
        "--style",
        "cube",
        "-o",
        o,
        "--region",
        "part:top",
        "--region-feather",
        "1",
        "--tint-region",
        "--set",
        "style.iterations=5",
        "--set",
        "run.turntable_size=32",
        "--set",
        "run.turntable_views=2",
        "-q",
    ]);
    assert!(
        ran.status.success(),
        "{}",
        String::from_utf8_lossy(&ran.stderr)
    );
    let summary: serde_json::Value = ok(serde_json::from_str(&ok(std::fs::read_to_string(
        out.join("run.json"),
    ))));
    assert_eq!(summary["region"]["specs"][0], "part:top");
    assert_eq!(summary["region"]["feather"], 1);
    let n = summary["vertices"].as_u64().unwrap_or(0);
    let selected = summary["region"]["vertices"].as_u64().unwrap_or(0);
    assert!(
        selected > n / 3 && selected < 2 * n / 3,
        "{selected} of {n}"
    );
    let missing = stylize(&[
        "run",
        m,
        "--style",
        "cube",
        "-o",
        o,
        "--force",
        "--region",
        "part:seat",
    ]);
    assert!(!missing.status.success());
    let err = String::from_utf8_lossy(&missing.stderr);
    assert!(
        err.contains("no part named `seat`") && err.contains("group `top`"),
        "{err}"
    );
}

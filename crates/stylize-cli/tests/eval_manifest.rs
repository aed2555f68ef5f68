//! `stylize eval --manifest`: every finished row of a batch manifest, the same report as naming
//! the run directories, written as JSON and CSV; the needle-face warning fires on the
//! triceratops (two needle faces, kept by repair) and not on the same shape remeshed.
//!
//! Cost: two model-free runs of 40 iterations on ~2,800-vertex meshes and one remesh.

use std::path::Path;

use mesh_core::TriMesh;

mod common;
use common::{ok, s, stderr, stylize};

fn fixture(name: &str) -> std::path::PathBuf {
    std::path::PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../../fixtures/meshes")
        .join(name)
}

/// The triceratops remeshed isotropically at its mean edge length: no needles left.
fn remeshed_triceratops(path: &Path) {
    let tri = ok(mesh_core::io::read_mesh(fixture("triceratops.off")));
    let repaired = ok(mesh_core::validate::repair(
        &tri,
        &mesh_core::validate::RepairOptions::default(),
    ));
    let m = repaired.mesh;
    let (mut sum, mut n) = (0.0, 0.0);
    for f in &m.faces {
        for k in 0..3 {
            let (a, b) = (
                m.positions[f[k] as usize],
                m.positions[f[(k + 1) % 3] as usize],
            );
            sum += ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)).sqrt();
            n += 1.0;
        }
    }
    let mut options = mesh_core::remesh::RemeshOptions::new(sum / n);
    options.iterations = 5;
    let r = ok(mesh_core::remesh::remesh(&m.positions, &m.faces, &options));
    ok(mesh_core::io::write_mesh(
        path,
        &TriMesh::new(r.positions, r.faces),
        None,
    ));
}

fn run(mesh: &Path, out: &Path) {
    let o = stylize(&[
        "run",
        s(mesh),
        "--style",
        "cube",
        "--out",
        s(out),
        "--quiet",
        // The triceratops as it is, needles included: `--remesh auto` would remesh it.
        "--remesh",
        "off",
        "--set",
        "style.iterations=40",
        "--set",
        "run.turntable_size=24",
        "--set",
        "run.turntable_views=1",
        "--set",
        "run.turntable_gif_frames=0",
        "--set",
        "run.preview_every=0",
        "--set",
        "run.snapshot_every=0",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
}

#[test]
fn eval_of_a_manifest_equals_eval_of_its_run_directories_and_flags_needles() {
    let tmp = ok(tempfile::tempdir());
    let root = tmp.path();
    let remeshed = root.join("triceratops_remeshed.obj");
    remeshed_triceratops(&remeshed);
    let manifest = root.join("paper.toml");
    ok(std::fs::write(
        &manifest,
        format!(
            "[[run]]\nmesh = {:?}\nstyle = \"cube\"\nout = \"runs/tri\"\n\n\
             [[run]]\nmesh = \"triceratops_remeshed.obj\"\nstyle = \"cube\"\nout = \"runs/remeshed\"\n\n\
             [[run]]\nmesh = \"triceratops_remeshed.obj\"\nstyle = \"octahedron\"\nout = \"runs/not_yet\"\n",
            s(&fixture("triceratops.off"))
        ),
    ));
    let (tri, rem) = (root.join("runs/tri"), root.join("runs/remeshed"));
    run(&fixture("triceratops.off"), &tri);
    run(&remeshed, &rem);

    let (json_file, csv_file) = (root.join("eval.json"), root.join("eval.csv"));
    let by_manifest = stylize(&[
        "eval",
        "--manifest",
        s(&manifest),
        "--json",
        "--json-out",
        s(&json_file),
        "--csv",
        s(&csv_file),
    ]);
    assert!(by_manifest.status.success(), "{}", stderr(&by_manifest));
    let err = stderr(&by_manifest);
    assert!(
        err.contains("1 row not finished") && err.contains("not_yet"),
        "{err}"
    );
    let by_dirs = stylize(&["eval", s(&tri), s(&rem), "--json"]);
    assert!(by_dirs.status.success(), "{}", stderr(&by_dirs));
    let a: serde_json::Value = ok(serde_json::from_slice(&by_manifest.stdout));
    let b: serde_json::Value = ok(serde_json::from_slice(&by_dirs.stdout));
    assert_eq!(a, b);
    let written: serde_json::Value = ok(serde_json::from_slice(&ok(std::fs::read(&json_file))));
    assert_eq!(written, a);

    // The warning names the triceratops, whose two needles dominate the spread, and not the
    // remeshed one.
    let pairs = a["pairs"].as_array().cloned().unwrap_or_default();
    assert_eq!(pairs.len(), 2);
    let share = |i: usize| {
        pairs[i]["needle_variance_share"]
            .as_f64()
            .unwrap_or(f64::NAN)
    };
    assert!(pairs[0]["needle_faces"].as_u64() >= Some(2), "{}", pairs[0]);
    assert!(share(0) >= 0.5, "triceratops share {}", share(0));
    assert!(share(1) < 0.5, "remeshed share {}", share(1));
    let warnings: Vec<String> = a["warnings"]
        .as_array()
        .cloned()
        .unwrap_or_default()
        .iter()
        .map(|w| w.as_str().unwrap_or_default().to_string())
        .collect();
    assert_eq!(warnings.len(), 1, "{warnings:?}");
    assert!(warnings[0].starts_with(s(&tri)), "{warnings:?}");
    // Without the needles the spread is the stylization's: far below the pooled one.
    let (std_all, std_without) = (
        a["area_ratio_std"].as_f64().unwrap_or(f64::NAN),
        a["area_ratio_std_without_needles"]
            .as_f64()
            .unwrap_or(f64::NAN),
    );
    assert!(std_without < std_all / 4.0, "{std_without} vs {std_all}");
    // The table says it too.
    let table = stylize(&["eval", s(&tri), s(&rem)]);
    let out = String::from_utf8_lossy(&table.stdout).into_owned();
    assert!(
        out.contains("warning:") && out.contains("pooled without needle faces"),
        "{out}"
    );

    // CSV: a header, one line per pair, the pooled line.
    let csv = ok(std::fs::read_to_string(&csv_file));
    let lines: Vec<&str> = csv.lines().collect();
    assert_eq!(lines.len(), 4, "{csv}");
    assert!(lines[0].starts_with("name,faces,skipped_faces,area_ratio_mean,area_ratio_std,"));
    assert!(lines[1].starts_with(&format!("{},{},", s(&tri), pairs[0]["faces"])));
    assert!(lines[3].starts_with("pooled,"));
    let mean: f64 = ok(lines[3].split(',').nth(3).unwrap_or("").parse());
    assert_eq!(Some(mean), a["area_ratio_mean"].as_f64());
}

#[test]
fn the_paper_manifests_parse_and_the_smoke_twin_needs_only_committed_meshes() {
    let dir = std::path::PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../fixtures/manifests");
    let paper = ok(stylize_cli::batch::read_manifest(
        &dir.join("paper_figures.toml"),
    ));
    let smoke = ok(stylize_cli::batch::read_manifest(
        &dir.join("paper_figures_smoke.toml"),
    ));
    assert!(paper.len() >= 5, "{} rows", paper.len());
    assert!(paper.iter().all(|r| r.prompt.is_some()));
    let name = |p: &Path| p.file_name().map(|n| n.to_os_string());
    for row in &smoke {
        assert!(
            row.style.is_some() && row.mesh.is_file(),
            "{}",
            row.mesh.display()
        );
        // The same mesh and run name as a row of the paper manifest.
        assert!(
            paper
                .iter()
                .any(|p| p.mesh == row.mesh && name(&p.out) == name(&row.out)),
            "{}",
            row.out.display()
        );
    }
}

//! Batch manifests end to end (model-free rows): failing rows do not stop the batch, complete rows
//! are skipped, partial rows are resumed, shards split the rows.

use std::path::Path;

use mesh_core::TriMesh;
use stylize::runner::RunRequest;
use stylize::style::Style;
use stylize_cli::batch::{BatchOptions, RowStatus, Shard, read_manifest, run_batch};
use stylize_cli::config::Config;
use stylize_cli::runner::{LogMode, execute};

mod common;
use common::ok;

fn setup(dir: &Path) -> Config {
    let (p, f) = mesh_core::shapes::icosphere(1).into_parts();
    let p: Vec<[f64; 3]> = p.iter().map(|v| [1.3 * v[0], v[1], v[2]]).collect();
    ok(mesh_core::io::write_mesh(
        dir.join("m.obj"),
        &TriMesh::new(p, f),
        None,
    ));
    let manifest = "[[run]]\nmesh = \"m.obj\"\nstyle = \"cube\"\nout = \"runs/cube\"\n\n\
                    [[run]]\nmesh = \"missing.obj\"\nstyle = \"cube\"\nout = \"runs/missing\"\n\n\
                    [[run]]\nmesh = \"m.obj\"\nstyle = \"octahedron\"\nout = \"runs/octa\"\nseed = 4\noverrides = [\"darap.lambda=5\"]\n";
    ok(std::fs::write(dir.join("batch.toml"), manifest));
    let mut c = Config::default();
    c.style.iterations = 6;
    c.run.checkpoint_every = 2;
    c.run.preview_every = 0;
    c.run.turntable_views = 1;
    c.run.turntable_size = 16;
    c
}

fn options(config: &Config, shard: Shard) -> BatchOptions {
    BatchOptions {
        config: config.clone(),
        shard,
        model: None,
        log: LogMode::Quiet,
        force: false,
        inputs: Vec::new(),
    }
}

#[test]
fn failing_row_is_reported_others_complete_then_skip() {
    let tmp = ok(tempfile::tempdir());
    let config = setup(tmp.path());
    let rows = ok(read_manifest(&tmp.path().join("batch.toml")));
    let results = run_batch(&rows, &options(&config, Shard::ALL));
    let statuses: Vec<&RowStatus> = results.iter().map(|r| &r.2).collect();
    assert_eq!(statuses[0], &RowStatus::Done { resumed: false });
    assert!(
        matches!(statuses[1], RowStatus::Failed(m) if m.contains("missing.obj")),
        "{:?}",
        statuses[1]
    );
    assert_eq!(statuses[2], &RowStatus::Done { resumed: false });
    let octa = ok(stylize_cli::config::load(
        &tmp.path().join("runs/octa/config.toml"),
    ));
    assert_eq!(
        (octa.run.seed, octa.darap.lambda),
        (4, 5.0),
        "row seed and overrides are applied"
    );
    let again = run_batch(&rows, &options(&config, Shard::ALL));
    assert_eq!(again[0].2, RowStatus::Skipped);
    assert!(matches!(again[1].2, RowStatus::Failed(_)));
    assert_eq!(again[2].2, RowStatus::Skipped);
}

#[test]
fn partial_row_is_resumed() {
    let tmp = ok(tempfile::tempdir());
    let config = setup(tmp.path());
    let rows = ok(read_manifest(&tmp.path().join("batch.toml")));
    // Interrupt row 0 after iteration 3 (checkpoint at 2).
    let request = RunRequest {
        mesh: rows[0].mesh.clone(),
        out: rows[0].out.clone(),
        config: config.clone(),
        force: false,
        resume: false,
        halt_after: Some(3),
    };
    ok(execute(&request, LogMode::Quiet, Style::Cube));
    let results = run_batch(&rows[..1], &options(&config, Shard::ALL));
    assert_eq!(results[0].2, RowStatus::Done { resumed: true });
    assert!(tmp.path().join("runs/cube/run.json").is_file());
}

#[test]
fn shards_split_rows_without_overlap() {
    let tmp = ok(tempfile::tempdir());
    let config = setup(tmp.path());
    let rows = ok(read_manifest(&tmp.path().join("batch.toml")));
    let a: Vec<usize> = run_batch(&rows, &options(&config, Shard { index: 0, count: 2 }))
        .iter()
        .map(|r| r.0)
        .collect();
    let b: Vec<usize> = run_batch(&rows, &options(&config, Shard { index: 1, count: 2 }))
        .iter()
        .map(|r| r.0)
        .collect();
    assert_eq!(a, vec![0, 2]);
    assert_eq!(b, vec![1]);
}

#[test]
fn process_wide_session_setting_cannot_be_overridden_per_row() {
    let tmp = ok(tempfile::tempdir());
    let config = setup(tmp.path());
    let manifest = "[[run]]\nmesh = \"m.obj\"\nprompt = \"a cube\"\nout = \"runs/text\"\n\
                    overrides = [\"guidance.onnx_memory_arena=false\"]\n";
    ok(std::fs::write(tmp.path().join("arena.toml"), manifest));
    let rows = ok(read_manifest(&tmp.path().join("arena.toml")));
    let mut opts = options(&config, Shard::ALL);
    opts.model = Some(tmp.path().join("no-model-needed-before-the-check"));
    let results = run_batch(&rows, &opts);
    assert!(
        matches!(&results[0].2, RowStatus::Failed(m) if m.contains("onnx_memory_arena")),
        "{:?}",
        results[0].2
    );
}

#[test]
fn duplicate_or_empty_outputs_are_manifest_errors_naming_the_rows() {
    let tmp = ok(tempfile::tempdir());
    setup(tmp.path());
    let path = tmp.path().join("dup.jsonl");
    let row =
        |out: &str| format!("{{\"mesh\": \"m.obj\", \"style\": \"cube\", \"out\": \"{out}\"}}\n");
    let err = |text: String| {
        ok(std::fs::write(&path, text));
        read_manifest(&path)
            .err()
            .map(|e| format!("{e:#}"))
            .unwrap_or_default()
    };
    let e = err(row("runs/a") + &row("runs/b") + &row("./runs/x/../a/"));
    assert!(e.contains("rows 0 and 2") && e.contains("runs/a"), "{e}");
    let abs = tmp.path().join("runs/b");
    let e = err(row("runs/b") + &row(abs.to_str().unwrap_or_default()));
    assert!(e.contains("rows 0 and 1"), "{e}");
    let e = err(row("runs/a") + &row(""));
    assert!(e.contains("row 1") && e.contains("empty"), "{e}");
    let e = err(row("runs/a") + &row("  "));
    assert!(e.contains("row 1") && e.contains("empty"), "{e}");
    // One run directory inside another's, in either row order and at any depth.
    let e = err(row("runs/a") + &row("runs/b") + &row("runs/a/previews"));
    assert!(
        e.contains("row 2's run directory") && e.contains("row 0's") && e.contains("nest"),
        "{e}"
    );
    let e = err(row("runs/n/x/y") + &row("./runs/n/"));
    assert!(
        e.contains("row 0's run directory") && e.contains("row 1's"),
        "{e}"
    );
    assert!(
        err(row("runs/ab") + &row("runs/a")).is_empty(),
        "a sibling with a common prefix"
    );
    // One row's input is another row's output.
    let e = err(row("runs/a")
        + "{\"mesh\": \"runs/a/mesh.obj\", \"style\": \"cube\", \"out\": \"runs/b\"}\n");
    assert!(e.contains("row 1's mesh") && e.contains("row 0"), "{e}");
}

#[test]
fn an_edited_row_is_never_skipped_or_mixed() {
    let tmp = ok(tempfile::tempdir());
    let config = setup(tmp.path());
    let rows = ok(read_manifest(&tmp.path().join("batch.toml")));
    let first = run_batch(&rows[..1], &options(&config, Shard::ALL));
    assert_eq!(first[0].2, RowStatus::Done { resumed: false });
    // The same row with another style: the complete run is of a different task.
    let mut edited = rows[0].clone();
    edited.style = Some("octahedron".into());
    let again = run_batch(std::slice::from_ref(&edited), &options(&config, Shard::ALL));
    assert!(
        matches!(&again[0].2, RowStatus::Failed(m) if m.contains("different task") && m.contains("octahedron")),
        "{:?}",
        again[0].2
    );
    // Another seed for the same row: also a different task.
    let mut seeded = rows[0].clone();
    seeded.seed = Some(11);
    let again = run_batch(std::slice::from_ref(&seeded), &options(&config, Shard::ALL));
    assert!(
        matches!(&again[0].2, RowStatus::Failed(m) if m.contains("config.run.seed")),
        "{:?}",
        again[0].2
    );
    // The unchanged row is skipped; --force redoes the edited one.
    let same = run_batch(&rows[..1], &options(&config, Shard::ALL));
    assert_eq!(same[0].2, RowStatus::Skipped);
    let mut forced = options(&config, Shard::ALL);
    forced.force = true;
    let redo = run_batch(std::slice::from_ref(&edited), &forced);
    assert_eq!(redo[0].2, RowStatus::Done { resumed: false });
    // A partial run of a different task is not resumed into this row.
    let request = RunRequest {
        mesh: rows[2].mesh.clone(),
        out: rows[2].out.clone(),
        config: config.clone(),
        force: false,
        resume: false,
        halt_after: Some(3),
    };
    ok(execute(&request, LogMode::Quiet, Style::Cube));
    let r = run_batch(&rows[2..], &options(&config, Shard::ALL));
    assert!(
        matches!(&r[0].2, RowStatus::Failed(m) if m.contains("refusing to resume")),
        "{:?}",
        r[0].2
    );
}

//! `snapshots.npz` of model-free runs through the library entry points: the entries (iteration 0,
//! every `run.snapshot_every`, the last), their frame (the last one is `mesh.obj`), and a run
//! killed or stopped and resumed (no duplicate or future entries; the same file as an uninterrupted
//! run, also when `snapshot_every` changes on resume).

use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};

use mesh_core::TriMesh;
use stylize::config::Config;
use stylize::runner::{
    Progress, RunHooks, RunOptions, RunOutcome, RunRequest, execute, execute_with,
};
use stylize::snapshots::{FILE_NAME, Snapshots};
use stylize::style::Style;

fn ok<T, E: std::fmt::Debug>(r: Result<T, E>) -> T {
    r.unwrap_or_else(|e| panic!("{e:?}"))
}

/// An icosphere (2 subdivisions, 162 vertices) stretched into an ellipsoid, as an OBJ file.
fn small_mesh(dir: &Path) -> PathBuf {
    let (p, f) = mesh_core::shapes::icosphere(2).into_parts();
    let p: Vec<[f64; 3]> = p.iter().map(|v| [1.5 * v[0], v[1], 0.8 * v[2]]).collect();
    let path = dir.join("ellipsoid.obj");
    ok(mesh_core::io::write_mesh(&path, &TriMesh::new(p, f), None));
    path
}

fn config(iterations: u64, snapshot_every: u64) -> Config {
    let mut c = Config::default();
    c.style.iterations = iterations;
    c.run.checkpoint_every = 2;
    c.run.preview_every = 0;
    c.run.turntable_views = 1;
    c.run.turntable_size = 16;
    c.run.turntable_gif_frames = 2;
    c.run.snapshot_every = snapshot_every;
    c
}

fn request(mesh: &Path, out: &Path, config: Config, resume: bool, halt: Option<u64>) -> RunRequest {
    RunRequest {
        mesh: mesh.to_path_buf(),
        out: out.to_path_buf(),
        config,
        force: false,
        resume,
        halt_after: halt,
    }
}

fn run(r: &RunRequest) -> stylize::Result<RunOutcome> {
    execute(r, Style::Cube)
}

/// Sets the cancel flag once iteration `at` is reported (as a signal handler would).
struct CancelAt<'a> {
    at: u64,
    flag: &'a AtomicBool,
}

impl Progress for CancelAt<'_> {
    fn iteration(&mut self, record: &stylize::pipeline::IterationRecord, _json: &str) {
        if record.iteration == self.at {
            self.flag.store(true, Ordering::SeqCst);
        }
    }
}

fn run_cancelled_at(r: &RunRequest, at: u64) -> stylize::Result<RunOutcome> {
    let flag = AtomicBool::new(false);
    let mut progress = CancelAt { at, flag: &flag };
    let hooks = RunHooks {
        progress: &mut progress,
        cancel: &flag,
    };
    execute_with(
        r,
        &Style::Cube,
        || Ok(Style::Cube),
        &RunOptions::default(),
        hooks,
    )
}

fn snapshots(dir: &Path) -> Snapshots {
    ok(Snapshots::read(&dir.join(FILE_NAME)))
}

fn max_abs_diff(a: &[[f32; 3]], b: &[[f64; 3]]) -> f64 {
    a.iter()
        .zip(b)
        .flat_map(|(p, q)| (0..3).map(move |c| (f64::from(p[c]) - q[c]).abs()))
        .fold(0.0, f64::max)
}

#[test]
fn entries_are_iteration_zero_every_n_and_the_last_in_the_normalized_frame_of_mesh_obj() {
    let tmp = ok(tempfile::tempdir());
    let mesh = small_mesh(tmp.path());
    let out = tmp.path().join("run");
    let outcome = ok(run(&request(&mesh, &out, config(7, 3), false, None)));
    assert!(outcome.complete);
    let s = snapshots(&out);
    assert_eq!(s.iterations, vec![0, 3, 6, 7]);
    let mut result = ok(mesh_core::io::read_mesh(out.join("mesh.obj")));
    // mesh.obj is written in the input's frame (run.output_frame = input, the default); the
    // snapshots are in the normalized frame: map it back by the recorded transform.
    let saved = ok(stylize::saved::SavedDeformation::read(
        out.join("deformation.npz"),
    ));
    let frame = ok(saved.input_frame()).unwrap_or_else(|| panic!("no to_input_frame"));
    result.positions = ok(frame.unplace_result(&result.positions, &saved.rest_positions(), true));
    assert_eq!(s.vertices, result.positions.len());
    assert_eq!(s.x.len(), 4 * s.vertices * 3);
    // The faces ride along (a viewer draws a running run with them): those of mesh.obj.
    let npz = ok(npy::npz::NpzReader::open(out.join(FILE_NAME)));
    assert_eq!(ok(npz.rows3_u32("faces")), result.faces);
    let last = s.positions(3).unwrap_or_default();
    let d = max_abs_diff(&last, &result.positions);
    assert!(d < 1e-5, "last snapshot vs mesh.obj: {d}");
    // Entry 0 is the undeformed mesh in the normalized frame: the prepared mesh recentred at its
    // vertex centroid (dARAP's post-process), not moved otherwise.
    let (rest, _) = ok(stylize::runner::prepare_mesh(&mesh));
    let n = rest.positions.len() as f64;
    let c = (0..3).map(|k| rest.positions.iter().map(|p| p[k]).sum::<f64>() / n);
    let c: Vec<f64> = c.collect();
    let centred: Vec<[f64; 3]> = rest
        .positions
        .iter()
        .map(|p| [p[0] - c[0], p[1] - c[1], p[2] - c[2]])
        .collect();
    let first = s.positions(0).unwrap_or_default();
    let d0 = max_abs_diff(&first, &centred);
    assert!(d0 < 1e-4, "snapshot 0 vs the rest mesh: {d0}");
    // The mesh moved between the first and the last entry.
    assert!(max_abs_diff(&first, &result.positions) > 1e-2);
    let summary: serde_json::Value = ok(serde_json::from_slice(&ok(std::fs::read(
        out.join("run.json"),
    ))));
    assert_eq!(summary["snapshot_every"], 3);
}

#[test]
fn snapshot_every_zero_writes_no_file() {
    let tmp = ok(tempfile::tempdir());
    let mesh = small_mesh(tmp.path());
    let out = tmp.path().join("run");
    ok(run(&request(&mesh, &out, config(3, 0), false, None)));
    assert!(out.join("run.json").is_file());
    assert!(!out.join(FILE_NAME).exists());
}

#[test]
fn killed_or_stopped_runs_resume_without_duplicate_or_future_entries() {
    let tmp = ok(tempfile::tempdir());
    let mesh = small_mesh(tmp.path());

    let reference = tmp.path().join("reference");
    ok(run(&request(&mesh, &reference, config(7, 1), false, None)));
    let expected = snapshots(&reference);
    assert_eq!(expected.iterations, (0..=7).collect::<Vec<i64>>());

    // Killed after iteration 5 (no checkpoint since iteration 4): entry 5 is in the file.
    let killed = tmp.path().join("killed");
    let halted = ok(run(&request(&mesh, &killed, config(7, 1), false, Some(5))));
    assert!(!halted.complete);
    assert_eq!(snapshots(&killed).iterations, (0..=5).collect::<Vec<i64>>());
    ok(run(&request(&mesh, &killed, config(7, 1), true, None)));
    assert_eq!(snapshots(&killed), expected, "killed at 5, resumed from 4");

    // Stopped through the cancel hook after iteration 3 (checkpoint at 3), resumed.
    let stopped = tmp.path().join("stopped");
    let e = run_cancelled_at(&request(&mesh, &stopped, config(7, 1), false, None), 3)
        .err()
        .unwrap_or_else(|| panic!("the run was not stopped"));
    let stylize::Error::Stopped(s) = e.kind() else {
        panic!("{}", e.full_message())
    };
    assert_eq!(s.checkpoint_iteration, Some(3));
    assert_eq!(snapshots(&stopped).iterations, vec![0, 1, 2, 3]);
    ok(run(&request(&mesh, &stopped, config(7, 1), true, None)));
    assert_eq!(snapshots(&stopped), expected, "stopped at 3, resumed");

    // snapshot_every is not part of the task: a resume may change it.
    let changed = tmp.path().join("changed");
    ok(run(&request(&mesh, &changed, config(7, 1), false, Some(5))));
    ok(run(&request(&mesh, &changed, config(7, 3), true, None)));
    let s = snapshots(&changed);
    assert_eq!(s.iterations, vec![0, 1, 2, 3, 4, 6, 7]);
    for (k, &i) in s.iterations.iter().enumerate() {
        let j = expected
            .iterations
            .iter()
            .position(|&e| e == i)
            .unwrap_or_else(|| panic!("iteration {i}"));
        assert_eq!(s.positions(k), expected.positions(j), "iteration {i}");
    }
}

#[test]
fn a_lost_snapshot_file_restarts_the_replay_with_a_warning() {
    let tmp = ok(tempfile::tempdir());
    let mesh = small_mesh(tmp.path());
    let out = tmp.path().join("run");
    ok(run(&request(&mesh, &out, config(7, 2), false, Some(5))));
    ok(std::fs::write(out.join(FILE_NAME), b"not a zip"));
    let outcome = ok(run(&request(&mesh, &out, config(7, 2), true, None)));
    assert!(
        outcome.warnings.iter().any(|w| w.contains(FILE_NAME)),
        "{:?}",
        outcome.warnings
    );
    // Restarted from entry 0 and the checkpoint (iteration 4), then every 2 and the last.
    assert_eq!(snapshots(&out).iterations, vec![0, 4, 6, 7]);
}

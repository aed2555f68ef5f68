//! Run directories with the real binary: two processes on one directory, stale locks, signals,
//! resume identity, and the user's files (inputs, foreign folders) left alone.

use std::path::{Path, PathBuf};
use std::process::{Child, Command, Output, Stdio};
use std::time::{Duration, Instant};

use mesh_core::TriMesh;
use stylize::checkpoint::Checkpoint;
use stylize::saved::SavedDeformation;

mod common;
use common::{ok, s, stderr};

fn command(args: &[&str], env: &[(&str, &str)]) -> Command {
    let mut c = Command::new(env!("CARGO_BIN_EXE_stylize"));
    c.args(args);
    for (k, v) in env {
        c.env(k, v);
    }
    c
}

fn stylize(args: &[&str]) -> Output {
    ok(command(args, &[]).output())
}

fn stylize_env(args: &[&str], env: &[(&str, &str)]) -> Output {
    ok(command(args, env).output())
}

fn must(o: &Output) {
    assert!(o.status.success(), "stylize failed:\n{}", stderr(o));
}

fn mesh(dir: &Path, name: &str, subdivisions: u32, squash: f64) -> PathBuf {
    let (p, f) = mesh_core::shapes::icosphere(subdivisions).into_parts();
    let p: Vec<[f64; 3]> = p
        .iter()
        .map(|v| [1.4 * v[0], v[1], squash * v[2]])
        .collect();
    let path = dir.join(name);
    ok(mesh_core::io::write_mesh(&path, &TriMesh::new(p, f), None));
    path
}

/// Arguments of a cube run of `iterations` into `out`.
fn cube_run<'a>(mesh: &'a Path, out: &'a Path, iterations: &'a str) -> Vec<&'a str> {
    vec![
        "run",
        s(mesh),
        "--style",
        "cube",
        "-o",
        s(out),
        "--quiet",
        "--set",
        iterations,
        "--set",
        "run.turntable_size=16",
        "--set",
        "run.turntable_views=1",
        "--set",
        "run.preview_every=0",
    ]
}

fn metrics_iterations(dir: &Path) -> Vec<u64> {
    ok(std::fs::read_to_string(dir.join("metrics.jsonl")))
        .lines()
        .map(|l| {
            ok(serde_json::from_str::<serde_json::Value>(l))["iteration"]
                .as_u64()
                .unwrap_or(0)
        })
        .collect()
}

/// Waits until `dir/metrics.jsonl` has at least `lines` lines (the loop is running).
fn wait_for_iterations(dir: &Path, lines: usize, child: &mut Child) {
    let start = Instant::now();
    loop {
        let n = std::fs::read_to_string(dir.join("metrics.jsonl"))
            .map(|t| t.lines().count())
            .unwrap_or(0);
        if n >= lines {
            return;
        }
        if let Ok(Some(status)) = child.try_wait() {
            panic!("the run ended ({status}) before iteration {lines}");
        }
        assert!(
            start.elapsed() < Duration::from_secs(120),
            "no progress in {}",
            dir.display()
        );
        std::thread::sleep(Duration::from_millis(5));
    }
}

fn signal(child: &Child, name: &str) {
    let status = ok(Command::new("kill")
        .args([format!("-{name}"), child.id().to_string()])
        .status());
    assert!(status.success(), "kill -{name} failed");
}

fn finish(child: Child) -> Output {
    ok(child.wait_with_output())
}

fn spawn(args: &[&str]) -> Child {
    ok(command(args, &[])
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn())
}

/// Two processes on one directory: exactly one proceeds, the other fails fast naming the holder.
/// SIGTERM then SIGINT stop the holder after a whole iteration with a checkpoint (exit 143, 130),
/// and the resumed run equals an uninterrupted one bit for bit.
#[test]
fn one_process_per_directory_and_signals_checkpoint_for_an_exact_resume() {
    let tmp = ok(tempfile::tempdir());
    let mesh = mesh(tmp.path(), "m.obj", 3, 0.8);
    let iterations = "style.iterations=1500";
    let reference = tmp.path().join("reference");
    must(&stylize(&cube_run(&mesh, &reference, iterations)));

    let run = tmp.path().join("run");
    let mut first = spawn(&cube_run(&mesh, &run, iterations));
    wait_for_iterations(&run, 2, &mut first);
    let second = stylize(&cube_run(&mesh, &run, iterations));
    let e = stderr(&second);
    assert_eq!(second.status.code(), Some(75), "{e}");
    assert!(
        e.contains(&format!("pid {}", first.id())) && e.contains("host") && e.contains("since"),
        "the refusal names the holder: {e}"
    );
    signal(&first, "TERM");
    let out = finish(first);
    let e = stderr(&out);
    assert_eq!(out.status.code(), Some(143), "{e}");
    assert!(e.contains("SIGTERM") && e.contains("--resume"), "{e}");
    assert!(!run.join("run.lock").exists(), "the lock is released");
    let c = ok(Checkpoint::load(&run.join("checkpoint.json")));
    assert!(c.iteration >= 2 && c.iteration < 1500, "{}", c.iteration);
    assert_eq!(
        metrics_iterations(&run),
        (1..=c.iteration).collect::<Vec<_>>(),
        "metrics hold each finished iteration once, none from the refused process"
    );
    // The printed command resumes; SIGINT this time.
    let resume_line = e
        .lines()
        .skip_while(|l| !l.starts_with("resume with"))
        .nth(1)
        .unwrap_or_default()
        .trim()
        .to_string();
    assert!(resume_line.ends_with("--resume"), "{resume_line}");
    let mut resumed = spawn(&[
        "run",
        s(&mesh),
        "--style",
        "cube",
        "-o",
        s(&run),
        "--quiet",
        "--resume",
    ]);
    wait_for_iterations(&run, c.iteration as usize + 2, &mut resumed);
    signal(&resumed, "INT");
    let out = finish(resumed);
    assert_eq!(out.status.code(), Some(130), "{}", stderr(&out));
    let c2 = ok(Checkpoint::load(&run.join("checkpoint.json")));
    assert!(
        c2.iteration > c.iteration,
        "{} {}",
        c2.iteration,
        c.iteration
    );
    // The exact printed command (through a shell) finishes the run.
    must(&ok(Command::new("sh").args(["-c", &resume_line]).output()));
    let a = ok(SavedDeformation::read(reference.join("deformation.npz")));
    let b = ok(SavedDeformation::read(run.join("deformation.npz")));
    assert_eq!(a.verts_normals, b.verts_normals, "resumed run differs");
    let (ca, cb) = (
        ok(Checkpoint::load(&reference.join("checkpoint.json"))),
        ok(Checkpoint::load(&run.join("checkpoint.json"))),
    );
    assert!(
        ca.state.x == cb.state.x && ca.state.adam == cb.state.adam,
        "state differs after resume"
    );
    assert_eq!(metrics_iterations(&run), (1..=1500).collect::<Vec<_>>());
}

fn write_lock(dir: &Path, record: serde_json::Value) {
    ok(std::fs::create_dir_all(dir));
    ok(std::fs::write(dir.join("run.lock"), record.to_string()));
}

fn now() -> f64 {
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map(|d| d.as_secs_f64())
        .unwrap_or(0.0)
}

fn lock_record(host: &str, pid: u32, heartbeat_age: f64) -> serde_json::Value {
    let read = |p: &str| {
        std::fs::read_to_string(p)
            .map(|s| s.trim().to_string())
            .unwrap_or_default()
    };
    let pid_ns = std::fs::read_link("/proc/self/ns/pid")
        .map(|p| p.display().to_string())
        .unwrap_or_default();
    serde_json::json!({
        "host": host, "pid": pid, "boot_id": read("/proc/sys/kernel/random/boot_id"),
        "pid_ns": pid_ns, "proc_start": 0, "since": now() - 3600.0,
        "heartbeat": now() - heartbeat_age, "interval": 0.1, "beat": 3,
        "token": "0123abcd", "command": "stylize run elsewhere"
    })
}

#[test]
fn live_locks_are_respected_and_stale_ones_taken_over() {
    let tmp = ok(tempfile::tempdir());
    let mesh = mesh(tmp.path(), "m.obj", 1, 0.8);
    let fast = [
        ("STYLIZE_LOCK_HEARTBEAT_SECS", "0.1"),
        ("STYLIZE_LOCK_STALE_SECS", "0.5"),
    ];
    // A live holder on another node.
    let run = tmp.path().join("live");
    write_lock(&run, lock_record("node-42", 777, 0.0));
    let out = stylize_env(&cube_run(&mesh, &run, "style.iterations=3"), &fast);
    let e = stderr(&out);
    assert_eq!(out.status.code(), Some(75), "{e}");
    assert!(e.contains("node-42") && e.contains("777"), "{e}");
    assert_eq!(
        ok(std::fs::read_dir(&run)).count(),
        1,
        "nothing but the other lock"
    );
    // A silent holder on another node: stale after the limit and a quiet observation.
    let run = tmp.path().join("silent");
    write_lock(&run, lock_record("node-42", 777, 30.0));
    must(&stylize_env(
        &cube_run(&mesh, &run, "style.iterations=3"),
        &fast,
    ));
    assert!(run.join("run.json").is_file() && !run.join("run.lock").exists());
    // A dead process on this host: taken over at once, with the default limits.
    let dead = ok(Command::new("true").spawn());
    let pid = dead.id();
    ok(finish(dead)
        .status
        .success()
        .then_some(())
        .ok_or("true failed"));
    let host = std::fs::read_to_string("/proc/sys/kernel/hostname")
        .map(|h| h.trim().to_string())
        .unwrap_or_default();
    let run = tmp.path().join("dead");
    write_lock(&run, lock_record(&host, pid, 1.0));
    let started = Instant::now();
    must(&stylize(&cube_run(&mesh, &run, "style.iterations=3")));
    assert!(run.join("run.json").is_file());
    assert!(
        started.elapsed() < Duration::from_secs(30),
        "no staleness wait for a dead local holder"
    );
}

#[test]
fn inputs_and_foreign_folders_are_never_overwritten() {
    let tmp = ok(tempfile::tempdir());
    let proj = tmp.path().join("proj");
    ok(std::fs::create_dir_all(&proj));
    let input = mesh(&proj, "mesh.obj", 1, 0.8);
    ok(std::fs::write(
        proj.join("config.toml"),
        "[style]\niterations = 3\n",
    ));
    let before = (
        ok(std::fs::read(&input)),
        ok(std::fs::read(proj.join("config.toml"))),
    );
    let base = cube_run(&input, &proj, "style.iterations=3");
    let out = stylize(&base);
    assert!(!out.status.success());
    assert!(stderr(&out).contains("input mesh"), "{}", stderr(&out));
    let other = mesh(tmp.path(), "other.obj", 1, 0.7);
    let out = stylize(&cube_run(&other, &proj, "style.iterations=3"));
    assert!(!out.status.success());
    assert!(
        stderr(&out).contains("not a stylize run directory")
            && stderr(&out).contains("config.toml"),
        "{}",
        stderr(&out)
    );
    let mut forced = base.clone();
    forced.push("--force");
    let out = stylize(&forced);
    assert!(!out.status.success());
    assert!(
        stderr(&out).contains("input mesh"),
        "an input is never replaced, even with --force: {}",
        stderr(&out)
    );
    // The config file inside the output folder, with the mesh elsewhere.
    let cfg = proj.join("config.toml");
    let out = stylize(&[
        "run",
        s(&other),
        "--style",
        "cube",
        "-o",
        s(&proj),
        "--config",
        s(&cfg),
        "--force",
        "--quiet",
    ]);
    assert!(stderr(&out).contains("config file"), "{}", stderr(&out));
    // An exemplar under previews/ of the run directory.
    let exemplar = proj.join("previews/ex.obj");
    ok(std::fs::create_dir_all(proj.join("previews")));
    ok(std::fs::copy(&other, &exemplar));
    let style = format!("exemplar:{}", s(&exemplar));
    let out = stylize(&[
        "run",
        s(&other),
        "--style",
        &style,
        "-o",
        s(&proj),
        "--force",
        "--quiet",
    ]);
    assert!(stderr(&out).contains("exemplar mesh"), "{}", stderr(&out));
    assert!(exemplar.is_file());
    assert_eq!(
        (
            ok(std::fs::read(&input)),
            ok(std::fs::read(proj.join("config.toml")))
        ),
        before,
        "the user's files are untouched"
    );
    assert!(!proj.join("run.lock").exists() && !proj.join("task.json").exists());

    // --force into a foreign folder keeps files that are not ours.
    let shared = tmp.path().join("shared");
    ok(std::fs::create_dir_all(&shared));
    ok(std::fs::write(shared.join("notes.txt"), "mine"));
    let mut args = cube_run(&other, &shared, "style.iterations=3");
    args.push("--force");
    must(&stylize(&args));
    assert_eq!(
        ok(std::fs::read_to_string(shared.join("notes.txt"))),
        "mine"
    );

    // apply and render outputs never replace their inputs either.
    let mask = tmp.path().join("mask.obj");
    ok(std::fs::write(&mask, "0\n"));
    let out = stylize(&[
        "apply",
        s(&shared.join("deformation.npz")),
        "-o",
        s(&mask),
        "--mask",
        s(&mask),
        "--force",
    ]);
    assert!(stderr(&out).contains("mask file"), "{}", stderr(&out));
    assert_eq!(ok(std::fs::read_to_string(&mask)), "0\n");
    let out = stylize(&[
        "apply",
        s(&shared.join("deformation.npz")),
        "-o",
        s(&tmp.path().join("twice.obj")),
        "--lambda",
        "5,5",
    ]);
    assert!(stderr(&out).contains("repeated"), "{}", stderr(&out));
    assert!(!tmp.path().join("twice_lambda5.obj").exists());
    let frames = tmp.path().join("frames");
    ok(std::fs::create_dir_all(&frames));
    ok(std::os::unix::fs::symlink(
        &other,
        frames.join("contact_sheet.png"),
    ));
    let out = stylize(&[
        "render",
        s(&other),
        "-o",
        s(&frames),
        "--turntable",
        "1",
        "--size",
        "8",
        "--cpu",
        "--force",
    ]);
    assert!(stderr(&out).contains("input mesh"), "{}", stderr(&out));
    assert!(ok(mesh_core::io::read_mesh(&other)).faces.len() > 10);
}

#[test]
fn resume_refuses_another_task_naming_the_fields() {
    let tmp = ok(tempfile::tempdir());
    let m = mesh(tmp.path(), "m.obj", 1, 0.8);
    // Same vertex count and faces, other geometry.
    let other = mesh(tmp.path(), "other.obj", 1, 0.6);
    let run = tmp.path().join("run");
    let mut first = cube_run(&m, &run, "style.iterations=9");
    first.extend(["--set", "run.checkpoint_every=2", "--stop-after", "3"]);
    must(&stylize(&first));
    let resume = |mesh: &Path, extra: &[&str]| {
        let mut a = vec!["run", s(mesh), "-o", s(&run), "--quiet", "--resume"];
        a.extend_from_slice(extra);
        stylize(&a)
    };
    let cases: Vec<(Output, &str)> =
        vec![
            (
                resume(&m, &["--style", "octahedron"]),
                "style: was cube, now octahedron",
            ),
            (resume(&other, &["--style", "cube"]), "mesh.sha256"),
            (
                resume(
                    &m,
                    &[
                        "--style",
                        "cube",
                        "--config",
                        s(&run.join("config.toml")),
                        "--seed",
                        "5",
                        "--set",
                        "darap.lambda=3",
                    ],
                ),
                "config.run.seed: was 0, now 5",
            ),
            (
                resume(
                    &m,
                    &[
                        "--prompt",
                        "a chair",
                        "--model",
                        s(&Path::new(env!("CARGO_MANIFEST_DIR"))
                            .join("../../fixtures/models/tiny-if")),
                    ],
                ),
                "objective: was style, now prompt",
            ),
        ];
    for (out, expected) in &cases {
        let e = stderr(out);
        assert!(
            !out.status.success() && e.contains(expected),
            "{expected}: {e}"
        );
        assert!(e.contains("--force"), "{e}");
    }
    assert!(
        stderr(&cases[2].0).contains("config.darap.lambda: was 8"),
        "every differing field is named: {}",
        stderr(&cases[2].0)
    );
    assert_eq!(
        ok(Checkpoint::load(&run.join("checkpoint.json"))).iteration,
        2
    );
    // Settings that only change cadence or pictures may differ.
    must(&resume(
        &m,
        &[
            "--style",
            "cube",
            "--config",
            s(&run.join("config.toml")),
            "--set",
            "run.checkpoint_every=5",
            "--set",
            "run.turntable_size=8",
        ],
    ));
    assert!(run.join("run.json").is_file());

    // A checkpoint without identity (written by an older stylize) is refused.
    let old = tmp.path().join("old");
    let mut args = cube_run(&m, &old, "style.iterations=9");
    args.extend(["--set", "run.checkpoint_every=2", "--stop-after", "3"]);
    must(&stylize(&args));
    let mut c: serde_json::Value = ok(serde_json::from_str(&ok(std::fs::read_to_string(
        old.join("checkpoint.json"),
    ))));
    c["version"] = 1.into();
    if let Some(o) = c.as_object_mut() {
        o.remove("identity");
    }
    ok(std::fs::write(old.join("checkpoint.json"), c.to_string()));
    let out = stylize(&["run", s(&m), "--style", "cube", "-o", s(&old), "--resume"]);
    assert!(stderr(&out).contains("older stylize"), "{}", stderr(&out));
}

#[test]
fn resume_without_a_checkpoint_is_an_error() {
    let tmp = ok(tempfile::tempdir());
    let m = mesh(tmp.path(), "m.obj", 1, 0.8);
    let missing = tmp.path().join("missing");
    let mut args = cube_run(&m, &missing, "style.iterations=3");
    args.push("--resume");
    let out = stylize(&args);
    assert!(!out.status.success());
    assert!(
        stderr(&out).contains("nothing to resume"),
        "{}",
        stderr(&out)
    );
    assert!(!missing.exists(), "no fresh run with defaults");
    let empty = tmp.path().join("empty");
    ok(std::fs::create_dir_all(&empty));
    let mut args = cube_run(&m, &empty, "style.iterations=3");
    args.push("--resume");
    let out = stylize(&args);
    assert!(stderr(&out).contains("no checkpoint"), "{}", stderr(&out));
    assert_eq!(ok(std::fs::read_dir(&empty)).count(), 0);
}

/// SIGTERM stops a batch after the current row's checkpoint; the same command then resumes it.
#[test]
fn sigterm_stops_a_batch_and_the_same_command_resumes_it() {
    let tmp = ok(tempfile::tempdir());
    mesh(tmp.path(), "m.obj", 3, 0.8);
    let manifest = tmp.path().join("m.toml");
    let common = "overrides = [\"run.turntable_size=16\", \"run.turntable_views=1\", \"run.preview_every=0\"";
    ok(std::fs::write(
        &manifest,
        format!(
            "[[run]]\nmesh = \"m.obj\"\nstyle = \"cube\"\nout = \"runs/long\"\n{common}, \"style.iterations=1500\"]\n\n\
             [[run]]\nmesh = \"m.obj\"\nstyle = \"octahedron\"\nout = \"runs/short\"\n{common}, \"style.iterations=3\"]\n"
        ),
    ));
    let args = ["batch", s(&manifest), "--quiet"];
    let mut batch = spawn(&args);
    let long = tmp.path().join("runs/long");
    wait_for_iterations(&long, 2, &mut batch);
    signal(&batch, "TERM");
    let out = finish(batch);
    let e = stderr(&out);
    assert_eq!(out.status.code(), Some(143), "{e}");
    assert!(e.contains("run the same command again"), "{e}");
    let c = ok(Checkpoint::load(&long.join("checkpoint.json")));
    assert!(c.iteration >= 2 && c.iteration < 1500);
    assert!(
        !tmp.path().join("runs/short").exists(),
        "the batch stops at the interrupted row"
    );
    let out = stylize(&args);
    must(&out);
    assert!(stderr(&out).contains("done (resumed)"), "{}", stderr(&out));
    assert_eq!(metrics_iterations(&long), (1..=1500).collect::<Vec<_>>());
    assert!(tmp.path().join("runs/short/run.json").is_file());
}

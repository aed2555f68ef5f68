//! Signals cannot lose work, measured: a model-free run (`stylize run` in odd trials, a one-row
//! `stylize batch` in even ones) is stopped many times at random moments — one SIGTERM, two
//! SIGTERMs a few milliseconds apart (what `srun` can deliver), a SIGHUP, SIGTERM then SIGKILL
//! after a short grace time (Slurm's `KillWait`), two SIGINTs (a person who means "now") — and
//! each time resumed (the same batch command; `run --resume` once a checkpoint exists), until it
//! completes. Every final output must equal an uninterrupted run's byte for byte, `metrics.jsonl`
//! must hold each iteration once with the uninterrupted run's values, and every exit must have the
//! documented status with no lock of its own left behind (SIGKILL aside: that lock is taken over).
//!
//! `signal_kills_at_random_moments_never_lose_work` is the CI-sized version (12 runs, each stopped
//! up to 8 times); `signal_kill_soak` (ignored) runs 150: `cargo test -p stylize-cli --test
//! signals -- --ignored`. `STYLIZE_SOAK_SEED` repeats a sequence; `STYLIZE_SOAK_TRIALS` sets the
//! soak's size.

use std::path::{Path, PathBuf};
use std::process::{Child, Command, ExitStatus, Stdio};
use std::time::{Duration, Instant};

use mesh_core::TriMesh;

mod common;
use common::{ok, s};

/// The files of a complete run that must be byte-identical to an uninterrupted run's (`run.json`
/// holds wall times and `metrics.jsonl` per-iteration seconds: compared without them).
const SAME_BYTES: &[&str] = &[
    "task.json",
    "config.toml",
    "checkpoint.json",
    "mesh.obj",
    "deformation.npz",
    "turntable.png",
];

/// Iterations of the row (short: each trial restarts it many times).
const ITERATIONS: u64 = 120;

/// A small deterministic generator (the trials' randomness; the seed is printed).
struct Lcg(u64);

impl Lcg {
    fn next(&mut self) -> u64 {
        self.0 = self
            .0
            .wrapping_mul(6_364_136_223_846_793_005)
            .wrapping_add(1_442_695_040_888_963_407);
        self.0 >> 33
    }

    /// Uniform in `[0, n)`.
    fn below(&mut self, n: u64) -> u64 {
        if n == 0 { 0 } else { self.next() % n }
    }
}

/// How a trial stops the process.
#[derive(Clone, Copy, Debug)]
enum Stop {
    Term,
    /// Two SIGTERMs this many milliseconds apart.
    DoubleTerm(u64),
    Hup,
    /// SIGTERM, then SIGKILL this many milliseconds later if it still runs.
    TermThenKill(u64),
    /// Two SIGINTs this many milliseconds apart.
    DoubleInt(u64),
}

impl Stop {
    fn pick(rng: &mut Lcg) -> Self {
        match rng.below(5) {
            0 => Stop::Term,
            1 => Stop::DoubleTerm(1 + rng.below(5)),
            2 => Stop::Hup,
            3 => Stop::TermThenKill(rng.below(30)),
            _ => Stop::DoubleInt(1 + rng.below(20)),
        }
    }

    fn name(self) -> &'static str {
        match self {
            Stop::Term => "TERM",
            Stop::DoubleTerm(_) => "TERM+TERM",
            Stop::Hup => "HUP",
            Stop::TermThenKill(_) => "TERM+KILL",
            Stop::DoubleInt(_) => "INT+INT",
        }
    }
}

fn kill(child: &Child, signal: &str) {
    // The process may have ended meanwhile: then `kill` fails, which is fine.
    let _ = Command::new("kill")
        .args([format!("-{signal}"), child.id().to_string()])
        .stderr(Stdio::null())
        .status();
}

fn write_mesh(dir: &Path) -> PathBuf {
    let (p, f) = mesh_core::shapes::icosphere(2).into_parts();
    let p: Vec<[f64; 3]> = p.iter().map(|v| [1.3 * v[0], v[1], 0.8 * v[2]]).collect();
    let path = dir.join("m.obj");
    ok(mesh_core::io::write_mesh(&path, &TriMesh::new(p, f), None));
    path
}

/// A one-row manifest writing `out` (relative to `dir`).
fn manifest(dir: &Path, out: &str) -> PathBuf {
    let path = dir.join(format!("{out}.toml"));
    ok(std::fs::write(
        &path,
        format!(
            "[[run]]\nmesh = \"m.obj\"\nstyle = \"cube\"\nout = \"{out}\"\noverrides = \
             [\"style.iterations={ITERATIONS}\", \"run.checkpoint_every=7\", \
             \"run.turntable_size=16\", \"run.turntable_views=1\", \"run.preview_every=0\"]\n"
        ),
    ));
    path
}

/// `stylize run` of the same row into `out` (with `--resume` when it holds a checkpoint, as a user
/// would type it again).
fn run(mesh: &Path, out: &Path) -> Child {
    let iterations = format!("style.iterations={ITERATIONS}");
    let mut args = vec![
        "run",
        s(mesh),
        "--style",
        "cube",
        "-o",
        s(out),
        "--quiet",
        "--set",
        &iterations,
        "--set",
        "run.checkpoint_every=7",
        "--set",
        "run.turntable_size=16",
        "--set",
        "run.turntable_views=1",
        "--set",
        "run.preview_every=0",
    ];
    if out.join("checkpoint.json").is_file() {
        args.push("--resume");
    }
    ok(Command::new(env!("CARGO_BIN_EXE_stylize"))
        .args(&args)
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn())
}

fn batch(manifest: &Path) -> Child {
    ok(Command::new(env!("CARGO_BIN_EXE_stylize"))
        .args(["batch", s(manifest), "--quiet"])
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn())
}

/// `metrics.jsonl` without the wall times.
fn metrics_values(dir: &Path) -> Vec<serde_json::Value> {
    ok(std::fs::read_to_string(dir.join("metrics.jsonl")))
        .lines()
        .map(|l| {
            let mut v: serde_json::Value = ok(serde_json::from_str(l));
            if let Some(o) = v.as_object_mut() {
                o.remove("seconds");
            }
            v
        })
        .collect()
}

/// One trial's attempt: what was sent, and how the process ended.
struct Attempt {
    kill: Stop,
    delay_ms: u64,
    status: ExitStatus,
}

/// Whether `status` is one the documented ones for `kill` (0 when the run ended first). A signal
/// that comes before the process has installed its handlers (the first milliseconds after `exec`)
/// kills it by the default action; the caller checks that nothing was touched then.
fn status_is_documented(kill: Stop, status: ExitStatus) -> bool {
    use std::os::unix::process::ExitStatusExt;
    let code = status.code();
    let by = status.signal();
    match kill {
        Stop::Term | Stop::DoubleTerm(_) => matches!(code, Some(0 | 143)) || by == Some(15),
        Stop::Hup => matches!(code, Some(0 | 129)) || by == Some(1),
        Stop::DoubleInt(_) => matches!(code, Some(0 | 130)) || by == Some(2),
        Stop::TermThenKill(_) => matches!(code, Some(0 | 143)) || by == Some(9) || by == Some(15),
    }
}

/// Runs `trials` interrupted runs; panics on the first that loses or changes anything.
fn trials(count: usize) {
    let seed = std::env::var("STYLIZE_SOAK_SEED")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or_else(|| {
            std::time::SystemTime::now()
                .duration_since(std::time::UNIX_EPOCH)
                .map(|d| d.as_nanos() as u64)
                .unwrap_or(1)
        });
    eprintln!("STYLIZE_SOAK_SEED={seed}");
    let mut rng = Lcg(seed);
    let tmp = ok(tempfile::tempdir());
    write_mesh(tmp.path());
    // The uninterrupted reference, and how long one takes here (the kill moments span it).
    let reference = tmp.path().join("reference");
    let start = Instant::now();
    let out = ok(batch(&manifest(tmp.path(), "reference")).wait_with_output());
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let span_ms = (start.elapsed().as_millis() as u64).max(50);
    let reference_metrics = metrics_values(&reference);
    assert_eq!(reference_metrics.len() as u64, ITERATIONS);
    // The same for `stylize run` (odd trials use it; its files are compared with its own).
    let mesh = tmp.path().join("m.obj");
    let run_reference = tmp.path().join("run-reference");
    let out = ok(run(&mesh, &run_reference).wait_with_output());
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert_eq!(metrics_values(&run_reference), reference_metrics);

    let mut kinds = std::collections::BTreeMap::<&str, (usize, usize)>::new();
    let mut killed_total = 0;
    for trial in 0..count {
        let name = format!("t{trial}");
        let dir = tmp.path().join(&name);
        let manifest = manifest(tmp.path(), &name);
        let by_run = trial % 2 == 1;
        let reference = if by_run { &run_reference } else { &reference };
        let mut attempts: Vec<Attempt> = Vec::new();
        let mut killed_complete = false;
        // Kill each attempt at a random moment until one completes (after 8, let it finish).
        loop {
            // An attempt SIGKILLed after its run completed (`run.json` written last) leaves a
            // complete run: `run --resume` would refuse it ("a complete run is never resumed");
            // a user is done there.
            if by_run && dir.join("run.json").is_file() {
                // Its lock, if left, is the SIGKILLed process's (the next run takes it over).
                use std::os::unix::process::ExitStatusExt;
                killed_complete = attempts
                    .last()
                    .is_some_and(|a| a.status.signal() == Some(9));
                break;
            }
            // A lock left by an earlier attempt's SIGKILL (taken over by the next process).
            let lock_before = std::fs::read(dir.join("run.lock")).ok();
            let child = if by_run {
                run(&mesh, &dir)
            } else {
                batch(&manifest)
            };
            if attempts.len() >= 8 {
                let out = ok(child.wait_with_output());
                assert!(
                    out.status.success(),
                    "{}",
                    String::from_utf8_lossy(&out.stderr)
                );
                break;
            }
            let kill_kind = Stop::pick(&mut rng);
            let delay_ms = rng.below(span_ms);
            std::thread::sleep(Duration::from_millis(delay_ms));
            match kill_kind {
                Stop::Term => kill(&child, "TERM"),
                Stop::Hup => kill(&child, "HUP"),
                Stop::DoubleTerm(ms) => {
                    kill(&child, "TERM");
                    std::thread::sleep(Duration::from_millis(ms));
                    kill(&child, "TERM");
                }
                Stop::DoubleInt(ms) => {
                    kill(&child, "INT");
                    std::thread::sleep(Duration::from_millis(ms));
                    kill(&child, "INT");
                }
                Stop::TermThenKill(ms) => {
                    kill(&child, "TERM");
                    std::thread::sleep(Duration::from_millis(ms));
                    kill(&child, "KILL");
                }
            }
            let out = ok(child.wait_with_output());
            let e = String::from_utf8_lossy(&out.stderr).into_owned();
            let entry = kinds.entry(kill_kind.name()).or_default();
            entry.0 += 1;
            assert!(
                status_is_documented(kill_kind, out.status),
                "seed {seed} trial {trial}: {kill_kind:?} after {delay_ms} ms ended with {}: {e}",
                out.status
            );
            let killed = out.status.code().is_none();
            let lock_after = std::fs::read(dir.join("run.lock")).ok();
            {
                use std::os::unix::process::ExitStatusExt;
                // Killed by the default action of TERM/HUP/INT: before the handlers, so before
                // the lock and before anything was written: the lock is as it was.
                if matches!(out.status.signal(), Some(1 | 2 | 15)) {
                    assert!(
                        lock_after == lock_before,
                        "seed {seed} trial {trial}: {kill_kind:?} after {delay_ms} ms killed a \
                         process that held the lock"
                    );
                }
            }
            if !killed {
                // Whatever the signals, no lock of this process is left (an earlier attempt's,
                // never touched, may be).
                assert!(
                    lock_after.is_none() || lock_after == lock_before,
                    "seed {seed} trial {trial}: {kill_kind:?} after {delay_ms} ms left run.lock: {e}"
                );
            }
            if out.status.code() != Some(0) {
                entry.1 += 1;
                killed_total += usize::from(killed);
            }
            let done = out.status.success();
            attempts.push(Attempt {
                kill: kill_kind,
                delay_ms,
                status: out.status,
            });
            if done {
                break;
            }
        }
        let story = attempts
            .iter()
            .map(|a| format!("{:?}@{}ms→{}", a.kill, a.delay_ms, a.status))
            .collect::<Vec<_>>()
            .join(", ");
        for file in SAME_BYTES {
            let a = ok(std::fs::read(reference.join(file)));
            let b = std::fs::read(dir.join(file))
                .unwrap_or_else(|e| panic!("seed {seed} trial {trial} ({story}): {file}: {e}"));
            assert!(
                a == b,
                "seed {seed} trial {trial} ({story}): {file} differs"
            );
        }
        assert_eq!(
            metrics_values(&dir),
            reference_metrics,
            "seed {seed} trial {trial} ({story}): metrics.jsonl differs"
        );
        assert!(dir.join("run.json").is_file());
        assert!(
            !dir.join("run.lock").exists() || killed_complete,
            "trial {trial}: lock left after completion"
        );
    }
    eprintln!("signal trials (seed {seed}): {count} runs, each equal to the uninterrupted one");
    eprintln!("  kind        attempts  stopped a running row");
    for (k, (n, stopped)) in &kinds {
        eprintln!("  {k:<10}  {n:>8}  {stopped:>8}");
    }
    eprintln!("  ({killed_total} attempts ended by SIGKILL)");
}

#[test]
fn signal_kills_at_random_moments_never_lose_work() {
    trials(12);
}

#[test]
#[ignore = "a long soak (minutes): cargo test -p stylize-cli --test signals -- --ignored"]
fn signal_kill_soak() {
    let count = std::env::var("STYLIZE_SOAK_TRIALS")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(150);
    trials(count);
}

/// A batch's exit status says its outcome: 75 when its only trouble was a row in use elsewhere
/// (the row line and the JSON row line say so), 1 when a row failed (even with another in use).
#[test]
fn batch_exit_statuses_per_outcome() {
    let tmp = ok(tempfile::tempdir());
    write_mesh(tmp.path());
    // A live holder on another node (fresh heartbeat): the row is left to it.
    let held = tmp.path().join("held");
    ok(std::fs::create_dir_all(&held));
    let now = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map(|d| d.as_secs_f64())
        .unwrap_or(0.0);
    let record = serde_json::json!({
        "host": "node-42", "pid": 777, "since": now - 60.0, "heartbeat": now,
        "interval": 5.0, "beat": 3, "token": "0123abcd", "command": "stylize batch elsewhere"
    });
    ok(std::fs::write(held.join("run.lock"), record.to_string()));
    let row = |mesh: &str, out: &str| {
        format!(
            "{{\"mesh\": \"{mesh}\", \"style\": \"cube\", \"out\": \"{out}\", \"overrides\": \
             [\"style.iterations=2\", \"run.turntable_size=16\", \"run.turntable_views=1\"]}}\n"
        )
    };
    let manifest = tmp.path().join("m.jsonl");
    ok(std::fs::write(
        &manifest,
        row("m.obj", "done") + &row("m.obj", "held"),
    ));
    let out = common::stylize(&["batch", s(&manifest), "--log-format", "jsonl"]);
    let e = common::stderr(&out);
    assert_eq!(out.status.code(), Some(75), "{e}");
    assert!(e.contains("row 0 ") && e.contains(": done ("), "{e}");
    assert!(
        e.contains("row 1 ") && e.contains("IN USE elsewhere") && e.contains("node-42"),
        "{e}"
    );
    let outcomes: Vec<(u64, String)> = String::from_utf8_lossy(&out.stdout)
        .lines()
        .filter_map(|l| serde_json::from_str::<serde_json::Value>(l).ok())
        .filter(|v| v["event"] == "row")
        .map(|v| {
            (
                v["row"].as_u64().unwrap_or(99),
                v["outcome"].as_str().unwrap_or_default().to_string(),
            )
        })
        .collect();
    assert_eq!(
        outcomes,
        [(0, "done".to_string()), (1, "in-use".to_string())]
    );
    // A failing row (a missing mesh) outranks the row in use: 1.
    ok(std::fs::write(
        &manifest,
        row("missing.obj", "bad") + &row("m.obj", "held"),
    ));
    let out = common::stylize(&["batch", s(&manifest), "--quiet"]);
    let e = common::stderr(&out);
    assert_eq!(out.status.code(), Some(1), "{e}");
    assert!(
        e.contains("FAILED") && e.contains("IN USE elsewhere"),
        "{e}"
    );
    // Inside a job array, --shard is required (the array's variables are not a shard count).
    let out = ok(Command::new(env!("CARGO_BIN_EXE_stylize"))
        .args(["batch", s(&manifest), "--quiet"])
        .env("SLURM_ARRAY_TASK_ID", "2")
        .env("SLURM_ARRAY_TASK_COUNT", "1")
        .output());
    let e = common::stderr(&out);
    assert_eq!(out.status.code(), Some(1), "{e}");
    assert!(e.contains("--shard \"$SLURM_ARRAY_TASK_ID/N\""), "{e}");
    assert!(!tmp.path().join("bad").exists(), "nothing ran");
}

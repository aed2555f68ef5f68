//! `cargo xtask fuzz [--seconds N] [--target NAME] [--seed S] [--replay FILE]`: an in-repo
//! mutation fuzzer over every reader of user files (meshes, `.npz`/`.npy`, masks, batch manifests
//! in TOML and JSONL with odd encodings, checkpoints, configs, region specs, model `manifest.toml`s)
//! and over the viewer's HTTP request handling (raw bytes answered in process, no socket). See
//! `docs/formats.md` ("Fuzzing the readers").
//!
//! Design:
//! - **Supervisor and child.** The command runs each target in a child process (`xtask
//!   fuzz-child …`, this same binary) and restarts it after a crash, so an abort (a refused
//!   allocation, a stack overflow) or a hang costs one restart, not the run, and is reported with
//!   its input.
//! - **In the child**, each input is written to `target/fuzz-work/<target>/input.<ext>` (and its
//!   iteration number next to it, so the supervisor can name the input a crash happened on), then
//!   read by the target in a worker thread under `catch_unwind`, with a time cap
//!   ([`TIME_CAP`]) and a memory cap (the counting allocator of [`alloc`]: at most
//!   [`MEMORY_SLACK`] plus [`MEMORY_PER_INPUT_BYTE`] × the input's size on top of what the child
//!   already holds).
//! - **Failures** (panic, timeout, memory-cap breach, any other crash) are saved under
//!   `target/fuzz-failures/<target>/` as the input plus a `.txt` description; the command lists
//!   them and exits non-zero. `--replay FILE` reruns one saved input in-process.
//! - **Determinism.** Iteration `i` of a target mutates seeds chosen by a generator seeded from
//!   (`--seed`, target, `i`), so a seed reproduces the same inputs in the same order; the
//!   budget only decides how many iterations run. The first iterations run the unmodified seeds.

pub mod alloc;
mod mutate;
mod targets;

use std::io::Write;
use std::os::unix::fs::FileExt;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::sync::Mutex;
use std::time::{Duration, Instant};

use anyhow::{Context, bail};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use targets::{TARGETS, Target};

/// Wall time one input may take before it counts as a hang.
pub const TIME_CAP: Duration = Duration::from_secs(2);
/// Memory an input may always use.
pub const MEMORY_SLACK: usize = 256 << 20;
/// Memory an input may use per byte of its size, on top of [`MEMORY_SLACK`].
pub const MEMORY_PER_INPUT_BYTE: usize = 64;
/// Mutants are cut to this size.
const MAX_INPUT: usize = 1 << 20;
/// Exit code of a child that stopped after recording a hang.
const EXIT_HANG: i32 = 3;

fn repo_root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .unwrap_or(Path::new("."))
        .to_path_buf()
}

fn work_dir(target: &str) -> PathBuf {
    repo_root().join("target/fuzz-work").join(target)
}

fn failure_dir(target: &str) -> PathBuf {
    repo_root().join("target/fuzz-failures").join(target)
}

/// SplitMix64 of the seed, target index and iteration: the generator seed of one input.
fn input_seed(seed: u64, target: usize, iteration: u64) -> u64 {
    let mut z = seed
        ^ (target as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15)
        ^ iteration.wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

struct Options {
    seconds: f64,
    target: Option<String>,
    seed: u64,
    replay: Option<PathBuf>,
}

fn parse_options(args: &[String]) -> anyhow::Result<Options> {
    let mut o = Options {
        seconds: 60.0,
        target: None,
        seed: 1,
        replay: None,
    };
    let mut it = args.iter();
    while let Some(a) = it.next() {
        let mut value = |name: &str| {
            it.next()
                .cloned()
                .with_context(|| format!("{name} needs a value"))
        };
        match a.as_str() {
            "--seconds" => {
                o.seconds = value("--seconds")?
                    .parse()
                    .context("--seconds: expected a number")?;
                if !(o.seconds > 0.0 && o.seconds.is_finite()) {
                    bail!("--seconds must be positive");
                }
            }
            "--target" => o.target = Some(value("--target")?),
            "--seed" => {
                o.seed = value("--seed")?
                    .parse()
                    .context("--seed: expected an integer")?
            }
            "--replay" => o.replay = Some(PathBuf::from(value("--replay")?)),
            other => bail!(
                "unknown argument {other:?}; usage: cargo xtask fuzz [--seconds N] [--target NAME] \
                 [--seed S] [--replay FILE]"
            ),
        }
    }
    Ok(o)
}

fn find_target(name: &str) -> anyhow::Result<(usize, &'static Target)> {
    TARGETS
        .iter()
        .enumerate()
        .find(|(_, t)| t.name == name)
        .with_context(|| {
            let names: Vec<&str> = TARGETS.iter().map(|t| t.name).collect();
            format!("unknown target {name:?} (targets: {})", names.join(", "))
        })
}

/// One failure found by a target.
struct Failure {
    target: &'static str,
    kind: String,
    input: PathBuf,
}

/// `cargo xtask fuzz …`: the supervisor.
pub fn run(args: &[String]) -> anyhow::Result<()> {
    let o = parse_options(args)?;
    let chosen: Vec<&'static Target> = match &o.target {
        Some(name) => vec![find_target(name)?.1],
        None => TARGETS.iter().collect(),
    };
    if let Some(file) = &o.replay {
        let t = chosen
            .first()
            .filter(|_| o.target.is_some())
            .context("--replay needs --target NAME")?;
        (t.run)(file);
        println!("{}: {} read without panicking", t.name, file.display());
        return Ok(());
    }
    let per_target = Duration::from_secs_f64(o.seconds / chosen.len() as f64);
    println!(
        "fuzzing {} target(s), {:.1} s each, seed {} (failures go to target/fuzz-failures/)",
        chosen.len(),
        per_target.as_secs_f64(),
        o.seed
    );
    let mut failures: Vec<Failure> = Vec::new();
    for t in chosen {
        let (execs, elapsed, found) = supervise(t, o.seed, per_target)?;
        println!(
            "{:>15}: {execs:>8} execs in {:5.1} s = {:>7.0} execs/s, {} failure(s)",
            t.name,
            elapsed.as_secs_f64(),
            execs as f64 / elapsed.as_secs_f64().max(1e-9),
            found.len()
        );
        failures.extend(found);
    }
    if failures.is_empty() {
        println!("fuzz: no failures");
        return Ok(());
    }
    eprintln!("fuzz: {} failure(s):", failures.len());
    for f in &failures {
        eprintln!(
            "  {} {}: {} (replay: cargo xtask fuzz --target {} --replay {})",
            f.target,
            f.kind,
            f.input.display(),
            f.target,
            f.input.display()
        );
    }
    bail!("the fuzzer found {} failure(s)", failures.len())
}

/// Runs `t` in child processes for `budget`, restarting after crashes and hangs.
fn supervise(
    t: &'static Target,
    seed: u64,
    budget: Duration,
) -> anyhow::Result<(u64, Duration, Vec<Failure>)> {
    let start = Instant::now();
    let exe = std::env::current_exe().context("cannot find the xtask executable")?;
    let work = work_dir(t.name);
    std::fs::create_dir_all(&work).with_context(|| format!("cannot create {}", work.display()))?;
    let mut from = 0u64;
    let mut execs = 0u64;
    let mut found = Vec::new();
    while start.elapsed() < budget {
        let left = budget.saturating_sub(start.elapsed());
        let out = Command::new(&exe)
            .args([
                "fuzz-child",
                t.name,
                &seed.to_string(),
                &from.to_string(),
                &left.as_millis().to_string(),
            ])
            .output()
            .context("cannot start the fuzz child process")?;
        let stdout = String::from_utf8_lossy(&out.stdout);
        for line in stdout.lines() {
            let w: Vec<&str> = line.split_whitespace().collect();
            match w.as_slice() {
                ["fail", kind, file] => found.push(Failure {
                    target: t.name,
                    kind: kind.to_string(),
                    input: PathBuf::from(file),
                }),
                ["done", next, n] => {
                    from = next.parse().unwrap_or(from);
                    execs += n.parse::<u64>().unwrap_or(0);
                }
                _ => {}
            }
        }
        if out.status.success() {
            continue;
        }
        if stdout.lines().any(|l| l.starts_with("setup-error")) {
            bail!(
                "fuzz target {}: {}{}",
                t.name,
                stdout,
                String::from_utf8_lossy(&out.stderr)
            );
        }
        // The child stopped on an input: a hang it recorded itself, or a crash we record here.
        let iteration = std::fs::read(work.join("iteration"))
            .ok()
            .and_then(|b| b.get(..8).and_then(|b| b.try_into().ok()))
            .map(u64::from_le_bytes)
            .unwrap_or(from);
        execs += iteration.saturating_sub(from) + 1;
        from = iteration + 1;
        if out.status.code() == Some(EXIT_HANG) {
            continue;
        }
        let stderr = String::from_utf8_lossy(&out.stderr);
        let kind = if stderr.contains("memory allocation of") {
            "memory"
        } else if stderr.contains("overflowed its stack") {
            "stack-overflow"
        } else {
            "crash"
        };
        let tail: String = {
            let lines: Vec<&str> = stderr.lines().collect();
            lines[lines.len().saturating_sub(20)..].join("\n")
        };
        let input = std::fs::read(work.join(format!("input.{}", t.ext))).unwrap_or_default();
        let saved = save_failure(
            t,
            seed,
            iteration,
            kind,
            &input,
            &format!("the process died ({}); stderr:\n{tail}", out.status),
        )?;
        found.push(Failure {
            target: t.name,
            kind: kind.into(),
            input: saved,
        });
    }
    Ok((execs, start.elapsed(), found))
}

/// Saves a failing input and its description; returns the input's path.
fn save_failure(
    t: &Target,
    seed: u64,
    iteration: u64,
    kind: &str,
    input: &[u8],
    what: &str,
) -> anyhow::Result<PathBuf> {
    let dir = failure_dir(t.name);
    std::fs::create_dir_all(&dir).with_context(|| format!("cannot create {}", dir.display()))?;
    let file = dir.join(format!("{kind}-seed{seed}-iter{iteration}.{}", t.ext));
    std::fs::write(&file, input).with_context(|| format!("cannot write {}", file.display()))?;
    let memory_cap = MEMORY_SLACK + MEMORY_PER_INPUT_BYTE * input.len();
    std::fs::write(
        file.with_extension(format!("{}.txt", t.ext)),
        format!(
            "target: {}\nkind: {kind}\nseed: {seed}\niteration: {iteration}\ninput: {} bytes\n\
             caps: {} s, {memory_cap} bytes\n\n{what}\n\nreplay: cargo xtask fuzz --target {} --replay {}\n",
            t.name,
            input.len(),
            TIME_CAP.as_secs_f64(),
            t.name,
            file.display()
        ),
    )
    .with_context(|| format!("cannot write the description of {}", file.display()))?;
    Ok(file)
}

static PANIC_MESSAGE: Mutex<Option<String>> = Mutex::new(None);

/// `xtask fuzz-child TARGET SEED FROM MILLIS`: runs iterations FROM… of TARGET for MILLIS ms.
pub fn child(args: &[String]) -> anyhow::Result<()> {
    let result = child_inner(args);
    if let Err(e) = &result {
        println!("setup-error {e:#}");
    }
    result
}

fn child_inner(args: &[String]) -> anyhow::Result<()> {
    let [name, seed, from, millis] = args else {
        bail!("usage: xtask fuzz-child TARGET SEED FROM MILLIS");
    };
    let (ti, t) = find_target(name)?;
    let seed: u64 = seed.parse()?;
    let mut iteration: u64 = from.parse()?;
    let deadline = Instant::now() + Duration::from_millis(millis.parse()?);
    let work = work_dir(t.name);
    let scratch = work.join("seeds");
    std::fs::create_dir_all(&scratch)?;
    let corpus = targets::seeds(t.name, &repo_root(), &scratch)?;
    let input_path = work.join(format!("input.{}", t.ext));
    let iteration_file = std::fs::File::create(work.join("iteration"))?;
    std::panic::set_hook(Box::new(|info| {
        if let Ok(mut m) = PANIC_MESSAGE.lock() {
            *m = Some(info.to_string());
        }
    }));
    let mut execs = 0u64;
    let stdout = std::io::stdout();
    while Instant::now() < deadline {
        let mut rng = ChaCha8Rng::seed_from_u64(input_seed(seed, ti, iteration));
        let input = match usize::try_from(iteration).ok().and_then(|i| corpus.get(i)) {
            Some(seed_file) => seed_file.clone(),
            None => {
                let a = &corpus[rng.random_range(0..corpus.len())];
                let b = &corpus[rng.random_range(0..corpus.len())];
                mutate::mutate(a, b, &mut rng, MAX_INPUT)
            }
        };
        std::fs::write(&input_path, &input)?;
        iteration_file.write_all_at(&iteration.to_le_bytes(), 0)?;
        let outcome = run_capped(t, &input_path, input.len());
        let failure = match outcome {
            Outcome::Fine => None,
            Outcome::Panic(msg) => Some(("panic", format!("panic: {msg}"))),
            Outcome::Hang => Some((
                "timeout",
                format!("still running after {} s", TIME_CAP.as_secs_f64()),
            )),
        };
        if let Some((kind, what)) = failure {
            let saved = save_failure(t, seed, iteration, kind, &input, &what)?;
            let mut out = stdout.lock();
            writeln!(out, "fail {kind} {}", saved.display())?;
            out.flush()?;
            if kind == "timeout" {
                // The worker cannot be stopped; a fresh child continues after this input.
                std::process::exit(EXIT_HANG);
            }
        }
        iteration += 1;
        execs += 1;
    }
    println!("done {iteration} {execs}");
    Ok(())
}

enum Outcome {
    Fine,
    Panic(String),
    Hang,
}

/// Runs the target on one file in a worker thread with the time and memory caps.
fn run_capped(t: &'static Target, path: &Path, input_len: usize) -> Outcome {
    let path = path.to_path_buf();
    let cap = alloc::live()
        .saturating_add(MEMORY_SLACK)
        .saturating_add(MEMORY_PER_INPUT_BYTE.saturating_mul(input_len));
    let (tx, rx) = std::sync::mpsc::channel();
    alloc::set_cap(cap);
    let spawned = std::thread::Builder::new()
        .name("fuzz-worker".into())
        .spawn(move || {
            let r = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| (t.run)(&path)));
            let _ = tx.send(r.is_ok());
        });
    let outcome = match spawned {
        Err(e) => Outcome::Panic(format!("cannot start the worker thread: {e}")),
        Ok(handle) => match rx.recv_timeout(TIME_CAP) {
            Ok(true) => {
                let _ = handle.join();
                match alloc::breached() {
                    // A refused allocation that the reader handled (`try_reserve`): still an
                    // attempt to use memory beyond what the input justifies.
                    Some(bytes) => Outcome::Panic(format!(
                        "an allocation of {bytes} bytes beyond the memory cap was refused"
                    )),
                    None => Outcome::Fine,
                }
            }
            Ok(false) => {
                let _ = handle.join();
                let msg = PANIC_MESSAGE
                    .lock()
                    .ok()
                    .and_then(|mut m| m.take())
                    .unwrap_or_else(|| "(no message)".into());
                Outcome::Panic(msg)
            }
            Err(_) => Outcome::Hang,
        },
    };
    alloc::set_cap(usize::MAX);
    outcome
}

//! The run-directory lock: one process at a time per run directory, for the whole life of a run.
//!
//! The lock is a file `run.lock` created with `O_CREAT | O_EXCL` (`create_new`) in the run
//! directory. It holds a JSON record — host, pid, boot id and pid namespace, process start time,
//! start time, last heartbeat, heartbeat interval, a random token and a heartbeat counter — padded to
//! a fixed size so that each heartbeat is one in-place write. A background thread rewrites it
//! every `heartbeat` (and `fsync`s it, so other NFS clients see it) and checks that `run.lock`
//! is still the file it created; the run checks [`RunLock::ensure_held`] before every checkpoint
//! and output it commits.
//!
//! A second process finds the file and fails fast naming the holder — unless the lock is
//! **stale**:
//! - the holder ran on this host (same host name, boot id and pid namespace) and its process is
//!   gone (or the pid now belongs to a process started at another time), or
//! - its heartbeat is older than `stale_after` by our clock **and** the file does not change during
//!   an observation window of two of the holder's heartbeat intervals plus one second (a quarter of
//!   `stale_after` when that is shorter), so a holder whose clock is behind ours is not mistaken
//!   for a dead one; or
//! - its heartbeat lies more than `stale_after` in our future (a holder whose clock is ahead by a
//!   day, a forged `1e300`): then the file's mtime stands in for it (set by the holder's last
//!   write, by the file server's clock) with the same rule, and when the mtime too is that far
//!   ahead, the lock is stale once the file has not changed for `stale_after` by our monotonic
//!   clock. A dead holder's lock is thus taken over after at most about `stale_after` whatever
//!   its clock said, never "once our clock catches up".
//!
//! Taking over a stale lock is race-free among any number of contenders: a contender first creates
//! `run.lock.takeover-<token>` with `O_EXCL` (only one can, per stale lock), re-reads `run.lock` to
//! check that it is still byte-for-byte the stale record, renames it to `run.lock.stale-<token>`,
//! and then competes with everyone else through the ordinary `O_EXCL` creation of `run.lock`.
//! Tokens are never reused, so the stale record can never reappear under `run.lock`.
//!
//! What this relies on, and its limits, are written down in `docs/cluster.md`.

use std::fs::File;
use std::io::{Read, Write};
use std::os::unix::fs::{FileExt, MetadataExt};
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc;
use std::thread::JoinHandle;
use std::time::{Duration, SystemTime, UNIX_EPOCH};

use serde::{Deserialize, Serialize};

/// The lock file's name inside a run directory.
pub const LOCK_FILE: &str = "run.lock";
/// Prefix of the renamed stale locks and of the take-over markers.
const STALE_PREFIX: &str = "run.lock.stale-";
const TAKEOVER_PREFIX: &str = "run.lock.takeover-";
/// Size every lock record is padded to (one in-place write per heartbeat).
const RECORD_BYTES: usize = 1024;
/// Environment variable: heartbeat interval in seconds (default 5).
pub const HEARTBEAT_ENV: &str = "STYLIZE_LOCK_HEARTBEAT_SECS";
/// Environment variable: staleness limit in seconds (default 60).
pub const STALE_ENV: &str = "STYLIZE_LOCK_STALE_SECS";

/// Whether `name` is one of the lock's files (the lock, a renamed stale lock, a take-over marker).
pub fn is_lock_name(name: &str) -> bool {
    name == LOCK_FILE || name.starts_with(STALE_PREFIX) || name.starts_with(TAKEOVER_PREFIX)
}

/// Timing of the heartbeat and of staleness.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LockSettings {
    /// How often the holder rewrites the lock.
    pub heartbeat: Duration,
    /// A heartbeat older than this (and no change while observed) makes the lock stale.
    pub stale_after: Duration,
}

impl Default for LockSettings {
    fn default() -> Self {
        Self {
            heartbeat: Duration::from_secs(5),
            stale_after: Duration::from_secs(60),
        }
    }
}

impl LockSettings {
    /// The defaults, overridden by [`HEARTBEAT_ENV`] and [`STALE_ENV`] (seconds, fractions
    /// allowed). The staleness limit must be at least three heartbeats.
    pub fn from_env() -> Result<Self, LockError> {
        let mut s = Self::default();
        let read = |name: &str| -> Result<Option<Duration>, LockError> {
            match std::env::var(name) {
                Ok(v) => {
                    let secs: f64 = v.trim().parse().map_err(|_| {
                        LockError::Settings(format!("{name}={v:?} is not a number of seconds"))
                    })?;
                    if !(secs.is_finite() && secs > 0.0 && secs < 1e6) {
                        return Err(LockError::Settings(format!(
                            "{name}={v:?} must be a positive number of seconds"
                        )));
                    }
                    Ok(Some(Duration::from_secs_f64(secs)))
                }
                Err(_) => Ok(None),
            }
        };
        if let Some(h) = read(HEARTBEAT_ENV)? {
            s.heartbeat = h;
        }
        if let Some(t) = read(STALE_ENV)? {
            s.stale_after = t;
        }
        if s.stale_after < 3 * s.heartbeat {
            return Err(LockError::Settings(format!(
                "{STALE_ENV} ({:?}) must be at least three heartbeats ({HEARTBEAT_ENV} = {:?})",
                s.stale_after, s.heartbeat
            )));
        }
        Ok(s)
    }
}

/// The record in a lock file.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct LockRecord {
    /// Host name of the holder.
    pub host: String,
    /// Process id of the holder (on its host).
    pub pid: u32,
    /// Linux boot id of the holder's host ("" when unknown).
    #[serde(default)]
    pub boot_id: String,
    /// Pid namespace of the holder ("" when unknown).
    #[serde(default)]
    pub pid_ns: String,
    /// Start time of the holder's process in clock ticks since boot (0 when unknown).
    #[serde(default)]
    pub proc_start: u64,
    /// When the lock was taken (Unix seconds, holder's clock).
    pub since: f64,
    /// Last heartbeat (Unix seconds, holder's clock).
    pub heartbeat: f64,
    /// Heartbeat interval of the holder in seconds.
    pub interval: f64,
    /// Heartbeats written so far.
    pub beat: u64,
    /// Random token, unique per lock.
    pub token: String,
    /// The holder's command line (for the message).
    #[serde(default)]
    pub command: String,
}

/// The holder of a lock, as its record says.
#[derive(Clone, Debug, PartialEq)]
pub struct Holder {
    /// Holder's host.
    pub host: String,
    /// Holder's pid.
    pub pid: u32,
    /// When the holder took the lock (UTC).
    pub since: String,
    /// Heartbeat age in words.
    pub age: String,
    /// The holder's command line ("" when unknown).
    pub command: String,
    /// Our staleness limit in seconds.
    pub stale_secs: f64,
}

fn held_message(dir: &Path, h: &Holder) -> String {
    format!(
        "run directory {} is in use: locked by pid {} on host {} since {} (last heartbeat {}){}; \
         two processes must not write one run directory. If that process is gone, its lock is \
         taken over automatically once it has not renewed its heartbeat for {} s ({STALE_ENV}), \
         whatever its clock says, or at once on the same host",
        dir.display(),
        h.pid,
        h.host,
        h.since,
        h.age,
        if h.command.is_empty() {
            String::new()
        } else {
            format!("; command: {}", h.command)
        },
        h.stale_secs
    )
}

/// Why a lock could not be taken.
#[derive(Debug, thiserror::Error)]
pub enum LockError {
    /// Another live process holds the lock.
    #[error("{}", held_message(dir, holder))]
    Held {
        /// The run directory.
        dir: PathBuf,
        /// Who holds it.
        holder: Box<Holder>,
    },
    /// The lock file exists but is being written or is unreadable garbage that still changes.
    #[error(
        "run directory {dir} is in use: {path} exists ({detail}); wait for the other process, \
         or remove the file if you are sure no process uses this run directory"
    )]
    Busy {
        /// The run directory.
        dir: PathBuf,
        /// The lock file.
        path: PathBuf,
        /// What was found.
        detail: Box<str>,
    },
    /// The lock settings from the environment are invalid ([`LockSettings::from_env`]).
    #[error("{0}")]
    Settings(String),
    /// The lock was taken over by another process while the run held it.
    #[error(
        "lost the lock of run directory {}{}: another process took it over; stopping without \
         writing",
        dir.display(),
        holder.as_deref().unwrap_or("")
    )]
    Lost {
        /// The run directory.
        dir: PathBuf,
        /// ` (now held by pid P on host H)` when known.
        holder: Option<String>,
    },
    /// Input/output error on the lock file.
    #[error("run directory lock {path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The error.
        source: std::io::Error,
    },
}

fn io_err(path: &Path) -> impl FnOnce(std::io::Error) -> LockError + '_ {
    move |source| LockError::Io {
        path: path.to_path_buf(),
        source,
    }
}

fn now_unix() -> f64 {
    SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map(|d| d.as_secs_f64())
        .unwrap_or(0.0)
}

fn read_trimmed(path: &str) -> String {
    std::fs::read_to_string(path)
        .map(|s| s.trim().to_string())
        .unwrap_or_default()
}

/// This machine's host name (from the kernel, else `$HOSTNAME`, else `unknown-host`).
pub fn host_name() -> String {
    let h = read_trimmed("/proc/sys/kernel/hostname");
    if !h.is_empty() {
        return h;
    }
    std::env::var("HOSTNAME")
        .ok()
        .filter(|h| !h.trim().is_empty())
        .unwrap_or_else(|| "unknown-host".into())
}

fn boot_id() -> String {
    read_trimmed("/proc/sys/kernel/random/boot_id")
}

fn pid_namespace() -> String {
    std::fs::read_link("/proc/self/ns/pid")
        .map(|p| p.display().to_string())
        .unwrap_or_default()
}

/// Start time of process `pid` in clock ticks since boot (`/proc/PID/stat` field 22).
fn process_start(pid: u32) -> Option<u64> {
    let stat = std::fs::read_to_string(format!("/proc/{pid}/stat")).ok()?;
    let rest = &stat[stat.rfind(')')? + 1..];
    rest.split_whitespace().nth(19)?.parse().ok()
}

/// Formats Unix seconds as `YYYY-MM-DD HH:MM:SS UTC`.
pub fn format_utc(unix: f64) -> String {
    // Beyond 9999-12-31: no calendar date worth printing (a broken clock or a forged record).
    if !unix.is_finite() || !(0.0..253_402_300_800.0).contains(&unix) {
        return "an unknown time".into();
    }
    let secs = unix as i64;
    let (days, rem) = (secs.div_euclid(86_400), secs.rem_euclid(86_400));
    // Civil date from days since 1970-01-01 (H. Hinnant's algorithm).
    let z = days + 719_468;
    let era = z.div_euclid(146_097);
    let doe = z - era * 146_097;
    let yoe = (doe - doe / 1460 + doe / 36_524 - doe / 146_096) / 365;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let d = doy - (153 * mp + 2) / 5 + 1;
    let m = if mp < 10 { mp + 3 } else { mp - 9 };
    let y = yoe + era * 400 + i64::from(m <= 2);
    format!(
        "{y:04}-{m:02}-{d:02} {:02}:{:02}:{:02} UTC",
        rem / 3600,
        rem % 3600 / 60,
        rem % 60
    )
}

/// What was found in an existing lock file.
#[derive(Clone, Debug)]
struct Seen {
    raw: Vec<u8>,
    record: Option<LockRecord>,
    mtime: f64,
}

fn read_seen(path: &Path) -> std::io::Result<Seen> {
    let mut f = File::open(path)?;
    let mtime = f
        .metadata()?
        .modified()
        .ok()
        .and_then(|t| t.duration_since(UNIX_EPOCH).ok())
        .map_or(0.0, |d| d.as_secs_f64());
    let mut raw = Vec::new();
    // A lock record is small; anything much larger is not ours (read a bounded prefix).
    Read::by_ref(&mut f)
        .take(4 * RECORD_BYTES as u64)
        .read_to_end(&mut raw)?;
    let record = std::str::from_utf8(&raw)
        .ok()
        .and_then(|t| serde_json::from_str::<LockRecord>(t.trim()).ok());
    Ok(Seen { raw, record, mtime })
}

/// Whether a holder on this host (same boot and pid namespace) is provably gone.
fn holder_is_dead_here(r: &LockRecord, me: &LockRecord) -> bool {
    if r.host != me.host || r.boot_id.is_empty() || r.boot_id != me.boot_id {
        return false;
    }
    if r.pid_ns.is_empty() || r.pid_ns != me.pid_ns {
        return false;
    }
    if r.pid == me.pid {
        // Our own process (another run in this process): alive by definition.
        return false;
    }
    match process_start(r.pid) {
        None => !Path::new(&format!("/proc/{}", r.pid)).exists(),
        Some(start) => r.proc_start != 0 && start != r.proc_start,
    }
}

enum Verdict {
    Live(Seen),
    Stale(Seen),
    Vanished,
}

/// A held lock. Dropping it stops the heartbeat and removes the lock file (if it is still ours).
#[derive(Debug)]
pub struct RunLock {
    dir: PathBuf,
    path: PathBuf,
    /// Kept open while the lock is held (the heartbeat thread writes through it).
    _file: Arc<File>,
    ino: (u64, u64),
    lost: Arc<AtomicBool>,
    stop: Option<mpsc::Sender<()>>,
    thread: Option<JoinHandle<()>>,
}

impl RunLock {
    /// Takes the lock of run directory `dir` (which must exist), with [`LockSettings::from_env`].
    pub fn acquire(dir: &Path) -> Result<Self, LockError> {
        let settings = LockSettings::from_env()?;
        Self::acquire_with(dir, settings)
    }

    /// Takes the lock of `dir` with explicit settings.
    pub fn acquire_with(dir: &Path, settings: LockSettings) -> Result<Self, LockError> {
        let path = dir.join(LOCK_FILE);
        let me = LockRecord {
            host: host_name(),
            pid: std::process::id(),
            boot_id: boot_id(),
            pid_ns: pid_namespace(),
            proc_start: process_start(std::process::id()).unwrap_or(0),
            since: now_unix(),
            heartbeat: now_unix(),
            interval: settings.heartbeat.as_secs_f64(),
            beat: 0,
            token: format!(
                "{:016x}{:016x}",
                crate::durable::random_u64(),
                crate::durable::random_u64()
            ),
            command: std::env::args().collect::<Vec<_>>().join(" "),
        };
        // A few rounds: each round either creates the lock, finds a live holder, or removes one
        // stale lock (which can only happen once per stale lock).
        let mut blocked_by: Option<PathBuf> = None;
        for _ in 0..8 {
            match create_registered(&path) {
                Ok((file, ino)) => {
                    return Self::hold(dir, path.clone(), file, ino, me, settings).inspect_err(
                        |_| {
                            // Not held after all: neither registered nor left behind.
                            let mut held = held_locks();
                            held.retain(|(p, i)| !(p == &path && *i == ino));
                            if owns(&path, ino) {
                                let _ = std::fs::remove_file(&path);
                            }
                        },
                    );
                }
                Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => {}
                Err(e) => return Err(io_err(&path)(e)),
            }
            match assess(&path, &me, settings)? {
                Verdict::Vanished => continue,
                Verdict::Live(seen) => return Err(held_error(dir, &path, &seen, settings)),
                Verdict::Stale(seen) => blocked_by = take_over(dir, &path, &seen)?,
            }
        }
        Err(LockError::Busy {
            dir: dir.to_path_buf(),
            path: path.clone(),
            detail: match blocked_by {
                Some(marker) => format!(
                    "it is stale, but another process's take-over of it is in progress or was \
                     interrupted ({}); if no process works in this directory, remove both files",
                    marker.display()
                )
                .into(),
                None => "it keeps changing hands between other processes".into(),
            },
        })
    }

    fn hold(
        dir: &Path,
        path: PathBuf,
        file: File,
        ino: (u64, u64),
        mut me: LockRecord,
        settings: LockSettings,
    ) -> Result<Self, LockError> {
        write_record(&file, &me).map_err(io_err(&path))?;
        let _ = crate::durable::sync_dir(dir);
        let file = Arc::new(file);
        let lost = Arc::new(AtomicBool::new(false));
        let (stop, stopped) = mpsc::channel::<()>();
        let thread = {
            let (file, lost, beat_path) = (Arc::clone(&file), Arc::clone(&lost), path.clone());
            std::thread::Builder::new()
                .name("run-lock-heartbeat".into())
                .spawn(move || {
                    while let Err(mpsc::RecvTimeoutError::Timeout) =
                        stopped.recv_timeout(settings.heartbeat)
                    {
                        me.beat += 1;
                        me.heartbeat = now_unix();
                        if !owns(&beat_path, ino) {
                            lost.store(true, Ordering::SeqCst);
                            return;
                        }
                        // A failed heartbeat write is retried next time; staleness needs many.
                        let _ = write_record(&file, &me);
                    }
                })
                .map_err(io_err(&path))?
        };
        Ok(Self {
            dir: dir.to_path_buf(),
            path,
            _file: file,
            ino,
            lost,
            stop: Some(stop),
            thread: Some(thread),
        })
    }

    /// The lock file.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// An error when the lock is no longer ours (another process took it over, e.g. after this
    /// process was suspended longer than the staleness limit): the run must stop writing.
    pub fn ensure_held(&self) -> Result<(), LockError> {
        if self.lost.load(Ordering::SeqCst) || !owns(&self.path, self.ino) {
            self.lost.store(true, Ordering::SeqCst);
            let holder = read_seen(&self.path)
                .ok()
                .and_then(|s| s.record)
                .map(|r| format!(" (now held by pid {} on host {})", r.pid, r.host));
            return Err(LockError::Lost {
                dir: self.dir.clone(),
                holder,
            });
        }
        Ok(())
    }
}

impl Drop for RunLock {
    fn drop(&mut self) {
        drop(self.stop.take());
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
        let mut held = held_locks();
        held.retain(|(p, ino)| !(p == &self.path && *ino == self.ino));
        if !self.lost.load(Ordering::SeqCst) && owns(&self.path, self.ino) {
            let _ = std::fs::remove_file(&self.path);
            let _ = crate::durable::sync_dir(&self.dir);
        }
    }
}

/// Creates the lock file exclusively and registers it as held in one step under the registry's
/// mutex, so [`release_all_before_exit`] (which takes the mutex) never misses a lock file this
/// process has created.
fn create_registered(path: &Path) -> std::io::Result<(File, (u64, u64))> {
    let mut held = held_locks();
    let file = std::fs::OpenOptions::new()
        .write(true)
        .create_new(true)
        .open(path)?;
    let meta = match file.metadata() {
        Ok(m) => m,
        Err(e) => {
            let _ = std::fs::remove_file(path);
            return Err(e);
        }
    };
    let ino = (meta.dev(), meta.ino());
    held.push((path.to_path_buf(), ino));
    Ok((file, ino))
}

/// The locks this process holds (path, device and inode), for [`release_all_before_exit`].
fn held_locks() -> std::sync::MutexGuard<'static, Vec<(PathBuf, (u64, u64))>> {
    static HELD: std::sync::Mutex<Vec<(PathBuf, (u64, u64))>> = std::sync::Mutex::new(Vec::new());
    HELD.lock()
        .unwrap_or_else(std::sync::PoisonError::into_inner)
}

/// Removes every lock file this process still holds (and still owns), for a process that is about
/// to exit without unwinding (`std::process::exit` after a second SIGINT): the [`RunLock`] values
/// are never dropped then, and their locks would otherwise be left for a take-over. Returns the
/// run directories released. After this call the locks' [`RunLock::ensure_held`] fail, so a run
/// still going writes nothing more, and the registry stays locked for the rest of the process: a
/// thread about to take a lock waits (forever; the caller exits at once), so no lock file can
/// appear between this call and the exit.
pub fn release_all_before_exit() -> Vec<PathBuf> {
    let held = held_locks();
    let mut released = Vec::new();
    for (path, ino) in held.iter() {
        if owns(path, *ino) && std::fs::remove_file(path).is_ok() {
            let dir = path.parent().unwrap_or(Path::new(".")).to_path_buf();
            let _ = crate::durable::sync_dir(&dir);
            released.push(dir);
        }
    }
    // Keep the registry locked until the exit.
    std::mem::forget(held);
    released
}

fn owns(path: &Path, ino: (u64, u64)) -> bool {
    std::fs::metadata(path).is_ok_and(|m| (m.dev(), m.ino()) == ino)
}

fn write_record(file: &File, r: &LockRecord) -> std::io::Result<()> {
    let mut text = serde_json::to_string(r).map_err(std::io::Error::other)?;
    if text.len() + 1 > RECORD_BYTES {
        // An enormous command line: keep the record within one write.
        let mut short = r.clone();
        short.command = String::new();
        text = serde_json::to_string(&short).map_err(std::io::Error::other)?;
    }
    let mut bytes = text.into_bytes();
    bytes.resize(RECORD_BYTES - 1, b' ');
    bytes.push(b'\n');
    file.write_all_at(&bytes, 0)?;
    file.sync_data()
}

fn assess(path: &Path, me: &LockRecord, settings: LockSettings) -> Result<Verdict, LockError> {
    let seen = match read_seen(path) {
        Ok(s) => s,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(Verdict::Vanished),
        Err(e) => return Err(io_err(path)(e)),
    };
    if let Some(r) = &seen.record
        && holder_is_dead_here(r, me)
    {
        return Ok(Verdict::Stale(seen));
    }
    let stale = settings.stale_after.as_secs_f64();
    let interval = seen
        .record
        .as_ref()
        .map(|r| r.interval)
        .filter(|i| i.is_finite())
        .unwrap_or(settings.heartbeat.as_secs_f64())
        .clamp(0.01, stale / 2.0);
    let margin = (stale / 4.0).min(1.0);
    // Watching two of the holder's heartbeats confirms a silence the clocks suggest.
    let confirm = Duration::from_secs_f64(2.0 * interval + margin);
    let watch = match silence(&seen, now_unix(), stale) {
        Silence::Recent => return Ok(Verdict::Live(seen)),
        Silence::Long => confirm,
        // No clock can be trusted (the holder's and the file server's are both ahead of ours):
        // the lock is stale only if the file does not change for the whole limit by our clock.
        Silence::Unknown => settings.stale_after.max(confirm),
    };
    observe(path, seen, watch, interval)
}

/// What the clocks say about how long a lock's holder has been silent.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Silence {
    /// It wrote within the limit.
    Recent,
    /// Its last write is older than the limit.
    Long,
    /// Neither the recorded heartbeat nor the file's mtime is a usable time.
    Unknown,
}

/// How long the holder of `seen` has been silent at `now` (Unix seconds, our clock), judged by the
/// recorded heartbeat (the holder's clock) or — when there is no readable record, or its heartbeat
/// lies more than `stale` seconds in our future or is not a number — by the file's mtime (the file
/// server's clock; it is set by the holder's last write, so a holder whose own clock is ahead, by
/// a day or by 1e300 s, still ages). A time at most `stale` seconds in our future counts as recent
/// (ordinary skew); one further ahead is not evidence of anything.
fn silence(seen: &Seen, now: f64, stale: f64) -> Silence {
    let judge = |t: f64| {
        let age = now - t;
        if !age.is_finite() || age < -stale {
            None
        } else if age <= stale {
            Some(Silence::Recent)
        } else {
            Some(Silence::Long)
        }
    };
    seen.record
        .as_ref()
        .and_then(|r| judge(r.heartbeat))
        .or_else(|| judge(seen.mtime))
        .unwrap_or(Silence::Unknown)
}

/// Watches the lock file for `window`: stale if it stays byte-for-byte `seen`, live if it changes.
fn observe(path: &Path, seen: Seen, window: Duration, interval: f64) -> Result<Verdict, LockError> {
    let step = Duration::from_secs_f64((interval / 2.0).clamp(0.01, 1.0));
    let start = std::time::Instant::now();
    while start.elapsed() < window {
        std::thread::sleep(step);
        match read_seen(path) {
            Ok(now) if now.raw != seen.raw => return Ok(Verdict::Live(now)),
            Ok(_) => {}
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(Verdict::Vanished),
            Err(e) => return Err(io_err(path)(e)),
        }
    }
    Ok(Verdict::Stale(seen))
}

fn held_error(dir: &Path, path: &Path, seen: &Seen, settings: LockSettings) -> LockError {
    match &seen.record {
        Some(r) => {
            let age = now_unix() - r.heartbeat;
            LockError::Held {
                dir: dir.to_path_buf(),
                holder: Box::new(Holder {
                    host: r.host.clone(),
                    pid: r.pid,
                    since: format_utc(r.since),
                    age: if age.is_finite() && age >= 0.0 {
                        format!("{age:.0} s ago")
                    } else {
                        "in the future by this host's clock: the holder's clock is ahead".into()
                    },
                    command: r.command.clone(),
                    stale_secs: settings.stale_after.as_secs_f64(),
                }),
            }
        }
        None => LockError::Busy {
            dir: dir.to_path_buf(),
            path: path.to_path_buf(),
            detail: "its holder is still writing it, or it is not a stylize lock".into(),
        },
    }
}

/// Removes one stale lock (see the module documentation). Returns `Ok` when the caller should try
/// to create the lock again (whether or not this call removed it), with the take-over marker of
/// another process when that blocked this call.
fn take_over(dir: &Path, path: &Path, seen: &Seen) -> Result<Option<PathBuf>, LockError> {
    let token = match &seen.record {
        Some(r) if !r.token.is_empty() && r.token.chars().all(|c| c.is_ascii_alphanumeric()) => {
            r.token.clone()
        }
        _ => {
            use sha2::Digest;
            let mut h = sha2::Sha256::new();
            h.update(&seen.raw);
            h.update(seen.mtime.to_le_bytes());
            h.finalize()
                .iter()
                .take(16)
                .map(|b| format!("{b:02x}"))
                .collect()
        }
    };
    let marker = dir.join(format!("{TAKEOVER_PREFIX}{token}"));
    let mut m = match std::fs::OpenOptions::new()
        .write(true)
        .create_new(true)
        .open(&marker)
    {
        Ok(m) => m,
        Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => {
            // Another process is taking over this very lock right now: let it finish, then look
            // again (its new lock will be live).
            std::thread::sleep(Duration::from_millis(200));
            return Ok(Some(marker));
        }
        Err(e) => return Err(io_err(&marker)(e)),
    };
    let _ = writeln!(m, "{} {}", host_name(), std::process::id());
    let result = (|| {
        match read_seen(path) {
            Ok(now) if now.raw == seen.raw => {}
            // Released or replaced meanwhile: nothing to take over.
            Ok(_) => return Ok(()),
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(()),
            Err(e) => return Err(io_err(path)(e)),
        }
        let stale = dir.join(format!("{STALE_PREFIX}{token}"));
        match std::fs::rename(path, &stale) {
            Ok(()) => {
                let _ = std::fs::remove_file(&stale);
                Ok(())
            }
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => Ok(()),
            Err(e) => Err(io_err(path)(e)),
        }
    })();
    drop(m);
    let _ = std::fs::remove_file(&marker);
    let _ = crate::durable::sync_dir(dir);
    result.map(|()| None)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn fast() -> LockSettings {
        LockSettings {
            heartbeat: Duration::from_millis(50),
            stale_after: Duration::from_millis(400),
        }
    }

    fn ok<T, E: std::fmt::Debug>(r: Result<T, E>) -> T {
        r.unwrap_or_else(|e| panic!("{e:?}"))
    }

    #[test]
    fn second_acquire_fails_naming_the_holder_and_drop_releases() {
        let dir = ok(tempfile::tempdir());
        let lock = ok(RunLock::acquire_with(dir.path(), fast()));
        let e = RunLock::acquire_with(dir.path(), fast())
            .err()
            .map(|e| e.to_string())
            .unwrap_or_default();
        assert!(
            e.contains(&format!("pid {}", std::process::id())) && e.contains(&host_name()),
            "{e}"
        );
        ok(lock.ensure_held());
        drop(lock);
        assert!(!dir.path().join(LOCK_FILE).exists());
        let again = ok(RunLock::acquire_with(dir.path(), fast()));
        drop(again);
    }

    #[test]
    fn heartbeat_keeps_a_lock_live_past_the_staleness_limit() {
        let dir = ok(tempfile::tempdir());
        let lock = ok(RunLock::acquire_with(dir.path(), fast()));
        std::thread::sleep(Duration::from_millis(700));
        assert!(RunLock::acquire_with(dir.path(), fast()).is_err());
        let seen = ok(read_seen(&dir.path().join(LOCK_FILE)));
        assert!(seen.record.is_some_and(|r| r.beat > 3));
        drop(lock);
    }

    fn write_foreign(dir: &Path, record: &LockRecord) {
        let f = ok(std::fs::OpenOptions::new()
            .write(true)
            .create_new(true)
            .open(dir.join(LOCK_FILE)));
        ok(write_record(&f, record));
    }

    fn foreign(host: &str, heartbeat_age: f64) -> LockRecord {
        LockRecord {
            host: host.into(),
            pid: 4_000_000,
            boot_id: "other-boot".into(),
            pid_ns: String::new(),
            proc_start: 0,
            since: now_unix() - 1000.0,
            heartbeat: now_unix() - heartbeat_age,
            interval: 0.05,
            beat: 7,
            token: "abc123".into(),
            command: "stylize run x".into(),
        }
    }

    #[test]
    fn stale_lock_of_a_silent_remote_holder_is_taken_over() {
        let dir = ok(tempfile::tempdir());
        write_foreign(dir.path(), &foreign("node-17", 10.0));
        let lock = ok(RunLock::acquire_with(dir.path(), fast()));
        let seen = ok(read_seen(&dir.path().join(LOCK_FILE)));
        assert_eq!(seen.record.map(|r| r.pid), Some(std::process::id()));
        let leftovers: Vec<String> = ok(std::fs::read_dir(dir.path()))
            .filter_map(|e| e.ok())
            .map(|e| e.file_name().to_string_lossy().into_owned())
            .collect();
        assert_eq!(leftovers, vec![LOCK_FILE.to_string()]);
        drop(lock);
    }

    #[test]
    fn fresh_remote_lock_is_respected_and_a_changing_one_is_live_despite_clock_skew() {
        let dir = ok(tempfile::tempdir());
        write_foreign(dir.path(), &foreign("node-17", 0.0));
        let e = RunLock::acquire_with(dir.path(), fast())
            .err()
            .map(|e| e.to_string())
            .unwrap_or_default();
        assert!(e.contains("node-17") && e.contains("4000000"), "{e}");
        // A holder whose clock is 1000 s behind but whose heartbeat keeps changing the file.
        ok(std::fs::remove_file(dir.path().join(LOCK_FILE)));
        write_foreign(dir.path(), &foreign("node-18", 1000.0));
        let path = dir.path().join(LOCK_FILE);
        let writer = std::thread::spawn(move || {
            let f = ok(std::fs::OpenOptions::new().write(true).open(&path));
            let mut r = foreign("node-18", 1000.0);
            for _ in 0..40 {
                r.beat += 1;
                let _ = write_record(&f, &r);
                std::thread::sleep(Duration::from_millis(25));
            }
        });
        let e = RunLock::acquire_with(dir.path(), fast())
            .err()
            .map(|e| e.to_string())
            .unwrap_or_default();
        assert!(e.contains("node-18"), "{e}");
        ok(writer.join().map_err(|_| "writer panicked"));
    }

    #[test]
    fn concurrent_takeovers_of_one_stale_lock_leave_exactly_one_holder() {
        let dir = ok(tempfile::tempdir());
        write_foreign(dir.path(), &foreign("node-17", 10.0));
        let root = dir.path().to_path_buf();
        let handles: Vec<_> = (0..6)
            .map(|_| {
                let root = root.clone();
                std::thread::spawn(move || {
                    RunLock::acquire_with(&root, fast()).map(|l| {
                        // Hold it long enough for every contender to finish trying.
                        std::thread::sleep(Duration::from_millis(1500));
                        drop(l);
                    })
                })
            })
            .collect();
        let winners = handles
            .into_iter()
            .filter_map(|h| h.join().ok())
            .filter(Result::is_ok)
            .count();
        assert_eq!(winners, 1);
    }

    #[test]
    fn an_interrupted_takeover_is_reported_with_its_marker() {
        let dir = ok(tempfile::tempdir());
        let record = foreign("node-17", 10.0);
        write_foreign(dir.path(), &record);
        let marker = dir
            .path()
            .join(format!("{TAKEOVER_PREFIX}{}", record.token));
        ok(std::fs::write(&marker, "node-3 12\n"));
        let settings = LockSettings {
            heartbeat: Duration::from_millis(10),
            stale_after: Duration::from_millis(30),
        };
        let e = RunLock::acquire_with(dir.path(), settings)
            .err()
            .map(|e| e.to_string())
            .unwrap_or_default();
        assert!(
            e.contains("take-over") && e.contains(TAKEOVER_PREFIX),
            "{e}"
        );
    }

    /// A foreign lock whose heartbeat is `ahead` seconds in our future and whose file was last
    /// written `mtime_age` seconds ago (negative: in our future too).
    fn ahead(dir: &Path, heartbeat_ahead: f64, mtime_age: f64) {
        let mut r = foreign("node-17", 0.0);
        r.heartbeat = now_unix() + heartbeat_ahead;
        r.since = r.heartbeat;
        write_foreign(dir, &r);
        let f = ok(File::options().write(true).open(dir.join(LOCK_FILE)));
        let t = if mtime_age >= 0.0 {
            SystemTime::now() - Duration::from_secs_f64(mtime_age)
        } else {
            SystemTime::now() + Duration::from_secs_f64(-mtime_age)
        };
        ok(f.set_modified(t));
    }

    #[test]
    fn a_dead_holder_whose_clock_was_ahead_is_taken_over_by_the_file_age() {
        for heartbeat_ahead in [86_400.0, 1e300, 1e18] {
            let dir = ok(tempfile::tempdir());
            ahead(dir.path(), heartbeat_ahead, 10.0);
            let start = std::time::Instant::now();
            let lock = RunLock::acquire_with(dir.path(), fast())
                .unwrap_or_else(|e| panic!("heartbeat +{heartbeat_ahead}: {e}"));
            // The short confirmation window (two of the holder's 50 ms beats and a margin).
            assert!(
                start.elapsed() < Duration::from_secs(2),
                "{heartbeat_ahead}"
            );
            let seen = ok(read_seen(&dir.path().join(LOCK_FILE)));
            assert_eq!(seen.record.map(|r| r.pid), Some(std::process::id()));
            drop(lock);
        }
    }

    #[test]
    fn a_dead_holder_with_every_clock_ahead_is_taken_over_after_the_limit_unchanged() {
        let dir = ok(tempfile::tempdir());
        ahead(dir.path(), 1e300, -86_400.0);
        let start = std::time::Instant::now();
        let lock = ok(RunLock::acquire_with(dir.path(), fast()));
        // Watched unchanged for the whole limit (400 ms) by our monotonic clock, not less.
        assert!(
            start.elapsed() >= fast().stale_after,
            "{:?}",
            start.elapsed()
        );
        drop(lock);
    }

    #[test]
    fn a_live_holder_whose_clock_is_a_day_ahead_keeps_its_lock() {
        let dir = ok(tempfile::tempdir());
        // The file looks as old as can be, but the holder keeps writing it.
        ahead(dir.path(), 86_400.0, 10.0);
        let path = dir.path().join(LOCK_FILE);
        let writer = std::thread::spawn(move || {
            let f = ok(std::fs::OpenOptions::new().write(true).open(&path));
            let mut r = foreign("node-17", -86_400.0);
            for _ in 0..60 {
                r.beat += 1;
                let _ = write_record(&f, &r);
                std::thread::sleep(Duration::from_millis(25));
            }
        });
        for _ in 0..3 {
            let e = RunLock::acquire_with(dir.path(), fast())
                .err()
                .map(|e| e.to_string())
                .unwrap_or_default();
            assert!(e.contains("node-17") && e.contains("ahead"), "{e}");
        }
        ok(writer.join().map_err(|_| "writer panicked"));
    }

    #[test]
    fn silence_is_judged_by_a_usable_clock() {
        let seen = |heartbeat: Option<f64>, mtime: f64| Seen {
            raw: Vec::new(),
            record: heartbeat.map(|h| {
                let mut r = foreign("n", 0.0);
                r.heartbeat = h;
                r
            }),
            mtime,
        };
        let now = 1e9;
        let s = 60.0;
        assert_eq!(
            silence(&seen(Some(now - 10.0), 0.0), now, s),
            Silence::Recent
        );
        assert_eq!(silence(&seen(Some(now - 61.0), now), now, s), Silence::Long);
        // Ordinary skew: a little ahead is recent.
        assert_eq!(
            silence(&seen(Some(now + 30.0), 0.0), now, s),
            Silence::Recent
        );
        // Far ahead: the mtime decides.
        assert_eq!(
            silence(&seen(Some(now + 1e5), now - 100.0), now, s),
            Silence::Long
        );
        assert_eq!(
            silence(&seen(Some(1e300), now - 5.0), now, s),
            Silence::Recent
        );
        assert_eq!(
            silence(&seen(Some(f64::MAX), now + 1e6), now, s),
            Silence::Unknown
        );
        // No record: the mtime.
        assert_eq!(silence(&seen(None, now - 100.0), now, s), Silence::Long);
        assert_eq!(
            silence(&seen(None, f64::INFINITY), now, s),
            Silence::Unknown
        );
    }

    #[test]
    fn utc_formatting() {
        assert_eq!(format_utc(1e300), "an unknown time");
        assert_eq!(format_utc(0.0), "1970-01-01 00:00:00 UTC");
        assert_eq!(format_utc(1_709_210_096.0), "2024-02-29 12:34:56 UTC");
    }
}

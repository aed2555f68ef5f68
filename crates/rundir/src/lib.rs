//! Run directories that survive crashes, kills and clusters: a folder that one process at a time
//! fills with a run's files, each replaced atomically and durably, and that a later process can
//! continue from its last checkpoint — or refuses, saying why.
//!
//! What it guarantees:
//! - [`lock`]: one process per run directory. `run.lock` is created with `O_CREAT | O_EXCL`,
//!   holds the holder's record, gets a heartbeat from a background thread, and a stale lock (its
//!   process gone on this host, or its heartbeat old and unchanging) is taken over race-free
//!   among any number of contenders; a run that lost its lock stops without writing.
//! - [`durable`]: every file is replaced atomically and durably — unique temporary file, `fsync`,
//!   rename over the target, `fsync` of the folder — so a crash leaves the old file or the new,
//!   never a mix.
//! - [`RunDir`]: the claim of a folder for a run ([`RunDir::claim`]): outputs never replace
//!   inputs, a foreign folder is refused unless `--force` (which removes only the run's own
//!   files), the lock is taken before anything is read or changed, and an existing run is
//!   resumed only when its recorded [`TaskIdentity`] equals the new one.
//! - [`checkpoint`]: the checkpoint container — layout version, last finished iteration and
//!   task identity around the caller's own state, written durably; older layouts still load.
//!
//! The task identity is an opaque record ([`TaskIdentity`], field name → value text) that the
//! caller computes; this crate compares and stores it, and never looks inside. It knows nothing of
//! meshes, optimizers or models (`cargo xtask check-deps` keeps it so).

pub mod checkpoint;
pub mod durable;
pub mod error;
pub mod identity;
pub mod lock;
mod run_dir;

pub use checkpoint::{CHECKPOINT_VERSION, Checkpoint, OLDEST_CHECKPOINT_VERSION};
pub use error::{Error, Result};
pub use identity::TaskIdentity;
pub use lock::{LockError, RunLock};
pub use run_dir::{
    Claim, Existing, RUN_FILES, ResumeMode, RunDir, Start, is_own_entry, is_preview_name,
    refuse_overwriting_inputs,
};

//! Adam with the reference semantics and the schedule grammar of the method spec (§5).
//!
//! - [`Adam`]: β1 0.9, β2 0.999, ε 1e-8, no weight decay, bias correction by step count — PyTorch's
//!   `torch.optim.Adam` defaults, as the reference uses them. The parameter is a flat `f64` slice
//!   (the loop passes the `V×3` target field row-major). The state ([`AdamState`]) is plain data and
//!   `serde`-serializable so checkpoints can restore it exactly.
//! - [`Schedule`]: the piecewise-linear weight schedule grammar (`"0.0>0.2:1000; 0.2>0.3:750"`),
//!   evaluated at **1-indexed** iterations.
//!
//! This crate depends on nothing heavy on purpose (see `docs/architecture.md`).

mod adam;
mod schedule;

pub use adam::{Adam, AdamConfig, AdamError, AdamState};
pub use schedule::{Phase, Schedule, ScheduleError};

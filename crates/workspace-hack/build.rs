//! Empty: its presence is what makes Cargo resolve this crate's `[build-dependencies]` (the
//! host-side features it pins; see src/lib.rs).
fn main() {}

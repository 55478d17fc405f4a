//! Helpers shared by the integration tests, included with `mod common;`: a
//! folder rather than `tests/common_*.rs` files, which cargo would build as
//! test crates of their own with no tests in them. (The fake run folder,
//! `tests/common_runs.rs`, is still a file of its own: the gate's unit tests
//! include it by path.)

pub mod cli;
pub mod gate;
pub mod scenes;
pub mod trials;

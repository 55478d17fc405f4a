//! Helpers shared by the integration tests, included with `mod common;`: a
//! folder rather than `tests/common_*.rs` files, which cargo would build as
//! test crates of their own with no tests in them. (The gate's unit tests
//! include the fake run folder, `runs.rs`, by path as well.)

pub mod cli;
pub mod gate;
pub mod runs;
pub mod scenes;
pub mod trials;

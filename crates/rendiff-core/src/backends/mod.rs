//! In-process external backends (called from Rust): Embree through its C API.

pub mod embree;

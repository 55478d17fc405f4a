//! rendiff: a differential-testing harness for renderers.
//!
//! The renderer core lives in the `rendiff-core` crate (re-exported here
//! under the same module names, so `rendiff::raster` and `rendiff::trace`
//! are the core's loops); this crate is the tool around it: the command line,
//! [`check`] (every backend on every scene, external processes), [`report`],
//! [`gate`] and the benchmarks ([`bench`]). See ARCHITECTURE.md for who owns
//! what.

pub use rendiff_core::{
    backends, camera, deadline, exr_io, frame, loop_cost, names, pending, predicate, raster,
    render, scene, shade, trace, visibility, vocab,
};

/// `println!` that never panics: with stdout a closed pipe (`rendiff scenes |
/// head -1`, `rendiff check ... | head -c1`) `println!` panicked, exit 101,
/// even after a check's run was published. Lines for a reader that has left
/// are dropped; the command's own result and exit code stand.
#[macro_export]
macro_rules! outln {
    ($($arg:tt)*) => {{
        use std::io::Write as _;
        let _ = writeln!(std::io::stdout(), $($arg)*);
    }};
}

/// [`outln!`] without the newline.
#[macro_export]
macro_rules! out {
    ($($arg:tt)*) => {{
        use std::io::Write as _;
        let _ = write!(std::io::stdout(), $($arg)*);
    }};
}

/// `eprintln!` that never panics on a closed stderr (see [`outln!`]).
#[macro_export]
macro_rules! errln {
    ($($arg:tt)*) => {{
        use std::io::Write as _;
        let _ = writeln!(std::io::stderr(), $($arg)*);
    }};
}

pub mod args;
pub mod check;
pub mod diff;
pub mod doctor;
pub mod fuzz;
pub mod gate;
pub mod preview;
pub mod progress;
pub mod report;
pub mod shutdown;

/// Depth comparison statistics (the `diff` command and tests).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct DepthStats {
    /// Pixels whose f32 bits differ (NaN/inf included).
    pub bit_differences: usize,
    /// Pixels where one side is a hit (finite) and the other is not.
    pub mask_mismatches: usize,
    /// Pixels where both sides hit.
    pub common_hits: usize,
    /// Largest absolute difference over common hits.
    pub max_abs: f64,
    /// Largest relative difference over common hits.
    pub max_rel: f64,
    /// Mean absolute difference over common hits.
    pub mean_abs: f64,
}

/// Compares two depth buffers: exact bits, hit/miss masks, and error statistics.
pub fn compare_depth(a: &[f32], b: &[f32]) -> DepthStats {
    let mut s = DepthStats::default();
    let mut sum = 0.0;
    for (&x, &y) in a.iter().zip(b) {
        if x.to_bits() != y.to_bits() {
            s.bit_differences += 1;
        }
        match (x.is_finite(), y.is_finite()) {
            (true, true) => {
                let d = (f64::from(x) - f64::from(y)).abs();
                s.common_hits += 1;
                sum += d;
                s.max_abs = s.max_abs.max(d);
                let m = f64::from(x.abs().max(y.abs()));
                if m > 0.0 {
                    s.max_rel = s.max_rel.max(d / m);
                }
            }
            (false, false) => {}
            _ => s.mask_mismatches += 1,
        }
    }
    if s.common_hits > 0 {
        s.mean_abs = sum / s.common_hits as f64;
    }
    s
}

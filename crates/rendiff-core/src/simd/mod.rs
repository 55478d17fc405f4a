//! The one home of SIMD: which instruction sets the running CPU has, and
//! every intrinsic the raster and the tracer use.
//!
//! A capability is a zero-sized token per instruction set ([`Portable`] for
//! none, [`Avx2`], [`Avx512`]) that only [`Avx2::detect`] and
//! [`Avx512::detect`] make (the wide ones), from
//! one detection per process; holding one is the proof that its
//! intrinsics may run, so the kernels' traits can take it by value and
//! stay safe to call. The kernels are written against traits whose
//! [`Portable`] forms (beside each kernel) are the definitions; the intrinsic forms live here only, each `unsafe`
//! block with the reason it is sound, and tests hold each to its
//! definition bit for bit:
//!
//! - [`Lanes`]: `N` f64 lanes, width-generic (four in plain Rust or AVX2,
//!   eight in AVX-512), for the raster's triangle boxes and the tracer's
//!   per-leaf camera set-up (`trace::lazy`, four triangles at a time);
//! - `chunks`: the raster's 8-pixel chunk operations
//!   ([`crate::raster::edges::ChunkOps`]) in AVX2;
//! - [`RowLanes`]: `N` f32 lanes, width-generic (a row of eight in AVX2,
//!   a pair of rows, sixteen, in AVX-512), for the packet tracer's row
//!   tests (`trace::rows`);
//! - `enter_pair`: the shading rays' test of both boxes of a node in SSE2
//!   (the x86-64 baseline, so no token), for `trace::general`.
//!
//! No closure and no array `map` wraps an intrinsic here: one that the
//! compiler left out of line ran without the kernel's target features, each
//! intrinsic a call, and the raster's time on `million` doubled
//! (ARCHITECTURE.md, "Why the kernels look the way they do";
//! `scripts/check-kernels.sh` checks the release binary and
//! `tests/invariants.rs` the source).

#[cfg(target_arch = "x86_64")]
mod chunks;
mod lanes;
#[cfg(target_arch = "x86_64")]
mod pair;
mod rows;

#[cfg(target_arch = "x86_64")]
pub(crate) use pair::enter_pair;

pub use lanes::{load_tris, Lanes};
pub use rows::RowLanes;

/// No instruction set beyond the baseline: every kernel trait's plain Rust
/// form, which is its definition (the token every CPU has).
#[derive(Debug, Clone, Copy)]
pub struct Portable;

/// What the one detection found ([`found`]).
#[cfg(target_arch = "x86_64")]
#[derive(Clone, Copy)]
struct Found {
    /// AVX2 and POPCNT.
    avx2: bool,
    /// AVX-512F as well as [`Found::avx2`].
    avx512: bool,
}

/// The CPU's instruction sets, detected on the first call and remembered.
#[cfg(target_arch = "x86_64")]
#[inline]
fn found() -> Found {
    static FOUND: std::sync::OnceLock<Found> = std::sync::OnceLock::new();
    *FOUND.get_or_init(|| {
        let avx2 = std::is_x86_feature_detected!("avx2") && std::is_x86_feature_detected!("popcnt");
        Found {
            avx2,
            avx512: avx2 && std::is_x86_feature_detected!("avx512f"),
        }
    })
}

/// Proof that the running CPU has AVX2 (so AVX) and POPCNT: only
/// [`Avx2::detect`] makes one.
#[cfg(target_arch = "x86_64")]
#[derive(Debug, Clone, Copy)]
pub struct Avx2(());

#[cfg(target_arch = "x86_64")]
impl Avx2 {
    /// The token, when the CPU has AVX2 and POPCNT.
    #[inline]
    pub fn detect() -> Option<Avx2> {
        found().avx2.then_some(Avx2(()))
    }
}

/// Proof that the running CPU has AVX-512F as well as everything [`Avx2`]
/// proves: only [`Avx512::detect`] makes one.
#[cfg(target_arch = "x86_64")]
#[derive(Debug, Clone, Copy)]
pub struct Avx512(());

#[cfg(target_arch = "x86_64")]
impl Avx512 {
    /// The token, when the CPU has AVX-512F, AVX2 and POPCNT.
    #[inline]
    pub fn detect() -> Option<Avx512> {
        found().avx512.then_some(Avx512(()))
    }

    /// The AVX2 token this one implies.
    #[inline(always)]
    pub fn avx2(self) -> Avx2 {
        Avx2(())
    }
}

/// Asks the CPU to start loading the cache line holding `*p` (a hint: no
/// effect on results, and a no-op off x86-64).
#[inline(always)]
pub(crate) fn prefetch<T>(p: &T) {
    #[cfg(target_arch = "x86_64")]
    {
        use std::arch::x86_64::{_mm_prefetch, _MM_HINT_T0};
        // SAFETY: SSE is part of the x86-64 baseline, and a prefetch of a
        // valid reference's address reads nothing the program can observe.
        unsafe { _mm_prefetch::<_MM_HINT_T0>((p as *const T).cast::<i8>()) };
    }
    #[cfg(not(target_arch = "x86_64"))]
    let _ = p;
}

#[cfg(all(test, target_arch = "x86_64"))]
mod tests {
    use super::*;

    /// The tokens follow the CPU's own answer, and AVX-512 implies AVX2.
    #[test]
    fn tokens_match_the_cpu() {
        let avx2 = std::is_x86_feature_detected!("avx2") && std::is_x86_feature_detected!("popcnt");
        assert_eq!(Avx2::detect().is_some(), avx2);
        assert_eq!(
            Avx512::detect().is_some(),
            avx2 && std::is_x86_feature_detected!("avx512f")
        );
        if Avx512::detect().is_some() {
            assert!(Avx2::detect().is_some());
        }
    }
}

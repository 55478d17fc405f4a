//! `N` f32 lanes, width-generic, for the packet tracer's rows
//! (`trace::rows`): each operation is the scalar IEEE one lane by lane, in
//! plain Rust ([`Portable`], any width), AVX2 ([`super::Avx2`], a row of
//! eight) or AVX-512 ([`super::Avx512`], a pair of rows, sixteen). The row
//! tests are written once over this trait, so every width runs the same
//! operations in the same order, and tests hold each instruction set to
//! [`Portable`] bit for bit.

use crate::simd::Portable;

/// `N`-lane f32 arithmetic with comparisons read off as `N` mask bits (bit
/// `j` is lane `j`): one value per instruction set so the packet tracer's
/// row tests are written once for every width (`trace::rows`). No fused
/// operations; `min` and `max` are `a < b ? a : b` and `a > b ? a : b`
/// (`trace::primary::{min, max}`, which is what `vminps`/`vmaxps` compute).
pub trait RowLanes<const N: usize>: Copy {
    /// `N` f32.
    type V: Copy;
    /// Whether the `N` lanes are one machine vector, so that a pair of the
    /// tracer's rows in them costs what one row does (`trace::rows::Rows`).
    const VECTOR: bool;
    /// `v` in every lane.
    fn splat(self, v: f32) -> Self::V;
    /// `lo` in lanes `0..N/2`, `hi` in the others (two boxes side by side).
    fn halves(self, lo: f32, hi: f32) -> Self::V;
    /// The lanes of `a`.
    fn load(self, a: &[f32; N]) -> Self::V;
    /// `a + b`.
    fn add(self, a: Self::V, b: Self::V) -> Self::V;
    /// `a * b`.
    fn mul(self, a: Self::V, b: Self::V) -> Self::V;
    /// `a < b ? a : b`.
    fn min(self, a: Self::V, b: Self::V) -> Self::V;
    /// `a > b ? a : b`.
    fn max(self, a: Self::V, b: Self::V) -> Self::V;
    /// `-a` (the sign bit flipped).
    fn neg(self, a: Self::V) -> Self::V;
    /// `a.abs()` (the sign bit cleared).
    fn abs(self, a: Self::V) -> Self::V;
    /// Bit `j` set where `a > b` (false for NaN).
    fn gt(self, a: Self::V, b: Self::V) -> u32;
    /// Bit `j` set where `a < b` (false for NaN).
    fn lt(self, a: Self::V, b: Self::V) -> u32;
}

/// A lane-by-lane operation in plain Rust (a loop, not an array `map`).
#[inline(always)]
fn zip<const N: usize>(a: [f32; N], b: [f32; N], f: impl Fn(f32, f32) -> f32) -> [f32; N] {
    let mut out = a;
    for (o, b) in out.iter_mut().zip(b) {
        *o = f(*o, b);
    }
    out
}

/// The bits of a lane-by-lane test in plain Rust.
#[inline(always)]
fn bits<const N: usize>(a: [f32; N], b: [f32; N], f: impl Fn(f32, f32) -> bool) -> u32 {
    let mut m = 0;
    for (j, (a, b)) in a.into_iter().zip(b).enumerate() {
        m |= u32::from(f(a, b)) << j;
    }
    m
}

impl<const N: usize> RowLanes<N> for Portable {
    type V = [f32; N];
    const VECTOR: bool = false;
    #[inline(always)]
    fn splat(self, v: f32) -> [f32; N] {
        [v; N]
    }
    #[inline(always)]
    fn halves(self, lo: f32, hi: f32) -> [f32; N] {
        let mut out = [hi; N];
        out[..N / 2].fill(lo);
        out
    }
    #[inline(always)]
    fn load(self, a: &[f32; N]) -> [f32; N] {
        *a
    }
    #[inline(always)]
    fn add(self, a: [f32; N], b: [f32; N]) -> [f32; N] {
        zip(a, b, |a, b| a + b)
    }
    #[inline(always)]
    fn mul(self, a: [f32; N], b: [f32; N]) -> [f32; N] {
        zip(a, b, |a, b| a * b)
    }
    #[inline(always)]
    fn min(self, a: [f32; N], b: [f32; N]) -> [f32; N] {
        zip(a, b, |a, b| if a < b { a } else { b })
    }
    #[inline(always)]
    fn max(self, a: [f32; N], b: [f32; N]) -> [f32; N] {
        zip(a, b, |a, b| if a > b { a } else { b })
    }
    #[inline(always)]
    fn neg(self, a: [f32; N]) -> [f32; N] {
        zip(a, a, |a, _| -a)
    }
    #[inline(always)]
    fn abs(self, a: [f32; N]) -> [f32; N] {
        zip(a, a, |a, _| a.abs())
    }
    #[inline(always)]
    fn gt(self, a: [f32; N], b: [f32; N]) -> u32 {
        bits(a, b, |a, b| a > b)
    }
    #[inline(always)]
    fn lt(self, a: [f32; N], b: [f32; N]) -> u32 {
        bits(a, b, |a, b| a < b)
    }
}

#[cfg(target_arch = "x86_64")]
mod avx2_rows {
    //! [`RowLanes`] over a row of eight lanes in AVX2 intrinsics.
    use super::RowLanes;
    use crate::simd::Avx2;
    use std::arch::x86_64::*;

    // Every `unsafe` below: an `Avx2` exists only on a CPU with AVX2
    // (`Avx2::detect`), and the only memory access is the load of an array
    // borrowed here (its SAFETY line says so).
    impl RowLanes<8> for Avx2 {
        type V = __m256;
        const VECTOR: bool = true;
        #[inline(always)]
        fn splat(self, v: f32) -> __m256 {
            // SAFETY: `self` proves AVX2 (`Avx2::detect`); no memory access.
            unsafe { _mm256_set1_ps(v) }
        }
        #[inline(always)]
        fn halves(self, lo: f32, hi: f32) -> __m256 {
            // SAFETY: `self` proves AVX2 (`Avx2::detect`); no memory access.
            unsafe { _mm256_set_m128(_mm_set1_ps(hi), _mm_set1_ps(lo)) }
        }
        #[inline(always)]
        fn load(self, a: &[f32; 8]) -> __m256 {
            // SAFETY: `self` proves AVX2; the load reads the 8 floats of `a`.
            unsafe { _mm256_loadu_ps(a.as_ptr()) }
        }
        #[inline(always)]
        fn add(self, a: __m256, b: __m256) -> __m256 {
            // SAFETY: `self` proves AVX2 (`Avx2::detect`); no memory access.
            unsafe { _mm256_add_ps(a, b) }
        }
        #[inline(always)]
        fn mul(self, a: __m256, b: __m256) -> __m256 {
            // SAFETY: `self` proves AVX2 (`Avx2::detect`); no memory access.
            unsafe { _mm256_mul_ps(a, b) }
        }
        #[inline(always)]
        fn min(self, a: __m256, b: __m256) -> __m256 {
            // `vminps a, b` is `a < b ? a : b`.
            // SAFETY: `self` proves AVX2 (`Avx2::detect`); no memory access.
            unsafe { _mm256_min_ps(a, b) }
        }
        #[inline(always)]
        fn max(self, a: __m256, b: __m256) -> __m256 {
            // `vmaxps a, b` is `a > b ? a : b`.
            // SAFETY: `self` proves AVX2 (`Avx2::detect`); no memory access.
            unsafe { _mm256_max_ps(a, b) }
        }
        #[inline(always)]
        fn neg(self, a: __m256) -> __m256 {
            // SAFETY: `self` proves AVX2 (`Avx2::detect`); no memory access.
            unsafe { _mm256_xor_ps(a, _mm256_set1_ps(-0.0)) }
        }
        #[inline(always)]
        fn abs(self, a: __m256) -> __m256 {
            // SAFETY: `self` proves AVX2 (`Avx2::detect`); no memory access.
            unsafe { _mm256_andnot_ps(_mm256_set1_ps(-0.0), a) }
        }
        #[inline(always)]
        fn gt(self, a: __m256, b: __m256) -> u32 {
            // SAFETY: `self` proves AVX2 (`Avx2::detect`); no memory access.
            unsafe { _mm256_movemask_ps(_mm256_cmp_ps::<_CMP_GT_OQ>(a, b)) as u32 }
        }
        #[inline(always)]
        fn lt(self, a: __m256, b: __m256) -> u32 {
            // SAFETY: `self` proves AVX2 (`Avx2::detect`); no memory access.
            unsafe { _mm256_movemask_ps(_mm256_cmp_ps::<_CMP_LT_OQ>(a, b)) as u32 }
        }
    }
}

#[cfg(target_arch = "x86_64")]
mod avx512_rows {
    //! [`RowLanes`] over a pair of rows, sixteen lanes, in AVX-512F
    //! intrinsics (negation by an integer xor: `vxorps` on 512 bits needs
    //! AVX-512DQ).
    use super::RowLanes;
    use crate::simd::Avx512;
    use std::arch::x86_64::*;

    // Every `unsafe` below: an `Avx512` exists only on a CPU with AVX-512F
    // (`Avx512::detect`), and the only memory access is the load of an
    // array borrowed here (its SAFETY line says so).
    impl RowLanes<16> for Avx512 {
        type V = __m512;
        const VECTOR: bool = true;
        #[inline(always)]
        fn splat(self, v: f32) -> __m512 {
            // SAFETY: `self` proves AVX-512F (`Avx512::detect`); no memory access.
            unsafe { _mm512_set1_ps(v) }
        }
        #[inline(always)]
        fn halves(self, lo: f32, hi: f32) -> __m512 {
            // SAFETY: `self` proves AVX-512F (`Avx512::detect`); no memory access.
            unsafe { _mm512_mask_blend_ps(0xff00, _mm512_set1_ps(lo), _mm512_set1_ps(hi)) }
        }
        #[inline(always)]
        fn load(self, a: &[f32; 16]) -> __m512 {
            // SAFETY: `self` proves AVX-512F; the load reads the 16 floats of `a`.
            unsafe { _mm512_loadu_ps(a.as_ptr()) }
        }
        #[inline(always)]
        fn add(self, a: __m512, b: __m512) -> __m512 {
            // SAFETY: `self` proves AVX-512F (`Avx512::detect`); no memory access.
            unsafe { _mm512_add_ps(a, b) }
        }
        #[inline(always)]
        fn mul(self, a: __m512, b: __m512) -> __m512 {
            // SAFETY: `self` proves AVX-512F (`Avx512::detect`); no memory access.
            unsafe { _mm512_mul_ps(a, b) }
        }
        #[inline(always)]
        fn min(self, a: __m512, b: __m512) -> __m512 {
            // As AVX2's: `a < b ? a : b` at every width.
            // SAFETY: `self` proves AVX-512F (`Avx512::detect`); no memory access.
            unsafe { _mm512_min_ps(a, b) }
        }
        #[inline(always)]
        fn max(self, a: __m512, b: __m512) -> __m512 {
            // As AVX2's: `a > b ? a : b` at every width.
            // SAFETY: `self` proves AVX-512F (`Avx512::detect`); no memory access.
            unsafe { _mm512_max_ps(a, b) }
        }
        #[inline(always)]
        fn neg(self, a: __m512) -> __m512 {
            // SAFETY: `self` proves AVX-512F (`Avx512::detect`); no memory access.
            unsafe {
                let sign = _mm512_set1_epi32(i32::MIN);
                _mm512_castsi512_ps(_mm512_xor_si512(_mm512_castps_si512(a), sign))
            }
        }
        #[inline(always)]
        fn abs(self, a: __m512) -> __m512 {
            // SAFETY: `self` proves AVX-512F (`Avx512::detect`); no memory access.
            unsafe { _mm512_abs_ps(a) }
        }
        #[inline(always)]
        fn gt(self, a: __m512, b: __m512) -> u32 {
            // SAFETY: `self` proves AVX-512F (`Avx512::detect`); no memory access.
            unsafe { u32::from(_mm512_cmp_ps_mask::<_CMP_GT_OQ>(a, b)) }
        }
        #[inline(always)]
        fn lt(self, a: __m512, b: __m512) -> u32 {
            // SAFETY: `self` proves AVX-512F (`Avx512::detect`); no memory access.
            unsafe { u32::from(_mm512_cmp_ps_mask::<_CMP_LT_OQ>(a, b)) }
        }
    }
}

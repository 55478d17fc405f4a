//! `N` f64 lanes, width-generic: each operation is the scalar IEEE one lane
//! by lane, in plain Rust ([`Portable`]), AVX2 ([`super::Avx2`], four lanes) or
//! AVX-512 ([`super::Avx512`], eight).

use crate::scene::resolve::Tri;
use crate::simd::Portable;

/// `N`-lane f64 arithmetic (the raster's boxes, `BoxMargin::bounds_wide`; the tracer's leaf
/// set-up, `LeafTri::aim_lanes` and `PixelRect::new_lanes`): each operation is
/// the scalar IEEE one lane by lane (no fused operations), in plain Rust
/// ([`Portable`]), AVX2 (`Avx2`, four lanes) or AVX-512 intrinsics (`Avx512`,
/// eight); a test checks each against [`BoxMargin::bounds`]. Lane `j`
/// belongs to triangle `j` of the batch.
pub trait Lanes<const N: usize>: Copy {
    /// `N` f64.
    type V: Copy;
    /// `v` in every lane.
    fn splat(self, v: f64) -> Self::V;
    /// Component `c` of vertex `i` of each triangle, widened to f64.
    fn load(self, t: &[Tri; N], i: usize, c: usize) -> Self::V;
    /// `N` f32 widened to f64 (exact).
    fn widen(self, v: [f32; N]) -> Self::V;
    /// `a + b`.
    fn add(self, a: Self::V, b: Self::V) -> Self::V;
    /// `a - b`.
    fn sub(self, a: Self::V, b: Self::V) -> Self::V;
    /// `a * b`.
    fn mul(self, a: Self::V, b: Self::V) -> Self::V;
    /// `a / b`.
    fn div(self, a: Self::V, b: Self::V) -> Self::V;
    /// `f64::max(a, b)` where neither is NaN (any rule for NaN: lanes that
    /// can meet one are not kept, module documentation).
    fn max(self, a: Self::V, b: Self::V) -> Self::V;
    /// `f64::min(a, b)` where neither is NaN (as `max`).
    fn min(self, a: Self::V, b: Self::V) -> Self::V;
    /// `f64::abs`.
    fn abs(self, a: Self::V) -> Self::V;
    /// `f64::sqrt` (correctly rounded, as IEEE's square root).
    fn sqrt(self, a: Self::V) -> Self::V;
    /// `f64::ceil`.
    fn ceil(self, a: Self::V) -> Self::V;
    /// `f64::floor`.
    fn floor(self, a: Self::V) -> Self::V;
    /// Bit `j` set where `a >= b` (false for NaN).
    fn ge(self, a: Self::V, b: Self::V) -> u32;
    /// Bit `j` set where `a < b` (false for NaN).
    fn lt(self, a: Self::V, b: Self::V) -> u32;
    /// Bit `j` set where `a > b` (false for NaN).
    fn gt(self, a: Self::V, b: Self::V) -> u32;
    /// The lanes.
    fn array(self, a: Self::V) -> [f64; N];
    /// The lanes rounded to f32 (to nearest, ties to even: `as f32`).
    fn to_f32(self, a: Self::V) -> [f32; N];
    /// `a as u32` for the lanes that hold whole numbers in `[0, 2^31)`; any
    /// value in the others. (A box's ends are such numbers wherever they are
    /// read: clamped to the image, whose side is below 2^31, and a box
    /// whose ends are not, is empty, and its ends are not read. Per lane,
    /// Rust's saturating cast cost three scalar instructions and a spill.)
    fn pixels(self, a: Self::V) -> [u32; N];
    /// `a as i32` for the lanes that hold whole numbers within i32's range;
    /// any value in the others (the rectangle's ends, clamped near the image).
    fn ints(self, a: Self::V) -> [i32; N];
    /// The lanes rounded to f32 (as [`Lanes::to_f32`]), and bit `j` set where
    /// lane `j`'s f32, widened back, is below its f64 (false for NaN): where
    /// rounding went down, so a bound rounds up by one step more.
    fn to_f32_below(self, a: Self::V) -> ([f32; N], u32);
}

/// Every vertex coordinate of `N` triangles widened to f64, loaded once:
/// `[vertex][axis]`. (Nine calls spelled out: as `[0, 1, 2].map(..)` the
/// closure stayed out of line and the leaf set-up took 1.9x as long.)
#[inline(always)]
pub fn load_tris<L: Lanes<N>, const N: usize>(l: L, t: &[Tri; N]) -> [[L::V; 3]; 3] {
    [
        [l.load(t, 0, 0), l.load(t, 0, 1), l.load(t, 0, 2)],
        [l.load(t, 1, 0), l.load(t, 1, 1), l.load(t, 1, 2)],
        [l.load(t, 2, 0), l.load(t, 2, 1), l.load(t, 2, 2)],
    ]
}

/// Bits of a four-lane test.
#[inline(always)]
fn bits4(a: [f64; 4], b: [f64; 4], f: impl Fn(f64, f64) -> bool) -> u32 {
    u32::from(f(a[0], b[0]))
        | u32::from(f(a[1], b[1])) << 1
        | u32::from(f(a[2], b[2])) << 2
        | u32::from(f(a[3], b[3])) << 3
}

/// A four-lane operation.
#[inline(always)]
fn zip4(a: [f64; 4], b: [f64; 4], f: impl Fn(f64, f64) -> f64) -> [f64; 4] {
    [f(a[0], b[0]), f(a[1], b[1]), f(a[2], b[2]), f(a[3], b[3])]
}

impl Lanes<4> for Portable {
    type V = [f64; 4];
    #[inline(always)]
    fn splat(self, v: f64) -> [f64; 4] {
        [v; 4]
    }
    #[inline(always)]
    fn load(self, t: &[Tri; 4], i: usize, c: usize) -> [f64; 4] {
        [t[0][i][c], t[1][i][c], t[2][i][c], t[3][i][c]].map(f64::from)
    }
    #[inline(always)]
    fn widen(self, v: [f32; 4]) -> [f64; 4] {
        v.map(f64::from)
    }
    #[inline(always)]
    fn add(self, a: [f64; 4], b: [f64; 4]) -> [f64; 4] {
        zip4(a, b, |a, b| a + b)
    }
    #[inline(always)]
    fn sub(self, a: [f64; 4], b: [f64; 4]) -> [f64; 4] {
        zip4(a, b, |a, b| a - b)
    }
    #[inline(always)]
    fn mul(self, a: [f64; 4], b: [f64; 4]) -> [f64; 4] {
        zip4(a, b, |a, b| a * b)
    }
    #[inline(always)]
    fn div(self, a: [f64; 4], b: [f64; 4]) -> [f64; 4] {
        zip4(a, b, |a, b| a / b)
    }
    #[inline(always)]
    fn max(self, a: [f64; 4], b: [f64; 4]) -> [f64; 4] {
        zip4(a, b, f64::max)
    }
    #[inline(always)]
    fn min(self, a: [f64; 4], b: [f64; 4]) -> [f64; 4] {
        zip4(a, b, f64::min)
    }
    #[inline(always)]
    fn abs(self, a: [f64; 4]) -> [f64; 4] {
        zip4(a, a, |a, _| a.abs())
    }
    #[inline(always)]
    fn sqrt(self, a: [f64; 4]) -> [f64; 4] {
        zip4(a, a, |a, _| a.sqrt())
    }
    #[inline(always)]
    fn ceil(self, a: [f64; 4]) -> [f64; 4] {
        zip4(a, a, |a, _| a.ceil())
    }
    #[inline(always)]
    fn floor(self, a: [f64; 4]) -> [f64; 4] {
        zip4(a, a, |a, _| a.floor())
    }
    #[inline(always)]
    fn ge(self, a: [f64; 4], b: [f64; 4]) -> u32 {
        bits4(a, b, |a, b| a >= b)
    }
    #[inline(always)]
    fn lt(self, a: [f64; 4], b: [f64; 4]) -> u32 {
        bits4(a, b, |a, b| a < b)
    }
    #[inline(always)]
    fn gt(self, a: [f64; 4], b: [f64; 4]) -> u32 {
        bits4(a, b, |a, b| a > b)
    }
    #[inline(always)]
    fn to_f32(self, a: [f64; 4]) -> [f32; 4] {
        [a[0] as f32, a[1] as f32, a[2] as f32, a[3] as f32]
    }
    #[inline(always)]
    fn array(self, a: [f64; 4]) -> [f64; 4] {
        a
    }
    #[inline(always)]
    fn pixels(self, a: [f64; 4]) -> [u32; 4] {
        a.map(|v| v as u32)
    }
    #[inline(always)]
    fn ints(self, a: [f64; 4]) -> [i32; 4] {
        a.map(|v| v as i32)
    }
    #[inline(always)]
    fn to_f32_below(self, a: [f64; 4]) -> ([f32; 4], u32) {
        let f = self.to_f32(a);
        (f, bits4(f.map(f64::from), a, |b, a| b < a))
    }
}

#[cfg(target_arch = "x86_64")]
mod avx2_lanes {
    //! [`Lanes`] in AVX2 intrinsics.
    use super::{Lanes, Tri};
    use crate::simd::Avx2;
    use std::arch::x86_64::*;

    // Every `unsafe` below: an `Avx2` exists only on a CPU with AVX2
    // (`Avx2::detect`), and the only memory accesses are stores into arrays
    // borrowed here (each block's SAFETY line says which).
    impl Lanes<4> for Avx2 {
        type V = __m256d;
        #[inline(always)]
        fn splat(self, v: f64) -> __m256d {
            // SAFETY: `self` proves AVX2 (`Avx2::detect`); no memory access.
            unsafe { _mm256_set1_pd(v) }
        }
        #[inline(always)]
        fn load(self, t: &[Tri; 4], i: usize, c: usize) -> __m256d {
            // Widening f32 to f64 is exact, as `f64::from`.
            let v = [t[0][i][c], t[1][i][c], t[2][i][c], t[3][i][c]];
            // SAFETY: `self` proves AVX2 (`Avx2::detect`); no memory access.
            unsafe { _mm256_cvtps_pd(_mm_set_ps(v[3], v[2], v[1], v[0])) }
        }
        #[inline(always)]
        fn widen(self, v: [f32; 4]) -> __m256d {
            // SAFETY: `self` proves AVX2; the load reads 16 bytes of `v`, a
            // `[f32; 4]` borrowed here.
            unsafe { _mm256_cvtps_pd(_mm_loadu_ps(v.as_ptr())) }
        }
        #[inline(always)]
        fn add(self, a: __m256d, b: __m256d) -> __m256d {
            // SAFETY: `self` proves AVX2 (`Avx2::detect`); no memory access.
            unsafe { _mm256_add_pd(a, b) }
        }
        #[inline(always)]
        fn sub(self, a: __m256d, b: __m256d) -> __m256d {
            // SAFETY: `self` proves AVX2 (`Avx2::detect`); no memory access.
            unsafe { _mm256_sub_pd(a, b) }
        }
        #[inline(always)]
        fn mul(self, a: __m256d, b: __m256d) -> __m256d {
            // SAFETY: `self` proves AVX2 (`Avx2::detect`); no memory access.
            unsafe { _mm256_mul_pd(a, b) }
        }
        #[inline(always)]
        fn div(self, a: __m256d, b: __m256d) -> __m256d {
            // SAFETY: `self` proves AVX2 (`Avx2::detect`); no memory access.
            unsafe { _mm256_div_pd(a, b) }
        }
        #[inline(always)]
        fn max(self, a: __m256d, b: __m256d) -> __m256d {
            // `maxpd(b, a)` is `b > a ? b : a`: `f64::max` of numbers.
            // SAFETY: `self` proves AVX2 (`Avx2::detect`); no memory access.
            unsafe { _mm256_max_pd(b, a) }
        }
        #[inline(always)]
        fn min(self, a: __m256d, b: __m256d) -> __m256d {
            // `minpd(b, a)` is `b < a ? b : a`: `f64::min` of numbers.
            // SAFETY: `self` proves AVX2 (`Avx2::detect`); no memory access.
            unsafe { _mm256_min_pd(b, a) }
        }
        #[inline(always)]
        fn abs(self, a: __m256d) -> __m256d {
            // SAFETY: `self` proves AVX2 (`Avx2::detect`); no memory access.
            unsafe { _mm256_and_pd(a, _mm256_castsi256_pd(_mm256_set1_epi64x(i64::MAX))) }
        }
        #[inline(always)]
        fn sqrt(self, a: __m256d) -> __m256d {
            // SAFETY: `self` proves AVX2 (`Avx2::detect`); no memory access.
            unsafe { _mm256_sqrt_pd(a) }
        }
        #[inline(always)]
        fn ceil(self, a: __m256d) -> __m256d {
            // SAFETY: `self` proves AVX2 (`Avx2::detect`); no memory access.
            unsafe { _mm256_round_pd::<{ _MM_FROUND_TO_POS_INF | _MM_FROUND_NO_EXC }>(a) }
        }
        #[inline(always)]
        fn floor(self, a: __m256d) -> __m256d {
            // SAFETY: `self` proves AVX2 (`Avx2::detect`); no memory access.
            unsafe { _mm256_round_pd::<{ _MM_FROUND_TO_NEG_INF | _MM_FROUND_NO_EXC }>(a) }
        }
        #[inline(always)]
        fn ge(self, a: __m256d, b: __m256d) -> u32 {
            // SAFETY: `self` proves AVX2 (`Avx2::detect`); no memory access.
            unsafe { _mm256_movemask_pd(_mm256_cmp_pd::<_CMP_GE_OQ>(a, b)) as u32 }
        }
        #[inline(always)]
        fn lt(self, a: __m256d, b: __m256d) -> u32 {
            // SAFETY: `self` proves AVX2 (`Avx2::detect`); no memory access.
            unsafe { _mm256_movemask_pd(_mm256_cmp_pd::<_CMP_LT_OQ>(a, b)) as u32 }
        }
        #[inline(always)]
        fn gt(self, a: __m256d, b: __m256d) -> u32 {
            // SAFETY: `self` proves AVX2 (`Avx2::detect`); no memory access.
            unsafe { _mm256_movemask_pd(_mm256_cmp_pd::<_CMP_GT_OQ>(a, b)) as u32 }
        }
        #[inline(always)]
        fn array(self, a: __m256d) -> [f64; 4] {
            let mut out = [0.0; 4];
            // SAFETY: `self` proves AVX2;
            // the store writes 32 bytes into `out`, a `[f64; 4]` borrowed here.
            unsafe { _mm256_storeu_pd(out.as_mut_ptr(), a) };
            out
        }
        #[inline(always)]
        fn to_f32(self, a: __m256d) -> [f32; 4] {
            let mut out = [0.0; 4];
            // `cvtpd2ps` rounds by MXCSR's mode, as `as f32`'s `cvtsd2ss`
            // does (to nearest unless a caller changed MXCSR, for both).
            // SAFETY: `self` proves AVX2; the store writes 16 bytes into
            // `out`, a `[f32; 4]` borrowed here.
            unsafe { _mm_storeu_ps(out.as_mut_ptr(), _mm256_cvtpd_ps(a)) };
            out
        }
        #[inline(always)]
        fn pixels(self, a: __m256d) -> [u32; 4] {
            // `vcvttpd2dq` truncates as `as` does, on the lanes whose
            // values the trait asks for.
            let mut out = [0u32; 4];
            // SAFETY: `self` proves AVX2;
            // the store writes 16 bytes into `out`, a `[u32; 4]` borrowed here (unaligned store).
            unsafe { _mm_storeu_si128(out.as_mut_ptr().cast(), _mm256_cvttpd_epi32(a)) };
            out
        }
        #[inline(always)]
        fn ints(self, a: __m256d) -> [i32; 4] {
            // `vcvttpd2dq` truncates as `as` does, on whole numbers in range.
            let mut out = [0i32; 4];
            // SAFETY: `self` proves AVX2;
            // the store writes 16 bytes into `out`, a `[i32; 4]` borrowed here (unaligned store).
            unsafe { _mm_storeu_si128(out.as_mut_ptr().cast(), _mm256_cvttpd_epi32(a)) };
            out
        }
        #[inline(always)]
        fn to_f32_below(self, a: __m256d) -> ([f32; 4], u32) {
            let mut out = [0.0; 4];
            // SAFETY: `self` proves AVX2; the store writes 16 bytes into
            // `out`, a `[f32; 4]` borrowed here.
            let below = unsafe {
                let f = _mm256_cvtpd_ps(a);
                _mm_storeu_ps(out.as_mut_ptr(), f);
                _mm256_movemask_pd(_mm256_cmp_pd::<_CMP_LT_OQ>(_mm256_cvtps_pd(f), a)) as u32
            };
            (out, below)
        }
    }
}

#[cfg(target_arch = "x86_64")]
mod avx512_lanes {
    //! [`Lanes`] over eight lanes in AVX-512 intrinsics: twice the
    //! triangles per instruction of AVX2 in the binning's boxes.
    use super::{Lanes, Tri};
    use crate::simd::Avx512;
    use std::arch::x86_64::*;

    // Every `unsafe` below: an `Avx512` exists only on a CPU with AVX-512F
    // (`Avx512::detect`, which implies AVX2), and the only memory accesses are the load of an
    // array and stores into arrays, all borrowed here (each block's SAFETY
    // line says which).
    impl Lanes<8> for Avx512 {
        type V = __m512d;
        #[inline(always)]
        fn splat(self, v: f64) -> __m512d {
            // SAFETY: `self` proves AVX-512F (`Avx512::detect`); no memory access.
            unsafe { _mm512_set1_pd(v) }
        }
        #[inline(always)]
        fn load(self, t: &[Tri; 8], i: usize, c: usize) -> __m512d {
            // Widening f32 to f64 is exact, as `f64::from`.
            // (An explicit array: `from_fn` is not trusted on a hot path.)
            let v = [
                t[0][i][c], t[1][i][c], t[2][i][c], t[3][i][c], t[4][i][c], t[5][i][c], t[6][i][c],
                t[7][i][c],
            ];
            // SAFETY: `self` proves AVX-512F;
            // the load reads 32 bytes from `v`, a `[f32; 8]` borrowed here.
            unsafe { _mm512_cvtps_pd(_mm256_loadu_ps(v.as_ptr())) }
        }
        #[inline(always)]
        fn widen(self, v: [f32; 8]) -> __m512d {
            // SAFETY: `self` proves AVX-512F; the load reads 32 bytes of
            // `v`, a `[f32; 8]` borrowed here.
            unsafe { _mm512_cvtps_pd(_mm256_loadu_ps(v.as_ptr())) }
        }
        #[inline(always)]
        fn add(self, a: __m512d, b: __m512d) -> __m512d {
            // SAFETY: `self` proves AVX-512F (`Avx512::detect`); no memory access.
            unsafe { _mm512_add_pd(a, b) }
        }
        #[inline(always)]
        fn sub(self, a: __m512d, b: __m512d) -> __m512d {
            // SAFETY: `self` proves AVX-512F (`Avx512::detect`); no memory access.
            unsafe { _mm512_sub_pd(a, b) }
        }
        #[inline(always)]
        fn mul(self, a: __m512d, b: __m512d) -> __m512d {
            // SAFETY: `self` proves AVX-512F (`Avx512::detect`); no memory access.
            unsafe { _mm512_mul_pd(a, b) }
        }
        #[inline(always)]
        fn div(self, a: __m512d, b: __m512d) -> __m512d {
            // SAFETY: `self` proves AVX-512F (`Avx512::detect`); no memory access.
            unsafe { _mm512_div_pd(a, b) }
        }
        #[inline(always)]
        fn max(self, a: __m512d, b: __m512d) -> __m512d {
            // As AVX2's: `b > a ? b : a`, `f64::max` of numbers.
            // SAFETY: `self` proves AVX-512F (`Avx512::detect`); no memory access.
            unsafe { _mm512_max_pd(b, a) }
        }
        #[inline(always)]
        fn min(self, a: __m512d, b: __m512d) -> __m512d {
            // SAFETY: `self` proves AVX-512F (`Avx512::detect`); no memory access.
            unsafe { _mm512_min_pd(b, a) }
        }
        #[inline(always)]
        fn abs(self, a: __m512d) -> __m512d {
            // SAFETY: `self` proves AVX-512F (`Avx512::detect`); no memory access.
            unsafe { _mm512_abs_pd(a) }
        }
        #[inline(always)]
        fn sqrt(self, a: __m512d) -> __m512d {
            // SAFETY: `self` proves AVX-512F (`Avx512::detect`); no memory access.
            unsafe { _mm512_sqrt_pd(a) }
        }
        #[inline(always)]
        fn ceil(self, a: __m512d) -> __m512d {
            // SAFETY: `self` proves AVX-512F (`Avx512::detect`); no memory access.
            unsafe { _mm512_roundscale_pd::<{ _MM_FROUND_TO_POS_INF | _MM_FROUND_NO_EXC }>(a) }
        }
        #[inline(always)]
        fn floor(self, a: __m512d) -> __m512d {
            // SAFETY: `self` proves AVX-512F (`Avx512::detect`); no memory access.
            unsafe { _mm512_roundscale_pd::<{ _MM_FROUND_TO_NEG_INF | _MM_FROUND_NO_EXC }>(a) }
        }
        #[inline(always)]
        fn ge(self, a: __m512d, b: __m512d) -> u32 {
            // SAFETY: `self` proves AVX-512F (`Avx512::detect`); no memory access.
            unsafe { u32::from(_mm512_cmp_pd_mask::<_CMP_GE_OQ>(a, b)) }
        }
        #[inline(always)]
        fn lt(self, a: __m512d, b: __m512d) -> u32 {
            // SAFETY: `self` proves AVX-512F (`Avx512::detect`); no memory access.
            unsafe { u32::from(_mm512_cmp_pd_mask::<_CMP_LT_OQ>(a, b)) }
        }
        #[inline(always)]
        fn gt(self, a: __m512d, b: __m512d) -> u32 {
            // SAFETY: `self` proves AVX-512F (`Avx512::detect`); no memory access.
            unsafe { u32::from(_mm512_cmp_pd_mask::<_CMP_GT_OQ>(a, b)) }
        }
        #[inline(always)]
        fn array(self, a: __m512d) -> [f64; 8] {
            let mut out = [0.0; 8];
            // SAFETY: `self` proves AVX-512F;
            // the store writes 64 bytes into `out`, a `[f64; 8]` borrowed here.
            unsafe { _mm512_storeu_pd(out.as_mut_ptr(), a) };
            out
        }
        #[inline(always)]
        fn to_f32(self, a: __m512d) -> [f32; 8] {
            let mut out = [0.0; 8];
            // As AVX2's, to nearest by MXCSR. SAFETY: `self` proves
            // AVX-512F; the store writes 32 bytes into `out`, a `[f32; 8]`.
            unsafe { _mm256_storeu_ps(out.as_mut_ptr(), _mm512_cvtpd_ps(a)) };
            out
        }
        #[inline(always)]
        fn pixels(self, a: __m512d) -> [u32; 8] {
            // As AVX2's `pixels`.
            let mut out = [0u32; 8];
            // SAFETY: `self` proves AVX-512F;
            // the store writes 32 bytes into `out`, a `[u32; 8]` borrowed here (unaligned store).
            unsafe { _mm256_storeu_si256(out.as_mut_ptr().cast(), _mm512_cvttpd_epi32(a)) };
            out
        }
        #[inline(always)]
        fn ints(self, a: __m512d) -> [i32; 8] {
            // As AVX2's `ints`.
            let mut out = [0i32; 8];
            // SAFETY: `self` proves AVX-512F;
            // the store writes 32 bytes into `out`, a `[i32; 8]` borrowed here (unaligned store).
            unsafe { _mm256_storeu_si256(out.as_mut_ptr().cast(), _mm512_cvttpd_epi32(a)) };
            out
        }
        #[inline(always)]
        fn to_f32_below(self, a: __m512d) -> ([f32; 8], u32) {
            let mut out = [0.0; 8];
            // SAFETY: `self` proves AVX-512F; the store writes 32 bytes into
            // `out`, a `[f32; 8]` borrowed here.
            let below = unsafe {
                let f = _mm512_cvtpd_ps(a);
                _mm256_storeu_ps(out.as_mut_ptr(), f);
                u32::from(_mm512_cmp_pd_mask::<_CMP_LT_OQ>(_mm512_cvtps_pd(f), a))
            };
            (out, below)
        }
    }
}

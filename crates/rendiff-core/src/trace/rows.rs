//! Reading a row of 8 lane comparisons off as 8 mask bits.
//!
//! The packet kernel decides everything per lane with f32 comparisons and then
//! works with bit masks. Left to itself the compiler turns `m |= (a > b) << i`
//! into an and-with-constants plus an or-reduction, about eight instructions
//! per row; AVX's `vmovmskps` does it in one. [`Avx2`] is a token that exists
//! only once the CPU is known to have AVX2, so the safe [`Rows::gt`] can use
//! it; [`Portable`] is the same function in plain Rust for every other CPU.

/// Lanes per row: one 256-bit vector of f32.
pub(crate) const ROW: usize = 8;

/// How a row of comparisons becomes mask bits.
pub(crate) trait Rows: Copy {
    /// Bit `j` set where `a[j] > b[j]` (false for NaN, which never arises here).
    fn gt(self, a: &[f32; ROW], b: &[f32; ROW]) -> u32;

    /// `gt(a, b) | gt(c, d)`: the AVX2 form ors the comparison vectors and
    /// moves one mask instead of two (the box test's per-row epilogue).
    #[inline(always)]
    fn gt_either(self, a: &[f32; ROW], b: &[f32; ROW], c: &[f32; ROW], d: &[f32; ROW]) -> u32 {
        self.gt(a, b) | self.gt(c, d)
    }
}

/// Plain Rust, for any CPU.
#[derive(Clone, Copy)]
pub(crate) struct Portable;

impl Rows for Portable {
    #[inline(always)]
    fn gt(self, a: &[f32; ROW], b: &[f32; ROW]) -> u32 {
        (0..ROW).fold(0, |m, j| m | (u32::from(a[j] > b[j]) << j))
    }
}

/// Proof that the running CPU has AVX2 (and so AVX): only [`Avx2::detect`]
/// makes one.
#[cfg(target_arch = "x86_64")]
#[derive(Clone, Copy)]
pub(crate) struct Avx2(());

#[cfg(target_arch = "x86_64")]
impl Avx2 {
    /// The token, when the CPU has AVX2.
    #[inline]
    pub fn detect() -> Option<Avx2> {
        std::is_x86_feature_detected!("avx2").then_some(Avx2(()))
    }
}

#[cfg(target_arch = "x86_64")]
impl Rows for Avx2 {
    #[inline(always)]
    fn gt(self, a: &[f32; ROW], b: &[f32; ROW]) -> u32 {
        use std::arch::x86_64::{_mm256_cmp_ps, _mm256_loadu_ps, _mm256_movemask_ps, _CMP_GT_OQ};
        // SAFETY: an `Avx2` exists only on a CPU with AVX2 (see `detect`), and
        // the loads read exactly the two 8-float arrays borrowed here.
        unsafe {
            let c = _mm256_cmp_ps::<_CMP_GT_OQ>(
                _mm256_loadu_ps(a.as_ptr()),
                _mm256_loadu_ps(b.as_ptr()),
            );
            _mm256_movemask_ps(c) as u32
        }
    }

    #[inline(always)]
    fn gt_either(self, a: &[f32; ROW], b: &[f32; ROW], c: &[f32; ROW], d: &[f32; ROW]) -> u32 {
        use std::arch::x86_64::{
            _mm256_cmp_ps, _mm256_loadu_ps, _mm256_movemask_ps, _mm256_or_ps, _CMP_GT_OQ,
        };
        // SAFETY: an `Avx2` exists only on a CPU with AVX2 (see `detect`), and
        // the loads read exactly the four 8-float arrays borrowed here.
        unsafe {
            let ab = _mm256_cmp_ps::<_CMP_GT_OQ>(
                _mm256_loadu_ps(a.as_ptr()),
                _mm256_loadu_ps(b.as_ptr()),
            );
            let cd = _mm256_cmp_ps::<_CMP_GT_OQ>(
                _mm256_loadu_ps(c.as_ptr()),
                _mm256_loadu_ps(d.as_ptr()),
            );
            _mm256_movemask_ps(_mm256_or_ps(ab, cd)) as u32
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Both implementations give the same bits, including for equal values,
    /// infinities and signed zeros.
    #[test]
    fn implementations_agree() {
        let vals = [
            0.0,
            -0.0,
            1.0,
            -1.0,
            f32::INFINITY,
            f32::NEG_INFINITY,
            1e-40,
            3.5,
        ];
        let mut s = 7u32;
        for _ in 0..2000 {
            let mut a = [0f32; ROW];
            let mut b = [0f32; ROW];
            for j in 0..ROW {
                s = s.wrapping_mul(1664525).wrapping_add(1013904223);
                a[j] = vals[(s >> 8) as usize % vals.len()];
                b[j] = vals[(s >> 16) as usize % vals.len()];
            }
            let want: u32 = (0..ROW).map(|j| u32::from(a[j] > b[j]) << j).sum();
            assert_eq!(Portable.gt(&a, &b), want);
            // Either of two comparisons: (a > b) | (b > a), and (a > b) | (a > a).
            let either = Portable.gt(&b, &a) | want;
            assert_eq!(Portable.gt_either(&a, &b, &b, &a), either);
            assert_eq!(Portable.gt_either(&a, &b, &a, &a), want);
            #[cfg(target_arch = "x86_64")]
            if let Some(avx) = Avx2::detect() {
                assert_eq!(avx.gt(&a, &b), want, "{a:?} > {b:?}");
                assert_eq!(avx.gt_either(&a, &b, &b, &a), either, "{a:?} <> {b:?}");
                assert_eq!(avx.gt_either(&a, &b, &a, &a), want, "{a:?} > {b:?}");
            }
        }
    }
}

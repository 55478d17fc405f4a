//! The packet kernel's row operations: 8 lanes at once, read off as 8 mask bits.
//!
//! The packet kernel decides everything per lane with f32 comparisons and then
//! works with bit masks. Left to itself the compiler turns `m |= (a > b) << i`
//! into an and-with-constants plus an or-reduction, about eight instructions
//! per row; AVX's `vmovmskps` does it in one. [`Avx2`] is a token that exists
//! only once the CPU is known to have AVX2, so the safe [`Rows::gt`] can use
//! it; [`Portable`] is the same function in plain Rust for every other CPU.
//!
//! The box test ([`Rows::box_out`]) is here too: written as plain loops over
//! a packet, its speed depended on the compiler's inlining and vectorizing
//! choices (the same source ran 2.5x slower in an LTO build), so the AVX2
//! form is spelled out, with the portable form as its definition.

use super::primary::{max, min, Node32};

/// Per axis, a box's bounds in the order a row of lanes meets them: `(near,
/// far, mixed)`, where `near * 1/D` is the entry parameter when every lane's
/// `1/D` has one sign, and `mixed` says the lanes differ (both orders taken).
pub(crate) type BoxAxes = [(f32, f32, bool); 3];

/// Lanes per row: one 256-bit vector of f32.
pub(crate) const ROW: usize = 8;

/// How a row of comparisons becomes mask bits.
pub(crate) trait Rows: Copy {
    /// Bit `j` set where `a[j] > b[j]` (false for NaN, which never arises here).
    fn gt(self, a: &[f32; ROW], b: &[f32; ROW]) -> u32;

    /// The packet box test for one row of lanes: bit `j` set where lane `j`
    /// misses the box (`tmin > tmax (1 + s)`, with `tmin` starting at 0, as
    /// in `Packet::node_mask`), or where its entry depth `tmin zscale` is
    /// beyond `best_z`. `inv` is the row's `1/D` per axis.
    fn box_out(
        self,
        axes: &BoxAxes,
        inv: [&[f32; ROW]; 3],
        zscale: &[f32; ROW],
        best_z: &[f32; ROW],
    ) -> u32;
}

/// Plain Rust, for any CPU.
#[derive(Clone, Copy)]
pub(crate) struct Portable;

impl Rows for Portable {
    #[inline(always)]
    fn gt(self, a: &[f32; ROW], b: &[f32; ROW]) -> u32 {
        (0..ROW).fold(0, |m, j| m | (u32::from(a[j] > b[j]) << j))
    }

    #[inline(always)]
    fn box_out(
        self,
        axes: &BoxAxes,
        inv: [&[f32; ROW]; 3],
        zscale: &[f32; ROW],
        best_z: &[f32; ROW],
    ) -> u32 {
        let mut m = 0;
        for j in 0..ROW {
            let (mut tmin, mut tmax) = (0f32, f32::INFINITY);
            for (&(near, far, mixed), inv) in axes.iter().zip(inv) {
                let (t0, t1) = (near * inv[j], far * inv[j]);
                let (t0, t1) = if mixed {
                    (min(t0, t1), max(t0, t1))
                } else {
                    (t0, t1)
                };
                tmin = max(tmin, t0);
                tmax = min(tmax, t1);
            }
            let out = tmin > Node32::slack_tmax(tmax) || tmin * zscale[j] > best_z[j];
            m |= u32::from(out) << j;
        }
        m
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
    fn box_out(
        self,
        axes: &BoxAxes,
        inv: [&[f32; ROW]; 3],
        zscale: &[f32; ROW],
        best_z: &[f32; ROW],
    ) -> u32 {
        use std::arch::x86_64::{
            _mm256_cmp_ps, _mm256_loadu_ps, _mm256_max_ps, _mm256_min_ps, _mm256_movemask_ps,
            _mm256_mul_ps, _mm256_or_ps, _mm256_set1_ps, _mm256_setzero_ps, _CMP_GT_OQ,
        };
        // SAFETY: an `Avx2` exists only on a CPU with AVX2 (see `detect`), and
        // the loads read exactly the five 8-float arrays borrowed here.
        // `vminps a, b` is `a < b ? a : b` and `vmaxps a, b` is `a > b ? a : b`,
        // which are `min` and `max` as the portable form uses them.
        unsafe {
            let mut tmin = _mm256_setzero_ps();
            let mut tmax = _mm256_set1_ps(f32::INFINITY);
            for (&(near, far, mixed), inv) in axes.iter().zip(inv) {
                let inv = _mm256_loadu_ps(inv.as_ptr());
                let t0 = _mm256_mul_ps(_mm256_set1_ps(near), inv);
                let t1 = _mm256_mul_ps(_mm256_set1_ps(far), inv);
                let (t0, t1) = if mixed {
                    (_mm256_min_ps(t0, t1), _mm256_max_ps(t0, t1))
                } else {
                    (t0, t1)
                };
                tmin = _mm256_max_ps(tmin, t0);
                tmax = _mm256_min_ps(tmax, t1);
            }
            let slack = _mm256_mul_ps(tmax, _mm256_set1_ps(Node32::TMAX_SLACK));
            let entry_z = _mm256_mul_ps(tmin, _mm256_loadu_ps(zscale.as_ptr()));
            let miss = _mm256_cmp_ps::<_CMP_GT_OQ>(tmin, slack);
            let pruned = _mm256_cmp_ps::<_CMP_GT_OQ>(entry_z, _mm256_loadu_ps(best_z.as_ptr()));
            _mm256_movemask_ps(_mm256_or_ps(miss, pruned)) as u32
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
            #[cfg(target_arch = "x86_64")]
            if let Some(avx) = Avx2::detect() {
                assert_eq!(avx.gt(&a, &b), want, "{a:?} > {b:?}");
            }
        }
    }

    /// The box test's two forms agree bit for bit, on both axis orders and on
    /// infinities, signed zeros and ties; and the portable form is the
    /// per-lane slab test of `Node32::misses` with the pruning comparison.
    #[test]
    fn box_out_forms_agree() {
        let vals = [
            0.5,
            -0.5,
            2.0,
            -3.0,
            f32::INFINITY,
            f32::NEG_INFINITY,
            f32::MIN_POSITIVE,
            -f32::MIN_POSITIVE,
            1e30,
            -0.0,
            0.0,
        ];
        let mut s = 11u32;
        let mut next = |n: usize| {
            s = s.wrapping_mul(1664525).wrapping_add(1013904223);
            (s >> 8) as usize % n
        };
        let (mut outs, mut ins) = (0, 0);
        for _ in 0..4000 {
            let mut axes: BoxAxes = [(0.0, 0.0, false); 3];
            let mut inv = [[0f32; ROW]; 3];
            for (k, a) in axes.iter_mut().enumerate() {
                // Bounds are never 0 (`Node32::new`).
                let lo = vals[next(9)];
                let hi = lo.max(vals[next(9)]);
                let (lo, hi) = (lo.min(hi), hi);
                let (lo, hi) = if !lo.is_finite() || !hi.is_finite() {
                    (-1.0, 1.0)
                } else {
                    (lo, hi)
                };
                let sign = next(3);
                *a = match sign {
                    0 => (lo, hi, true),
                    1 => (lo, hi, false),
                    _ => (hi, lo, false),
                };
                for v in inv[k].iter_mut() {
                    let x = vals[next(vals.len())];
                    *v = match sign {
                        0 => x,
                        1 => x.abs(),
                        _ => -x.abs(),
                    };
                }
            }
            let zscale: [f32; ROW] = std::array::from_fn(|_| vals[next(5)].abs());
            let best_z: [f32; ROW] = std::array::from_fn(|_| vals[next(5)].abs());
            let inv_rows = [&inv[0], &inv[1], &inv[2]];
            let want = Portable.box_out(&axes, inv_rows, &zscale, &best_z);
            // The portable form, lane by lane, from `Node32::misses`' definition.
            for j in 0..ROW {
                let (mut tmin, mut tmax) = (0f32, f32::INFINITY);
                for (k, &(near, far, _)) in axes.iter().enumerate() {
                    let (t0, t1) = (near * inv[k][j], far * inv[k][j]);
                    tmin = max(tmin, min(t0, t1));
                    tmax = min(tmax, max(t0, t1));
                }
                let out =
                    tmin > tmax * (1.0 + 1.0 / (1u32 << 20) as f32) || tmin * zscale[j] > best_z[j];
                if !(tmin.is_nan() || tmax.is_nan()) {
                    assert_eq!(want >> j & 1 == 1, out, "lane {j}: {axes:?}");
                }
                if out {
                    outs += 1;
                } else {
                    ins += 1;
                }
            }
            #[cfg(target_arch = "x86_64")]
            if let Some(avx) = Avx2::detect() {
                assert_eq!(
                    avx.box_out(&axes, inv_rows, &zscale, &best_z),
                    want,
                    "{axes:?}"
                );
            }
        }
        // Both answers occur often.
        assert!(outs > 1000 && ins > 1000, "{outs} out, {ins} in");
    }
}

//! The packet tracer's row operations ([`Rows`]) in AVX2, and pairs of rows
//! in AVX-512 (single rows and the frustum test are AVX2's there). The
//! definitions they must equal bit for bit are `Rows`' default methods
//! ([`Portable`](crate::simd::Portable)'s, in `trace::rows`).

use crate::simd::{Avx2, Avx512};
use crate::trace::frustum::{BOX_ABS, BOX_REL};
use crate::trace::primary::Node32;
use crate::trace::rows::{BoxAxes, Rows, ROW, ROW2};

impl Rows for Avx2 {
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

    #[inline(always)]
    fn edge_signs(
        self,
        n: &[[f32; 3]; 3],
        beta: &[f32; 3],
        dir: [&[f32; ROW]; 3],
        dir_norm: &[f32; ROW],
    ) -> [(u32, u32); 3] {
        use std::arch::x86_64::{
            _mm256_add_ps, _mm256_cmp_ps, _mm256_loadu_ps, _mm256_movemask_ps, _mm256_mul_ps,
            _mm256_set1_ps, _mm256_xor_ps, _CMP_GT_OQ,
        };
        // SAFETY: an `Avx2` exists only on a CPU with AVX2 (see `detect`), and
        // the loads read exactly the four 8-float arrays borrowed here.
        // `edge_det32`'s operations in its order (`(n0 d0 + n1 d1) + n2 d2`);
        // flipping the sign bit is negation.
        unsafe {
            // (Not `dir.map`: array `map` compiled to an out-of-line call here.)
            let d = [
                _mm256_loadu_ps(dir[0].as_ptr()),
                _mm256_loadu_ps(dir[1].as_ptr()),
                _mm256_loadu_ps(dir[2].as_ptr()),
            ];
            let dn = _mm256_loadu_ps(dir_norm.as_ptr());
            let sign = _mm256_set1_ps(-0.0);
            let mut out = [(0, 0); 3];
            for ((n, &beta), out) in n.iter().zip(beta).zip(&mut out) {
                let det = _mm256_add_ps(
                    _mm256_add_ps(
                        _mm256_mul_ps(_mm256_set1_ps(n[0]), d[0]),
                        _mm256_mul_ps(_mm256_set1_ps(n[1]), d[1]),
                    ),
                    _mm256_mul_ps(_mm256_set1_ps(n[2]), d[2]),
                );
                let bound = _mm256_mul_ps(_mm256_set1_ps(beta), dn);
                let pos = _mm256_cmp_ps::<_CMP_GT_OQ>(det, bound);
                let neg = _mm256_cmp_ps::<_CMP_GT_OQ>(_mm256_xor_ps(det, sign), bound);
                *out = (
                    _mm256_movemask_ps(pos) as u32,
                    _mm256_movemask_ps(neg) as u32,
                );
            }
            out
        }
    }

    #[inline(always)]
    fn planes_out(self, n: &[[f32; ROW]; 3], a: &[(f32, f32); 3], b: &[(f32, f32); 3]) -> u32 {
        use std::arch::x86_64::{
            _mm256_add_ps, _mm256_andnot_ps, _mm256_cmp_ps, _mm256_loadu_ps, _mm256_max_ps,
            _mm256_movemask_ps, _mm256_mul_ps, _mm256_set1_ps, _mm256_set_m128, _mm256_setzero_ps,
            _mm256_xor_ps, _mm_set1_ps, _CMP_LT_OQ,
        };
        // SAFETY: an `Avx2` exists only on a CPU with AVX2 (see `detect`), and
        // the loads read exactly the three 8-float arrays borrowed here. The
        // portable form's operations in its order; `vmaxps a, b` is `max(a,
        // b)` as the portable form uses it, and clearing or flipping the sign
        // bit is `abs` or negation.
        unsafe {
            let sign = _mm256_set1_ps(-0.0);
            let (mut s, mut mag) = (_mm256_setzero_ps(), _mm256_setzero_ps());
            for k in 0..3 {
                let lo = _mm256_set_m128(_mm_set1_ps(b[k].0), _mm_set1_ps(a[k].0));
                let hi = _mm256_set_m128(_mm_set1_ps(b[k].1), _mm_set1_ps(a[k].1));
                let nk = _mm256_loadu_ps(n[k].as_ptr());
                let p = _mm256_max_ps(_mm256_mul_ps(nk, lo), _mm256_mul_ps(nk, hi));
                s = _mm256_add_ps(s, p);
                mag = _mm256_add_ps(mag, _mm256_andnot_ps(sign, p));
            }
            let bound = _mm256_add_ps(
                _mm256_mul_ps(_mm256_set1_ps(BOX_REL), mag),
                _mm256_set1_ps(BOX_ABS),
            );
            let out = _mm256_cmp_ps::<_CMP_LT_OQ>(s, _mm256_xor_ps(bound, sign));
            _mm256_movemask_ps(out) as u32
        }
    }
}

impl Rows for Avx512 {
    const PAIRS: bool = true;

    #[inline(always)]
    fn box_out(
        self,
        axes: &BoxAxes,
        inv: [&[f32; ROW]; 3],
        zscale: &[f32; ROW],
        best_z: &[f32; ROW],
    ) -> u32 {
        self.avx2().box_out(axes, inv, zscale, best_z)
    }

    #[inline(always)]
    fn edge_signs(
        self,
        n: &[[f32; 3]; 3],
        beta: &[f32; 3],
        dir: [&[f32; ROW]; 3],
        dir_norm: &[f32; ROW],
    ) -> [(u32, u32); 3] {
        self.avx2().edge_signs(n, beta, dir, dir_norm)
    }

    #[inline(always)]
    fn planes_out(self, n: &[[f32; ROW]; 3], a: &[(f32, f32); 3], b: &[(f32, f32); 3]) -> u32 {
        self.avx2().planes_out(n, a, b)
    }

    #[inline(always)]
    fn box_out2(
        self,
        axes: &BoxAxes,
        inv: [&[f32; ROW2]; 3],
        zscale: &[f32; ROW2],
        best_z: &[f32; ROW2],
    ) -> u32 {
        use std::arch::x86_64::{
            _mm512_cmp_ps_mask, _mm512_loadu_ps, _mm512_max_ps, _mm512_min_ps, _mm512_mul_ps,
            _mm512_set1_ps, _mm512_setzero_ps, _CMP_GT_OQ,
        };
        // SAFETY: an `Avx512` exists only on a CPU with AVX-512F (see
        // `detect`), and the loads read exactly the five 16-float arrays
        // borrowed here. `Avx2::box_out`'s operations, 16 lanes at a time
        // (`vminps`/`vmaxps` pick the same operand at every width).
        unsafe {
            let mut tmin = _mm512_setzero_ps();
            let mut tmax = _mm512_set1_ps(f32::INFINITY);
            for (&(near, far, mixed), inv) in axes.iter().zip(inv) {
                let inv = _mm512_loadu_ps(inv.as_ptr());
                let t0 = _mm512_mul_ps(_mm512_set1_ps(near), inv);
                let t1 = _mm512_mul_ps(_mm512_set1_ps(far), inv);
                let (t0, t1) = if mixed {
                    (_mm512_min_ps(t0, t1), _mm512_max_ps(t0, t1))
                } else {
                    (t0, t1)
                };
                tmin = _mm512_max_ps(tmin, t0);
                tmax = _mm512_min_ps(tmax, t1);
            }
            let slack = _mm512_mul_ps(tmax, _mm512_set1_ps(Node32::TMAX_SLACK));
            let entry_z = _mm512_mul_ps(tmin, _mm512_loadu_ps(zscale.as_ptr()));
            let miss = _mm512_cmp_ps_mask::<_CMP_GT_OQ>(tmin, slack);
            let pruned =
                _mm512_cmp_ps_mask::<_CMP_GT_OQ>(entry_z, _mm512_loadu_ps(best_z.as_ptr()));
            u32::from(miss | pruned)
        }
    }

    #[inline(always)]
    fn edge_signs2(
        self,
        n: &[[f32; 3]; 3],
        beta: &[f32; 3],
        dir: [&[f32; ROW2]; 3],
        dir_norm: &[f32; ROW2],
    ) -> [(u32, u32); 3] {
        use std::arch::x86_64::{
            _mm512_add_ps, _mm512_cmp_ps_mask, _mm512_loadu_ps, _mm512_mul_ps, _mm512_set1_ps,
            _CMP_GT_OQ, _CMP_LT_OQ,
        };
        // SAFETY: an `Avx512` exists only on a CPU with AVX-512F (see
        // `detect`), and the loads read exactly the four 16-float arrays
        // borrowed here. `edge_det32`'s operations in its order. `-det >
        // beta |D|` is taken as `det < (-beta) |D|`: negation is exact and
        // rounding symmetric, so `(-beta) |D|` is `-(beta |D|)` bit for bit,
        // and `-x > y` is `x < -y` for every pair, NaN included (both false).
        unsafe {
            let d = [
                _mm512_loadu_ps(dir[0].as_ptr()),
                _mm512_loadu_ps(dir[1].as_ptr()),
                _mm512_loadu_ps(dir[2].as_ptr()),
            ];
            let dn = _mm512_loadu_ps(dir_norm.as_ptr());
            let mut out = [(0, 0); 3];
            for ((n, &beta), out) in n.iter().zip(beta).zip(&mut out) {
                let det = _mm512_add_ps(
                    _mm512_add_ps(
                        _mm512_mul_ps(_mm512_set1_ps(n[0]), d[0]),
                        _mm512_mul_ps(_mm512_set1_ps(n[1]), d[1]),
                    ),
                    _mm512_mul_ps(_mm512_set1_ps(n[2]), d[2]),
                );
                let bound = _mm512_mul_ps(_mm512_set1_ps(beta), dn);
                let low = _mm512_mul_ps(_mm512_set1_ps(-beta), dn);
                *out = (
                    u32::from(_mm512_cmp_ps_mask::<_CMP_GT_OQ>(det, bound)),
                    u32::from(_mm512_cmp_ps_mask::<_CMP_LT_OQ>(det, low)),
                );
            }
            out
        }
    }
}

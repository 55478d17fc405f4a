//! The shading rays' pair test (`trace::general`: a ray against both
//! children's boxes of an inner node, and whether it meets each within its
//! segment) in SSE2, two lanes at a time. SSE2 is part of the x86-64
//! baseline, so no token is needed. `maxpd`/`minpd` are `x > y ? x : y`
//! and `x < y ? x : y` lane by lane, the folds of the definition
//! (`SlabRay::slab2` and `met2` in `trace/general.rs`), and every other
//! operation is the same IEEE operation in the same order, so the results
//! are the same bits (a test there compares them).

use std::arch::x86_64::*;

/// Entry distances of two boxes and whether the ray `o + t / inv` meets
/// each within `(tmin, tmax)`. Per axis `k`, `near[k]` and `far[k]` are the
/// two boxes' planes the ray enters and leaves by.
#[inline(always)]
pub(crate) fn enter_pair(
    near: [&[f64; 2]; 3],
    far: [&[f64; 2]; 3],
    o: [f64; 3],
    inv: [f64; 3],
    tmin: f64,
    tmax: f64,
) -> ([f64; 2], [bool; 2]) {
    // SAFETY: SSE2 is part of the x86-64 baseline (every x86_64 target
    // enables it), and none of these intrinsics reads or writes memory.
    unsafe {
        let mut a = _mm_set1_pd(f64::NEG_INFINITY);
        let mut z = _mm_set1_pd(f64::INFINITY);
        for k in 0..3 {
            let (ok, ik) = (_mm_set1_pd(o[k]), _mm_set1_pd(inv[k]));
            let n = _mm_mul_pd(_mm_sub_pd(_mm_setr_pd(near[k][0], near[k][1]), ok), ik);
            let f = _mm_mul_pd(_mm_sub_pd(_mm_setr_pd(far[k][0], far[k][1]), ok), ik);
            a = _mm_max_pd(a, n);
            z = _mm_min_pd(z, f);
        }
        // `meets`: tol = (|a| min MAX + |z| min MAX) * 4e-16, and a miss is
        // a > z + tol, z < -tol, a > tmax or z < tmin.
        let sign = _mm_set1_pd(-0.0);
        let big = _mm_set1_pd(f64::MAX);
        let abs_a = _mm_min_pd(_mm_andnot_pd(sign, a), big);
        let abs_z = _mm_min_pd(_mm_andnot_pd(sign, z), big);
        let tol = _mm_mul_pd(_mm_add_pd(abs_a, abs_z), _mm_set1_pd(4e-16));
        let miss = _mm_or_pd(
            _mm_or_pd(
                _mm_cmpgt_pd(a, _mm_add_pd(z, tol)),
                _mm_cmplt_pd(z, _mm_xor_pd(tol, sign)),
            ),
            _mm_or_pd(
                _mm_cmpgt_pd(a, _mm_set1_pd(tmax)),
                _mm_cmplt_pd(z, _mm_set1_pd(tmin)),
            ),
        );
        let bits = _mm_movemask_pd(miss);
        let lanes = [_mm_cvtsd_f64(a), _mm_cvtsd_f64(_mm_unpackhi_pd(a, a))];
        (lanes, [bits & 1 == 0, bits & 2 == 0])
    }
}

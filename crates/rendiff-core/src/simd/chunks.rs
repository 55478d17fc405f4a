//! The raster's 8-pixel chunk operations ([`ChunkOps`]) in AVX2: the
//! definitions they must equal bit for bit are the trait's default methods
//! ([`Portable`](crate::simd::Portable)'s, in `raster::edges`), and the tests in `raster::edges` and
//! `raster::screen_depth` hold them to it.

use crate::camera::Camera;
use crate::predicate::EdgePlane;
use crate::raster::edges::{
    BlockRows, ChunkDepth, ChunkOps, Extremes, CHUNK, CLAMP_FREE_MARGIN, CLAMP_FREE_MAX_T,
    CLAMP_FREE_MIN_MARGIN,
};
use crate::raster::screen_depth::{ScreenRow, DROPPED_MASK, MIDPOINT};
use crate::scene::resolve::Tri;
use crate::simd::{Avx2, Portable};
use glam::DVec3;
use std::arch::x86_64::*;

/// [`Extremes`] in AVX2 registers while a row is written ([`Avx2`]'s
/// `dir_row` and `planar_row`).
#[derive(Clone, Copy)]
struct WideExtremes {
    /// Running minimum per lane.
    lo: __m256d,
    /// Running maximum per lane.
    hi: __m256d,
    /// `Σ 0 v` per lane.
    bad: __m256d,
}

impl WideExtremes {
    /// `ext`'s four lanes.
    ///
    /// # Safety
    /// The CPU has AVX2 (callers hold an [`Avx2`]).
    #[inline(always)]
    unsafe fn load(ext: &Extremes) -> Self {
        // SAFETY: the caller holds an `Avx2` (this fn's contract);
        // the loads read four f64 from each of `ext`'s arrays, borrowed here.
        unsafe {
            WideExtremes {
                lo: _mm256_loadu_pd(ext.lo.as_ptr()),
                hi: _mm256_loadu_pd(ext.hi.as_ptr()),
                bad: _mm256_loadu_pd(ext.bad.as_ptr()),
            }
        }
    }

    /// Takes in four values, lane by lane as [`Extremes::add`] does
    /// (`minpd(v, lo)` is `if v < lo { v } else { lo }`).
    ///
    /// # Safety
    /// As [`WideExtremes::load`].
    #[inline(always)]
    unsafe fn add(&mut self, v: __m256d) {
        // SAFETY: the caller holds an `Avx2` (this fn's contract); no memory access.
        unsafe {
            self.lo = _mm256_min_pd(v, self.lo);
            self.hi = _mm256_max_pd(v, self.hi);
            self.bad = _mm256_add_pd(self.bad, _mm256_mul_pd(v, _mm256_setzero_pd()));
        }
    }

    /// Back into `ext`.
    ///
    /// # Safety
    /// As [`WideExtremes::load`].
    #[inline(always)]
    unsafe fn store(self, ext: &mut Extremes) {
        // SAFETY: the caller holds an `Avx2` (this fn's contract);
        // the stores write four f64 into each of `ext`'s arrays, borrowed mutably here.
        unsafe {
            _mm256_storeu_pd(ext.lo.as_mut_ptr(), self.lo);
            _mm256_storeu_pd(ext.hi.as_mut_ptr(), self.hi);
            _mm256_storeu_pd(ext.bad.as_mut_ptr(), self.bad);
        }
    }
}

impl ChunkOps for Avx2 {
    #[inline(always)]
    fn chunk_depth(self, cam: &Camera, t: &Tri) -> ChunkDepth {
        // SAFETY: an `Avx2` exists only on a CPU with AVX2 (see `detect`);
        // the stores write 4 f64 into the 4-element arrays here. Lanes are
        // the axes x, y, z (lane 3 carries zeros and is dropped), and each
        // lane is the scalar definition's arithmetic, operation for operation:
        // * `glam`'s `Vec3::min` / `max` are `a < b ? a : b` / `a > b ? a : b`,
        //   which is what `vminps a, b` / `vmaxps a, b` compute, ties and all;
        //   f32 to f64 is exact either way;
        // * `DVec3::cross` is `a.y b.z - b.y a.z` and so on: products of
        //   the rotated lanes, then one subtraction;
        // * `DVec3::dot` is `(x + y) + z` over the products, summed in that order;
        // * `grow_box`'s `DVec3::max` is `vmaxpd` by the same rule; `f64::max`
        //   of two magnitudes in `ChunkDepth` differs from `vmaxpd` only where
        //   an operand is NaN, and none is: each is the magnitude of a
        //   difference of two finite values (the vertices are finite f32,
        //   `resolve` rejects others; the eye is finite, or `Camera::new`'s
        //   basis would be zero; a grown bound is a vertex moved by a finite
        //   margin), which may overflow to infinity but is never NaN;
        // * `abs` clears the sign bit, as `f64::abs` does.
        unsafe {
            // Each vertex's f32 lanes, then widened (no closure around
            // intrinsics: module documentation of `crate::simd`).
            let (qa, qb, qc) = (xyz0(t[0]), xyz0(t[1]), xyz0(t[2]));
            let e = _mm256_setr_pd(cam.eye.x, cam.eye.y, cam.eye.z, 0.0);
            let (a, b, c) = (
                _mm256_cvtps_pd(qa),
                _mm256_cvtps_pd(qb),
                _mm256_cvtps_pd(qc),
            );
            let (e1, e2) = (_mm256_sub_pd(b, a), _mm256_sub_pd(c, a));
            // Lanes (y, z, x, w) and (z, x, y, w).
            const YZX: i32 = 0b11_00_10_01;
            const ZXY: i32 = 0b11_01_00_10;
            let normal = _mm256_sub_pd(
                _mm256_mul_pd(
                    _mm256_permute4x64_pd::<YZX>(e1),
                    _mm256_permute4x64_pd::<ZXY>(e2),
                ),
                _mm256_mul_pd(
                    _mm256_permute4x64_pd::<YZX>(e2),
                    _mm256_permute4x64_pd::<ZXY>(e1),
                ),
            );
            let p = _mm256_mul_pd(normal, _mm256_sub_pd(a, e));
            let (pxy, pz) = (_mm256_castpd256_pd128(p), _mm256_extractf128_pd::<1>(p));
            let num = _mm_cvtsd_f64(_mm_add_sd(_mm_add_sd(pxy, _mm_unpackhi_pd(pxy, pxy)), pz));
            let lo = _mm256_cvtps_pd(_mm_min_ps(_mm_min_ps(qa, qb), qc));
            let hi = _mm256_cvtps_pd(_mm_max_ps(_mm_max_ps(qa, qb), qc));
            let sign = _mm256_set1_pd(-0.0);
            let m = _mm256_mul_pd(
                _mm256_max_pd(
                    _mm256_andnot_pd(sign, _mm256_sub_pd(lo, e)),
                    _mm256_andnot_pd(sign, _mm256_sub_pd(hi, e)),
                ),
                _mm256_set1_pd(crate::visibility::BOX_MARGIN),
            );
            let (blo, bhi) = (_mm256_sub_pd(lo, m), _mm256_add_pd(hi, m));
            let (slo, shi) = (_mm256_sub_pd(blo, e), _mm256_sub_pd(bhi, e));
            let mm = _mm256_mul_pd(
                _mm256_set1_pd(CLAMP_FREE_MARGIN),
                _mm256_max_pd(_mm256_andnot_pd(sign, slo), _mm256_andnot_pd(sign, shi)),
            );
            let misses = _mm256_or_pd(
                _mm256_cmp_pd::<_CMP_LT_OQ>(e, blo),
                _mm256_cmp_pd::<_CMP_GT_OQ>(e, bhi),
            );
            let settles = _mm256_cmp_pd::<_CMP_GE_OQ>(
                _mm256_andnot_pd(sign, mm),
                _mm256_set1_pd(CLAMP_FREE_MIN_MARGIN),
            );
            let free_lo = _mm256_blendv_pd(
                _mm256_set1_pd(f64::INFINITY),
                _mm256_add_pd(slo, mm),
                settles,
            );
            let free_hi = _mm256_blendv_pd(
                _mm256_set1_pd(f64::NEG_INFINITY),
                _mm256_sub_pd(shi, mm),
                settles,
            );
            let mut out = [[0f64; 4]; 5];
            for (o, x) in out.iter_mut().zip([normal, slo, shi, free_lo, free_hi]) {
                _mm256_storeu_pd(o.as_mut_ptr(), x);
            }
            let three = |o: [f64; 4]| [o[0], o[1], o[2]];
            let bits = _mm256_movemask_pd(misses);
            ChunkDepth {
                normal: three(out[0]),
                num,
                lo: three(out[1]),
                hi: three(out[2]),
                zero_misses: [bits & 1 != 0, bits & 2 != 0, bits & 4 != 0],
                clamp_free_lo: three(out[3]),
                clamp_free_hi: three(out[4]),
            }
        }
    }

    #[inline(always)]
    fn gt(self, a: &[f64; CHUNK], b: f64) -> u32 {
        // SAFETY: an `Avx2` exists only on a CPU with AVX2 (see `detect`), and
        // the loads read the 8 f64 of the array borrowed here, 4 at a time.
        unsafe {
            let b = _mm256_set1_pd(b);
            let lo = _mm256_cmp_pd::<_CMP_GT_OQ>(_mm256_loadu_pd(a.as_ptr()), b);
            let hi = _mm256_cmp_pd::<_CMP_GT_OQ>(_mm256_loadu_pd(a.as_ptr().add(4)), b);
            (_mm256_movemask_pd(lo) | (_mm256_movemask_pd(hi) << 4)) as u32
        }
    }

    #[inline(always)]
    fn clamp_free_depths(
        self,
        cd: &ChunkDepth,
        cam: &Camera,
        d: [&[f64; CHUNK]; 3],
        planar: &[f64; CHUNK],
        want: u32,
    ) -> Option<([f32; CHUNK], u32, u32)> {
        let mut z = [0f32; CHUNK];
        let (mut ok, mut free) = (0u32, 0u32);
        // SAFETY: an `Avx2` exists only on a CPU with AVX2; the loads read
        // 4 f64 of the borrowed 8-lane arrays, the stores write 4 f32 of `z`.
        // Each lane is `ChunkDepth::lanes`' arithmetic, operation for
        // operation (mul, add, div, compares; `cvtpd2ps` rounds to nearest
        // like `as f32`, `cvtps2pd` is exact).
        unsafe {
            let abs_mask = _mm256_castsi256_pd(_mm256_set1_epi64x(i64::MAX));
            // No array `map` or closure around intrinsics (see `filter4`).
            let (cn, cl, ch) = (cd.normal, cd.clamp_free_lo, cd.clamp_free_hi);
            let n = [
                _mm256_set1_pd(cn[0]),
                _mm256_set1_pd(cn[1]),
                _mm256_set1_pd(cn[2]),
            ];
            let num = _mm256_set1_pd(cd.num);
            let lo = [
                _mm256_set1_pd(cl[0]),
                _mm256_set1_pd(cl[1]),
                _mm256_set1_pd(cl[2]),
            ];
            let hi = [
                _mm256_set1_pd(ch[0]),
                _mm256_set1_pd(ch[1]),
                _mm256_set1_pd(ch[2]),
            ];
            let max_t = _mm256_set1_pd(CLAMP_FREE_MAX_T);
            let (zero, inf) = (_mm256_setzero_pd(), _mm256_set1_pd(f64::INFINITY));
            let (near, far) = (_mm256_set1_pd(cam.near), _mm256_set1_pd(cam.far));
            for h in 0..2 {
                if (want >> (4 * h)) & 0xf == 0 {
                    continue;
                }
                let dk = [
                    _mm256_loadu_pd(d[0].as_ptr().add(4 * h)),
                    _mm256_loadu_pd(d[1].as_ptr().add(4 * h)),
                    _mm256_loadu_pd(d[2].as_ptr().add(4 * h)),
                ];
                // DVec3::dot: x*x' + y*y' + z*z', left to right.
                let denom = _mm256_add_pd(
                    _mm256_add_pd(_mm256_mul_pd(n[0], dk[0]), _mm256_mul_pd(n[1], dk[1])),
                    _mm256_mul_pd(n[2], dk[2]),
                );
                let t = _mm256_div_pd(num, denom);
                let mut f = _mm256_cmp_pd::<_CMP_LE_OQ>(_mm256_and_pd(t, abs_mask), max_t);
                for k in 0..3 {
                    let q = _mm256_mul_pd(t, dk[k]);
                    f = _mm256_and_pd(f, _mm256_cmp_pd::<_CMP_GE_OQ>(q, lo[k]));
                    f = _mm256_and_pd(f, _mm256_cmp_pd::<_CMP_LE_OQ>(q, hi[k]));
                }
                let valid = _mm256_and_pd(
                    _mm256_cmp_pd::<_CMP_NEQ_OQ>(denom, zero),
                    _mm256_cmp_pd::<_CMP_LT_OQ>(_mm256_and_pd(denom, abs_mask), inf),
                );
                let zs = _mm256_cvtpd_ps(_mm256_mul_pd(
                    t,
                    _mm256_loadu_pd(planar.as_ptr().add(4 * h)),
                ));
                _mm_storeu_ps(z.as_mut_ptr().add(4 * h), zs);
                let zf = _mm256_cvtps_pd(zs);
                let in_range = _mm256_and_pd(
                    _mm256_cmp_pd::<_CMP_GE_OQ>(zf, near),
                    _mm256_cmp_pd::<_CMP_LE_OQ>(zf, far),
                );
                ok |= (_mm256_movemask_pd(_mm256_and_pd(valid, in_range)) as u32) << (4 * h);
                free |= (_mm256_movemask_pd(f) as u32) << (4 * h);
            }
        }
        Some((z, ok, free))
    }

    #[inline(always)]
    fn small_signs(self, eye: DVec3, t: &Tri, d: &[[f64; 4]; 3], n: usize) -> (u32, u32, u32) {
        let (mut front, mut back, mut open) = (0u32, 0u32, 0u32);
        // SAFETY: an `Avx2` exists only on a CPU with AVX2; no memory is
        // touched but the borrowed arrays, read by index. Lane `k` is edge
        // `k` (lane 3 repeats edge 0): `EdgePlane::new`'s operations on its
        // endpoints, then `EdgePlane::filter`'s per ray, in their orders
        // (`abs` and negation by sign bit, exact).
        unsafe {
            let sign = _mm256_set1_pd(-0.0);
            // Per component, `v - eye` for the vertices a, b, c, a (each
            // widened exactly), and the edges' second endpoints b, c, a, b.
            // (No closures around intrinsics: see `filter4`.)
            let (v0, v1, v2) = (t[0].as_dvec3(), t[1].as_dvec3(), t[2].as_dvec3());
            let ax = _mm256_sub_pd(_mm256_set_pd(v0.x, v2.x, v1.x, v0.x), _mm256_set1_pd(eye.x));
            let ay = _mm256_sub_pd(_mm256_set_pd(v0.y, v2.y, v1.y, v0.y), _mm256_set1_pd(eye.y));
            let az = _mm256_sub_pd(_mm256_set_pd(v0.z, v2.z, v1.z, v0.z), _mm256_set1_pd(eye.z));
            const NEXT: i32 = 0b01_00_10_01;
            let bx = _mm256_permute4x64_pd::<NEXT>(ax);
            let by = _mm256_permute4x64_pd::<NEXT>(ay);
            let bz = _mm256_permute4x64_pd::<NEXT>(az);
            let (yz, zy) = (_mm256_mul_pd(ay, bz), _mm256_mul_pd(az, by));
            let (zx, xz) = (_mm256_mul_pd(az, bx), _mm256_mul_pd(ax, bz));
            let (xy, yx) = (_mm256_mul_pd(ax, by), _mm256_mul_pd(ay, bx));
            let nx = _mm256_sub_pd(yz, zy);
            let ny = _mm256_sub_pd(zx, xz);
            let nz = _mm256_sub_pd(xy, yx);
            let px = _mm256_add_pd(_mm256_andnot_pd(sign, yz), _mm256_andnot_pd(sign, zy));
            let py = _mm256_add_pd(_mm256_andnot_pd(sign, zx), _mm256_andnot_pd(sign, xz));
            let pz = _mm256_add_pd(_mm256_andnot_pd(sign, xy), _mm256_andnot_pd(sign, yx));
            let bound_a = _mm256_set1_pd(crate::predicate::O3D_ERRBOUND_A);
            let [dx, dy, dz] = d;
            for (j, ((&x, &y), &z)) in dx.iter().zip(dy).zip(dz).take(n).enumerate() {
                let (vx, vy, vz) = (_mm256_set1_pd(x), _mm256_set1_pd(y), _mm256_set1_pd(z));
                let det = _mm256_add_pd(
                    _mm256_add_pd(_mm256_mul_pd(vx, nx), _mm256_mul_pd(vy, ny)),
                    _mm256_mul_pd(vz, nz),
                );
                let (ux, uy, uz) = (
                    _mm256_andnot_pd(sign, vx),
                    _mm256_andnot_pd(sign, vy),
                    _mm256_andnot_pd(sign, vz),
                );
                let sum = _mm256_add_pd(
                    _mm256_add_pd(_mm256_mul_pd(ux, px), _mm256_mul_pd(uy, py)),
                    _mm256_mul_pd(uz, pz),
                );
                let bound = _mm256_mul_pd(bound_a, sum);
                let minus = _mm256_xor_pd(det, sign);
                let pos = _mm256_movemask_pd(_mm256_cmp_pd::<_CMP_GT_OQ>(det, bound)) as u32 & 7;
                let neg = _mm256_movemask_pd(_mm256_cmp_pd::<_CMP_GT_OQ>(minus, bound)) as u32 & 7;
                front |= u32::from(pos == 7) << j;
                back |= u32::from(neg == 7) << j;
                open |= u32::from((pos | neg) != 7) << j;
            }
        }
        (front, back, open)
    }

    #[inline(always)]
    fn filter4(self, e: &[EdgePlane; 3], d: &[[f64; 4]; 3]) -> ([u32; 3], [u32; 3]) {
        let (mut pos, mut neg) = ([0u32; 3], [0u32; 3]);
        // SAFETY: an `Avx2` exists only on a CPU with AVX2; the loads read
        // the four f64 of each borrowed array. Per lane: `EdgePlane::filter`'s
        // operations in its order (`abs` and negation by sign bit, exact).
        unsafe {
            let sign = _mm256_set1_pd(-0.0);
            let a = _mm256_set1_pd(crate::predicate::O3D_ERRBOUND_A);
            // No array `map` around intrinsics: its closures can be
            // compiled out of line, without this function's target features
            // (each intrinsic then a call).
            let x = _mm256_loadu_pd(d[0].as_ptr());
            let y = _mm256_loadu_pd(d[1].as_ptr());
            let z = _mm256_loadu_pd(d[2].as_ptr());
            let (ax, ay, az) = (
                _mm256_andnot_pd(sign, x),
                _mm256_andnot_pd(sign, y),
                _mm256_andnot_pd(sign, z),
            );
            for (k, e) in e.iter().enumerate() {
                let n = [
                    _mm256_set1_pd(e.n.x),
                    _mm256_set1_pd(e.n.y),
                    _mm256_set1_pd(e.n.z),
                ];
                let p = [
                    _mm256_set1_pd(e.perm.x),
                    _mm256_set1_pd(e.perm.y),
                    _mm256_set1_pd(e.perm.z),
                ];
                let det = _mm256_add_pd(
                    _mm256_add_pd(_mm256_mul_pd(x, n[0]), _mm256_mul_pd(y, n[1])),
                    _mm256_mul_pd(z, n[2]),
                );
                let sum = _mm256_add_pd(
                    _mm256_add_pd(_mm256_mul_pd(ax, p[0]), _mm256_mul_pd(ay, p[1])),
                    _mm256_mul_pd(az, p[2]),
                );
                let bound = _mm256_mul_pd(a, sum);
                let minus = _mm256_xor_pd(det, sign);
                pos[k] = _mm256_movemask_pd(_mm256_cmp_pd::<_CMP_GT_OQ>(det, bound)) as u32;
                neg[k] = _mm256_movemask_pd(_mm256_cmp_pd::<_CMP_GT_OQ>(minus, bound)) as u32;
            }
        }
        (pos, neg)
    }

    #[inline(always)]
    fn dir_row(self, e: f64, up: f64, across: &[f64], d: &mut [f64], ext: Option<&mut Extremes>) {
        let n = d.len().min(across.len());
        let whole = n / 4 * 4;
        // SAFETY: an `Avx2` exists only on a CPU with AVX2; loads and
        // stores touch 4 f64 at `i + 4 <= n`, within both slices, and the
        // four lanes of `ext`'s arrays. Per lane: `dir_lane`'s operations in
        // its order, and `Extremes::add`'s (`minpd(v, lo)` is `if v < lo {
        // v } else { lo }`).
        unsafe {
            let (ev, uv) = (_mm256_set1_pd(e), _mm256_set1_pd(up));
            let (a, out) = (across.as_ptr(), d.as_mut_ptr());
            match ext {
                Some(ext) => {
                    let mut wide = WideExtremes::load(ext);
                    for i in (0..whole).step_by(4) {
                        wide.add(dir_lanes4(ev, uv, a.add(i), out.add(i)));
                    }
                    wide.store(ext);
                    Portable.dir_row(e, up, &across[whole..n], &mut d[whole..n], Some(ext));
                }
                None => {
                    for i in (0..whole).step_by(4) {
                        dir_lanes4(ev, uv, a.add(i), out.add(i));
                    }
                    Portable.dir_row(e, up, &across[whole..n], &mut d[whole..n], None);
                }
            }
        }
    }

    #[inline(always)]
    fn planar_row(self, f: [f64; 3], [x, y, z]: [&[f64]; 3], p: &mut [f64]) {
        let n = p.len().min(x.len()).min(y.len()).min(z.len());
        let whole = n / 4 * 4;
        // SAFETY: as in `dir_row`: 4 f64 at `i + 4 <= n` of each slice.
        // Per lane `(x f0 + y f1) + z f2`.
        unsafe {
            let (f0, f1, f2) = (
                _mm256_set1_pd(f[0]),
                _mm256_set1_pd(f[1]),
                _mm256_set1_pd(f[2]),
            );
            for i in (0..whole).step_by(4) {
                let xv = _mm256_mul_pd(_mm256_loadu_pd(x.as_ptr().add(i)), f0);
                let yv = _mm256_mul_pd(_mm256_loadu_pd(y.as_ptr().add(i)), f1);
                let zv = _mm256_mul_pd(_mm256_loadu_pd(z.as_ptr().add(i)), f2);
                let v = _mm256_add_pd(_mm256_add_pd(xv, yv), zv);
                _mm256_storeu_pd(p.as_mut_ptr().add(i), v);
            }
        }
        let rest = [&x[whole..n], &y[whole..n], &z[whole..n]];
        Portable.planar_row(f, rest, &mut p[whole..n]);
    }

    #[inline(always)]
    fn screen_row(self, p: &ScreenRow, sx: &[f64; CHUNK]) -> ([f32; CHUNK], u32, u32) {
        let mut z = [0f32; CHUNK];
        let (mut ok, mut sure) = (0u32, 0u32);
        // SAFETY: an `Avx2` exists only on a CPU with AVX2; loads and stores
        // stay within the borrowed arrays (4 f64 or 4 f32 at a time).
        unsafe {
            let (num, a, r) = (
                _mm256_set1_pd(p.num),
                _mm256_set1_pd(p.a),
                _mm256_set1_pd(p.r),
            );
            let (near, far) = (_mm256_set1_pd(p.near), _mm256_set1_pd(p.far));
            let eu = _mm256_set1_epi64x(p.eu);
            for h in 0..2 {
                // Each lane is `ScreenRow::lanes`' arithmetic, operation for operation.
                let x = _mm256_loadu_pd(sx.as_ptr().add(4 * h));
                let w = _mm256_div_pd(num, _mm256_add_pd(_mm256_mul_pd(a, x), r));
                let zh = _mm256_cvtpd_ps(w);
                _mm_storeu_ps(z.as_mut_ptr().add(4 * h), zh);
                let zf = _mm256_cvtps_pd(zh);
                let hit = _mm256_and_pd(
                    _mm256_cmp_pd::<_CMP_GE_OQ>(zf, near),
                    _mm256_cmp_pd::<_CMP_LE_OQ>(zf, far),
                );
                ok |= (_mm256_movemask_pd(hit) as u32) << (4 * h);
                let alone = _mm256_castsi256_pd(rounds_alone4(w, eu));
                sure |= (_mm256_movemask_pd(alone) as u32) << (4 * h);
            }
        }
        (z, ok, sure)
    }

    #[inline(always)]
    #[allow(clippy::too_many_arguments)]
    fn screen_keys(
        self,
        p: &ScreenRow,
        r: &[f64; CHUNK],
        sx: &[f64; CHUNK],
        rows: &mut BlockRows,
        prim: u32,
    ) -> u32 {
        let mut done = 0;
        // SAFETY: an `Avx2` exists only on a CPU with AVX2; loads read the
        // borrowed arrays, and each key row is 8 keys.
        unsafe {
            let num = _mm256_set1_pd(p.num);
            let a = _mm256_set1_pd(p.a);
            // `fl(a sx)` is the same in every row.
            let ax0 = _mm256_mul_pd(a, _mm256_loadu_pd(sx.as_ptr()));
            let ax1 = _mm256_mul_pd(a, _mm256_loadu_pd(sx.as_ptr().add(4)));
            let eu = _mm256_set1_epi64x(p.eu);
            let low = _mm256_set1_epi64x(i64::from(prim));
            for (i, &r) in r.iter().enumerate() {
                let rv = _mm256_set1_pd(r);
                let w0 = _mm256_div_pd(num, _mm256_add_pd(ax0, rv));
                let w1 = _mm256_div_pd(num, _mm256_add_pd(ax1, rv));
                // (Helpers, not closures: a closure here was compiled out
                // of line, without AVX2, its intrinsics then calls.)
                let sure = _mm256_and_si256(rounds_alone4(w0, eu), rounds_alone4(w1, eu));
                if _mm256_movemask_pd(_mm256_castsi256_pd(sure)) != 0xf {
                    continue;
                }
                // `min_keys` with every lane a hit.
                let row = rows[i].as_mut_ptr();
                let bits0 = _mm_castps_si128(_mm256_cvtpd_ps(w0));
                let bits1 = _mm_castps_si128(_mm256_cvtpd_ps(w1));
                min_keys4(row, hit_keys4(bits0, low));
                min_keys4(row.add(4), hit_keys4(bits1, low));
                done |= 1 << i;
            }
        }
        done
    }

    #[inline(always)]
    fn min_key_rows(self, rows: &mut BlockRows, key: &[u64; CHUNK]) {
        // SAFETY: an `Avx2` exists only on a CPU with AVX2; each row is 8 keys.
        unsafe {
            for (row, &k) in rows.iter_mut().zip(key) {
                let row = row.as_mut_ptr();
                let new = _mm256_set1_epi64x(k as i64);
                min_keys4(row, new);
                min_keys4(row.add(4), new);
            }
        }
    }

    #[inline(always)]
    fn min_keys(self, keys: &mut [u64; CHUNK], z: &[f32; CHUNK], hits: u32, prim: u32) {
        // SAFETY: an `Avx2` exists only on a CPU with AVX2; loads and stores
        // stay within the borrowed arrays (4 u64 or 4 f32 at a time).
        unsafe {
            let low = _mm256_set1_epi64x(i64::from(prim));
            let no_hit = _mm256_set1_epi64x(-1);
            let lane_bit = _mm256_setr_epi64x(1, 2, 4, 8);
            for h in 0..2 {
                let bits = _mm_loadu_si128(z.as_ptr().add(4 * h).cast());
                let sel = _mm256_set1_epi64x(i64::from((hits >> (4 * h)) & 0xf));
                let hit = _mm256_cmpeq_epi64(_mm256_and_si256(sel, lane_bit), lane_bit);
                let new = _mm256_blendv_epi8(no_hit, hit_keys4(bits, low), hit);
                min_keys4(keys.as_mut_ptr().add(4 * h), new);
            }
        }
    }
}

/// [`rounds_alone`](crate::raster::screen_depth::rounds_alone) on four
/// lanes: all ones where `|low 29 bits of w - midpoint| > eu`, the one
/// wide form of the certificate ([`Avx2`]'s `screen_row` and `screen_keys`).
///
/// # Safety
/// The CPU has AVX2 (callers hold an [`Avx2`]).
#[inline(always)]
unsafe fn rounds_alone4(w: __m256d, eu: __m256i) -> __m256i {
    // SAFETY: the caller holds an `Avx2` (this fn's contract); no memory access.
    unsafe {
        let mask = _mm256_set1_epi64x(DROPPED_MASK as i64);
        let d = _mm256_sub_epi64(
            _mm256_and_si256(_mm256_castpd_si256(w), mask),
            _mm256_set1_epi64x(MIDPOINT),
        );
        let neg = _mm256_sub_epi64(_mm256_setzero_si256(), d);
        // |d|: the negation where d's sign bit is set.
        let abs = _mm256_blendv_pd(
            _mm256_castsi256_pd(d),
            _mm256_castsi256_pd(neg),
            _mm256_castsi256_pd(d),
        );
        _mm256_cmpgt_epi64(_mm256_castpd_si256(abs), eu)
    }
}

/// The z-test on four keys at `ptr`: each lowered to `new` where that is
/// smaller as an unsigned key ([`Avx2`]'s `min_keys` and `screen_keys`).
///
/// # Safety
/// The CPU has AVX2, and `ptr` points to four keys the caller may write.
#[inline(always)]
unsafe fn min_keys4(ptr: *mut u64, new: __m256i) {
    // SAFETY: the caller guarantees AVX2 and that `ptr` points to four keys it may write (this fn's contract).
    unsafe {
        let sign = _mm256_set1_epi64x(i64::MIN);
        let p = ptr.cast::<__m256i>();
        let old = _mm256_loadu_si256(p);
        // Unsigned comparison as signed, with the top bits flipped.
        let old_bigger =
            _mm256_cmpgt_epi64(_mm256_xor_si256(old, sign), _mm256_xor_si256(new, sign));
        _mm256_storeu_si256(p, _mm256_blendv_epi8(old, new, old_bigger));
    }
}

/// `hit_key` on four lanes: the f32 bits (`bits`) above, `low` (the prim,
/// broadcast) below.
///
/// # Safety
/// The CPU has AVX2.
#[inline(always)]
unsafe fn hit_keys4(bits: __m128i, low: __m256i) -> __m256i {
    // SAFETY: the caller guarantees AVX2 (this fn's contract); no memory access.
    unsafe { _mm256_or_si256(_mm256_slli_epi64::<32>(_mm256_cvtepu32_epi64(bits)), low) }
}

/// A vertex's `(x, y, z, 0)` in f32 lanes ([`Avx2`]'s `chunk_depth`).
///
/// # Safety
/// The CPU has AVX2 (callers hold an [`Avx2`]).
#[inline(always)]
unsafe fn xyz0(p: glam::Vec3) -> __m128 {
    // SAFETY: the caller holds an `Avx2` (this fn's contract); no memory access.
    unsafe { _mm_setr_ps(p.x, p.y, p.z, 0.0) }
}

/// `dir_lane` on four lanes: `(e + (across + up)) - e` for the four values
/// at `across`, written to `d` and returned ([`Avx2`]'s `dir_row`).
///
/// # Safety
/// The CPU has AVX2, `across` points to four f64 the caller may read and
/// `d` to four it may write.
#[inline(always)]
unsafe fn dir_lanes4(e: __m256d, up: __m256d, across: *const f64, d: *mut f64) -> __m256d {
    // SAFETY: the caller guarantees AVX2 and the four f64 at `across` and
    // at `d` (this fn's contract). Per lane `dir_lane`'s operations in its order.
    unsafe {
        let a = _mm256_loadu_pd(across);
        let v = _mm256_sub_pd(_mm256_add_pd(e, _mm256_add_pd(a, up)), e);
        _mm256_storeu_pd(d, v);
        v
    }
}

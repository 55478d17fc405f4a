//! The packet kernel's row operations: 8 lanes at once, read off as 8 mask bits.
//!
//! The packet kernel decides everything per lane with f32 comparisons and then
//! works with bit masks: the box test ([`box_out`]), a triangle's edge signs
//! ([`edge_signs`]) and the frustum test of a node's two children
//! ([`planes_out`]). Written as plain loops over a packet, their speed
//! depended on the compiler's inlining and vectorizing choices (the same box
//! test ran 2.5x slower in an LTO build, its intervals spilled to the stack),
//! and left to itself the compiler turns `m |= (a > b) << i` into an
//! and-with-constants plus an or-reduction, about eight instructions per row,
//! where AVX's `vmovmskps` does it in one. So each test is written once,
//! width-generic, over the lanes of [`RowLanes`] (in [`crate::simd`]: plain
//! Rust for every CPU, AVX2 intrinsics for a row, AVX-512 for two rows at
//! once), and [`Rows`] names the lanes the kernel uses for one row and for
//! a pair; plain Rust's lanes are the definition the tests hold the others
//! to.

use super::frustum::{BOX_ABS, BOX_REL};
use super::primary::Node32;
use crate::simd::RowLanes;

/// Per axis, a box's bounds in the order a row of lanes meets them: `(near,
/// far, mixed)`, where `near * 1/D` is the entry parameter when every lane's
/// `1/D` has one sign, and `mixed` says the lanes differ (both orders taken).
pub(crate) type BoxAxes = [(f32, f32, bool); 3];

/// Lanes per row: one 256-bit vector of f32.
pub(crate) const ROW: usize = 8;

/// Lanes in two neighbouring rows: one 512-bit vector of f32 ([`Rows::PAIRS`]).
pub(crate) const ROW2: usize = 2 * ROW;

/// The lanes the packet kernel's row tests run in: `(R, P)`, `R` for one
/// row and `P` for two neighbouring rows (lanes 0-7 the first row, 8-15 the
/// second; lane by lane, so the same bits as the two single rows). The
/// kernel takes pairs only where `P` is one vector (AVX-512's 16 lanes);
/// elsewhere it keeps to single rows, which skip more work when a triangle
/// meets one row only.
pub(crate) trait Rows: Copy {
    /// Lanes for one row.
    type One: RowLanes<ROW>;
    /// Lanes for a pair of rows.
    type Two: RowLanes<ROW2>;
    /// Whether the kernel takes two rows in one step.
    const PAIRS: bool;
    /// The lanes for one row.
    fn one(self) -> Self::One;
    /// The lanes for a pair of rows.
    fn two(self) -> Self::Two;
}

impl<R: RowLanes<ROW>, P: RowLanes<ROW2>> Rows for (R, P) {
    type One = R;
    type Two = P;
    const PAIRS: bool = P::VECTOR;
    #[inline(always)]
    fn one(self) -> R {
        self.0
    }
    #[inline(always)]
    fn two(self) -> P {
        self.1
    }
}

/// The packet box test for `N` lanes (a row or a pair): bit `j` set where
/// lane `j` misses the box (`tmin > tmax (1 + s)`, with `tmin` starting at
/// 0, as in `Packet::node_mask`), or where its entry depth `tmin zscale` is
/// beyond `best_z`. `inv` is the lanes' `1/D` per axis.
#[inline(always)]
pub(crate) fn box_out<const N: usize, L: RowLanes<N>>(
    l: L,
    axes: &BoxAxes,
    inv: [&[f32; N]; 3],
    zscale: &[f32; N],
    best_z: &[f32; N],
) -> u32 {
    let (mut tmin, mut tmax) = (l.splat(0.0), l.splat(f32::INFINITY));
    for (&(near, far, mixed), inv) in axes.iter().zip(inv) {
        let inv = l.load(inv);
        let (t0, t1) = (l.mul(l.splat(near), inv), l.mul(l.splat(far), inv));
        let (t0, t1) = if mixed {
            (l.min(t0, t1), l.max(t0, t1))
        } else {
            (t0, t1)
        };
        tmin = l.max(tmin, t0);
        tmax = l.min(tmax, t1);
    }
    // `Node32::slack_tmax` and the pruning comparison.
    let slack = l.mul(tmax, l.splat(Node32::TMAX_SLACK));
    let entry_z = l.mul(tmin, l.load(zscale));
    l.gt(tmin, slack) | l.gt(entry_z, l.load(best_z))
}

/// A triangle's three f32 edge signs for `N` lanes: per edge `k` (normal
/// `n[k]`, filter bound `beta[k]`), the bits of the lanes where
/// [`super::primary::edge_det32`]'s determinant certainly clears its bound
/// above, and where it certainly clears it below; its operations in its
/// order (`(n0 d0 + n1 d1) + n2 d2`).
#[inline(always)]
pub(crate) fn edge_signs<const N: usize, L: RowLanes<N>>(
    l: L,
    n: &[[f32; 3]; 3],
    beta: &[f32; 3],
    dir: [&[f32; N]; 3],
    dir_norm: &[f32; N],
) -> [(u32, u32); 3] {
    // (Not `dir.map`: array `map` compiled to an out-of-line call here.)
    let d = [l.load(dir[0]), l.load(dir[1]), l.load(dir[2])];
    let dn = l.load(dir_norm);
    let mut out = [(0, 0); 3];
    for ((n, &beta), out) in n.iter().zip(beta).zip(&mut out) {
        let det = l.add(
            l.add(l.mul(l.splat(n[0]), d[0]), l.mul(l.splat(n[1]), d[1])),
            l.mul(l.splat(n[2]), d[2]),
        );
        let bound = l.mul(l.splat(beta), dn);
        *out = (l.gt(det, bound), l.gt(l.neg(det), bound));
    }
    out
}

/// The frustum test of two boxes ([`super::frustum`]): lane `j` holds
/// plane `j % 4`'s normal `n[..][j]` against box `a` (lanes 0-3) or `b`
/// (lanes 4-7), given per axis as `(lo, hi)`; bit `j` is set where the
/// box's far corner along the normal is proven below the plane:
/// `s < -(BOX_REL mag + BOX_ABS)`, with `s` the sum of
/// `max(n lo, n hi)` over the axes in order and `mag` that of their
/// magnitudes.
#[inline(always)]
pub(crate) fn planes_out<L: RowLanes<ROW>>(
    l: L,
    n: &[[f32; ROW]; 3],
    a: &[(f32, f32); 3],
    b: &[(f32, f32); 3],
) -> u32 {
    let (mut s, mut mag) = (l.splat(0.0), l.splat(0.0));
    for k in 0..3 {
        let (lo, hi) = (l.halves(a[k].0, b[k].0), l.halves(a[k].1, b[k].1));
        let nk = l.load(&n[k]);
        let p = l.max(l.mul(nk, lo), l.mul(nk, hi));
        s = l.add(s, p);
        mag = l.add(mag, l.abs(p));
    }
    let bound = l.add(l.mul(l.splat(BOX_REL), mag), l.splat(BOX_ABS));
    l.lt(s, l.neg(bound))
}

#[cfg(test)]
mod tests {
    use super::super::primary::{max, min};
    use super::*;
    use crate::simd::Portable;
    #[cfg(target_arch = "x86_64")]
    use crate::simd::{Avx2, Avx512};

    /// A small deterministic generator of indices below `n` (an LCG), so
    /// each test draws the same cases on every run.
    fn picker(seed: u32) -> impl FnMut(usize) -> usize {
        let mut s = seed;
        move |n| {
            s = s.wrapping_mul(1664525).wrapping_add(1013904223);
            (s >> 8) as usize % n
        }
    }

    /// One axis of a drawn box test, box bounds `lo <= hi`: the ray lanes'
    /// `1/D` in `inv` drawn from `vals`, of both signs (the axis `mixed`,
    /// bounds in both orders), all positive (`lo` the near bound) or all
    /// negative (`hi` the near one), as `Packet::node_mask` orders them.
    fn random_axis<const N: usize>(
        (lo, hi): (f32, f32),
        vals: &[f32],
        next: &mut impl FnMut(usize) -> usize,
        inv: &mut [f32; N],
    ) -> (f32, f32, bool) {
        let sign = next(3);
        for v in inv.iter_mut() {
            let x = vals[next(vals.len())];
            *v = match sign {
                0 => x,
                1 => x.abs(),
                _ => -x.abs(),
            };
        }
        match sign {
            0 => (lo, hi, true),
            1 => (lo, hi, false),
            _ => (hi, lo, false),
        }
    }

    /// Every single-row test in each row lanes this CPU has gives plain
    /// Rust's bits, and plain Rust's are the lane-by-lane definitions.
    #[test]
    fn row_forms_agree() {
        row_tests_agree(Portable);
        #[cfg(target_arch = "x86_64")]
        if let Some(avx) = Avx2::detect() {
            row_tests_agree(avx);
        }
    }

    /// Values of both signs that round, cancel and overflow in the edge
    /// and plane tests (their first eight), then `rest`.
    fn with(rest: &[f32]) -> Vec<f32> {
        let signed = [0.0, -0.0, 1.0, -1.0, 0.1, -3.3, 1e20, -1e20];
        signed.iter().chain(rest).copied().collect()
    }

    /// The three single-row tests in the lanes `l`.
    fn row_tests_agree<L: RowLanes<ROW>>(l: L) {
        box_out_agrees(l);
        edge_signs_agree(l);
        planes_out_agree(l);
    }

    /// The box test in `l` agrees with plain Rust bit for bit, on both axis
    /// orders and on infinities, signed zeros and ties; and plain Rust's is
    /// the per-lane slab test of `Node32::misses` with the pruning comparison.
    fn box_out_agrees<L: RowLanes<ROW>>(l: L) {
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
        let mut next = picker(11);
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
                *a = random_axis((lo, hi), &vals, &mut next, &mut inv[k]);
            }
            let zscale: [f32; ROW] = std::array::from_fn(|_| vals[next(5)].abs());
            let best_z: [f32; ROW] = std::array::from_fn(|_| vals[next(5)].abs());
            let inv_rows = [&inv[0], &inv[1], &inv[2]];
            let want = box_out(Portable, &axes, inv_rows, &zscale, &best_z);
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
            let got = box_out(l, &axes, inv_rows, &zscale, &best_z);
            assert_eq!(got, want, "{axes:?}");
        }
        // Both answers occur often.
        assert!(outs > 1000 && ins > 1000, "{outs} out, {ins} in");
    }

    /// The first and second row of a pair of rows.
    fn halves(a: &[f32; ROW2]) -> (&[f32; ROW], &[f32; ROW]) {
        let (lo, hi) = a.split_at(ROW);
        (lo.try_into().unwrap(), hi.try_into().unwrap())
    }

    /// A pair of rows gives the two single rows' bits (bits 0-7 the first,
    /// 8-15 the second), box test and edge signs, in plain Rust and in
    /// AVX-512, on the single-row tests' kinds of values: both axis orders,
    /// infinities, signed zeros, NaN products, overflow and ties.
    #[test]
    fn pair_forms_agree() {
        let vals = [
            0.5,
            -0.5,
            2.0,
            -3.0,
            0.0,
            -0.0,
            1e-20,
            1e20,
            -1e20,
            f32::INFINITY,
            f32::NEG_INFINITY,
            f32::MAX,
        ];
        let mut next = picker(13);
        let mut seen = [0u32; 3];
        for _ in 0..4000 {
            let mut axes: BoxAxes = [(0.0, 0.0, false); 3];
            let mut inv = [[0f32; ROW2]; 3];
            for (k, a) in axes.iter_mut().enumerate() {
                let (x, y) = (vals[next(9)], vals[next(9)]);
                let (lo, hi) = (x.min(y), x.max(y));
                *a = random_axis((lo, hi), &vals, &mut next, &mut inv[k]);
            }
            let lanes = |next: &mut dyn FnMut(usize) -> usize| -> [f32; ROW2] {
                std::array::from_fn(|_| vals[next(vals.len())].abs())
            };
            let (zscale, best_z) = (lanes(&mut next), lanes(&mut next));
            let [(i0, i1), (j0, j1), (k0, k1)] = [&inv[0], &inv[1], &inv[2]].map(halves);
            let ((z0, z1), (b0, b1)) = (halves(&zscale), halves(&best_z));
            let want = box_out(Portable, &axes, [i0, j0, k0], z0, b0)
                | box_out(Portable, &axes, [i1, j1, k1], z1, b1) << ROW;
            let inv_rows = [&inv[0], &inv[1], &inv[2]];
            let pair = box_out(Portable, &axes, inv_rows, &zscale, &best_z);
            assert_eq!(pair, want, "{axes:?} {inv:?}");
            #[cfg(target_arch = "x86_64")]
            if let Some(wide) = Avx512::detect() {
                let got = box_out(wide, &axes, inv_rows, &zscale, &best_z);
                assert_eq!(got, want, "{axes:?} {inv:?}");
            }
            seen[0] += want.count_ones();
            let n: [[f32; 3]; 3] =
                std::array::from_fn(|_| std::array::from_fn(|_| vals[next(vals.len())]));
            let beta: [f32; 3] = std::array::from_fn(|_| vals[next(vals.len())].abs());
            let dir: [[f32; ROW2]; 3] =
                std::array::from_fn(|_| std::array::from_fn(|_| vals[next(vals.len())]));
            let dir_norm = lanes(&mut next);
            let [(d0, d1), (e0, e1), (f0, f1)] = [&dir[0], &dir[1], &dir[2]].map(halves);
            let (n0, n1) = halves(&dir_norm);
            let a = edge_signs(Portable, &n, &beta, [d0, e0, f0], n0);
            let b = edge_signs(Portable, &n, &beta, [d1, e1, f1], n1);
            let want = [0, 1, 2].map(|k| (a[k].0 | b[k].0 << ROW, a[k].1 | b[k].1 << ROW));
            let rows = [&dir[0], &dir[1], &dir[2]];
            let pair = edge_signs(Portable, &n, &beta, rows, &dir_norm);
            assert_eq!(pair, want, "{n:?} {beta:?}");
            #[cfg(target_arch = "x86_64")]
            if let Some(wide) = Avx512::detect() {
                let got = edge_signs(wide, &n, &beta, rows, &dir_norm);
                assert_eq!(got, want, "{n:?} {beta:?}");
            }
            for (p, q) in want {
                seen[1] += p.count_ones();
                seen[2] += q.count_ones();
            }
        }
        // Both answers of each test occur often.
        assert!(seen.iter().all(|&k| k > 5000), "{seen:?}");
    }

    /// The edge signs in `l` agree with plain Rust bit for bit, and plain
    /// Rust's are `edge_det32`'s sign test lane by lane, on values that
    /// round, overflow, cancel and tie.
    fn edge_signs_agree<L: RowLanes<ROW>>(l: L) {
        let vals = with(&[1e-20, f32::INFINITY, f32::MAX]);
        let mut next = picker(5);
        let (mut pos, mut neg, mut unsure) = (0, 0, 0);
        for _ in 0..4000 {
            let n: [[f32; 3]; 3] = std::array::from_fn(|_| std::array::from_fn(|_| vals[next(9)]));
            let beta: [f32; 3] = std::array::from_fn(|_| vals[next(vals.len())].abs());
            let dir: [[f32; ROW]; 3] =
                std::array::from_fn(|_| std::array::from_fn(|_| vals[next(9)]));
            let dir_norm: [f32; ROW] = std::array::from_fn(|_| vals[next(vals.len())].abs());
            let rows = [&dir[0], &dir[1], &dir[2]];
            let want = edge_signs(Portable, &n, &beta, rows, &dir_norm);
            for (k, &(p, q)) in want.iter().enumerate() {
                for j in 0..ROW {
                    let d = [dir[0][j], dir[1][j], dir[2][j]];
                    let det = n[k][0] * d[0] + n[k][1] * d[1] + n[k][2] * d[2];
                    let bound = beta[k] * dir_norm[j];
                    assert_eq!(p >> j & 1 == 1, det > bound, "{n:?} {d:?}");
                    assert_eq!(q >> j & 1 == 1, -det > bound, "{n:?} {d:?}");
                    match (p >> j & 1, q >> j & 1) {
                        (1, _) => pos += 1,
                        (_, 1) => neg += 1,
                        _ => unsure += 1,
                    }
                }
            }
            assert_eq!(edge_signs(l, &n, &beta, rows, &dir_norm), want, "{n:?}");
        }
        // Every outcome occurs often.
        assert!(
            pos > 5000 && neg > 5000 && unsure > 5000,
            "{pos} {neg} {unsure}"
        );
    }

    /// The frustum test in `l` agrees with plain Rust bit for bit, on
    /// infinities (NaN products), signed zeros and values near the bound,
    /// and plain Rust's is the plane test lane by lane.
    fn planes_out_agree<L: RowLanes<ROW>>(l: L) {
        let vals = with(&[1e-30, f32::INFINITY, f32::NEG_INFINITY]);
        let mut next = picker(7);
        let (mut outs, mut ins) = (0, 0);
        for _ in 0..4000 {
            let n: [[f32; ROW]; 3] =
                std::array::from_fn(|_| std::array::from_fn(|_| vals[next(9)]));
            let mut boxes = [[(0f32, 0f32); 3]; 2];
            for b in boxes.iter_mut().flatten() {
                let (x, y) = (vals[next(vals.len())], vals[next(vals.len())]);
                *b = (x.min(y), x.max(y));
            }
            let want = planes_out(Portable, &n, &boxes[0], &boxes[1]);
            for j in 0..ROW {
                let bx = &boxes[j / 4];
                let (mut s, mut mag) = (0f32, 0f32);
                for k in 0..3 {
                    let (lo, hi) = bx[k];
                    let p = if n[k][j] > 0.0 {
                        n[k][j] * hi
                    } else {
                        n[k][j] * lo
                    };
                    let p = if n[k][j] == 0.0 {
                        max(0.0 * lo, 0.0 * hi)
                    } else {
                        p
                    };
                    s += p;
                    mag += p.abs();
                }
                let out = s < -(BOX_REL * mag + BOX_ABS);
                assert_eq!(want >> j & 1 == 1, out, "{n:?} {bx:?}");
                if out {
                    outs += 1;
                } else {
                    ins += 1;
                }
            }
            let got = planes_out(l, &n, &boxes[0], &boxes[1]);
            assert_eq!(got, want, "{n:?} {boxes:?}");
        }
        // Both answers occur often.
        assert!(outs > 3000 && ins > 3000, "{outs} out, {ins} in");
    }
}

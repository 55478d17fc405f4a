//! The primary-ray kernel: the same visibility answers as the f64 path, found
//! with less work.
//!
//! Two things make the f64 traversal slow: 56-byte f64 node boxes tested in
//! world space, and three edge planes set up per candidate triangle. For pixel
//! rays every quantity can instead be taken relative to the eye once per render:
//!
//! - node boxes become eye-relative f32 boxes, rounded outward and grown by
//!   2^-21 of their extent from the eye, so the f32 copy of a pixel ray never
//!   misses a box the exact ray enters (see [`Node32::new`]);
//! - each triangle's three edge normals `(a - eye) x (b - eye)` are stored in
//!   f32 in BVH order, with a per-edge error bound (mostly relative to the
//!   normal's own length, so short, distant edges do not widen it). An edge sign is taken from
//!   the f32 dot product only when it clears that bound, i.e. only when it is
//!   certainly the exact sign; otherwise the edge goes to
//!   [`crate::visibility::edge_sign`] (f64 filter, exact arithmetic, tie rule),
//!   so coverage, depth and the operation counts are unchanged bit for bit.

use super::rows::edge_signs;
use crate::camera::PixelRay;
use crate::predicate::EdgePlane;
use crate::scene::resolve::Tri;
use crate::simd::{Lanes, RowLanes};
use crate::visibility::RayBox;
use glam::DVec3;

/// Unit roundoff of f32.
const U32: f64 = 1.0 / (1u64 << 24) as f64;

/// Relative growth of eye-relative boxes: 8x the f32 rounding of the ray
/// direction (a point of the f32 ray is within `U32 * |coordinate|` of the
/// exact ray's point at the same parameter, per axis).
const BOX_GROWTH: f64 = 8.0 * U32;

/// Smallest half-width of a grown box, so that no bound is exactly 0 and
/// `0 * inf` never arises for an axis-parallel ray.
const MIN_GROWTH: f64 = 1e-35;

/// Coefficient of the f32 edge filter on `|n| |D|`. The f32 determinant
/// differs from the f64 one by at most about `5 U32 |n| |D|` (rounding of the
/// normal and of the direction to f32, and a 3-term f32 dot product), so
/// `8 U32` leaves room for the bound's own rounding.
const EDGE_FILTER: f64 = 8.0 * U32;

/// Coefficient on `|perm| |D|` for the error of the f64 normal itself
/// (`(a - eye) x (b - eye)` cancels when the edge is short next to its
/// distance from the eye; Shewchuk's bound is about `7 u64` on the same scale).
const EDGE_FILTER_F64: f64 = 16.0 / (1u64 << 53) as f64;

/// Relative slack on f32 slab parameters (each is a product of two rounded values).
const SLAB_SLACK: f32 = 1.0 / (1u32 << 20) as f32;

/// `min` for operands that are never NaN (one `minss`, unlike `f32::min`).
#[inline(always)]
pub(crate) fn min(a: f32, b: f32) -> f32 {
    if a < b {
        a
    } else {
        b
    }
}

/// `max` for operands that are never NaN.
#[inline(always)]
pub(crate) fn max(a: f32, b: f32) -> f32 {
    if a > b {
        a
    } else {
        b
    }
}

/// Largest f32 not above `x` (NaN for NaN): `x` rounded to nearest, and
/// the next f32 down when that rounded up. Branch-free (a new camera rounds
/// every node box this way, and the direction is a coin toss, so branches
/// were mispredicted half the time): the step down is one unit of the bits
/// toward zero above zero, away from it below, and from either zero the
/// smallest negative subnormal, as `f32::next_down` steps (a rounded-up
/// `f` is never -inf or NaN, and +inf steps to `f32::MAX`).
#[inline(always)]
pub(crate) fn round_down(x: f64) -> f32 {
    let f = x as f32;
    let b = f.to_bits();
    let below = if f > 0.0 {
        b - 1
    } else if f < 0.0 {
        b + 1
    } else {
        0x8000_0001
    };
    f32::from_bits(if f64::from(f) > x { below } else { b })
}

/// The factor an edge's filter bound is grown by before its rounding up
/// (room for the roundings of the bound's own arithmetic).
const BOUND_GROWTH: f64 = 1.0 + 1e-9;

/// `DVec3::length` in lanes: the square root of `(x x + y y) + z z`.
#[inline(always)]
fn length3<L: Lanes<N>, const N: usize>(l: L, v: &[L::V; 3]) -> L::V {
    l.sqrt(l.add(
        l.add(l.mul(v[0], v[0]), l.mul(v[1], v[1])),
        l.mul(v[2], v[2]),
    ))
}

/// The permanent's length bounded without a square root: its components'
/// sum, `(x + y) + z`, at least its Euclidean length (the components are
/// magnitudes), and no more than `sqrt(3)` times it. Its coefficient
/// [`EDGE_FILTER_F64`] is 2^28 times smaller than [`EDGE_FILTER`]'s, so
/// the looser term moves the bound only where the normal nearly cancels;
/// it saves a third of the leaf set-up's square roots.
#[inline(always)]
fn perm_sum(p: DVec3) -> f64 {
    (p.x + p.y) + p.z
}

/// The least `|n|` whose edge the f32 filter vouches for: below it the
/// normal's f32 components may be subnormal, whose rounding is absolute.
const NORMAL_FLOOR: f64 = 1e-25;
/// The greatest `|perm|` whose edge the f32 filter vouches for: above it the
/// bound's products could leave f32's range.
const PERM_CEILING: f64 = 1e30;

/// An edge's filter bound from its normal's length `nn`, its permanent's
/// length `pn` and the unrounded bound `b` made of them: `b` rounded up, or
/// +inf where the f32 path cannot vouch for a sign (normals in f32's normal
/// range only: subnormal rounding is absolute, not relative).
#[inline(always)]
fn edge_bound(nn: f64, pn: f64, b: f64) -> f32 {
    if nn.is_finite() && pn.is_finite() && nn >= NORMAL_FLOOR && pn <= PERM_CEILING {
        round_up(b)
    } else {
        f32::INFINITY
    }
}

/// Smallest f32 not below `x` (NaN for NaN), as [`round_down`] mirrored.
#[inline(always)]
fn round_up(x: f64) -> f32 {
    let f = x as f32;
    let b = f.to_bits();
    let above = if f > 0.0 {
        b + 1
    } else if f < 0.0 {
        b - 1
    } else {
        0x0000_0001
    };
    f32::from_bits(if f64::from(f) < x { above } else { b })
}

/// [`round_up`] lane by lane (the leaves' bounds and the nodes' upper
/// corners; the lower ones as `-round_up(-x)`): the nearest f32, stepped up where it rounded
/// down (`f32::next_up`'s steps: away from zero above it, toward zero below
/// it, and from a zero to the least positive subnormal). Branch-free: the
/// direction of rounding is as good as random per lane, and a branch on it
/// made the node set-up 1.7x slower than the scalar one.
#[inline(always)]
fn round_up_lanes<L: Lanes<N>, const N: usize>(l: L, x: L::V) -> [f32; N] {
    let (mut f, below) = l.to_f32_below(x);
    for (j, f) in f.iter_mut().enumerate() {
        let b = f.to_bits();
        let (pos, neg) = (u32::from(*f > 0.0), u32::from(*f < 0.0));
        let zero = 1 - pos - neg;
        // `b + 1` above zero, `b - 1` below it, 1 at either zero.
        let stepped = (b.wrapping_add(pos).wrapping_sub(neg) & zero.wrapping_sub(1)) | zero;
        let take = 0u32.wrapping_sub(below >> j & 1);
        *f = f32::from_bits((stepped & take) | (b & !take));
    }
    f
}

/// A BVH node as the primary kernel sees it: an eye-relative f32 box.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Node32 {
    /// Lower corner minus the eye, rounded down.
    lo: [f32; 3],
    /// Upper corner minus the eye, rounded up.
    hi: [f32; 3],
    /// Leaf: index of the first prim; inner: index of the first child.
    pub first: u32,
    /// Leaf: number of prims; inner: 0.
    pub count: u32,
}

impl Node32 {
    /// Converts a (world-space, already grown) f64 box. Per axis the box grows
    /// by [`BOX_GROWTH`] times its largest distance from the eye, which covers
    /// the f32 rounding of the ray direction, then rounds outward.
    #[inline(always)]
    pub fn new(eye: DVec3, b: &RayBox, first: u32, count: u32) -> Node32 {
        let mut lo = [0f32; 3];
        let mut hi = [0f32; 3];
        for k in 0..3 {
            let l = b.lo[k] - eye[k];
            let h = b.hi[k] - eye[k];
            let g = (l.abs().max(h.abs()) * BOX_GROWTH).max(MIN_GROWTH);
            lo[k] = round_down(l - g);
            hi[k] = round_up(h + g);
            // Never 0, so `bound * (1/0)` is +-inf and never NaN.
            if lo[k] == 0.0 {
                lo[k] = -f32::MIN_POSITIVE;
            }
            if hi[k] == 0.0 {
                hi[k] = f32::MIN_POSITIVE;
            }
        }
        Node32 {
            lo,
            hi,
            first,
            count,
        }
    }

    /// [`Node32::new`] of `N` boxes at once after [`grow_box`]
    /// (`crate::visibility::grow_box`, of the f32 corners `lo` and `hi`,
    /// `[axis][lane]`), in the f64 lanes `l`: the same IEEE operations in the
    /// same order lane by lane, the directed roundings included, so the
    /// same bits (a test holds it to the scalar pair on every lane type).
    /// Returns each axis's rounded corners per lane.
    #[inline(always)]
    pub fn grown_lanes<L: Lanes<N>, const N: usize>(
        l: L,
        eye: DVec3,
        lo: &[[f32; N]; 3],
        hi: &[[f32; N]; 3],
    ) -> ([[f32; N]; 3], [[f32; N]; 3]) {
        let mut out = ([[0f32; N]; 3], [[0f32; N]; 3]);
        for k in 0..3 {
            let e = l.splat(eye[k]);
            let (lo, hi) = (l.widen(lo[k]), l.widen(hi[k]));
            // `grow_box`: the margin from the corners' distances to the eye.
            let m = l.mul(
                l.max(l.abs(l.sub(lo, e)), l.abs(l.sub(hi, e))),
                l.splat(crate::visibility::BOX_MARGIN),
            );
            let (blo, bhi) = (l.sub(lo, m), l.add(hi, m));
            // `Node32::new`.
            let (lr, hr) = (l.sub(blo, e), l.sub(bhi, e));
            let g = l.max(
                l.mul(l.max(l.abs(lr), l.abs(hr)), l.splat(BOX_GROWTH)),
                l.splat(MIN_GROWTH),
            );
            // `round_down(x)` is `-round_up(-x)` bit for bit (rounding to
            // nearest is symmetric; a zero's sign is replaced below).
            let down = round_up_lanes(l, l.mul(l.sub(lr, g), l.splat(-1.0)));
            let up = round_up_lanes(l, l.add(hr, g));
            for j in 0..N {
                let (d, u) = (-down[j], up[j]);
                out.0[k][j] = if d == 0.0 { -f32::MIN_POSITIVE } else { d };
                out.1[k][j] = if u == 0.0 { f32::MIN_POSITIVE } else { u };
            }
        }
        out
    }

    /// A node from corners [`Node32::grown_lanes`] made.
    #[inline(always)]
    pub fn from_corners(lo: [f32; 3], hi: [f32; 3], first: u32, count: u32) -> Node32 {
        Node32 {
            lo,
            hi,
            first,
            count,
        }
    }

    /// The corners, bit for bit comparable (tests).
    #[cfg(test)]
    pub fn corner_bits(&self) -> [u32; 6] {
        std::array::from_fn(|i| if i < 3 { self.lo[i] } else { self.hi[i - 3] }.to_bits())
    }

    /// Slab interval of the f32 ray, and whether it certainly misses.
    /// Bounds are never 0 and `1/D` is never NaN, so no product is NaN and
    /// plain comparisons (which compile to single min/max instructions) suffice.
    #[inline]
    pub fn slab(&self, inv: &[f32; 3]) -> (f32, f32, bool) {
        let mut tmin = f32::NEG_INFINITY;
        let mut tmax = f32::INFINITY;
        for ((lo, hi), inv) in self.lo.iter().zip(&self.hi).zip(inv) {
            let t0 = lo * inv;
            let t1 = hi * inv;
            tmin = max(tmin, min(t0, t1));
            tmax = min(tmax, max(t0, t1));
        }
        (tmin, tmax, Node32::misses(tmin, tmax))
    }

    /// True when an f32 slab interval is certainly empty, or behind the eye
    /// (branch-free, so the packet kernel's lanes vectorize).
    ///
    /// Each slab parameter is one product of a bound and a rounded `1/D`, so it
    /// has the sign of the exact product (bounds are never 0) and is within
    /// `2.1 u` of it relatively; min and max keep both properties. Hence
    /// `tmax < 0` needs no tolerance, and an exact `tmin <= tmax` with
    /// `tmax > 0` always passes `tmin <= tmax (1 + 2^-20)` (16 u of room).
    #[inline]
    pub fn misses(tmin: f32, tmax: f32) -> bool {
        (tmin > Node32::slack_tmax(tmax)) | (tmax < 0.0)
    }

    /// `tmax` with the room [`Node32::misses`] gives it (the packet kernel
    /// applies the same test to a row of lanes at once).
    #[inline(always)]
    pub fn slack_tmax(tmax: f32) -> f32 {
        tmax * Node32::TMAX_SLACK
    }

    /// The factor [`Node32::slack_tmax`] applies: `1 + 2^-20`, exact in f32.
    pub const TMAX_SLACK: f32 = 1.0 + SLAB_SLACK;

    /// The box's eye-relative extent on axis `k`.
    #[inline]
    pub fn bounds(&self, k: usize) -> (f32, f32) {
        (self.lo[k], self.hi[k])
    }

    /// The box center's projection on a direction (orders children near to far).
    #[inline]
    pub fn center_along(&self, d: &[f32; 3]) -> f32 {
        (0..3).map(|k| (self.lo[k] + self.hi[k]) * d[k]).sum()
    }
}

/// A triangle as the primary kernel sees it: its edge normals in f32, with
/// the bound that makes an f32 sign trustworthy, stored in BVH order.
#[derive(Debug, Clone, Copy)]
pub(crate) struct LeafTri {
    /// `(a - eye) x (b - eye)` for the edges a->b, b->c, c->a, rounded to f32.
    n: [[f32; 3]; 3],
    /// The filter bound per unit `|D|`: [`EDGE_FILTER`] `|n|` plus
    /// [`EDGE_FILTER_F64`] `|perm|` (bounded by [`perm_sum`]), rounded up; +inf when the edge must always
    /// take the f64 path (a normal outside f32's normal range).
    beta: [f32; 3],
    /// The triangle's id in the scene.
    pub prim: u32,
    /// Its vertices (a copy in BVH order: the exact fallback and the depth
    /// read them from the cache line just fetched, not from the scene).
    pub tri: Tri,
}

impl LeafTri {
    /// A triangle's leaf before any eye: its bounds are infinite, so the
    /// f32 filter vouches for no sign until [`LeafTri::aim`] sets it up.
    pub fn unaimed(t: &Tri, prim: u32) -> LeafTri {
        LeafTri {
            n: [[0f32; 3]; 3],
            beta: [f32::INFINITY; 3],
            prim,
            tri: *t,
        }
    }

    /// Sets up a triangle's edges relative to the eye.
    #[cfg(test)]
    pub fn new(eye: DVec3, t: &Tri, prim: u32) -> LeafTri {
        let mut leaf = LeafTri::unaimed(t, prim);
        leaf.aim(eye);
        leaf
    }

    /// Sets the edges up again for another eye, in place: the triangle and
    /// its id are the camera-independent part, kept with the tree, so a new
    /// camera reads them from the leaf array in order instead of from the
    /// scene in BVH order (scattered loads: most of the set-up's time when
    /// it did). The result is [`LeafTri::new`]'s for the same eye.
    #[inline]
    pub fn aim(&mut self, eye: DVec3) {
        let (a, b, c) = (
            self.tri[0].as_dvec3(),
            self.tri[1].as_dvec3(),
            self.tri[2].as_dvec3(),
        );
        for (k, (p, q)) in [(a, b), (b, c), (c, a)].into_iter().enumerate() {
            let e = EdgePlane::new(eye, p, q);
            self.n[k] = [e.n.x as f32, e.n.y as f32, e.n.z as f32];
            let nn = e.n.length();
            let pn = perm_sum(e.perm);
            let b = (nn * EDGE_FILTER + pn * EDGE_FILTER_F64) * BOUND_GROWTH;
            self.beta[k] = edge_bound(nn, pn, b);
        }
    }

    /// [`LeafTri::aim`] of `N` triangles at once in the f64 lanes `l` (lane
    /// `j`: triangle `j`, its vertices `v[vertex][axis]` as
    /// [`crate::simd::load_tris`] loads them): the same IEEE operations in
    /// the same order, lane by lane, so the same bits (a test holds it to
    /// `aim` on every lane type). The bound's checks and its rounding up are
    /// lane operations too ([`edge_bound`]'s, for the positive bounds it
    /// meets). Returns each lane's edge normals and bounds, for
    /// [`LeafTri::set_aimed`].
    #[inline(always)]
    pub fn aim_lanes<L: Lanes<N>, const N: usize>(
        l: L,
        v: &[[L::V; 3]; 3],
        eye: DVec3,
    ) -> ([[[f32; 3]; 3]; N], [[f32; 3]; N]) {
        let e = [l.splat(eye.x), l.splat(eye.y), l.splat(eye.z)];
        let mut n_out = [[[0f32; 3]; 3]; N];
        let mut beta_out = [[f32::INFINITY; 3]; N];
        for (k, (p, q)) in [(0, 1), (1, 2), (2, 0)].into_iter().enumerate() {
            // `EdgePlane::new(eye, p, q)`: `ad = p - eye`, `bd = q - eye`.
            let ad = [
                l.sub(v[p][0], e[0]),
                l.sub(v[p][1], e[1]),
                l.sub(v[p][2], e[2]),
            ];
            let bd = [
                l.sub(v[q][0], e[0]),
                l.sub(v[q][1], e[1]),
                l.sub(v[q][2], e[2]),
            ];
            // The three components' products, each normal component their
            // difference and each permanent the sum of their magnitudes.
            let prods = [
                (l.mul(ad[1], bd[2]), l.mul(ad[2], bd[1])),
                (l.mul(ad[2], bd[0]), l.mul(ad[0], bd[2])),
                (l.mul(ad[0], bd[1]), l.mul(ad[1], bd[0])),
            ];
            let mut n = [l.splat(0.0); 3];
            let mut perm = [l.splat(0.0); 3];
            for c in 0..3 {
                n[c] = l.sub(prods[c].0, prods[c].1);
                perm[c] = l.add(l.abs(prods[c].0), l.abs(prods[c].1));
            }
            // `perm_sum`: the permanent's components are not negative.
            let (nn, pn) = (length3(l, &n), l.add(l.add(perm[0], perm[1]), perm[2]));
            let b = l.mul(
                l.add(
                    l.mul(nn, l.splat(EDGE_FILTER)),
                    l.mul(pn, l.splat(EDGE_FILTER_F64)),
                ),
                l.splat(BOUND_GROWTH),
            );
            let n = [l.to_f32(n[0]), l.to_f32(n[1]), l.to_f32(n[2])];
            // `edge_bound`: its range checks (false for NaN, as
            // `is_finite` is), then `round_up(b)` in lanes (the nodes' one,
            // `round_up_lanes`).
            let inf = l.splat(f64::INFINITY);
            let kept =
                l.ge(nn, l.splat(NORMAL_FLOOR)) & l.lt(nn, inf) & l.ge(l.splat(PERM_CEILING), pn);
            let f = round_up_lanes(l, b);
            for j in 0..N {
                n_out[j][k] = [n[0][j], n[1][j], n[2][j]];
                beta_out[j][k] = if kept >> j & 1 == 1 {
                    f[j]
                } else {
                    f32::INFINITY
                };
            }
        }
        (n_out, beta_out)
    }

    /// The edge normals and bounds, bit for bit comparable (tests).
    #[cfg(test)]
    pub fn edge_bits(&self) -> [u32; 12] {
        let n = self.n.as_flattened();
        std::array::from_fn(|i| if i < 9 { n[i] } else { self.beta[i - 9] }.to_bits())
    }

    /// Installs what [`LeafTri::aim_lanes`] computed for this triangle.
    #[inline(always)]
    pub fn set_aimed(&mut self, n: [[f32; 3]; 3], beta: [f32; 3]) {
        self.n = n;
        self.beta = beta;
    }

    /// The f32 sign of edge `k` for a ray direction `d` with `|d|` rounded up
    /// to `dir_norm`, or 0 when the filter cannot vouch for it. Branch-free, so
    /// the packet kernel's lane loop vectorizes.
    #[inline(always)]
    pub fn edge_sign32(&self, k: usize, d: [f32; 3], dir_norm: f32) -> i8 {
        let (det, bound) = self.edge_det32(k, d, dir_norm);
        i8::from(det > bound) - i8::from(-det > bound)
    }

    /// Edge `k`'s f32 determinant and the bound its magnitude must clear for
    /// its sign to be exact.
    #[inline(always)]
    pub fn edge_det32(&self, k: usize, d: [f32; 3], dir_norm: f32) -> (f32, f32) {
        edge_det32(&self.n[k], self.beta[k], d, dir_norm)
    }

    /// All three edges' f32 signs for a row of lanes, or a pair of rows (the
    /// packet kernel's form of [`LeafTri::edge_sign32`]): per edge, the bits
    /// of the lanes whose sign is certainly positive, and of those certainly
    /// negative.
    #[inline(always)]
    pub fn edge_rows<const N: usize, L: RowLanes<N>>(
        &self,
        l: L,
        dir: [&[f32; N]; 3],
        dir_norm: &[f32; N],
    ) -> [(u32, u32); 3] {
        edge_signs(l, &self.n, &self.beta, dir, dir_norm)
    }
}

/// An edge's f32 determinant `n . d` and the bound `beta |d|` its magnitude
/// must clear for its sign to be exact: the one home of the formula, which
/// the per-ray tests evaluate and the row-wise one
/// ([`super::rows::edge_signs`]) spells in lane operations, in its order
/// (its tests hold the two equal).
#[inline(always)]
pub(crate) fn edge_det32(n: &[f32; 3], beta: f32, d: [f32; 3], dir_norm: f32) -> (f32, f32) {
    let det = n[0] * d[0] + n[1] * d[1] + n[2] * d[2];
    (det, beta * dir_norm)
}

/// A pixel ray's direction rounded to f32, with what the kernel needs per ray.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Ray32 {
    /// `D` rounded to nearest.
    pub dir: [f32; 3],
    /// `1 / D` per component (infinite where D is 0).
    pub inv: [f32; 3],
    /// `|D|`, rounded up with slack for its own rounding.
    pub dir_norm: f32,
}

impl Ray32 {
    /// Rounds a pixel ray to f32.
    #[inline]
    pub fn new(ray: &PixelRay) -> Ray32 {
        let dir = [ray.dir.x as f32, ray.dir.y as f32, ray.dir.z as f32];
        Ray32 {
            dir,
            inv: dir.map(|d| 1.0 / d),
            dir_norm: dir_norm_bound(dir),
        }
    }
}

/// An upper bound on `|D|` from its f32 rounding `d`, for the edge filter.
/// The f32 sum of squares and square root are each within a few ulps, and `d`
/// within one ulp per component of `D`, so a 2^-18 margin (64 ulps) covers them
/// (pixel directions are near unit length: no overflow or underflow).
#[inline(always)]
pub(crate) fn dir_norm_bound(d: [f32; 3]) -> f32 {
    (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt() * (1.0 + 1.0 / (1u32 << 18) as f32)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::predicate::exact_sign;
    use crate::predicate::tests::lcg;

    #[test]
    fn rounding_is_directed() {
        for x in [0.1, -0.1, 1e-40, -3.3e38, 1.0 / 3.0] {
            assert!(f64::from(round_down(x)) <= x && f64::from(round_up(x)) >= x);
        }
    }

    /// The branch-free directed roundings are std's `next_down`/`next_up`
    /// of the nearest f32 where that rounded the wrong way, bit for bit:
    /// at zeros, around subnormals, at f32's extremes, infinities, NaN and
    /// random magnitudes, each value also one f64 ulp to either side.
    #[test]
    fn directed_rounding_is_std() {
        let down = |x: f64| {
            let f = x as f32;
            if f64::from(f) > x {
                f.next_down()
            } else {
                f
            }
        };
        let up = |x: f64| {
            let f = x as f32;
            if f64::from(f) < x {
                f.next_up()
            } else {
                f
            }
        };
        let mut xs = vec![0.0, f64::INFINITY, f64::MAX, f64::NAN, 1e-300, 1.0 / 3.0];
        for f in [f32::MAX, f32::MIN_POSITIVE, 1e-45, 1.0, 0.1, 3e38] {
            let f = f64::from(f);
            xs.extend([f, f * (1.0 + 1e-9), f * (1.0 - 1e-9), f * 1.5, f * 0.5]);
        }
        let mut s = 23u64;
        for i in 0..20000 {
            xs.push(lcg(&mut s) * 10f64.powi(i % 90 - 50));
        }
        for x in xs.clone() {
            xs.extend([-x, x.next_up(), x.next_down()]);
        }
        for x in xs {
            assert_eq!(round_down(x).to_bits(), down(x).to_bits(), "{x:e}");
            assert_eq!(round_up(x).to_bits(), up(x).to_bits(), "{x:e}");
        }
    }

    /// The f32 filter never claims a sign the exact predicate disagrees with,
    /// at any scale or offset, and decides the clear cases.
    #[test]
    fn edge_filter_sign_is_exact_when_given() {
        let mut s = 11u64;
        let (mut decided, mut clear) = (0, 0);
        for i in 0..40000 {
            let mag = 10f64.powi((i % 13) - 6);
            let off = if i % 7 == 0 { 1e6 } else { 0.0 };
            let mut eye = DVec3::new(lcg(&mut s), lcg(&mut s), lcg(&mut s)) * mag + off;
            // Triangles from eye-sized down to 1e-5 of their distance (short, distant edges).
            let spread = [1.0, 1e-3, 1e-5][(i as usize / 2) % 3];
            let mut center = eye + DVec3::new(lcg(&mut s), lcg(&mut s), lcg(&mut s)) * mag;
            if i % 11 == 0 {
                // A small triangle near the origin seen from 1e12 away: its f64 edge
                // normals cancel almost completely.
                center = DVec3::new(lcg(&mut s), lcg(&mut s), lcg(&mut s)) * 1e-3;
                eye = DVec3::new(lcg(&mut s), lcg(&mut s), lcg(&mut s)) * 1e12;
            }
            let m = if i % 11 == 0 { 1e-3 } else { mag };
            let v = |s: &mut u64| center + DVec3::new(lcg(s), lcg(s), lcg(s)) * m * spread;
            let t: Tri = [v(&mut s), v(&mut s), v(&mut s)].map(|p| p.as_vec3());
            // Directions: random, or nearly inside an edge plane.
            let [a, b, _] = t.map(|p| p.as_dvec3());
            let dir = if i % 2 == 0 {
                ((a - eye) * lcg(&mut s) + (b - eye) * lcg(&mut s)).normalize()
                    + DVec3::splat(lcg(&mut s) * [1e-5, 1e-7, 1e-9][(i as usize / 6) % 3])
            } else {
                DVec3::new(lcg(&mut s), lcg(&mut s), lcg(&mut s))
            };
            let p = eye + dir;
            let ray = PixelRay {
                p,
                dir: p - eye,
                inv_dir: DVec3::ONE / (p - eye),
                planar: 1.0,
            };
            let leaf = LeafTri::new(eye, &t, 0);
            let r = Ray32::new(&ray);
            let s32 = leaf.edge_sign32(0, r.dir, r.dir_norm);
            if s32 != 0 {
                assert_eq!(s32, exact_sign(a, b, p, eye), "case {i}");
            }
            // Random directions near the origin are clear cases the filter must take.
            if i % 2 == 1 && off == 0.0 && i % 11 != 0 {
                clear += 1;
                decided += usize::from(s32 != 0);
            }
        }
        assert!(
            decided * 100 >= clear * 99,
            "filter decided {decided} of {clear} clear cases"
        );
    }

    /// An f32 node box is never missed by a ray whose exact line crosses the f64 box.
    #[test]
    fn node_box_contains_exact_ray_points() {
        let mut s = 5u64;
        for i in 0..20000 {
            let mag = 10f64.powi((i % 11) - 5);
            let eye = DVec3::new(lcg(&mut s), lcg(&mut s), lcg(&mut s)) * 1e4;
            let c = eye + DVec3::new(lcg(&mut s), lcg(&mut s), lcg(&mut s)) * mag * 10.0;
            let h = DVec3::new(lcg(&mut s), lcg(&mut s), lcg(&mut s)).abs() * mag;
            // Grown as the tracer grows its f64 boxes (this absorbs the rounding of `p`).
            let g = DVec3::splat((c - eye).length() * 1e-12);
            let b = RayBox {
                lo: c - h - g,
                hi: c + h + g,
            };
            // A ray from the eye through a point inside (or on the surface of) the box.
            let target =
                c + h * DVec3::new(lcg(&mut s).signum(), lcg(&mut s).signum(), lcg(&mut s));
            let d = (target - eye) / (target - eye).length();
            let p = eye + d;
            let ray = PixelRay {
                p,
                dir: p - eye,
                inv_dir: DVec3::ONE / (p - eye),
                planar: 1.0,
            };
            let (_, _, miss) = Node32::new(eye, &b, 0, 0).slab(&Ray32::new(&ray).inv);
            assert!(!miss, "case {i}: box {b:?} missed");
        }
    }
}

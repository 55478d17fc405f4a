//! Early depth rejection for the rasterizer: a triangle whose smallest
//! possible key is no smaller than every key already in its box (within one
//! tile) cannot change any pixel, so it is skipped before its setup.
//!
//! # The lower bound on a triangle's depth in a tile
//!
//! [`TriDepth::depth`](crate::visibility::TriDepth::depth) records
//! `z = f32(fl(t · planar))` with `t = fl(num / denom).max(lo).min(hi.max(lo))`,
//! where `lo` is the slab test's entry parameter (never NaN: `f64::max`
//! ignores NaN, and an empty slab sets it to `+inf`). Whatever `num / denom`
//! is, `t >= lo`, and `lo >= a_k`, the entry parameter of any axis `k` the
//! ray is not parallel to: `a_k = fl(fl(F - e_k) · fl(1 / D_k))`, with `F` the
//! grown box's face the ray enters first (`hi` when `D_k < 0`, `lo` when
//! `D_k > 0`). When `(F - e_k) / D_k > 0`, rounding being monotone and
//! `planar > 0`:
//!
//! `fl(t · planar) >= fl(a_k · planar) >= |F - e_k| (planar / |D_k|) (1 - u)^4`.
//!
//! Per tile the axis `k` is the camera's most forward one; when every ray of
//! the tile has `D_k` of one sign (not 0) and `planar >= P > 0`, `κ = (1 -
//! 2^-40) fl(P / max |D_k|)` bounds `planar / |D_k|` from below: every
//! pixel's quotient is at least the exact `P / max |D_k|`, which one
//! rounding and the slack keep above `κ`. `P` is the tile's lower bound on
//! `planar` from its four corners ([`TileRays`](crate::raster::edges::TileRays),
//! `planar_low`: within about `1e-15` of the least `planar`, and it needs no
//! ray but the corners', so a tile whose pixels never need their rays does
//! not compute them for this bound). (The extremes need no division per
//! pixel: the per-pixel minimum of `fl(planar / |D_k|)` cost a tenth of the
//! raster's time on two screen-filling triangles, and a tile spans so small
//! an angle that the two minima differ by about a percent.) The grown face
//! lies at most `m = 2^-48 max(|lo - e|, |hi - e|)` nearer the eye than the
//! vertices' extreme coordinate (`grow_box`), so `|F - e_k| >= |V - e_k| -
//! 2^-47 (|lo - e_k| + |hi - e_k|)` with `V` the extreme vertex coordinate
//! (`fl(V + m)` exceeds `V` by at most `2m`; `F` and `e_k` are exact, so
//! `fl(F - e_k)` errs by one rounding). The bound is evaluated as `zlow =
//! (|V - e_k| (1 - 2^-40) - 2 g) κ (1 - 2^-40)` with `g` that margin: the
//! slack sits on each term, not on their difference, so cancellation cannot
//! eat it, and `zlow` is below the recorded f64 depth by far more than the
//! few ulps above, and `f32(zlow (1 - 10^-6))` is an f32 no
//! larger than any f32 the depth rounds to.
//!
//! The triangle's factor `w = |V - e_k| (1 - 2^-40) - 2 g` needs no tile: the
//! binning computes it once per triangle ([`NearFaces`], for the sign of the
//! camera's own `f_k`) and stores it rounded down to an f32 beside each bin
//! entry, so a hidden triangle is skipped without reading its vertices
//! (they were a cache miss per skipped triangle on a million of them). A
//! smaller `w` only lowers `zlow` (every later rounding is monotone and `κ`
//! is positive), so the bound stays below every key the triangle can make.
//! A tile whose rays' `D_k` sign is not the camera's (very wide fields of
//! view) has no bound: it skips nothing. Recorded depths are at least
//! `near > 0`, so their f32 bits order like their values and every key the
//! triangle can make is at least `hit_key(zlow32, prim)`.
//!
//! A pixel keeps its key unless the new key is smaller, so when that lowest
//! key is `>=` every key in the triangle's box within the tile nothing
//! changes: skipping is exact. Both the fast path and
//! [`render_exact`](crate::raster::render_exact) skip the same triangles
//! (their keys agree after every triangle), so their counts still agree;
//! a skipped triangle costs no setup and no coverage test. Renders that count
//! coverage never skip (every covering triangle counts there).
//! `raster::tests::hidden_triangles_are_skipped_exactly` checks renders with
//! and without skipping are identical, and that a bound 1% too high breaks them.

use crate::camera::Camera;
use crate::raster::edges::Span;
use crate::scene::resolve::Tri;
use crate::visibility::hit_key;

/// The relative slack `2^-40` of the module documentation.
const SLACK: f64 = 1.0 / (1u64 << 40) as f64;

/// `2^-47`: twice `grow_box`'s margin (module documentation).
const GROW: f64 = 1.0 / (1u64 << 47) as f64;

/// The camera's half of the bound: its most forward axis `k`, the sign of
/// `f_k` (the sign most tiles' `D_k` share) and `e_k`, to compute each
/// triangle's factor `w` once, at binning (module documentation).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct NearFaces {
    /// The camera's most forward axis.
    axis: usize,
    /// `f_axis < 0`: the faces are the triangles' largest coordinates.
    negative: bool,
    /// `e_axis`.
    eye: f64,
}

impl NearFaces {
    /// The camera's axis, sign and eye coordinate.
    #[inline(always)]
    pub fn new(cam: &Camera) -> NearFaces {
        let axis = TileDepthBound::axis(cam);
        NearFaces {
            axis,
            negative: cam.forward.to_array()[axis] < 0.0,
            eye: cam.eye.to_array()[axis],
        }
    }

    /// The axis `k`.
    #[inline(always)]
    pub fn axis(&self) -> usize {
        self.axis
    }

    /// The sign the faces were taken for: `f_k < 0`.
    #[inline(always)]
    pub fn negative(&self) -> bool {
        self.negative
    }

    /// Triangle `t`'s factor `w` (module documentation), rounded down to an
    /// f32 (0, no bound, where `w` is not positive). The binning's batched
    /// form (`raster::bounds`) performs the same operations lane by lane.
    #[inline(always)]
    pub fn face(&self, t: &Tri) -> f32 {
        let (k, e) = (self.axis, self.eye);
        // `fl(V - e_k)` per vertex (arrays, not glam's run-time component
        // index; not array `map`, which can compile to an out-of-line call).
        let q = |i: usize| f64::from(t[i].to_array()[k]) - e;
        self.face_of(q(0), q(1), q(2))
    }

    /// [`NearFaces::face`] from the vertices' `fl(V - e_k)`: rounding is
    /// monotone, so their least and largest are `fl(lo - e_k)` and
    /// `fl(hi - e_k)`, and `fl(e_k - hi) = -fl(hi - e_k)`.
    #[inline(always)]
    pub(crate) fn face_of(&self, a: f64, b: f64, c: f64) -> f32 {
        let (lo, hi) = (a.min(b).min(c), a.max(b).max(c));
        // The face entered first, relative to the eye, signed along the ray.
        let v = if self.negative { -hi } else { lo };
        f32_below(Self::w(v, lo, hi))
    }

    /// `w` from the signed face `v` and the extremes relative to the eye.
    #[inline(always)]
    pub(crate) fn w<T>(v: T, lo: T, hi: T) -> T
    where
        T: Copy + std::ops::Add<Output = T> + std::ops::Sub<Output = T> + Abs,
        T: std::ops::Mul<f64, Output = T>,
    {
        let grow = (lo.abs() + hi.abs()) * GROW;
        // Slack on both terms, not on their difference: safe under cancellation.
        v * (1.0 - SLACK) - grow * 2.0
    }
}

/// `abs` for [`NearFaces::w`]'s scalar and lane forms.
pub(crate) trait Abs {
    /// The absolute value, lane by lane.
    fn abs(self) -> Self;
}

impl Abs for f64 {
    #[inline(always)]
    fn abs(self) -> f64 {
        f64::abs(self)
    }
}

/// The largest f32 no larger than `x`, where `x` is positive; 0 where it
/// is not (or NaN): a face of 0 gives no bound. (Branch-free: the binning
/// computes one per triangle, and a branch on the rounding's direction
/// mispredicted half the time.)
#[inline(always)]
pub(crate) fn f32_below(x: f64) -> f32 {
    // `f64::max` ignores NaN.
    let x = x.max(0.0);
    let y = x as f32;
    // Rounded up: one step down (`y > x >= 0`, so `y`'s bits are at least 1;
    // `+inf` steps down to `f32::MAX`).
    f32::from_bits(y.to_bits() - u32::from(f64::from(y) > x))
}

/// One tile's depth bound: `κ`, for triangles whose faces
/// ([`NearFaces`]) were taken for the sign its rays share.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TileDepthBound {
    /// `κ`: a lower bound on `planar / |D_axis|` over the tile.
    kappa: f64,
    /// Multiplies the bound (tests: above 1 it must break renders).
    factor: f64,
}

impl TileDepthBound {
    /// The camera's most forward axis: the one whose `D` component the bound divides by.
    #[inline(always)]
    pub fn axis(cam: &Camera) -> usize {
        let f = cam.forward.abs();
        if f.x >= f.y && f.x >= f.z {
            0
        } else if f.y >= f.z {
            1
        } else {
            2
        }
    }

    /// The bound from every one of a tile's `planar` and `D_axis` values
    /// (pairwise, any order, repeats allowed): the least `planar` itself as
    /// the lower bound. `None` when they do not all share the strict sign
    /// `negative` or some `planar` is not positive. Tests only: renders take
    /// the corners' bound ([`TileDepthBound::from_low`]), which tests hold
    /// against this.
    #[cfg(test)]
    pub(crate) fn new(negative: bool, planar: &[f64], dk: &[f64]) -> Option<Self> {
        let n = planar.len().min(dk.len());
        let p = Span::of(&planar[..n]);
        Self::from_low(
            negative,
            if p.finite { p.lo } else { f64::NAN },
            Span::of(&dk[..n]),
        )
    }

    /// The bound from a lower bound `planar_low` on the tile's `planar`
    /// values (NaN: none) and the span of its `D_axis` values (module
    /// documentation), for faces taken with sign `negative`
    /// ([`NearFaces::negative`]; a tile of the other sign has none): what
    /// renders use, from the tile's corners.
    #[inline(always)]
    pub fn from_low(negative: bool, planar_low: f64, dk: Span) -> Option<Self> {
        let sign = if negative { dk.hi < 0.0 } else { dk.lo > 0.0 };
        let ok = dk.finite && planar_low > 0.0 && sign;
        // With one sign, the largest magnitude is an extreme's.
        let kappa = planar_low / (-dk.lo).max(dk.hi);
        if !(ok && kappa > 0.0 && kappa.is_finite()) {
            return None;
        }
        Some(TileDepthBound {
            kappa: kappa * (1.0 - SLACK),
            factor: 1.0,
        })
    }

    /// `κ` (tests: how far a bound lies below another).
    #[cfg(test)]
    pub(crate) fn kappa(&self) -> f64 {
        self.kappa
    }

    /// The same bound multiplied by `factor` (1 in renders; tests: too high must break).
    pub(crate) fn scaled(mut self, factor: f64) -> Self {
        self.factor = factor;
        self
    }

    /// The smallest key triangle `prim`, of face `face` ([`NearFaces::face`]),
    /// can record in the tile, or 0 when no positive bound is known.
    #[inline(always)]
    pub fn lowest_key(&self, face: f32, prim: u32) -> u64 {
        let zlow = f64::from(face) * self.kappa * (1.0 - SLACK) * self.factor;
        let z32 = (zlow * (1.0 - 1e-6)) as f32;
        if z32 > 0.0 && z32.is_finite() {
            hit_key(z32, prim)
        } else {
            0
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::predicate::tests::lcg;

    /// `f32_below` gives the largest f32 not above a positive `x` (so a
    /// face never exceeds its `w`, and loses at most one f32 step), and 0
    /// for what is not positive.
    #[test]
    fn faces_round_down_to_the_next_f32() {
        let mut s = 7u64;
        let mut xs = vec![
            f64::from(f32::MAX),
            f64::from(f32::MAX) * 1.5,
            f64::MAX,
            f64::INFINITY,
            f64::from(f32::MIN_POSITIVE),
            1e-46,
            1e-300,
            1.0,
        ];
        for _ in 0..20_000 {
            let exp = (lcg(&mut s) * 60.0).round() as i32;
            xs.push((1.5 + lcg(&mut s)) * 2f64.powi(exp));
        }
        for &x in &xs {
            let y = f32_below(x);
            assert!(f64::from(y) <= x, "{x}: {y} above");
            if x < f64::INFINITY {
                assert!(f64::from(y.next_up()) > x, "{x}: {y} not the largest");
            }
        }
        for x in [0.0, -0.0, -1.0, -1e-300, f64::NEG_INFINITY, f64::NAN] {
            assert_eq!(f32_below(x).to_bits(), 0, "{x}");
        }
    }

    /// [`TileDepthBound::new`]'s conditions and `κ`, one value at a time:
    /// the definition its lane-parallel reductions must equal (every `D_k`
    /// of the sign `negative` says).
    fn reference(negative: bool, planar: &[f64], dk: &[f64]) -> Option<f64> {
        let (mut ok, mut neg, mut pos) = (true, false, false);
        let (mut p_min, mut d_abs_max) = (f64::INFINITY, 0.0f64);
        for (&p, &d) in planar.iter().zip(dk) {
            ok &= p > 0.0 && d != 0.0 && d.is_finite() && p.is_finite();
            neg |= d < 0.0;
            pos |= d > 0.0;
            p_min = p_min.min(p);
            d_abs_max = d_abs_max.max(d.abs());
        }
        let kappa = p_min / d_abs_max;
        let sign = if negative { neg && !pos } else { pos && !neg };
        (ok && sign && kappa > 0.0 && kappa.is_finite()).then_some(kappa * (1.0 - SLACK))
    }

    /// The reductions agree with the definition on every length (whole and
    /// partial vectors), with NaN, infinities, zeros, mixed signs and tiny
    /// directions among ordinary values.
    #[test]
    fn bound_reductions_equal_the_definition() {
        let odd = [
            0.0,
            -0.0,
            f64::NAN,
            f64::INFINITY,
            -f64::INFINITY,
            1e-310,
            -2.0,
        ];
        let mut s = 3u64;
        let (mut some, mut none) = (0, 0);
        for len in 0..24 {
            for _ in 0..300 {
                let sign = if lcg(&mut s) > 0.0 { 1.0 } else { -1.0 };
                let mut p: Vec<f64> = (0..len).map(|_| 1.0 + lcg(&mut s).abs()).collect();
                let mut d: Vec<f64> = (0..len).map(|_| sign * (0.1 + lcg(&mut s).abs())).collect();
                if len > 0 && lcg(&mut s) > 0.3 {
                    let i = ((lcg(&mut s) + 1.0) * 0.5 * len as f64) as usize % len;
                    let v = odd[((lcg(&mut s) + 1.0) * 3.5) as usize % odd.len()];
                    if lcg(&mut s) > 0.0 {
                        p[i] = v;
                    } else {
                        d[i] = v;
                    }
                }
                // The faces' sign, mostly the values' own.
                let negative = (sign < 0.0) != (lcg(&mut s) > 0.8);
                let got = TileDepthBound::new(negative, &p, &d).map(|b| b.kappa);
                let want = reference(negative, &p, &d);
                assert_eq!(got.map(f64::to_bits), want.map(f64::to_bits), "{p:?} {d:?}");
                if got.is_some() {
                    some += 1;
                } else {
                    none += 1;
                }
            }
        }
        assert!(some > 1000 && none > 1000, "{some} bounds, {none} refusals");
    }
}

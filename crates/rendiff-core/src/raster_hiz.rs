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
//! the tile has `D_k` of one sign (not 0) and `planar > 0`, `κ = (1 - 2^-40)
//! min fl(planar / |D_k|)` bounds `planar / |D_k|` from below. The grown face
//! lies at most `m = 2^-48 max(|lo - e|, |hi - e|)` nearer the eye than the
//! vertices' extreme coordinate (`grow_box`), so `|F - e_k| >= |V - e_k| -
//! 2^-47 (|lo - e_k| + |hi - e_k|)` with `V` the extreme vertex coordinate
//! (`fl(V + m)` exceeds `V` by at most `2m`; `F` and `e_k` are exact, so
//! `fl(F - e_k)` errs by one rounding). The bound is evaluated as `zlow =
//! (|V - e_k| (1 - 2^-40) - 2 g) κ (1 - 2^-40)` with `g` that margin: the
//! slack sits on each term, not on their difference, so cancellation cannot
//! eat it, and `zlow` is below the recorded f64 depth by far more than the
//! few ulps above, and `f32(zlow (1 - 10^-6))` is an f32 no
//! larger than any f32 the depth rounds to. Recorded depths are at least
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
use crate::scene::resolve::Tri;
use crate::visibility::hit_key;

/// The relative slack `2^-40` of the module documentation.
const SLACK: f64 = 1.0 / (1u64 << 40) as f64;

/// `2^-47`: twice `grow_box`'s margin (module documentation).
const GROW: f64 = 1.0 / (1u64 << 47) as f64;

/// One tile's depth bound: the axis, the common sign of its rays' `D_k`,
/// and `κ`.
#[derive(Debug, Clone, Copy)]
pub struct TileDepthBound {
    /// The camera's most forward axis.
    axis: usize,
    /// True when every ray of the tile has `D_axis < 0`.
    negative: bool,
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

    /// The bound for a tile whose rays have these `planar` and `D_axis`
    /// values (pairwise, any order, repeats allowed); `None` when they do not
    /// all share a strict sign or some `planar` is not positive.
    #[inline(always)]
    pub fn new(axis: usize, planar: &[f64], dk: &[f64]) -> Option<Self> {
        let (mut ok, mut neg, mut pos) = (true, false, false);
        let mut kappa = f64::INFINITY;
        for (&p, &d) in planar.iter().zip(dk) {
            // Written so that NaN fails.
            ok &= p > 0.0 && d != 0.0 && d.is_finite() && p.is_finite();
            neg |= d < 0.0;
            pos |= d > 0.0;
            kappa = kappa.min(p / d.abs());
        }
        if !ok || neg == pos || !(kappa > 0.0 && kappa.is_finite()) {
            return None;
        }
        Some(TileDepthBound {
            axis,
            negative: neg,
            kappa: kappa * (1.0 - SLACK),
            factor: 1.0,
        })
    }

    /// The same bound multiplied by `factor` (1 in renders; tests: too high must break).
    pub(crate) fn scaled(mut self, factor: f64) -> Self {
        self.factor = factor;
        self
    }

    /// The smallest key triangle `t` (id `prim`) can record in the tile, or
    /// 0 when no positive bound is known.
    #[inline(always)]
    pub fn lowest_key(&self, cam: &Camera, t: &Tri, prim: u32) -> u64 {
        let k = self.axis;
        // Arrays, not glam's run-time component index (a match per access).
        let e = cam.eye.to_array()[k];
        let [a, b, c] = t.map(|v| f64::from(v.to_array()[k]));
        let (lo, hi) = (a.min(b).min(c), a.max(b).max(c));
        // The face entered first, relative to the eye, signed along the ray.
        let v = if self.negative { e - hi } else { lo - e };
        let grow = GROW * ((lo - e).abs() + (hi - e).abs());
        // Slack on both terms, not on their difference: safe under cancellation.
        let zlow = (v * (1.0 - SLACK) - 2.0 * grow) * self.kappa * (1.0 - SLACK) * self.factor;
        let z32 = (zlow * (1.0 - 1e-6)) as f32;
        if z32 > 0.0 && z32.is_finite() {
            hit_key(z32, prim)
        } else {
            0
        }
    }
}

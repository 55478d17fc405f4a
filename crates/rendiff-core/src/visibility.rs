//! The one definition of visibility that both loops share: coverage predicate,
//! tie rule, depth function and the nearest-hit order.
//!
//! Raster and trace differ only in loop order; each calls [`covers`] and
//! [`TriDepth::depth`] with the same [`PixelRay`], so their `id.prim` and `Z`
//! buffers are equal bit for bit.
//!
//! Coverage: the pixel ray through `eye` and `P` covers triangle `(a, b, c)`
//! when the three orientations `orient3d(a, b, P, eye)`, `orient3d(b, c, P, eye)`,
//! `orient3d(c, a, P, eye)` have one sign. A zero orientation (P exactly on an
//! edge's plane) takes the sign it would have if P were moved by `+e1 right`
//! then `-e2 up` (e2 << e1, infinitesimal): a symbolic perturbation of the
//! sample point, the same for every triangle. That is the top-left rule
//! expressed on the edge's projected direction: a shared edge or vertex is
//! covered by exactly one triangle of a watertight mesh, whatever the winding.

use crate::camera::{Camera, PixelRay};
use crate::predicate::EdgePlane;
use crate::scene::resolve::Tri;
use glam::{DVec3, Vec3};

/// Operation counts of one render: the lesson's "same image, different work".
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct Counters {
    /// Pixel-triangle coverage decisions made (raster: per pixel of a triangle's box in a tile,
    /// boxes proven empty and triangles skipped as hidden adding none; trace: per candidate ray,
    /// a packet's lanes outside the triangle's pixel rectangle adding none).
    pub coverage_tests: u64,
    /// Coverage tests that found the pixel covered.
    pub covered: u64,
    /// Orientation signs the f64 filter could not decide (exact arithmetic used).
    pub exact_fallbacks: u64,
    /// Orientations that were exactly zero and went to the tie rule.
    pub ties: u64,
    /// Triangle setups (raster: per triangle and tile its box touches, hidden skips excluded).
    pub triangle_setups: u64,
    /// Ray-box tests (trace only): nodes tested per ray; a packet counts each live lane.
    pub bvh_nodes_visited: u64,
    /// Raster only: coverage tests its edge-function fast path (`raster::edges`)
    /// decided without calling the orientation predicate; the other
    /// `coverage_tests - fast_decided` called it (and `exact_fallbacks` counts
    /// its exact arithmetic). Absent in older records, hence the default.
    #[serde(default)]
    pub fast_decided: u64,
    /// Raster only: triangle-tile pairs skipped whole because no pixel of
    /// the triangle's box in that tile could beat the keys already there
    /// (`raster::hiz`); they add no setup and no coverage test. Absent in
    /// older records, hence the default.
    #[serde(default)]
    pub hidden_skipped: u64,
}

impl std::ops::AddAssign for Counters {
    fn add_assign(&mut self, o: Counters) {
        self.coverage_tests += o.coverage_tests;
        self.covered += o.covered;
        self.exact_fallbacks += o.exact_fallbacks;
        self.ties += o.ties;
        self.triangle_setups += o.triangle_setups;
        self.bvh_nodes_visited += o.bvh_nodes_visited;
        self.fast_decided += o.fast_decided;
        self.hidden_skipped += o.hidden_skipped;
    }
}

/// Sign of one edge's orientation at the pixel, ties broken by the perturbation rule.
/// Returns 0 only for an edge whose plane is undefined (eye, a and b collinear).
#[inline]
pub fn edge_sign(cam: &Camera, e: &EdgePlane, ray: &PixelRay, c: &mut Counters) -> i8 {
    let s = e.sign_with(
        cam.eye,
        ray.p,
        ray.dir,
        cam.precision,
        &mut c.exact_fallbacks,
    );
    if s != 0 {
        return s;
    }
    c.ties += 1;
    let s = e.sign_with(
        cam.eye,
        cam.tie_right,
        cam.tie_right - cam.eye,
        cam.precision,
        &mut c.exact_fallbacks,
    );
    if s != 0 {
        return s;
    }
    -e.sign_with(
        cam.eye,
        cam.tie_up,
        cam.tie_up - cam.eye,
        cam.precision,
        &mut c.exact_fallbacks,
    )
}

/// The three edge planes of a triangle seen from the eye.
#[derive(Debug, Clone, Copy)]
pub struct TriEdges(pub [EdgePlane; 3]);

impl TriEdges {
    /// Sets up the edges a->b, b->c, c->a.
    #[inline]
    pub fn new(cam: &Camera, t: &Tri) -> TriEdges {
        let [a, b, c] = t.map(|v| v.as_dvec3());
        TriEdges([
            EdgePlane::new(cam.eye, a, b),
            EdgePlane::new(cam.eye, b, c),
            EdgePlane::new(cam.eye, c, a),
        ])
    }

    /// Coverage: 0 if not covered, else the common sign (-1: front-facing, i.e.
    /// counter-clockwise seen from the eye; +1: back-facing).
    #[inline]
    pub fn covers(&self, cam: &Camera, ray: &PixelRay, c: &mut Counters) -> i8 {
        covers_by(c, |k, c| edge_sign(cam, &self.0[k], ray, c))
    }
}

/// The coverage rule, given each edge's sign (edges a->b, b->c, c->a, asked
/// for in that order and only as far as needed): covered when all three signs
/// agree and are not 0; the common sign is the facing. Counts the test. Every
/// loop combines signs through here, whatever computed them, so an early exit
/// skips the same (counted) work everywhere.
#[inline(always)]
pub fn covers_by(c: &mut Counters, mut sign: impl FnMut(usize, &mut Counters) -> i8) -> i8 {
    c.coverage_tests += 1;
    let s0 = sign(0, c);
    if s0 == 0 || sign(1, c) != s0 || sign(2, c) != s0 {
        return 0;
    }
    c.covered += 1;
    s0
}

/// Relative margin by which boxes grow, per axis, proportional to their distance
/// from the eye: it absorbs the rounding of the ray direction `D = P - eye`, so
/// a box the exact pixel ray passes through is never reported as missed.
pub(crate) const BOX_MARGIN: f64 = 1.0 / (1u64 << 48) as f64;

/// A box in f64, grown for robust slab tests (see [`grow_box`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RayBox {
    /// Lower corner.
    pub lo: DVec3,
    /// Upper corner.
    pub hi: DVec3,
}

/// Grows an f32 box by [`BOX_MARGIN`] times the largest distance from the eye on each axis.
/// Monotone: a box containing another still contains it after growing, which
/// the tracer's pruning relies on.
#[inline]
pub fn grow_box(eye: DVec3, lo: Vec3, hi: Vec3) -> RayBox {
    let (lo, hi) = (lo.as_dvec3(), hi.as_dvec3());
    let m = (lo - eye).abs().max((hi - eye).abs()) * BOX_MARGIN;
    RayBox {
        lo: lo - m,
        hi: hi + m,
    }
}

/// Slab test: the ray-parameter interval `[tmin, tmax]` over which the pixel ray is inside the box.
/// Monotone in the box, so nested boxes give nested intervals.
#[inline]
pub fn slab(eye: DVec3, ray: &PixelRay, b: &RayBox) -> (f64, f64) {
    slab_od(eye, ray.dir, ray.inv_dir, b)
}

/// Slab test for any ray `origin + t dir` (shadow and path rays).
#[inline]
pub fn slab_od(origin: DVec3, dir: DVec3, inv_dir: DVec3, b: &RayBox) -> (f64, f64) {
    let mut tmin = f64::NEG_INFINITY;
    let mut tmax = f64::INFINITY;
    for k in 0..3 {
        let d = dir[k];
        if d == 0.0 {
            if origin[k] < b.lo[k] || origin[k] > b.hi[k] {
                return (f64::INFINITY, f64::NEG_INFINITY);
            }
            continue;
        }
        let t0 = (b.lo[k] - origin[k]) * inv_dir[k];
        let t1 = (b.hi[k] - origin[k]) * inv_dir[k];
        let (a, bb) = if d > 0.0 { (t0, t1) } else { (t1, t0) };
        tmin = tmin.max(a);
        tmax = tmax.min(bb);
    }
    (tmin, tmax)
}

/// True when a slab interval is empty or behind the eye beyond rounding error.
#[inline]
pub fn slab_misses(tmin: f64, tmax: f64) -> bool {
    let tol = (tmin.abs().min(f64::MAX) + tmax.abs().min(f64::MAX)) * 4e-16;
    tmin > tmax + tol || tmax < -tol
}

/// Per-triangle data for the depth function.
#[derive(Debug, Clone, Copy)]
pub struct TriDepth {
    /// Plane normal `(b - a) x (c - a)` in f64.
    pub normal: DVec3,
    /// `normal . (a - eye)`.
    pub num: f64,
    /// The triangle's grown bounding box (depth is clamped into its slab interval).
    pub bounds: RayBox,
}

impl TriDepth {
    /// Sets up the plane and box of a triangle.
    #[inline]
    pub fn new(cam: &Camera, t: &Tri) -> TriDepth {
        let [a, b, c] = t.map(|v| v.as_dvec3());
        let normal = (b - a).cross(c - a);
        TriDepth {
            normal,
            num: normal.dot(a - cam.eye),
            bounds: grow_box(cam.eye, t[0].min(t[1]).min(t[2]), t[0].max(t[1]).max(t[2])),
        }
    }

    /// Planar depth of the pixel ray's hit on the triangle's plane, in f64 and
    /// rounded once to f32; `None` when parallel or outside `[near, far]`.
    /// The ray parameter is clamped into the triangle's own slab interval, which
    /// keeps ill-conditioned (grazing) hits inside the triangle's box and lets the
    /// tracer prune boxes without ever pruning a winner.
    #[inline]
    pub fn depth(&self, cam: &Camera, ray: &PixelRay) -> Option<f32> {
        let denom = self.normal.dot(ray.dir);
        if denom == 0.0 || !denom.is_finite() {
            return None;
        }
        let (lo, hi) = slab(cam.eye, ray, &self.bounds);
        let t = (self.num / denom).max(lo).min(hi.max(lo));
        let z = (t * ray.planar) as f32;
        let zf = f64::from(z);
        if zf >= cam.near && zf <= cam.far {
            Some(z)
        } else {
            None
        }
    }
}

/// Key that orders candidate hits: nearest depth first, then lower prim id.
/// Depths are positive, so their f32 bit patterns order like the values.
#[inline]
pub fn hit_key(z: f32, prim: u32) -> u64 {
    (u64::from(z.to_bits()) << 32) | u64::from(prim)
}

/// Key of an empty pixel: loses to every hit.
pub const NO_HIT: u64 = u64::MAX;

/// A band of a key buffer that was never written (`Vec::spare_capacity_mut`),
/// filled with [`NO_HIT`] and handed back as keys. Visibility passes fill
/// their bands this way inside their parallel loops, each on its own
/// thread, rather than pre-filling the buffer serially (or having `calloc`
/// zero reused memory) before the loop: the tracer, and the Embree backend
/// so that its timed region pays no serial fill either. (The raster goes
/// one step further: each tile writes its own keys, `NO_HIT` only where no
/// triangle covers it whole, `raster::TileOut`.) The one home of this
/// cast's safety argument.
#[inline]
pub fn fill_no_hit(band: &mut [std::mem::MaybeUninit<u64>]) -> &mut [u64] {
    band.fill(std::mem::MaybeUninit::new(NO_HIT));
    // SAFETY: every element was just written; `MaybeUninit<u64>` and `u64`
    // have the same layout.
    unsafe { &mut *(band as *mut [std::mem::MaybeUninit<u64>] as *mut [u64]) }
}

/// Depth of a key (for assembling buffers).
#[inline]
pub fn key_depth(k: u64) -> f32 {
    if k == NO_HIT {
        f32::INFINITY
    } else {
        f32::from_bits((k >> 32) as u32)
    }
}

/// Prim id of a key, `u32::MAX` for background.
#[inline]
pub fn key_prim(k: u64) -> u32 {
    if k == NO_HIT {
        u32::MAX
    } else {
        k as u32
    }
}

/// Unit geometric normal of a triangle in world space (its winding's orientation).
pub fn geometric_normal(t: &Tri) -> [f32; 3] {
    // Not `t.map(..)`: an array `map` stays a call on the frame's hot path
    // (ARCHITECTURE.md, "what the compiler").
    let [a, b, c] = [t[0].as_dvec3(), t[1].as_dvec3(), t[2].as_dvec3()];
    let n = (b - a).cross(c - a).normalize_or_zero();
    [n.x as f32, n.y as f32, n.z as f32]
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cam(w: u32, h: u32, vfov: f64) -> Camera {
        Camera::new(
            DVec3::new(0.0, 0.0, 1.0),
            DVec3::ZERO,
            DVec3::Y,
            vfov,
            w,
            h,
            1e-3,
            f64::INFINITY,
        )
        .unwrap()
    }

    #[test]
    fn ccw_triangle_seen_from_eye_is_front_facing() {
        let c = cam(8, 8, 90.0);
        let t = [
            Vec3::new(-1.0, -1.0, 0.0),
            Vec3::new(1.0, -1.0, 0.0),
            Vec3::new(0.0, 1.0, 0.0),
        ];
        let mut k = Counters::default();
        let ray = c.pixel_ray(4, 4);
        assert_eq!(TriEdges::new(&c, &t).covers(&c, &ray, &mut k), -1);
        let back = [t[0], t[2], t[1]];
        assert_eq!(TriEdges::new(&c, &back).covers(&c, &ray, &mut k), 1);
    }

    #[test]
    fn depth_of_facing_plane_is_exact() {
        let c = cam(8, 8, 90.0);
        let t = [
            Vec3::new(-9.0, -9.0, -2.0),
            Vec3::new(9.0, -9.0, -2.0),
            Vec3::new(0.0, 9.0, -2.0),
        ];
        let d = TriDepth::new(&c, &t);
        for (x, y) in [(0, 0), (3, 5), (7, 7)] {
            assert_eq!(d.depth(&c, &c.pixel_ray(x, y)), Some(3.0));
        }
    }

    #[test]
    fn shared_edge_through_pixel_center_is_covered_once() {
        // 90 degrees, 8x8: pixel centers are at odd multiples of 1/8 on the z = 0 plane.
        let c = cam(8, 8, 90.0);
        let v = |x: f32, y: f32| Vec3::new(x, y, 0.0);
        // Vertical edge x = 0.125 passes through the centers of column 4.
        let left = [v(-0.9, -0.9), v(0.125, -0.9), v(0.125, 0.9)];
        let right = [v(0.125, -0.9), v(0.9, -0.9), v(0.125, 0.9)];
        let right_flipped = [right[0], right[2], right[1]];
        for other in [right, right_flipped] {
            for y in 1..7 {
                let ray = c.pixel_ray(4, y);
                let mut k = Counters::default();
                let a = TriEdges::new(&c, &left).covers(&c, &ray, &mut k) != 0;
                let b = TriEdges::new(&c, &other).covers(&c, &ray, &mut k) != 0;
                assert!(k.ties > 0);
                assert!(
                    a ^ b,
                    "pixel (4,{y}) covered by {} triangles",
                    a as u8 + b as u8
                );
            }
        }
    }

    #[test]
    fn grow_box_is_monotone() {
        let eye = DVec3::new(0.3, -2.0, 7.0);
        let inner = grow_box(eye, Vec3::new(0.0, 0.0, 0.0), Vec3::new(1.0, 1.0, 1.0));
        let outer = grow_box(eye, Vec3::new(-1.0, 0.0, -3.0), Vec3::new(1.0, 2.0, 1.0));
        assert!(outer.lo.cmple(inner.lo).all() && outer.hi.cmpge(inner.hi).all());
    }

    #[test]
    fn hit_keys_order_by_depth_then_prim() {
        assert!(hit_key(1.0, 9) < hit_key(2.0, 0));
        assert!(hit_key(1.0, 3) < hit_key(1.0, 4));
        assert!(hit_key(f32::MAX, u32::MAX - 1) < NO_HIT);
    }

    #[test]
    fn counters_add_field_by_field() {
        let mut a = Counters {
            coverage_tests: 1,
            covered: 2,
            exact_fallbacks: 3,
            ties: 4,
            triangle_setups: 5,
            bvh_nodes_visited: 6,
            fast_decided: 7,
            hidden_skipped: 8,
        };
        a += Counters {
            coverage_tests: 10,
            covered: 20,
            exact_fallbacks: 30,
            ties: 40,
            triangle_setups: 50,
            bvh_nodes_visited: 60,
            fast_decided: 70,
            hidden_skipped: 80,
        };
        assert_eq!(
            a,
            Counters {
                coverage_tests: 11,
                covered: 22,
                exact_fallbacks: 33,
                ties: 44,
                triangle_setups: 55,
                bvh_nodes_visited: 66,
                fast_decided: 77,
                hidden_skipped: 88,
            }
        );
    }

    /// The tie rule's two steps: a vertical edge through the pixel center is
    /// decided by the move right (the triangle on the right covers it); a
    /// horizontal one lies along that move and is decided by the move down
    /// (the triangle below covers it), whatever the winding.
    #[test]
    fn ties_go_right_then_down() {
        let c = cam(8, 8, 90.0);
        let v = |x: f32, y: f32| Vec3::new(x, y, 0.0);
        let flip = |t: [Vec3; 3]| [t[0], t[2], t[1]];
        let covered = |t: [Vec3; 3], x: u32, y: u32| {
            let mut k = Counters::default();
            let s = TriEdges::new(&c, &t).covers(&c, &c.pixel_ray(x, y), &mut k);
            (s != 0, k)
        };
        // x = 0.125 is column 4's centers; y = 0.125 is row 3's.
        let left = [v(-0.9, -0.9), v(0.125, -0.9), v(0.125, 0.9)];
        let right = [v(0.125, -0.9), v(0.9, -0.9), v(0.125, 0.9)];
        let below = [v(-0.9, -0.9), v(0.9, 0.125), v(-0.9, 0.125)];
        let above = [v(-0.9, 0.125), v(0.9, 0.125), v(0.0, 0.9)];
        for y in 2..6 {
            for (t, want) in [(left, false), (right, true)] {
                for t in [t, flip(t)] {
                    let (got, k) = covered(t, 4, y);
                    assert_eq!(got, want, "pixel (4, {y}) of {t:?}");
                    assert!(k.ties >= 1, "an edge through the center is a tie");
                }
            }
        }
        for x in 2..6 {
            for (t, want) in [(below, true), (above, false)] {
                for t in [t, flip(t)] {
                    let (got, k) = covered(t, x, 3);
                    assert_eq!(got, want, "pixel ({x}, 3) of {t:?}");
                    assert!(k.ties >= 1);
                }
            }
        }
        // Off the edges: no tie, and the pixel clearly inside one triangle.
        let (got, k) = covered(right, 5, 4);
        assert!(got && k.ties == 0 && k.coverage_tests == 1 && k.covered == 1);
    }

    /// The tie rule's moves are directions from the eye (`tie_right - eye`,
    /// `tie_up - eye`), not points: with the eye away from the origin, a
    /// move taken as `tie + eye` or `tie / eye` tilts the direction by the
    /// eye's coordinates and flips the decision on some rows and columns.
    /// The scene of [`ties_go_right_then_down`] moved to eye (-3, -3, 8)
    /// (every coordinate on a pixel center stays exact in f32 and f64), with
    /// an edge through every column's and every row's centers: for a
    /// vertical edge at x (relative to the eye), `tie / eye` gives the move
    /// (2/3, 1, 1), which decides as right only while 2/3 + x > 0 (column 0,
    /// x = -7/8, flips); for a horizontal one at y, `tie_up + eye` gives
    /// (-6, -5, 16) ahead of the plane, deciding as down only while
    /// -5 + 16 y > 0 wrongly (rows 3 to 7 flip), and `tie_up / eye` gives
    /// (1, 2/3, 1) (row 7 flips).
    #[test]
    fn ties_go_right_then_down_wherever_the_eye_is() {
        let at = DVec3::new(-3.0, -3.0, 7.0);
        let c = Camera::new(at + DVec3::Z, at, DVec3::Y, 90.0, 8, 8, 1e-3, f64::INFINITY).unwrap();
        let v = |x: f64, y: f64| (at + DVec3::new(x, y, 0.0)).as_vec3();
        let flip = |t: [Vec3; 3]| [t[0], t[2], t[1]];
        let covered = |t: [Vec3; 3], x: u32, y: u32| {
            let mut k = Counters::default();
            let s = TriEdges::new(&c, &t).covers(&c, &c.pixel_ray(x, y), &mut k);
            (s != 0, k.ties)
        };
        // Pixel i's center is at -1 + (2i + 1)/8 across and 1 - (2i + 1)/8 down.
        let center = |i: u32| (2 * i + 1) as f64 / 8.0;
        for col in 0..8 {
            let x = -1.0 + center(col);
            let left = [v(-2.0, -0.9), v(x, -0.9), v(x, 0.9)];
            let right = [v(x, -0.9), v(2.0, -0.9), v(x, 0.9)];
            for row in 2..6 {
                for (t, want) in [(left, false), (right, true)] {
                    for t in [t, flip(t)] {
                        let (got, ties) = covered(t, col, row);
                        assert_eq!(got, want, "pixel ({col}, {row}) of {t:?}");
                        assert!(ties >= 1, "an edge through the center is a tie");
                    }
                }
            }
        }
        for row in 0..8 {
            let y = 1.0 - center(row);
            let below = [v(-0.9, -2.0), v(0.9, y), v(-0.9, y)];
            let above = [v(-0.9, y), v(0.9, y), v(0.0, 2.0)];
            for col in 2..6 {
                for (t, want) in [(below, true), (above, false)] {
                    for t in [t, flip(t)] {
                        let (got, ties) = covered(t, col, row);
                        assert_eq!(got, want, "pixel ({col}, {row}) of {t:?}");
                        assert!(ties >= 1, "an edge through the center is a tie");
                    }
                }
            }
        }
    }

    #[test]
    fn coverage_needs_three_equal_nonzero_signs_and_stops_at_the_first_difference() {
        let run = |signs: [i8; 3]| {
            let mut k = Counters::default();
            let mut asked = Vec::new();
            let s = covers_by(&mut k, |i, _| {
                asked.push(i);
                signs[i]
            });
            (s, asked, k.coverage_tests, k.covered)
        };
        assert_eq!(run([1, 1, 1]), (1, vec![0, 1, 2], 1, 1));
        assert_eq!(run([-1, -1, -1]), (-1, vec![0, 1, 2], 1, 1));
        assert_eq!(run([0, 0, 0]), (0, vec![0], 1, 0));
        assert_eq!(run([1, -1, 1]), (0, vec![0, 1], 1, 0));
        assert_eq!(run([-1, -1, 1]), (0, vec![0, 1, 2], 1, 0));
        assert_eq!(run([1, 1, 0]), (0, vec![0, 1, 2], 1, 0));
    }

    #[test]
    fn boxes_grow_by_the_margin_times_their_distance_from_the_eye() {
        assert_eq!(BOX_MARGIN, 2f64.powi(-48));
        let m = BOX_MARGIN;
        let eye = DVec3::new(1.0, 1.0, 1.0);
        // lo - eye = (0, -3, 3), hi - eye = (2, 0, 7): the larger distances are (2, 3, 7).
        let b = grow_box(eye, Vec3::new(1.0, -2.0, 4.0), Vec3::new(3.0, 1.0, 8.0));
        assert_eq!(
            b.lo,
            DVec3::new(1.0 - 2.0 * m, -2.0 - 3.0 * m, 4.0 - 7.0 * m)
        );
        assert_eq!(
            b.hi,
            DVec3::new(3.0 + 2.0 * m, 1.0 + 3.0 * m, 8.0 + 7.0 * m)
        );
    }

    #[test]
    fn slabs_give_the_parameter_interval_inside_a_box() {
        let b = RayBox {
            lo: DVec3::new(1.0, 1.0, -1.0),
            hi: DVec3::new(3.0, 8.0, 1.0),
        };
        let inv = |d: DVec3| DVec3::ONE / d;
        let d = DVec3::new(1.0, 2.0, 0.0);
        assert_eq!(slab_od(DVec3::ZERO, d, inv(d), &b), (1.0, 3.0));
        // Going the other way from the far side: the same box, entered at x = 3.
        let d = DVec3::new(-1.0, -0.5, 0.0);
        assert_eq!(
            slab_od(DVec3::new(5.0, 6.0, 0.0), d, inv(d), &b),
            (2.0, 4.0)
        );
        // A zero direction component: inside the slab (its faces included) or a miss.
        let d = DVec3::new(1.0, 0.0, 0.0);
        for y in [1.0, 8.0, 4.0] {
            assert_eq!(
                slab_od(DVec3::new(0.0, y, 1.0), d, inv(d), &b),
                (1.0, 3.0),
                "y {y}"
            );
        }
        for (y, z) in [(0.5, 0.0), (8.5, 0.0), (4.0, -1.5), (4.0, 1.5)] {
            assert_eq!(
                slab_od(DVec3::new(0.0, y, z), d, inv(d), &b),
                (f64::INFINITY, f64::NEG_INFINITY),
                "({y}, {z})"
            );
        }
        let eye = DVec3::new(0.0, 4.0, 0.0);
        let ray = PixelRay {
            p: eye + d,
            dir: d,
            inv_dir: inv(d),
            planar: 1.0,
        };
        assert_eq!(slab(eye, &ray, &b), (1.0, 3.0));
    }

    #[test]
    fn an_interval_misses_only_beyond_its_rounding() {
        assert!(!slab_misses(1.0, 3.0));
        assert!(!slab_misses(0.0, 0.0));
        assert!(!slab_misses(1.0, 1.0));
        // Within (|tmin| + |tmax|) 4e-16 of touching: kept.
        assert!(!slab_misses(1.0 + f64::EPSILON, 1.0));
        assert!(slab_misses(1.0 + 2f64.powi(-48), 1.0));
        assert!(slab_misses(3.0, 1.0));
        // Behind the eye beyond rounding: a miss; just behind it: kept.
        assert!(!slab_misses(-1.0, -1e-17));
        assert!(slab_misses(-1.0, -1e-15));
        assert!(slab_misses(-3.0, -2.0));
        assert!(!slab_misses(f64::NEG_INFINITY, 2.0));
    }

    #[test]
    fn depth_is_the_planar_distance_of_the_plane_hit() {
        let c = cam(8, 8, 90.0);
        // The plane z = -2 - x/2 seen from (0, 0, 1) along (1/8, -1/8, -1):
        // 1 - t = -2 - t/16, so t = 3 / (1 - 1/16) = 3.2, planar depth too.
        let t = [
            Vec3::new(-8.0, -8.0, 2.0),
            Vec3::new(8.0, -8.0, -6.0),
            Vec3::new(0.0, 8.0, -2.0),
        ];
        let d = TriDepth::new(&c, &t);
        assert_eq!(
            d.normal,
            DVec3::new(16.0, 0.0, -8.0).cross(DVec3::new(8.0, 16.0, -4.0))
        );
        assert_eq!(d.num, d.normal.dot(DVec3::new(-8.0, -8.0, 1.0)));
        let ray = c.pixel_ray(4, 4);
        assert_eq!(ray.dir, DVec3::new(0.125, -0.125, -1.0));
        assert_eq!(d.depth(&c, &ray), Some(3.2));
    }

    /// Depth is `t (D . f)`: the planar distance of the hit `eye + t D` on the
    /// ray along the *rounded* direction `D = P - eye`. Near the origin
    /// `D . f` is 1 to the last bit and `t / (D . f)` would give the same
    /// depth; with the eye at 2^34 each of P's coordinates is rounded to
    /// 2^-18, so `D . f` moves off 1 by up to about 10^-6, and dividing
    /// instead of multiplying moves the depth by 2 |D . f - 1| relative,
    /// several f32 roundings (2^-24 each). The reference takes the other
    /// route, `((eye + t D) - eye) . f` in f64 (the sum rounds at 2^-18 on a
    /// distance of 3.7e5: 10^-11 relative), so the f32 depth, rounded once,
    /// is within one f32 step of it.
    #[test]
    fn depth_is_along_the_rounded_direction_far_from_the_origin() {
        let eye = DVec3::splat(2f64.powi(34)) + DVec3::new(0.3, 0.7, 0.1);
        let f = DVec3::new(-1.0, -2.0, -3.0).normalize();
        let c = Camera::new(
            eye,
            eye + f * 1e5,
            DVec3::Y,
            60.0,
            16,
            16,
            1e-3,
            f64::INFINITY,
        )
        .unwrap();
        // A plane across the view 3.7e5 ahead; its corners far off-screen.
        let mid = eye + f * 3.7e5;
        let u = f.cross(DVec3::Y).normalize();
        let v = u.cross(f);
        let t = [mid - (u + v) * 1e7, mid + (u - v) * 1e7, mid + v * 1e7].map(|p| p.as_vec3());
        let d = TriDepth::new(&c, &t);
        let mut off_one = 0;
        for (x, y) in (0..16).flat_map(|y| (0..16).map(move |x| (x, y))) {
            let ray = c.pixel_ray(x, y);
            if (ray.planar - 1.0).abs() <= 2f64.powi(-21) {
                continue;
            }
            off_one += 1;
            let hit = c.eye + ray.dir * (d.num / d.normal.dot(ray.dir));
            let want = (hit - c.eye).dot(c.forward);
            let w32 = want as f32;
            let step = f64::from(f32::from_bits(w32.to_bits() + 1) - w32);
            let got = f64::from(d.depth(&c, &ray).expect("the plane faces every ray"));
            assert!(
                (got - want).abs() <= step,
                "pixel ({x}, {y}): depth {got}, planar distance {want} (D . f - 1 = {:e})",
                ray.planar - 1.0
            );
        }
        assert!(off_one > 0, "no pixel's D . f is off 1 by more than 2^-21");
    }

    #[test]
    fn depth_is_clamped_into_the_triangles_box() {
        // The plane z = -2 (depth 3) is hit at x = 0.375, outside the
        // triangle's box x in [1, 2]; the depth is clamped to where the ray
        // enters the box's slab in x: t = 1 / 0.125 = 8.
        let c = cam(8, 8, 90.0);
        let t = [
            Vec3::new(1.0, -1.0, -2.0),
            Vec3::new(2.0, -1.0, -2.0),
            Vec3::new(1.5, 1.0, -2.0),
        ];
        let ray = c.pixel_ray(4, 4);
        assert_eq!(ray.dir, DVec3::new(0.125, -0.125, -1.0));
        assert_eq!(TriDepth::new(&c, &t).depth(&c, &ray), Some(8.0));
    }

    #[test]
    fn depth_is_kept_from_near_to_far_inclusive() {
        let t = [
            Vec3::new(-9.0, -9.0, -2.0),
            Vec3::new(9.0, -9.0, -2.0),
            Vec3::new(0.0, 9.0, -2.0),
        ];
        let with = |near: f64, far: f64| {
            let c = Camera::new(DVec3::Z, DVec3::ZERO, DVec3::Y, 90.0, 8, 8, near, far).unwrap();
            TriDepth::new(&c, &t).depth(&c, &c.pixel_ray(3, 3))
        };
        assert_eq!(with(3.0, 3.5), Some(3.0), "at near");
        assert_eq!(with(2.5, 3.0), Some(3.0), "at far");
        assert_eq!(with(3.0f64.next_up(), 4.0), None, "nearer than near");
        assert_eq!(with(1.0, 3.0f64.next_down()), None, "farther than far");
    }

    #[test]
    fn a_plane_along_the_ray_has_no_depth() {
        // 1x1 at the origin's axis: the ray is (0, 0, -1), in the plane x = 0.
        let c = cam(1, 1, 90.0);
        let t = [
            Vec3::new(0.0, -1.0, 0.0),
            Vec3::new(0.0, 1.0, 0.0),
            Vec3::new(0.0, 0.0, -3.0),
        ];
        assert_eq!(TriDepth::new(&c, &t).depth(&c, &c.pixel_ray(0, 0)), None);
        // A vertex at infinity: the normal is not finite, and there is no depth either.
        let far = [
            Vec3::new(0.0, -1.0, -1.0),
            Vec3::new(1.0, -1.0, -1.0),
            Vec3::new(0.0, f32::INFINITY, -1.0),
        ];
        let d = TriDepth::new(&c, &far);
        assert!(!d.normal.dot(c.pixel_ray(0, 0).dir).is_finite());
        assert_eq!(d.depth(&c, &c.pixel_ray(0, 0)), None);
    }

    #[test]
    fn keys_carry_depth_and_prim_and_the_empty_key_reads_as_background() {
        let k = hit_key(2.5, 7);
        assert_eq!(k, (u64::from(2.5f32.to_bits()) << 32) + 7);
        assert_eq!((key_depth(k), key_prim(k)), (2.5, 7));
        assert_eq!(
            (key_depth(NO_HIT), key_prim(NO_HIT)),
            (f32::INFINITY, u32::MAX)
        );
        assert_eq!(NO_HIT, u64::MAX);
        let mut band = vec![std::mem::MaybeUninit::new(5u64); 3];
        assert_eq!(fill_no_hit(&mut band), &[NO_HIT; 3]);
    }

    #[test]
    fn geometric_normals_follow_the_winding() {
        let t = [
            Vec3::new(1.0, 1.0, 1.0),
            Vec3::new(3.0, 1.0, 1.0),
            Vec3::new(1.0, 4.0, 1.0),
        ];
        assert_eq!(geometric_normal(&t), [0.0, 0.0, 1.0]);
        assert_eq!(geometric_normal(&[t[0], t[2], t[1]]), [0.0, 0.0, -1.0]);
        assert_eq!(geometric_normal(&[t[0], t[1], t[0]]), [0.0; 3]);
    }
}

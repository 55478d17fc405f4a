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
    let [a, b, c] = t.map(|v| v.as_dvec3());
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
}

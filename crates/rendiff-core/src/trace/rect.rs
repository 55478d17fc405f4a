//! Which pixel centers a triangle can cover: a conservative pixel rectangle
//! per leaf triangle, computed once per camera, that lets a packet drop most
//! (triangle, lane) pairs before any edge test.
//!
//! On the million-triangle scene triangles are about a pixel wide, so of the
//! 64 lanes a leaf's box lets through, a triangle covers one or two: a few
//! integer comparisons on the rectangle replace the three edge tests of the
//! others, and a triangle whose rectangle misses the packet is not even read.
//!
//! Why it is conservative. Let `proj(X) = ((X - eye).r / (X - eye).f,
//! (X - eye).u / (X - eye).f)` with the camera's own basis vectors. When all
//! three vertices have `(v - eye).f > 0`, the triangle lies in that open
//! half-space, where `proj` is a central projection: it maps the triangle onto
//! the triangle of the projected vertices (convex combinations stay inside).
//! A pixel ray is the line through `eye` and `P` with `(P - eye).f > 0`, so
//! where it meets the triangle (in that half-space, hence on its forward
//! half) the meeting point projects to `proj(P)`, which therefore lies in the
//! bounding box of the projected vertices. Coverage decided by the tie rule
//! (`P` exactly on an edge plane) also has `proj(P)` on the closed triangle.
//! The computed box is grown by bounds on the rounding of `proj(v)` and on
//! how far `proj(P)` (with `P = eye + d` rounded, and `d` rounded) lies from
//! the pixel center's ideal screen position, both taken 2^13 times larger
//! than a first-order analysis gives (see [`RectSlack`]). A triangle with a
//! vertex at or behind the eye plane (or too close to it for the bound) gets
//! the whole image. So a lane outside the rectangle is never covered by the
//! triangle, and dropping it changes no key.

use super::packet::{Mask, PH, PW};
use crate::camera::Camera;
use crate::scene::resolve::Tri;
use crate::simd::Lanes;
use glam::DVec3;

/// The relative error allowance of every rounding step (2^13 times f64's
/// unit roundoff, covering the few roundings of each step with room to spare).
const REL: f64 = 1.0 / (1u64 << 40) as f64;

/// A vertex closer to the eye plane than this fraction of its distance
/// from the eye (or behind it) gives its triangle the whole image: too
/// close for the projection's rounding bound.
const NEAR_EYE_PLANE: f64 = 1.0 / (1u64 << 20) as f64;

/// The absolute part of a rectangle's margin, in pixels, on top of the
/// rounding bounds.
const MARGIN_FLOOR: f64 = 1e-9;

/// Rectangle ends are clamped to `[CLAMP_BEFORE, size + CLAMP_PAST]`: just
/// outside the image, so the packets' spans cannot overflow.
const CLAMP_BEFORE: f64 = -2.0;
/// See [`CLAMP_BEFORE`].
const CLAMP_PAST: f64 = 1.0;

/// Per-camera rounding allowances for [`PixelRect::new`].
#[derive(Debug, Clone, Copy)]
pub(crate) struct RectSlack {
    /// How far `proj(P)` may lie from the pixel center's ideal screen
    /// position, in screen units: `P = eye + d` rounds at the scale of the
    /// eye's coordinates, `d` and the basis at the scale of `|d|`.
    ray: f64,
    /// Pixels per screen unit, horizontally and vertically.
    scale: [f64; 2],
}

impl RectSlack {
    /// The allowances for one camera.
    pub fn new(cam: &Camera) -> RectSlack {
        let w = f64::from(cam.width);
        let h = f64::from(cam.height);
        let aspect_tan = cam.tan_half_vfov * (w / h);
        let smax = 1.0 + aspect_tan + cam.tan_half_vfov;
        let eye = cam.eye.abs().max_element();
        RectSlack {
            ray: REL * (1.0 + eye + smax) * smax * smax,
            scale: [w / (2.0 * aspect_tan), h / (2.0 * cam.tan_half_vfov)],
        }
    }
}

/// Bound on the rounding error of `proj(v) = (c.x / c.z, c.y / c.z)` in
/// screen units, for `c` = [`Camera::to_camera`]`(v)`, `(sx, sy) = (c.x r,
/// c.y r)` with `r = inv_cz`, `1 / c.z` rounded, and `qn = |v - eye|_inf`:
/// `v - eye` and the three dot products each round by about `3 u |q|`, and
/// dividing by `c.z` scales that by `(1 + |proj|) / c.z`. Multiplying by the
/// rounded reciprocal instead of dividing (one division per vertex, not
/// three) adds at most `2 u |sx|` to `sx` (likewise `sy`), while the bound
/// is at least `REL |sx| qn / c.z >= REL |sx| / sqrt(3)` (`c.z <= |q| <=
/// sqrt(3) qn`): `REL` is `2^13 u`, so the allowance covers it many times.
fn vertex_slack(qn: f64, inv_cz: f64, sx: f64, sy: f64) -> f64 {
    REL * qn * (1.0 + sx.abs() + sy.abs()) * inv_cz
}

/// `q . v` in lanes, as `DVec3::dot`: `(q.x v.x + q.y v.y) + q.z v.z`.
#[inline(always)]
fn dot3<L: Lanes<N>, const N: usize>(l: L, q: &[L::V; 3], v: DVec3) -> L::V {
    l.add(
        l.add(l.mul(q[0], l.splat(v.x)), l.mul(q[1], l.splat(v.y))),
        l.mul(q[2], l.splat(v.z)),
    )
}

/// `x.ceil().clamp(l, h) as i32` for a finite `x` and integers `l <= h`
/// within i32's range, without a call to libm's `ceil` (x86-64's baseline
/// has no rounding instruction): clamping first changes nothing, as `ceil`
/// is monotone and fixes integers, and on `[l, h]` the truncation toward
/// zero is exact and off from the ceiling by at most one.
#[inline(always)]
fn ceil_within(x: f64, l: f64, h: f64) -> i32 {
    let x = x.clamp(l, h);
    let t = x as i32;
    t + i32::from(f64::from(t) < x)
}

/// `x.floor().clamp(l, h) as i32`, as [`ceil_within`].
#[inline(always)]
fn floor_within(x: f64, l: f64, h: f64) -> i32 {
    let x = x.clamp(l, h);
    let t = x as i32;
    t - i32::from(f64::from(t) > x)
}

/// Inclusive column and row ranges of the pixels whose centers a triangle
/// may cover (empty when `lo > hi`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) struct PixelRect {
    /// First and last column.
    pub x: [i32; 2],
    /// First and last row.
    pub y: [i32; 2],
}

impl PixelRect {
    /// Every pixel.
    pub const ALL: PixelRect = PixelRect {
        x: [i32::MIN, i32::MAX],
        y: [i32::MIN, i32::MAX],
    };

    /// The rectangle of triangle `t` (see the module comment for the proof).
    pub fn new(cam: &Camera, slack: &RectSlack, t: &Tri) -> PixelRect {
        let mut lo = [f64::INFINITY; 2];
        let mut hi = [f64::NEG_INFINITY; 2];
        let mut err = [0f64; 2];
        let half = [f64::from(cam.width) * 0.5, f64::from(cam.height) * 0.5];
        for v in t {
            // `Camera::to_camera`, sharing `v - eye` with the bound below.
            let q = v.as_dvec3() - cam.eye;
            let c = DVec3::new(q.dot(cam.right), q.dot(cam.up_ortho), q.dot(cam.forward));
            let qn = q.abs().max_element();
            // Too close to the eye plane (or behind it) for the bound: all pixels.
            let in_front = c.z > qn * NEAR_EYE_PLANE;
            if !in_front || !qn.is_finite() {
                return PixelRect::ALL;
            }
            // One division per vertex (see `vertex_slack` for its rounding).
            let inv_cz = 1.0 / c.z;
            let (sx, sy) = (c.x * inv_cz, c.y * inv_cz);
            // Pixel coordinates `(sx / aspect_tan + 1) W / 2` and
            // `(1 - sy / tan) H / 2`, as a product and a sum each (their
            // rounding, and that of `scale`, is within `REL (|p| + size)`).
            let (px, py) = (sx * slack.scale[0] + half[0], half[1] - sy * slack.scale[1]);
            if !px.is_finite() || !py.is_finite() {
                return PixelRect::ALL;
            }
            // Rounding of proj(v) in screen units, then pixels, plus the
            // rounding of the pixel mapping itself.
            let s = vertex_slack(qn, inv_cz, sx, sy);
            for (k, p) in [px, py].into_iter().enumerate() {
                lo[k] = lo[k].min(p);
                hi[k] = hi[k].max(p);
                err[k] = err[k].max(s * slack.scale[k] + REL * p.abs());
            }
        }
        let size = [f64::from(cam.width), f64::from(cam.height)];
        let mut out = [[0i32; 2]; 2];
        for k in 0..2 {
            let m = err[k] + slack.ray * slack.scale[k] + REL * size[k] + MARGIN_FLOOR;
            // Pixel `i`'s center is at `i + 0.5`; clamp to just outside the image.
            let (l, h) = (CLAMP_BEFORE, size[k] + CLAMP_PAST);
            out[k] = [
                ceil_within(lo[k] - m - 0.5, l, h),
                floor_within(hi[k] + m - 0.5, l, h),
            ];
        }
        PixelRect {
            x: out[0],
            y: out[1],
        }
    }

    /// [`PixelRect::new`] of `N` triangles at once in the f64 lanes `l`
    /// (lane `j`: `t[j]`): the same IEEE operations in the same order, lane
    /// by lane, every vertex of every lane computed and a lane that fails a
    /// test given the whole image, as `new` returns it at the first
    /// failure; a test holds it to `new` on every lane type.
    #[inline(always)]
    pub fn new_lanes<L: Lanes<N>, const N: usize>(
        l: L,
        cam: &Camera,
        slack: &RectSlack,
        v: &[[L::V; 3]; 3],
    ) -> [PixelRect; N] {
        let inf = l.splat(f64::INFINITY);
        let mut lo = [inf; 2];
        let mut hi = [l.splat(f64::NEG_INFINITY); 2];
        let mut err = [l.splat(0.0); 2];
        let half = [f64::from(cam.width) * 0.5, f64::from(cam.height) * 0.5];
        let eye = [l.splat(cam.eye.x), l.splat(cam.eye.y), l.splat(cam.eye.z)];
        let mut all = 0u32;
        for vi in v {
            let q = [
                l.sub(vi[0], eye[0]),
                l.sub(vi[1], eye[1]),
                l.sub(vi[2], eye[2]),
            ];
            let c = [
                dot3(l, &q, cam.right),
                dot3(l, &q, cam.up_ortho),
                dot3(l, &q, cam.forward),
            ];
            let qn = l.max(l.abs(q[0]), l.max(l.abs(q[1]), l.abs(q[2])));
            let in_front = l.gt(c[2], l.mul(qn, l.splat(NEAR_EYE_PLANE)));
            let finite = l.lt(qn, inf);
            let inv_cz = l.div(l.splat(1.0), c[2]);
            let (sx, sy) = (l.mul(c[0], inv_cz), l.mul(c[1], inv_cz));
            let p = [
                l.add(l.mul(sx, l.splat(slack.scale[0])), l.splat(half[0])),
                l.sub(l.splat(half[1]), l.mul(sy, l.splat(slack.scale[1]))),
            ];
            let p_finite = l.lt(l.abs(p[0]), inf) & l.lt(l.abs(p[1]), inf);
            all |= !(in_front & finite & p_finite);
            // `vertex_slack(qn, c.z, sx, sy)`.
            let one_plus = l.add(l.add(l.splat(1.0), l.abs(sx)), l.abs(sy));
            let s = l.mul(l.mul(l.mul(l.splat(REL), qn), one_plus), inv_cz);
            for k in 0..2 {
                lo[k] = l.min(lo[k], p[k]);
                hi[k] = l.max(hi[k], p[k]);
                let e = l.add(
                    l.mul(s, l.splat(slack.scale[k])),
                    l.mul(l.splat(REL), l.abs(p[k])),
                );
                err[k] = l.max(err[k], e);
            }
        }
        let size = [f64::from(cam.width), f64::from(cam.height)];
        let mut ends = [[[0i32; N]; 2]; 2];
        for k in 0..2 {
            let m = l.add(
                l.add(
                    l.add(err[k], l.splat(slack.ray * slack.scale[k])),
                    l.splat(REL * size[k]),
                ),
                l.splat(MARGIN_FLOOR),
            );
            let half_px = l.splat(0.5);
            // `ceil_within` / `floor_within`: clamp, then round (exact).
            let (lw, hw) = (l.splat(CLAMP_BEFORE), l.splat(size[k] + CLAMP_PAST));
            let first = l.sub(l.sub(lo[k], m), half_px);
            let last = l.sub(l.add(hi[k], m), half_px);
            // The rounded ends are whole numbers in `[CLAMP_BEFORE, size +
            // CLAMP_PAST]`, which `ints` converts exactly.
            ends[k] = [
                l.ints(l.ceil(l.min(l.max(first, lw), hw))),
                l.ints(l.floor(l.min(l.max(last, lw), hw))),
            ];
        }
        let mut out = [PixelRect::ALL; N];
        for (j, o) in out.iter_mut().enumerate() {
            if all & (1 << j) == 0 {
                *o = PixelRect {
                    x: [ends[0][0][j], ends[0][1][j]],
                    y: [ends[1][0][j], ends[1][1][j]],
                };
            }
        }
        out
    }

    /// The lanes of the packet whose top-left pixel is `(x0, y0)` inside the
    /// rectangle (branch-free: a rectangle's bounds lie in `[-2, size + 1]`
    /// or are [`PixelRect::ALL`]'s, so the differences below cannot overflow
    /// once clamped in i64).
    #[inline(always)]
    pub fn lanes(&self, x0: i32, y0: i32) -> Mask {
        let span = |r: [i32; 2], o: i32, n: usize| {
            let a = (i64::from(r[0]) - i64::from(o)).clamp(0, n as i64) as u32;
            let b = (i64::from(r[1]) - i64::from(o) + 1).clamp(0, n as i64) as u32;
            (a, b)
        };
        let (xa, xb) = span(self.x, x0, PW);
        let (ya, yb) = span(self.y, y0, PH);
        // Bits xa..xb (none when xb <= xa), and bit 0 of rows ya..yb.
        let ones = |n: u32| (1u128 << n) - 1;
        let cols = ones(xb) & !ones(xa);
        let rows = ones(yb * PW as u32) & !ones(ya * PW as u32) & REPEAT as u128;
        // No carries: `cols` is below 2^PW and `rows` has one bit per row.
        (cols * rows) as Mask
    }
}

// `lanes` shifts a u128 by up to `PW * PH`.
const _: () = assert!(PW * PH < 128);

/// Bit 0 of every packet row.
const REPEAT: Mask = {
    let mut m = 0;
    let mut r = 0;
    while r < PH {
        m |= 1 << (r * PW);
        r += 1;
    }
    m
};

#[cfg(test)]
mod tests {
    use super::*;
    use crate::predicate::tests::lcg;
    use crate::visibility::{Counters, TriDepth, TriEdges};

    /// `a + b` as an unevaluated sum (Knuth's TwoSum).
    fn two_sum(a: f64, b: f64) -> (f64, f64) {
        let s = a + b;
        let bb = s - a;
        (s, (a - (s - bb)) + (b - bb))
    }

    /// `sum_k q_k m_k` for double-double `q_k`, to about 2^-100 relative.
    fn dot_dd(q: [(f64, f64); 3], m: DVec3) -> (f64, f64) {
        let (mut hi, mut lo) = (0.0, 0.0);
        for k in 0..3 {
            let p = q[k].0 * m[k];
            let pe = q[k].0.mul_add(m[k], -p) + q[k].1 * m[k];
            let (s, e) = two_sum(hi, p);
            hi = s;
            lo += e + pe;
        }
        two_sum(hi, lo)
    }

    /// `a / b` for double-doubles, to about 2^-100 relative.
    fn div_dd(a: (f64, f64), b: (f64, f64)) -> f64 {
        let q1 = a.0 / b.0;
        let p = q1 * b.0;
        let r = (a.0 - p) - q1.mul_add(b.0, -p) + a.1 - q1 * b.1;
        q1 + r / b.0
    }

    /// `proj(X)` from `X - eye`, computed in double-double.
    fn proj_dd(cam: &Camera, x: DVec3) -> [f64; 2] {
        let q = [0, 1, 2].map(|k| two_sum(x[k], -cam.eye[k]));
        let z = dot_dd(q, cam.forward);
        [
            div_dd(dot_dd(q, cam.right), z),
            div_dd(dot_dd(q, cam.up_ortho), z),
        ]
    }

    /// The two rounding allowances the rectangle rests on hold against a
    /// double-double reference: `proj(v)` in f64 is within
    /// [`vertex_slack`] of the reference, and every pixel ray's `proj(P)`
    /// within `RectSlack::ray` of the pixel center's ideal screen position.
    /// (With `REL` set to 0 both allowances vanish and this fails: the
    /// measured errors are rarely exactly 0. The coverage test below rarely
    /// can, as f32 vertices seldom land within rounding of a pixel center.)
    #[test]
    fn rounding_allowances_hold() {
        let mut s = 29u64;
        let mut worst = [0f64; 2];
        for i in 0..4000 {
            let off = [0.0, 1e3, 1e6, -3e7][i % 4];
            let eye = DVec3::new(lcg(&mut s), lcg(&mut s), lcg(&mut s)) * 3.0 + off;
            let look = eye + DVec3::new(lcg(&mut s), lcg(&mut s), lcg(&mut s)) + DVec3::X * 0.1;
            let (w, h) = (13 + (i % 7) as u32, 7 + (i % 5) as u32);
            let vfov = [1.0, 45.0, 90.0, 150.0][(i / 4) % 4];
            let Ok(cam) = Camera::new(eye, look, DVec3::Y, vfov, w, h, 1e-6, f64::INFINITY) else {
                continue;
            };
            let slack = RectSlack::new(&cam);
            // A pixel ray: its exact proj(P) against the ideal center.
            let (x, y) = (i as u32 % w, i as u32 % h);
            let ray = cam.pixel_ray(x, y);
            let at = cam.tan_half_vfov * (f64::from(w) / f64::from(h));
            let ideal = [
                (2.0 * (f64::from(x) + 0.5) / f64::from(w) - 1.0) * at,
                (1.0 - 2.0 * (f64::from(y) + 0.5) / f64::from(h)) * cam.tan_half_vfov,
            ];
            let pp = proj_dd(&cam, ray.p);
            for k in 0..2 {
                let e = (pp[k] - ideal[k]).abs();
                assert!(e <= slack.ray, "case {i}: ray error {e} > {}", slack.ray);
                worst[0] = worst[0].max(e / slack.ray);
            }
            // A vertex near that ray, rounded to f32.
            let t = 0.01 + lcg(&mut s).abs() * [1.0, 1e3, 1e6][i % 3];
            let v = (eye + ray.dir * t + DVec3::new(lcg(&mut s), lcg(&mut s), lcg(&mut s)) * 1e-3)
                .as_vec3()
                .as_dvec3();
            let c = cam.to_camera(v);
            let qn = (v - eye).abs().max_element();
            if c.z <= qn * NEAR_EYE_PLANE {
                continue;
            }
            // As `PixelRect::new` computes it: times the rounded reciprocal.
            let inv_cz = 1.0 / c.z;
            let got = [c.x * inv_cz, c.y * inv_cz];
            let want = proj_dd(&cam, v);
            for k in 0..2 {
                let e = (got[k] - want[k]).abs();
                let allow = vertex_slack(qn, inv_cz, got[0], got[1]);
                assert!(e <= allow, "case {i}: vertex error {e} > {allow}");
                worst[1] = worst[1].max(e / allow);
            }
        }
        // The allowances are generous, but not vacuous.
        assert!(worst[0] > 0.0 && worst[1] > 0.0, "{worst:?}");
    }

    /// The lane masks are the rectangle, lane by lane.
    /// The rounding without libm is std's `ceil`/`floor`, clamped and
    /// converted, bit for bit: at and between integers, near the bounds,
    /// far outside them, at infinities and NaN.
    #[test]
    fn ceil_and_floor_within_are_std() {
        let (l, h) = (-2.0, 1921.0);
        let mut xs = vec![
            f64::NAN,
            f64::INFINITY,
            f64::NEG_INFINITY,
            f64::MAX,
            -f64::MAX,
        ];
        for i in -5..1926 {
            let x = f64::from(i);
            xs.extend([x, x.next_up(), x.next_down(), x + 0.5, x - 1e-9, x + 1e-9]);
        }
        let mut s = 5u64;
        for _ in 0..10000 {
            xs.push((lcg(&mut s) - 0.5) * 1e12);
        }
        for x in xs {
            assert_eq!(ceil_within(x, l, h), x.ceil().clamp(l, h) as i32, "{x}");
            assert_eq!(floor_within(x, l, h), x.floor().clamp(l, h) as i32, "{x}");
        }
    }

    #[test]
    fn lanes_are_the_rectangle() {
        let mut s = 3u64;
        for _ in 0..5000 {
            let mut r = || (lcg(&mut s) * 14.0) as i32 - 3;
            let rect = PixelRect {
                x: [r(), r()],
                y: [r(), r()],
            };
            let (x0, y0) = (r(), r());
            let m = rect.lanes(x0, y0);
            for i in 0..PW * PH {
                let (x, y) = (x0 + (i % PW) as i32, y0 + (i / PW) as i32);
                let inside = rect.x[0] <= x && x <= rect.x[1] && rect.y[0] <= y && y <= rect.y[1];
                assert_eq!(m >> i & 1 == 1, inside, "{rect:?} at ({x0}, {y0}) lane {i}");
            }
            let all = Mask::MAX >> (Mask::BITS as usize - PW * PH);
            assert_eq!(PixelRect::ALL.lanes(x0, y0), all);
        }
    }

    /// Every pixel a triangle covers with a depth in range lies in its
    /// rectangle: tiny triangles with vertices on pixel-center rays (where
    /// coverage is decided by rounding and the tie rule), triangles crossing
    /// the eye plane, and cameras far from the origin.
    #[test]
    fn covered_pixels_are_inside() {
        let mut s = 17u64;
        let mut checked = 0;
        for i in 0..3000 {
            let off = [0.0, 1e3, 1e6, -3e7][i % 4];
            let eye = DVec3::new(lcg(&mut s), lcg(&mut s), lcg(&mut s)) * 3.0 + off;
            let look = eye + DVec3::new(lcg(&mut s), lcg(&mut s), lcg(&mut s)) + DVec3::X * 0.1;
            let (w, h) = (13 + (i % 5) as u32, 7 + (i % 3) as u32);
            let vfov = [1.0, 45.0, 90.0, 150.0][(i / 4) % 4];
            let Ok(cam) = Camera::new(eye, look, DVec3::Y, vfov, w, h, 1e-6, f64::INFINITY) else {
                continue;
            };
            let slack = RectSlack::new(&cam);
            // Vertices on (or next to) pixel-center rays, at random depths;
            // every fourth triangle has a vertex behind the eye or on its plane.
            let vert = |s: &mut u64, k: usize| {
                let (x, y) = (
                    (lcg(s).abs() * w as f64) as u32,
                    (lcg(s).abs() * h as f64) as u32,
                );
                let d = cam.pixel_ray(x.min(w - 1), y.min(h - 1)).dir;
                let t = match (i % 4, k) {
                    (3, 0) => -lcg(s).abs(),
                    (2, 0) => 0.0,
                    _ => 0.5 + lcg(s).abs() * 4.0,
                };
                let jitter = [0.0, 1e-9, 1e-4][(i / 16) % 3];
                (eye + d * t + DVec3::new(lcg(s), lcg(s), lcg(s)) * jitter).as_vec3()
            };
            let t: Tri = [vert(&mut s, 0), vert(&mut s, 1), vert(&mut s, 2)];
            let rect = PixelRect::new(&cam, &slack, &t);
            let edges = TriEdges::new(&cam, &t);
            let depth = TriDepth::new(&cam, &t);
            let mut c = Counters::default();
            for y in 0..h {
                for x in 0..w {
                    let ray = cam.pixel_ray(x, y);
                    if edges.covers(&cam, &ray, &mut c) != 0 && depth.depth(&cam, &ray).is_some() {
                        checked += 1;
                        let (x, y) = (x as i32, y as i32);
                        assert!(
                            rect.x[0] <= x && x <= rect.x[1] && rect.y[0] <= y && y <= rect.y[1],
                            "case {i}: pixel ({x}, {y}) outside {rect:?} of {t:?}"
                        );
                    }
                }
            }
        }
        assert!(checked > 1000, "only {checked} covered pixels");
    }
}

//! The rasterizer's conservative screen box of a triangle, with a margin
//! derived from the rounding errors instead of a fixed pixel.
//!
//! A box that is too small loses covered pixels; one that is too big only
//! costs time. A triangle smaller than a pixel (millions of them in
//! `scenes/million.toml`) usually contains no pixel center at all: with a
//! one-pixel margin it still cost a setup and a 3x3 or bigger box, with the
//! margin below its box is empty and it costs nothing past this test.
//!
//! # What the box must contain
//!
//! The triangle is clipped against the plane at planar depth `zmin =
//! near (1 - 1e-6)` (exactly as before: the raster never records a hit at a
//! depth below `near`, and the part in front of that plane is what the box
//! covers). A pixel can get a hit only when the line from the eye `e` through
//! its image-plane point `P` meets that clipped polygon `Q`, i.e. when the
//! exact difference `δ = P - e` lies in the cone of `Q` seen from `e`. Let
//! `Φ(v) = (v·r / v·f, v·u / v·f)` in exact arithmetic, with `r`, `u`, `f`
//! the camera's f64 basis vectors. `Φ` is a central projection, so for points in
//! front (`v·f > 0`) it maps the cone onto the convex hull of the vertices'
//! images: `Φ(δ) ∈ hull(Φ(q_i - e))`.
//!
//! # Errors bounded ([`BoxMargin`])
//!
//! With `U = 2^-53`, `A = aspect tan`, `T = tan(vfov / 2)`, in pixel units
//! (one screen unit is `W / (2A)` pixels across, `H / (2T)` down):
//!
//! 1. The pixel's sample against its ideal center. The pixel ray's point is
//!    `P = fl(e + fl(fl(f + fl(r sx~)) + fl(u sy~)))` with `sx~`, `sy~` the
//!    rounded screen coordinates (`|sx~ - sx| <= 5U A`, `|sy~ - sy| <= 5U T`
//!    for the exact `sx`, `sy` of the center: four roundings of values below 2).
//!    So `δ = g + Δ` with `g = f + r sx + u sy` and `|Δ_k| <= 9U H_k + O(U²)`,
//!    `H_k = |e_k| + |f_k| + |r_k| A + |u_k| T`. The basis is orthonormal up
//!    to `ε_B` (its six dot products are evaluated and each is given
//!    `16U` of evaluation error), so `g·r = sx + ε_x`, `g·f = 1 + ε_z`, with
//!    `|ε| <= ε_B (1 + A + T)`. With `α = ε_B (1 + A + T) + 10U |H|_1`,
//!    `|Φ(δ)_x - sx| <= α (1 + A) (1 + 2α)`, likewise in `y`.
//! 2. Each computed vertex projection against `Φ` of the exact vertex. A kept
//!    vertex: `q = fl(v - e)` (one rounding per component), three dot products
//!    (`3U` each, against `|q|_1`), `s = c (1 / z)` and the affine map to
//!    pixels `scale s + W / 2` (`scale = fl(W / 2A)`: five more roundings): at most `8U (|q|_1 (1 + |s|) / z + |s|)` screen
//!    units plus `4U (|p| + W)` pixels, with `s` the screen coordinate and `z`
//!    the planar depth. A vertex made by clipping the edge `p q` is the
//!    intersection computed in camera space: the endpoints' errors move it
//!    along the edge by up to `|q - p|_1 / |q_z - p_z|` times themselves,
//!    so it is counted with `2 (|p|_1 + |q|_1)(1 + |q - p|_1 / |q_z - p_z|)`
//!    plus the camera-space magnitudes in place of `|q|_1`. A vertex whose
//!    error could reach half its depth gives up: the whole image.
//!
//! The box is then the pixels whose centers `k + 1/2` lie within the hull's
//! computed extent grown by `μ = 2 (bound 1 + max bound 2)` (the factor 2
//! covers the second-order terms and the rounding of `μ` and of the final
//! comparisons, all relatively `O(U)`). Non-finite values fall back to the
//! whole image. `tests::tight_boxes_lose_no_pixel` renders with these boxes
//! and with whole-image boxes and checks the buffers are identical; with
//! `μ = 0` it fails.
//!
//! # Four or eight at a time
//!
//! [`bounds_into`] (the binning) takes the common case, no vertex needing
//! clipping, several triangles at a time (`BoxMargin::bounds_wide`, one
//! triangle per f64 lane: eight in AVX-512 where the CPU has it, else four,
//! in AVX2 or plain Rust; AVX-512 took 3-6% off the raster's pass on
//! `million`, alternated in one process): each lane performs exactly
//! the operations of [`BoxMargin::bounds`]' no-clipping path in the same
//! order, with no fused multiply-add, so its boxes are the same bit for
//! bit; a lane that needs clipping goes to [`BoxMargin::bounds`] itself,
//! and so does a lane with a vertex as far as `|q|_1 >= 2^996` from the eye.
//! Below that, every value a kept lane computes is finite: `|q|_1 <
//! 2^996` bounds the camera-space coordinates by `2^998`; `z >= zmin > 0`
//! and `16 U |q|_1 < z` give `|x| / z, |y| / z < 2^50`, so the projections,
//! `|q|_1 / z` and every error term stay far below overflow. So `max` and
//! `min` need no NaN rule (`maxpd` and `f64::max` agree on numbers; of `+0`
//! and `-0` either would do, the boxes depend on values only), which saved
//! two instructions in three of each. `tests::batched_bounds_match_scalar`
//! checks both paths against it triangle by triangle, and
//! `tests::non_finite_lanes_match_scalar` with NaN, infinite and huge
//! coordinates.

use crate::camera::Camera;
use crate::raster::hiz::{f32_below, Abs, NearFaces};
use crate::raster::PixelRect;
use crate::scene::resolve::Tri;
#[cfg(target_arch = "x86_64")]
use crate::simd::{Avx2, Avx512};
use crate::simd::{Lanes, Portable};
use glam::{DVec3, Vec3};

/// Unit roundoff of f64.
const U: f64 = f64::EPSILON / 2.0;

/// `2^996`: the batched lanes keep triangles whose vertices' `|q|_1` lie
/// below it (module documentation: every value is then finite).
const MAX_MAG: f64 = f64::from_bits((996 + 1023) << 52);

/// A camera's constants for [`BoxMargin::bounds`]: the pixel-ray error in
/// pixels (bound 1 of the module documentation) and the scale factors of
/// bound 2.
#[derive(Debug, Clone, Copy)]
pub struct BoxMargin {
    /// Bound 1 in pixels, per axis, already doubled.
    center: [f64; 2],
    /// Pixels per screen unit, per axis.
    scale: [f64; 2],
    /// Half the image's width and height in pixels.
    half: [f64; 2],
    /// Set by tests to check the margin is needed: multiplies every margin.
    factor: f64,
}

impl BoxMargin {
    /// The camera's constants.
    pub fn new(cam: &Camera) -> BoxMargin {
        let (r, u, f, e) = (cam.right, cam.up_ortho, cam.forward, cam.eye);
        // The camera's private `aspect_tan`, by the same expression.
        let a = cam.tan_half_vfov * (f64::from(cam.width) / f64::from(cam.height));
        let t = cam.tan_half_vfov;
        let dev = [
            (r.dot(r) - 1.0).abs(),
            (u.dot(u) - 1.0).abs(),
            (f.dot(f) - 1.0).abs(),
            r.dot(f).abs(),
            u.dot(f).abs(),
            u.dot(r).abs(),
        ];
        let eps_b = dev.iter().fold(0.0f64, |m, &d| m.max(d)) + 16.0 * U;
        let h: f64 = (0..3)
            .map(|k| e[k].abs() + f[k].abs() + r[k].abs() * a + u[k].abs() * t)
            .sum();
        let alpha = eps_b * (1.0 + a + t) + 10.0 * U * h;
        let scale = [
            0.5 * f64::from(cam.width) / a,
            0.5 * f64::from(cam.height) / t,
        ];
        let grow = |s: f64, lim: f64| 2.0 * s * alpha * (1.0 + lim) * (1.0 + 2.0 * alpha);
        BoxMargin {
            center: [grow(scale[0], a), grow(scale[1], t)],
            scale,
            half: [0.5 * f64::from(cam.width), 0.5 * f64::from(cam.height)],
            factor: 1.0,
        }
    }

    /// The same constants with every margin multiplied by `factor` (tests:
    /// 0 must lose pixels somewhere).
    #[cfg(test)]
    pub(crate) fn scaled(mut self, factor: f64) -> BoxMargin {
        self.factor = factor;
        self
    }

    /// Conservative pixel box of the part of triangle `t` at planar depth at
    /// least `near (1 - 1e-6)`: every pixel whose ray can meet that part
    /// (module documentation). `None` when no pixel center can be covered.
    #[inline(always)]
    pub fn bounds(&self, cam: &Camera, t: &Tri) -> Option<PixelRect> {
        let zmin = cam.near * (1.0 - 1e-6);
        let whole = PixelRect {
            x0: 0,
            y0: 0,
            x1: cam.width - 1,
            y1: cam.height - 1,
        };
        // Camera-space vertices and the l1 magnitude of the world difference behind each.
        let cam_space = |v: Vec3| {
            let q = v.as_dvec3() - cam.eye;
            let c = DVec3::new(q.dot(cam.right), q.dot(cam.up_ortho), q.dot(cam.forward));
            (c, q.abs().element_sum())
        };
        // (Not `t.map`: array `map` compiled to out-of-line calls here.)
        let pts: [(DVec3, f64); 3] = [cam_space(t[0]), cam_space(t[1]), cam_space(t[2])];
        if pts
            .iter()
            .all(|&(p, mag)| p.z >= zmin && 16.0 * U * mag < p.z)
        {
            // No clipping (the common case): the same bounds with bound 2
            // taken at the largest `|q|_1 / z`, `|s|` and `|p|` over the
            // vertices (the bound grows with each), in straight-line code.
            let iz = pts.map(|(p, _)| 1.0 / p.z);
            let sx = [0, 1, 2].map(|i| pts[i].0.x * iz[i]);
            let sy = [0, 1, 2].map(|i| pts[i].0.y * iz[i]);
            let px = sx.map(|s| s * self.scale[0] + self.half[0]);
            let py = sy.map(|s| self.half[1] - s * self.scale[1]);
            let max3 = |v: [f64; 3]| v[0].max(v[1]).max(v[2]);
            let min3 = |v: [f64; 3]| v[0].min(v[1]).min(v[2]);
            let mi = max3([0, 1, 2].map(|i| pts[i].1 * iz[i]));
            let (lo, hi) = ([min3(px), min3(py)], [max3(px), max3(py)]);
            let sm = [max3(sx.map(f64::abs)), max3(sy.map(f64::abs))];
            let err_k = |k: usize| {
                self.scale[k] * 8.0 * U * (mi * (1.0 + sm[k]) + sm[k])
                    + 4.0 * U * (lo[k].abs().max(hi[k].abs()) + 2.0 * self.half[k])
            };
            // (Not `[0, 1].map`: it compiled to an out-of-line call per triangle.)
            let err = [err_k(0), err_k(1)];
            if cam.far.is_finite() && pts.iter().all(|(p, _)| p.z > cam.far * (1.0 + 1e-6)) {
                return None;
            }
            return self.finish(cam, lo, hi, err);
        }
        // Clipping a triangle by one plane leaves at most 4 vertices (no allocation).
        let mut poly = [(DVec3::ZERO, 0.0); 4];
        let mut len = 0;
        for i in 0..3 {
            let ((p, pm), (q, qm)) = (pts[i], pts[(i + 1) % 3]);
            let (pin, qin) = (p.z >= zmin, q.z >= zmin);
            if pin {
                poly[len] = (p, pm);
                len += 1;
            }
            if pin != qin {
                let s = (zmin - p.z) / (q.z - p.z);
                let mut m = p + (q - p) * s;
                m.z = m.z.max(zmin);
                // Bound 2 for a clipped vertex: both endpoints' errors, moved
                // along the edge by the error of `s` (sensitivity
                // |q - p| / |q.z - p.z|), plus the interpolation's rounding.
                let slope = (q - p).abs().element_sum() / (q.z - p.z).abs();
                let mag =
                    2.0 * (pm + qm) * (1.0 + slope) + p.abs().element_sum() + q.abs().element_sum();
                poly[len] = (m, mag);
                len += 1;
            }
        }
        let poly = &poly[..len];
        if poly.is_empty() {
            return None;
        }
        if cam.far.is_finite() && poly.iter().all(|(p, _)| p.z > cam.far * (1.0 + 1e-6)) {
            return None;
        }
        let (mut lo, mut hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
        let mut err = [0.0f64; 2];
        for &(p, mag) in poly {
            let known = 16.0 * U * mag < p.z;
            if !known {
                // The depth is not known to a relative 1/2: no useful box.
                return Some(whole);
            }
            // `s = c / z` as `c (1 / z)` (two roundings), then `scale s + W / 2`
            // (`W / 2 - scale s` down): within bound 2's allowance.
            let iz = 1.0 / p.z;
            let s = [p.x * iz, p.y * iz];
            let px = s[0] * self.scale[0] + self.half[0];
            let py = self.half[1] - s[1] * self.scale[1];
            for (k, v) in [px, py].into_iter().enumerate() {
                let e = self.scale[k] * 8.0 * U * (mag * (1.0 + s[k].abs()) * iz + s[k].abs())
                    + 4.0 * U * (v.abs() + 2.0 * self.half[k]);
                err[k] = err[k].max(e);
                lo[k] = lo[k].min(v);
                hi[k] = hi[k].max(v);
            }
        }
        self.finish(cam, lo, hi, err)
    }

    /// The pixel box of the projected extent `[lo, hi]` (x, then y) grown by
    /// `μ` from the vertex errors `err` (module documentation).
    #[inline(always)]
    fn finish(&self, cam: &Camera, lo: [f64; 2], hi: [f64; 2], err: [f64; 2]) -> Option<PixelRect> {
        let whole = PixelRect {
            x0: 0,
            y0: 0,
            x1: cam.width - 1,
            y1: cam.height - 1,
        };
        let mut out = [(0u32, 0u32); 2];
        for k in 0..2 {
            let n = f64::from([cam.width, cam.height][k]);
            let mu = self.factor * (self.center[k] + 2.0 * err[k]);
            // Center `i + 1/2` in [lo - mu, hi + mu]: i in [lo - mu - 1/2, hi + mu - 1/2].
            let (a, b) = ((lo[k] - mu - 0.5).ceil(), (hi[k] + mu - 0.5).floor());
            if !(a.is_finite() && b.is_finite() && mu.is_finite()) {
                return Some(whole);
            }
            let (a, b) = (a.max(0.0), b.min(n - 1.0));
            if a > b {
                return None;
            }
            out[k] = (a as u32, b as u32);
        }
        Some(PixelRect {
            x0: out[0].0,
            y0: out[1].0,
            x1: out[0].1,
            y1: out[1].1,
        })
    }
}

/// The `N` lanes of [`Lanes`] `L`, with the arithmetic operators (a scalar
/// operand stands for itself in every lane), so that [`BoxMargin::bounds_wide`]
/// reads as [`BoxMargin::bounds`].
#[derive(Clone, Copy)]
struct Wide<L: Lanes<N>, const N: usize>(L::V, L);

impl<L: Lanes<N>, const N: usize> Wide<L, N> {
    /// `f64::max` lane by lane (of numbers).
    #[inline(always)]
    fn max(self, o: Wide<L, N>) -> Wide<L, N> {
        Wide(self.1.max(self.0, o.0), self.1)
    }
    /// `f64::min` lane by lane (of numbers).
    #[inline(always)]
    fn min(self, o: Wide<L, N>) -> Wide<L, N> {
        Wide(self.1.min(self.0, o.0), self.1)
    }
    /// `f64::abs` lane by lane.
    #[inline(always)]
    fn abs(self) -> Wide<L, N> {
        Wide(self.1.abs(self.0), self.1)
    }
    /// `f64::is_finite` lane by lane (as std: `|x| < ∞`), as bits.
    #[inline(always)]
    fn is_finite(self) -> u32 {
        let l = self.1;
        l.lt(l.abs(self.0), l.splat(f64::INFINITY))
    }
}

/// Lane-wise `+ - * /` between [`Wide`]s and with scalars on either side.
macro_rules! f4_op {
    ($tr:ident, $f:ident) => {
        impl<L: Lanes<N>, const N: usize> std::ops::$tr for Wide<L, N> {
            type Output = Wide<L, N>;
            #[inline(always)]
            fn $f(self, o: Wide<L, N>) -> Wide<L, N> {
                Wide(self.1.$f(self.0, o.0), self.1)
            }
        }
        impl<L: Lanes<N>, const N: usize> std::ops::$tr<f64> for Wide<L, N> {
            type Output = Wide<L, N>;
            #[inline(always)]
            fn $f(self, o: f64) -> Wide<L, N> {
                Wide(self.1.$f(self.0, self.1.splat(o)), self.1)
            }
        }
        impl<L: Lanes<N>, const N: usize> std::ops::$tr<Wide<L, N>> for f64 {
            type Output = Wide<L, N>;
            #[inline(always)]
            fn $f(self, o: Wide<L, N>) -> Wide<L, N> {
                Wide(o.1.$f(o.1.splat(self), o.0), o.1)
            }
        }
    };
}
f4_op!(Add, add);
f4_op!(Sub, sub);
f4_op!(Mul, mul);
f4_op!(Div, div);

/// The largest of three, as [`BoxMargin::bounds`] takes it (left to right).
#[inline(always)]
fn max3<L: Lanes<N>, const N: usize>(v: [Wide<L, N>; 3]) -> Wide<L, N> {
    v[0].max(v[1]).max(v[2])
}

/// The smallest of three, as [`BoxMargin::bounds`] takes it (left to right).
#[inline(always)]
fn min3<L: Lanes<N>, const N: usize>(v: [Wide<L, N>; 3]) -> Wide<L, N> {
    v[0].min(v[1]).min(v[2])
}

/// One axis of [`BoxMargin::finish`] for `N` triangles
/// ([`BoxMargin::axis_wide`]), lane `j` in bit or element `j`.
struct AxisWide<const N: usize> {
    /// The rounded ends and `μ` are finite (else: the whole image).
    finite: u32,
    /// The clamped ends are empty (else: no pixel).
    empty: u32,
    /// The clamped first pixel index (meaningful where not `empty`).
    lo: [u32; N],
    /// The clamped last pixel index (meaningful where not `empty`).
    hi: [u32; N],
}

/// Vertex `i` of `N` triangles in camera space, as [`BoxMargin::bounds`]
/// computes it: `x`, `y`, `z` (glam's `dot`: left to right) and `|q|_1`
/// (`element_sum`: left to right) of `q = v - e`; and `q`'s component on
/// `axis` (for [`NearFaces::face`]).
#[inline(always)]
fn vertex_wide<L: Lanes<N>, const N: usize>(
    l: L,
    cam: &Camera,
    t: &[Tri; N],
    i: usize,
    axis: usize,
) -> [Wide<L, N>; 5] {
    let (e, r, u, f) = (cam.eye, cam.right, cam.up_ortho, cam.forward);
    let qx = Wide(l.load(t, i, 0), l) - e.x;
    let qy = Wide(l.load(t, i, 1), l) - e.y;
    let qz = Wide(l.load(t, i, 2), l) - e.z;
    [
        qx * r.x + qy * r.y + qz * r.z,
        qx * u.x + qy * u.y + qz * u.z,
        qx * f.x + qy * f.y + qz * f.z,
        qx.abs() + qy.abs() + qz.abs(),
        [qx, qy, qz][axis],
    ]
}

impl<L: Lanes<N>, const N: usize> Abs for Wide<L, N> {
    #[inline(always)]
    fn abs(self) -> Wide<L, N> {
        Wide::abs(self)
    }
}

/// [`NearFaces::face_of`] for `N` triangles, from their vertices' `q` on
/// the faces' axis: the same operations lane by lane (for kept lanes, free
/// of NaN; the others' are recomputed).
#[inline(always)]
fn faces_wide<L: Lanes<N>, const N: usize>(faces: &NearFaces, q: [Wide<L, N>; 3]) -> [f32; N] {
    let (lo, hi) = (min3(q), max3(q));
    let v = if faces.negative() { hi * -1.0 } else { lo };
    let w = NearFaces::w(v, lo, hi);
    w.1.array(w.0).map(f32_below)
}

impl BoxMargin {
    /// [`BoxMargin::bounds`] of `N` triangles at once (the binning's hot
    /// loop), for the common case that needs no clipping: writes triangle
    /// `j`'s box to `out[j]`, or leaves `out[j]` alone and sets bit `j` of
    /// the result when the triangle needs the scalar path (clipping, a depth
    /// not known to a relative 1/2, a NaN depth, a vertex too far to keep
    /// every value finite), which also recomputes its face; and as the
    /// second result, [`faces_away`] of each lane's triangle (the scalar
    /// lanes' too: the same operations, on the same camera-space vertices). Each lane performs exactly
    /// the scalar no-clipping path's operations, in the same order on the
    /// same operands ([`Lanes`]), then `finish`'s checks in its order, so
    /// the boxes are the same bit for bit.
    #[inline(always)]
    fn bounds_wide<L: Lanes<N>, const N: usize>(
        &self,
        l: L,
        cam: &Camera,
        t: &[Tri; N],
        out: &mut [Option<PixelRect>; N],
        (faces, face_out): (&NearFaces, &mut [f32; N]),
    ) -> (u32, u32) {
        let k = faces.axis();
        let p = [
            vertex_wide(l, cam, t, 0, k),
            vertex_wide(l, cam, t, 1, k),
            vertex_wide(l, cam, t, 2, k),
        ];
        *face_out = faces_wide(faces, [p[0][4], p[1][4], p[2][4]]);
        // `faces_away`, lane by lane: the same expression.
        // (Not array `map`: it can compile to out-of-line calls.)
        let det = det3([
            [p[0][0], p[0][1], p[0][2]],
            [p[1][0], p[1][1], p[1][2]],
            [p[2][0], p[2][1], p[2][2]],
        ]);
        let away = l.lt(det.0, l.splat(0.0));
        let zmin = l.splat(cam.near * (1.0 - 1e-6));
        let far = l.splat(cam.far * (1.0 + 1e-6));
        let all = (1u32 << N) - 1;
        let (mut kept, mut beyond) = (all, if cam.far.is_finite() { all } else { 0 });
        let far_mag = l.splat(MAX_MAG);
        for pi in &p {
            kept &= l.ge(pi[2].0, zmin) & l.lt((16.0 * U * pi[3]).0, pi[2].0);
            // Every value finite, so no NaN (module documentation).
            kept &= l.lt(pi[3].0, far_mag);
            beyond &= l.gt(pi[2].0, far);
        }
        let iz = [1.0 / p[0][2], 1.0 / p[1][2], 1.0 / p[2][2]];
        let sx = [p[0][0] * iz[0], p[1][0] * iz[1], p[2][0] * iz[2]];
        let sy = [p[0][1] * iz[0], p[1][1] * iz[1], p[2][1] * iz[2]];
        let (s0, h0, s1, h1) = (self.scale[0], self.half[0], self.scale[1], self.half[1]);
        let px = [sx[0] * s0 + h0, sx[1] * s0 + h0, sx[2] * s0 + h0];
        let py = [h1 - sy[0] * s1, h1 - sy[1] * s1, h1 - sy[2] * s1];
        let mi = max3([p[0][3] * iz[0], p[1][3] * iz[1], p[2][3] * iz[2]]);
        let sm = [
            max3([sx[0].abs(), sx[1].abs(), sx[2].abs()]),
            max3([sy[0].abs(), sy[1].abs(), sy[2].abs()]),
        ];
        let x = self.axis_wide(cam, 0, min3(px), max3(px), mi, sm[0]);
        let y = self.axis_wide(cam, 1, min3(py), max3(py), mi, sm[1]);
        // The common case, both axes finite, and the lanes left to `bounds`.
        let common = kept & !beyond & x.finite & y.finite;
        let empty = x.empty | y.empty;
        for (j, o) in out.iter_mut().enumerate() {
            let rect = PixelRect {
                x0: x.lo[j],
                y0: y.lo[j],
                x1: x.hi[j],
                y1: y.hi[j],
            };
            let bit = 1 << j;
            if common & bit != 0 {
                *o = (empty & bit == 0).then_some(rect);
            } else if kept & bit != 0 {
                // `bounds`' far test, then `finish`'s tests in its order.
                *o = if beyond & bit != 0 || x.finite & x.empty & bit != 0 {
                    None
                } else if (x.finite & y.finite & bit) == 0 {
                    Some(PixelRect {
                        x0: 0,
                        y0: 0,
                        x1: cam.width - 1,
                        y1: cam.height - 1,
                    })
                } else {
                    (empty & bit == 0).then_some(rect)
                };
            }
        }
        (!kept & all, away)
    }

    /// `bounds`' error `err` and [`BoxMargin::finish`]'s steps for axis `k`
    /// of `N` triangles, from their projected extents `[lo, hi]`, largest
    /// `|q|_1 / z` `mi` and largest `|s|` `sm`.
    #[inline(always)]
    fn axis_wide<L: Lanes<N>, const N: usize>(
        &self,
        cam: &Camera,
        k: usize,
        lo: Wide<L, N>,
        hi: Wide<L, N>,
        mi: Wide<L, N>,
        sm: Wide<L, N>,
    ) -> AxisWide<N> {
        let l = lo.1;
        let err = self.scale[k] * 8.0 * U * (mi * (1.0 + sm) + sm)
            + 4.0 * U * (lo.abs().max(hi.abs()) + 2.0 * self.half[k]);
        let mu = self.factor * (self.center[k] + 2.0 * err);
        let a = Wide(l.ceil((lo - mu - 0.5).0), l);
        let b = Wide(l.floor((hi + mu - 0.5).0), l);
        let finite = a.is_finite() & b.is_finite() & mu.is_finite();
        let last = f64::from([cam.width, cam.height][k]) - 1.0;
        let (a, b) = (l.max(a.0, l.splat(0.0)), l.min(b.0, l.splat(last)));
        AxisWide {
            finite,
            empty: l.gt(a, b),
            lo: l.pixels(a),
            hi: l.pixels(b),
        }
    }
}

/// True when triangle `t`'s vertices, seen from the eye, run clockwise:
/// its front (the side its winding's normal points to) faces away, as the
/// far side of a closed, outward-wound mesh does. The binning lists these
/// triangles after the others in each tile ([`crate::raster::bins`]), so
/// that a closed mesh's near side fills the tile first and its far side is
/// skipped as hidden. Only an order: no key depends on it.
///
/// The sign of the determinant of the vertices' camera-space coordinates
/// (as [`BoxMargin::bounds`] computes them), which is minus the world-space
/// `((b - a) x (c - a)) . (e - a)`: the camera's basis (right, up, forward)
/// has determinant -1 (`right = forward x up`, `up = right x forward`).
/// Rounding can flip it for a triangle seen edge-on, which costs time only.
/// NaN: false.
pub fn faces_away(cam: &Camera, t: &Tri) -> bool {
    let c = |v: Vec3| {
        let q = v.as_dvec3() - cam.eye;
        [q.dot(cam.right), q.dot(cam.up_ortho), q.dot(cam.forward)]
    };
    det3([c(t[0]), c(t[1]), c(t[2])]) < 0.0
}

/// The determinant of three camera-space vertices (rows), [`faces_away`]'s
/// sign: one expression for the scalar path and the batched lanes, so that
/// both round alike.
#[inline(always)]
fn det3<T>([[x0, y0, z0], [x1, y1, z1], [x2, y2, z2]]: [[T; 3]; 3]) -> T
where
    T: Copy + std::ops::Mul<Output = T> + std::ops::Sub<Output = T> + std::ops::Add<Output = T>,
{
    x0 * (y1 * z2 - z1 * y2) - y0 * (x1 * z2 - z1 * x2) + z0 * (x1 * y2 - y1 * x2)
}

/// Where [`bounds_into`] writes, one element per triangle (the shortest
/// slice, input or output, sets how many).
pub struct BoundsOut<'a> {
    /// Its box ([`BoxMargin::bounds`]).
    pub boxes: &'a mut [Option<PixelRect>],
    /// Its face ([`NearFaces::face`]).
    pub faces: &'a mut [f32],
    /// Its side ([`faces_away`]).
    pub away: &'a mut [bool],
}

/// [`BoxMargin::bounds`] of each triangle of `tris` into `out.boxes` (`None` for
/// degenerate ones, and the whole image for all when `margin` is `None`),
/// its [`NearFaces::face`] into `out.faces` and [`faces_away`] into `out.away`: the
/// binning's first step. Several triangles at a time through
/// `BoxMargin::bounds_wide` (the scalar [`BoxMargin::bounds`] for lanes that
/// need clipping): eight in AVX-512, else four in AVX2 or plain Rust (the
/// arithmetic is the same).
pub fn bounds_into(
    cam: &Camera,
    tris: &[Tri],
    degenerate: &[bool],
    margin: Option<BoxMargin>,
    out: BoundsOut<'_>,
) {
    #[cfg(target_arch = "x86_64")]
    if let Some(wide) = Avx512::detect() {
        // SAFETY: the CPU has AVX-512F (just detected).
        return unsafe { bounds_avx512(wide, cam, tris, degenerate, margin, out) };
    }
    #[cfg(target_arch = "x86_64")]
    if let Some(avx2) = Avx2::detect() {
        // SAFETY: the CPU has AVX2 (just detected).
        return unsafe { bounds_avx2(avx2, cam, tris, degenerate, margin, out) };
    }
    bounds_chunk(Portable, cam, tris, degenerate, margin, out)
}

/// [`bounds_chunk`] compiled for AVX-512F, eight triangles at a time.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f")]
fn bounds_avx512(
    wide: Avx512,
    cam: &Camera,
    tris: &[Tri],
    deg: &[bool],
    margin: Option<BoxMargin>,
    out: BoundsOut<'_>,
) {
    bounds_chunk(wide, cam, tris, deg, margin, out)
}

/// [`bounds_chunk`] compiled for AVX2.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
fn bounds_avx2(
    avx2: Avx2,
    cam: &Camera,
    tris: &[Tri],
    deg: &[bool],
    margin: Option<BoxMargin>,
    out: BoundsOut<'_>,
) {
    bounds_chunk(avx2, cam, tris, deg, margin, out)
}

/// [`bounds_into`] with the lanes `l`.
#[inline(always)]
fn bounds_chunk<L: Lanes<N>, const N: usize>(
    l: L,
    cam: &Camera,
    tris: &[Tri],
    deg: &[bool],
    margin: Option<BoxMargin>,
    out: BoundsOut<'_>,
) {
    let BoundsOut {
        boxes: out,
        faces,
        away,
    } = out;
    let n = out
        .len()
        .min(tris.len())
        .min(deg.len())
        .min(faces.len())
        .min(away.len());
    let (out, tris, deg, faces, away) = (
        &mut out[..n],
        &tris[..n],
        &deg[..n],
        &mut faces[..n],
        &mut away[..n],
    );
    let nf = NearFaces::new(cam);
    let Some(m) = margin else {
        let whole = PixelRect {
            x0: 0,
            y0: 0,
            x1: cam.width - 1,
            y1: cam.height - 1,
        };
        for ((((o, &d), f), a), t) in out.iter_mut().zip(deg).zip(faces).zip(away).zip(tris) {
            *o = (!d).then_some(whole);
            *f = nf.face(t);
            *a = faces_away(cam, t);
        }
        return;
    };
    let (mut o4, mut t4, mut d4, mut f4, mut a4) = (
        out.chunks_exact_mut(N),
        tris.chunks_exact(N),
        deg.chunks_exact(N),
        faces.chunks_exact_mut(N),
        away.chunks_exact_mut(N),
    );
    for ((((o, t), d), f), a) in (&mut o4)
        .zip(&mut t4)
        .zip(&mut d4)
        .zip(&mut f4)
        .zip(&mut a4)
    {
        let (o, t): (&mut [_; N], &[Tri; N]) = (o.try_into().unwrap(), t.try_into().unwrap());
        let f: &mut [f32; N] = f.try_into().unwrap();
        let (scalar, back) = m.bounds_wide(l, cam, t, o, (&nf, f));
        for (j, a) in a.iter_mut().enumerate() {
            *a = (back >> j) & 1 == 1;
        }
        for j in 0..N {
            if d[j] {
                o[j] = None;
            } else if scalar & (1 << j) != 0 {
                o[j] = m.bounds(cam, &t[j]);
            }
            if scalar & (1 << j) != 0 {
                f[j] = nf.face(&t[j]);
            }
        }
    }
    let rest = o4
        .into_remainder()
        .iter_mut()
        .zip(t4.remainder())
        .zip(d4.remainder())
        .zip(f4.into_remainder())
        .zip(a4.into_remainder());
    for ((((o, t), &d), f), a) in rest {
        *o = if d { None } else { m.bounds(cam, t) };
        *f = nf.face(t);
        *a = faces_away(cam, t);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Vec3;

    /// Uniform in [0, 1) (xorshift64*).
    fn rand(s: &mut u64) -> f64 {
        *s ^= *s >> 12;
        *s ^= *s << 25;
        *s ^= *s >> 27;
        (s.wrapping_mul(0x2545_f491_4f6c_dd1d) >> 11) as f64 / (1u64 << 53) as f64
    }

    /// A point within `r` of `c` in each coordinate.
    fn near(s: &mut u64, c: DVec3, r: f64) -> DVec3 {
        c + DVec3::new(rand(s) - 0.5, rand(s) - 0.5, rand(s) - 0.5) * (2.0 * r)
    }

    /// The cameras: exact 90°, tilted non-dyadic, far from the origin, a
    /// finite far plane, a tiny near plane, a full-HD image.
    fn cameras() -> Vec<Camera> {
        let inf = f64::INFINITY;
        let o = DVec3::new(1e7, -1e7, 1e7);
        let cam = |e: DVec3, at: DVec3, vfov, w, h, n, f| {
            Camera::new(e, at, DVec3::Y, vfov, w, h, n, f).unwrap()
        };
        vec![
            cam(DVec3::Z * 3.0, DVec3::ZERO, 90.0, 64, 48, 1e-3, inf),
            cam(
                DVec3::new(0.4, -1.1, 3.0),
                DVec3::new(0.1, 0.2, -0.3),
                47.3,
                61,
                37,
                1e-3,
                inf,
            ),
            cam(o + DVec3::new(0.4, -1.1, 3.0), o, 45.0, 50, 40, 1e-3, inf),
            cam(
                DVec3::new(-3.0, 0.2, 0.1),
                DVec3::ZERO,
                50.0,
                40,
                40,
                0.5,
                4.0,
            ),
            cam(
                DVec3::new(0.3, 0.7, 2.0),
                DVec3::ZERO,
                60.0,
                33,
                65,
                1e-9,
                inf,
            ),
            cam(
                DVec3::new(0.0, 1.2, 3.2),
                DVec3::Y * 0.1,
                45.0,
                1920,
                1080,
                1e-3,
                inf,
            ),
        ]
    }

    /// Every kind of triangle the binning meets, in random order.
    fn triangles(cam: &Camera, seed: u64, n: usize) -> Vec<Tri> {
        let mut s = seed | 1;
        let s = &mut s;
        let (e, f) = (cam.eye, cam.forward);
        let depth = if cam.far.is_finite() { cam.far } else { 20.0 };
        let mut out = Vec::with_capacity(n);
        while out.len() < n {
            let kind = (rand(s) * 10.0) as u32;
            let c = near(s, cam.look_at, 2.0);
            let t: [DVec3; 3] = match kind {
                // Random, around what the camera looks at.
                0 => [near(s, c, 1.0), near(s, c, 1.0), near(s, c, 1.0)],
                // Sub-pixel.
                1 => {
                    let r = 1e-3 * rand(s);
                    [near(s, c, r), near(s, c, r), near(s, c, r)]
                }
                // Huge.
                2 => [near(s, c, 1e4), near(s, c, 1e4), near(s, c, 1e3)],
                // Behind the eye.
                3 => {
                    let b = e - f * (0.5 + rand(s));
                    [near(s, b, 0.3), near(s, b, 0.3), near(s, b, 0.3)]
                }
                // Crossing or touching the near plane.
                4 => {
                    let z = cam.near
                        * [1.0, 1.0 - 1e-6, 1.0 + 1e-9, 4.0 * rand(s) - 2.0]
                            [(rand(s) * 4.0) as usize];
                    let a = e + f * z + near(s, DVec3::ZERO, cam.near);
                    [a, near(s, c, 0.5), near(s, c, 0.5)]
                }
                // Around the far plane (or far away).
                5 => {
                    let b = e + f * depth * (0.9 + 0.2 * rand(s));
                    let r = 0.05 * depth;
                    [near(s, b, r), near(s, b, r), near(s, b, r)]
                }
                // Degenerate but finite: a point, a segment.
                6 => {
                    let d = near(s, DVec3::ZERO, 0.1);
                    if rand(s) < 0.5 {
                        [c; 3]
                    } else {
                        [c, c + d, c + d * 2.0]
                    }
                }
                // Straddling the image's borders: on the border pixels' rays.
                7 | 8 => {
                    let (w, h) = (cam.width - 1, cam.height - 1);
                    let (x, y) = match (rand(s) * 4.0) as u32 {
                        0 => (0, (rand(s) * f64::from(h)) as u32),
                        1 => (w, (rand(s) * f64::from(h)) as u32),
                        2 => ((rand(s) * f64::from(w)) as u32, 0),
                        _ => ((rand(s) * f64::from(w)) as u32, h),
                    };
                    let p = e + cam.pixel_ray(x, y).dir * (0.5 + 4.0 * rand(s));
                    let r = [1e-4, 1e-2, 0.5][(rand(s) * 3.0) as usize];
                    [near(s, p, r), near(s, p, r), near(s, p, r)]
                }
                // In front, spread over the view at any depth.
                _ => {
                    let p = e + f * (cam.near + 10.0 * rand(s)) + near(s, DVec3::ZERO, 3.0);
                    let r = 0.1 * rand(s);
                    [near(s, p, r), near(s, p, r), near(s, p, r)]
                }
            };
            out.push(t.map(|v| v.as_vec3()));
        }
        out
    }

    /// The batched path ([`bounds_into`], portable, AVX2 and AVX-512) gives
    /// every triangle exactly [`BoxMargin::bounds`]' box,
    /// [`NearFaces::face`]'s face and [`faces_away`]' side, under every camera,
    /// margin factor, degenerate flag and batch remainder; and the batched
    /// lanes really do most of the work.
    #[test]
    fn batched_bounds_match_scalar() {
        for (ci, cam) in cameras().iter().enumerate() {
            let tris = triangles(cam, 0x9e37_79b9 + ci as u64, 20_000);
            let deg: Vec<bool> = (0..tris.len()).map(|i| i % 17 == 5).collect();
            let base = BoxMargin::new(cam);
            for margin in [
                Some(base),
                Some(base.scaled(0.0)),
                Some(base.scaled(3.0)),
                None,
            ] {
                let whole = PixelRect {
                    x0: 0,
                    y0: 0,
                    x1: cam.width - 1,
                    y1: cam.height - 1,
                };
                let want: Vec<_> = (0..tris.len())
                    .map(|i| match (deg[i], margin) {
                        (true, _) => None,
                        (false, Some(m)) => m.bounds(cam, &tris[i]),
                        (false, None) => Some(whole),
                    })
                    .collect();
                let nf = NearFaces::new(cam);
                let want_faces: Vec<u32> = tris.iter().map(|t| nf.face(t).to_bits()).collect();
                let bits = |f: &[f32]| f.iter().map(|v| v.to_bits()).collect::<Vec<_>>();
                let want_away: Vec<bool> = tris.iter().map(|t| faces_away(cam, t)).collect();
                // Both sides occur.
                assert!(want_away.iter().any(|&a| a) && want_away.iter().any(|&a| !a));
                for len in [tris.len(), tris.len() - 1, tris.len() - 3, 2] {
                    let (t, d) = (&tris[..len], &deg[..len]);
                    let check = |what: &str, run: &dyn Fn(BoundsOut)| {
                        let mut got = vec![Some(whole); len];
                        let mut faces = vec![f32::NAN; len];
                        let mut away = vec![false; len];
                        run(BoundsOut {
                            boxes: &mut got,
                            faces: &mut faces,
                            away: &mut away,
                        });
                        assert_eq!(got, want[..len], "{what}, camera {ci}");
                        assert_eq!(bits(&faces), want_faces[..len], "{what}, camera {ci}");
                        assert_eq!(away, want_away[..len], "{what}, camera {ci}");
                    };
                    check("portable", &|o| {
                        bounds_chunk(Portable, cam, t, d, margin, o)
                    });
                    #[cfg(target_arch = "x86_64")]
                    if let Some(avx2) = Avx2::detect() {
                        // SAFETY: the CPU has AVX2 (just detected).
                        check("AVX2", &|o| unsafe {
                            bounds_avx2(avx2, cam, t, d, margin, o)
                        });
                    }
                    #[cfg(target_arch = "x86_64")]
                    if let Some(wide) = Avx512::detect() {
                        // SAFETY: the CPU has AVX-512F (just detected).
                        check("AVX-512", &|o| unsafe {
                            bounds_avx512(wide, cam, t, d, margin, o)
                        });
                    }
                    check("bounds_into", &|o| bounds_into(cam, t, d, margin, o));
                }
            }
            // Most lanes are decided by the batch, not left to `bounds`.
            let mut batched = 0;
            for t in tris.chunks_exact(4) {
                let (mut o, mut f) = ([None; 4], [0.0; 4]);
                let nf = NearFaces::new(cam);
                batched += 4 - base
                    .bounds_wide(Portable, cam, t.try_into().unwrap(), &mut o, (&nf, &mut f))
                    .0
                    .count_ones();
            }
            assert!(
                batched as usize > tris.len() / 2,
                "camera {ci}: {batched} batched"
            );
        }
    }

    /// Lanes with NaN or infinite coordinates give the scalar boxes (and
    /// faces and sides) too.
    #[test]
    fn non_finite_lanes_match_scalar() {
        let good = [
            Vec3::new(0.1, 0.2, 0.0),
            Vec3::new(0.3, 0.1, 0.0),
            Vec3::new(0.2, 0.4, 0.1),
        ];
        let mut tris = Vec::new();
        for bad in [
            f32::NAN,
            f32::INFINITY,
            f32::NEG_INFINITY,
            f32::MAX,
            f32::MIN_POSITIVE,
        ] {
            for k in 0..9 {
                let mut t = good;
                t[k / 3][k % 3] = bad;
                tris.extend([good, t, good, good]);
            }
        }
        // Far eyes: as far as `Camera::new` allows (its basis must
        // normalize `look_at - eye`), and beyond the batched lanes' range
        // (`MAX_MAG`), moved there after its checks.
        let far = |z: f64| {
            let e = DVec3::new(0.0, 0.0, z);
            let at = DVec3::new(0.0, 0.0, z - z * 1e-12);
            Camera::new(e, at, DVec3::Y, 40.0, 30, 20, 1e-3, f64::INFINITY).unwrap()
        };
        let mut beyond = far(1e150);
        beyond.eye.z = 2.0 * MAX_MAG;
        for cam in [&cameras()[1], &far(1e150), &beyond] {
            let m = BoxMargin::new(cam);
            let deg = vec![false; tris.len()];
            let want: Vec<_> = tris.iter().map(|t| m.bounds(cam, t)).collect();
            let nf = NearFaces::new(cam);
            let want_faces: Vec<u32> = tris.iter().map(|t| nf.face(t).to_bits()).collect();
            let bits = |f: &[f32]| f.iter().map(|v| v.to_bits()).collect::<Vec<_>>();
            let want_away: Vec<bool> = tris.iter().map(|t| faces_away(cam, t)).collect();
            let n = tris.len();
            // Each entry point fills fresh outputs with the scalar answers.
            let check = |fill: &dyn Fn(BoundsOut<'_>)| {
                let (mut got, mut faces, mut away) =
                    (vec![None; n], vec![f32::NAN; n], vec![true; n]);
                fill(BoundsOut {
                    boxes: &mut got,
                    faces: &mut faces,
                    away: &mut away,
                });
                assert_eq!(got, want);
                assert_eq!(bits(&faces), want_faces);
                assert_eq!(away, want_away);
            };
            check(&|o| bounds_chunk(Portable, cam, &tris, &deg, Some(m), o));
            check(&|o| bounds_into(cam, &tris, &deg, Some(m), o));
            assert!(want.iter().any(Option::is_some));
        }
    }
}

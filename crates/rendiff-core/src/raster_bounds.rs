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

use crate::camera::Camera;
use crate::raster::PixelRect;
use crate::scene::resolve::Tri;
use glam::DVec3;

/// Unit roundoff of f64.
const U: f64 = f64::EPSILON / 2.0;

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
        let pts: [(DVec3, f64); 3] = t.map(|v| {
            let q = v.as_dvec3() - cam.eye;
            let c = DVec3::new(q.dot(cam.right), q.dot(cam.up_ortho), q.dot(cam.forward));
            (c, q.abs().element_sum())
        });
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
            let err = [0, 1].map(|k| {
                self.scale[k] * 8.0 * U * (mi * (1.0 + sm[k]) + sm[k])
                    + 4.0 * U * (lo[k].abs().max(hi[k].abs()) + 2.0 * self.half[k])
            });
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

/// [`BoxMargin::bounds`] of each triangle of `tris` into `out` (`None` for
/// degenerate ones, and the whole image for all when `margin` is `None`); on
/// x86-64 CPUs with AVX2 compiled for it (rounding to integers is then one
/// instruction; the arithmetic is the same).
pub fn bounds_into(
    cam: &Camera,
    tris: &[Tri],
    degenerate: &[bool],
    margin: Option<BoxMargin>,
    out: &mut [Option<PixelRect>],
) {
    #[cfg(target_arch = "x86_64")]
    if crate::raster_edges::Avx2::detect().is_some() {
        // SAFETY: the CPU has AVX2 (just detected).
        return unsafe { bounds_avx2(cam, tris, degenerate, margin, out) };
    }
    bounds_chunk(cam, tris, degenerate, margin, out)
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
fn bounds_avx2(
    cam: &Camera,
    tris: &[Tri],
    deg: &[bool],
    margin: Option<BoxMargin>,
    out: &mut [Option<PixelRect>],
) {
    bounds_chunk(cam, tris, deg, margin, out)
}

#[inline(always)]
fn bounds_chunk(
    cam: &Camera,
    tris: &[Tri],
    deg: &[bool],
    margin: Option<BoxMargin>,
    out: &mut [Option<PixelRect>],
) {
    let whole = PixelRect {
        x0: 0,
        y0: 0,
        x1: cam.width - 1,
        y1: cam.height - 1,
    };
    for ((o, t), &d) in out.iter_mut().zip(tris).zip(deg) {
        *o = match (d, &margin) {
            (true, _) => None,
            (false, Some(m)) => m.bounds(cam, t),
            (false, None) => Some(whole),
        };
    }
}

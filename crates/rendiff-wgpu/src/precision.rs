//! The renderer's precision model, derived from the Vulkan specification and
//! from the arithmetic this crate does; the harness judges ID and depth
//! differences against it (docs/verifier.md). The numbers are derived, not
//! fitted: nothing here was tuned to make a scene pass.
//!
//! # Edge distance
//!
//! Coverage is decided by the Vulkan rasterizer. The spec ("Rasterization",
//! `subPixelPrecisionBits`) lets an implementation snap framebuffer vertex
//! coordinates to a grid of `2^-b` pixels, `b = subPixelPrecisionBits`, and
//! does not fix the rounding direction, so a vertex may move by up to `2^-b`
//! per axis (llvmpipe rounds to nearest, `2^-(b+1)`; we do not rely on it).
//! After the snap, coverage of the snapped triangle is exact in fixed point
//! (the spec's edge tie rule picks exactly one triangle for shared edges).
//! Before the snap, the vertex carries the f32 errors of:
//!
//! 1. the upload: `d = f32(X - eye)` subtracted in f64 and rounded once (u per
//!    coordinate, `u = 2^-24`), and each matrix entry rounded once from f64 (u);
//! 2. the vertex shader's `clip = M d` (three products and three additions,
//!    a zero translation term included): clip x, y and w each carry at most
//!    `gamma_6 |row| |d|`, where `gamma_n = n u / (1 - n u)` and `|row|` is
//!    `1/(tan W/H)`, `1/tan` and `1` for x, y and w;
//! 3. the perspective divide and the viewport transform (one rounding each
//!    for the divide, the scale and the offset).
//!
//! With `s = x_c / w_c` the vertex's NDC x, `rho = |d| / w_c` (1 on the axis,
//! `sqrt(1 + (tan W/H)^2 + tan^2)` at the image corner) and `F = H / (2 tan)`
//! the focal length in pixels, the first-order error of the vertex's
//! framebuffer x is
//!
//! ```text
//! e_x <= gamma_6 rho (F + |s| W/2) + u (W/2) (3|s| + 1)
//! ```
//!
//! and the same with H for y. For a vertex inside the image (`|s| <= 1`) that is
//! `gamma_6 rho (F + W/2) + 2 u W`. An edge is a convex combination of its two
//! (snapped) ends, so a point of the edge moves by no more than its ends do:
//!
//! ```text
//! edge_px = sqrt((2^-b + e_x)^2 + (2^-b + e_y)^2)
//! ```
//!
//! The harness wants one number per renderer, so [`EDGE_PX`] is this bound over
//! an envelope of cameras: `W, H <= 4096`, `F <= 4096` px (e.g. 1080 rows at
//! vfov >= 15 degrees) and `rho <= 2` (image corners within 60 degrees of the
//! view axis), with `b = 8` (lavapipe's `subPixelPrecisionBits`, read from the
//! adapter at run time). Every render also computes the bound for its own
//! camera and adapter ([`edge_px`]), stores it in the EXR as `rendiff:edge_px`,
//! and warns when it exceeds the declared number.
//!
//! Not covered: vertices projecting far outside the image (`|s| > 1`) add
//! error that grows with `|s|`, and the rasterizer's clipping against the near
//! plane or its guard band makes new vertices in f32; pixels near such edges
//! may differ by more.
//!
//! # Depth
//!
//! `Z` is not interpolated: the fragment shader recomputes it from the
//! triangle's plane, the core's own definition (docs/DESIGN.md: ray-plane
//! intersection). On the CPU, in f64 from the exact f32 vertices, each
//! triangle gets its unit normal in camera coordinates `(n.r, n.u, n.f)` and
//! its offset `k = n . (a - eye)`, rounded once to f32; each column's `sx` and
//! each row's `sy` are the resolved-scene formula in f64, rounded once. The
//! shader evaluates `Z = k / (n.f + n.r sx + n.u sy)`. The denominator's terms
//! carry at most `gamma_5` each (two roundings of inputs, one product, two
//! sums), i.e. `gamma_5 |n| |d|` in all, and the true denominator is
//! `|n| |d| |cos|` (cos between the pixel ray and the normal), so its relative
//! error is `gamma_5 / |cos|`; the offset and the division add `2u`:
//!
//! ```text
//! |Z_wgpu - Z| <= (5/|cos| + 2) u Z <= 7 u Z / |cos|
//! ```
//!
//! The reference's f32 `Z` is one more rounding (`u Z`), so against it
//! `|dZ| <= 8 u Z / |cos|`: [`DEPTH_RELATIVE`] = `8u` in the form
//! `depth_relative * Z / |cos|` the harness uses (`tolerance.relative_grazing`).
//! Visibility uses the same numbers: the shader writes
//! `frag_depth = near_clip / Z` into a Depth32Float buffer (compare `Greater`,
//! so among equal depths the first drawn, the lower prim, wins), so the nearer
//! plane wins unless the two agree within that tolerance (a *tie*).
//! Pixels whose `Z` falls outside `[near, far]` are discarded in the shader,
//! the core's near/far rule.

/// f32's unit roundoff.
pub const U: f64 = 1.0 / 16_777_216.0;

/// `subPixelPrecisionBits` assumed when the adapter cannot be asked
/// (lavapipe/llvmpipe report 8).
pub const ASSUMED_SUBPIXEL_BITS: u32 = 8;

/// The envelope of cameras [`EDGE_PX`] covers: largest width or height.
pub const ENVELOPE_MAX_SIZE_PX: f64 = 4096.0;
/// The envelope's largest focal length `H / (2 tan(vfov/2))`, in pixels.
pub const ENVELOPE_MAX_FOCAL_PX: f64 = 4096.0;
/// The envelope's largest `|d| / depth` at the image corner (60 degrees off axis).
pub const ENVELOPE_MAX_RHO: f64 = 2.0;

/// Declared edge distance in pixels (renderers/wgpu.toml `edge_px`): the
/// bound of [`edge_px_parts`] over the envelope, rounded up.
pub const EDGE_PX: f64 = 0.0125;

/// Declared relative depth tolerance per `1/|cos|` (renderers/wgpu.toml
/// `depth_relative`): `8u`, rounded up.
pub const DEPTH_RELATIVE: f64 = 4.8e-7;

/// `gamma_n = n u / (1 - n u)`: the bound on `n` successive f32 roundings.
pub fn gamma(n: u32) -> f64 {
    let nu = f64::from(n) * U;
    nu / (1.0 - nu)
}

/// The edge distance (px) for an image `width x height`, focal length
/// `focal_px`, corner ratio `rho` and `bits` of sub-pixel precision: the
/// formula of this module's documentation, for vertices inside the image.
pub fn edge_px_parts(width: f64, height: f64, focal_px: f64, rho: f64, bits: u32) -> f64 {
    let snap = (-f64::from(bits)).exp2();
    let ex = gamma(6) * rho * (focal_px + width / 2.0) + 2.0 * U * width;
    let ey = gamma(6) * rho * (focal_px + height / 2.0) + 2.0 * U * height;
    (snap + ex).hypot(snap + ey)
}

/// The edge distance (px) for this camera and adapter.
pub fn edge_px(view: &crate::camera::View, bits: u32) -> f64 {
    let (w, h) = (f64::from(view.width), f64::from(view.height));
    let focal = h / (2.0 * view.tan_half_vfov);
    let rho = (1.0 + view.aspect_tan().powi(2) + view.tan_half_vfov.powi(2)).sqrt();
    edge_px_parts(w, h, focal, rho, bits)
}

/// The bound over the declared envelope (what [`EDGE_PX`] rounds up).
pub fn envelope_edge_px() -> f64 {
    edge_px_parts(
        ENVELOPE_MAX_SIZE_PX,
        ENVELOPE_MAX_SIZE_PX,
        ENVELOPE_MAX_FOCAL_PX,
        ENVELOPE_MAX_RHO,
        ASSUMED_SUBPIXEL_BITS,
    )
}

/// The depth bound per `1/|cos|` against an f32 reference: `(5 + 2 + 1) u`,
/// with the gammas' second-order terms.
pub fn derived_depth_relative() -> f64 {
    gamma(5) + gamma(3)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn declared_numbers_cover_the_derivation_and_are_not_padded() {
        let e = envelope_edge_px();
        assert!(EDGE_PX >= e, "{EDGE_PX} < {e}");
        assert!(EDGE_PX < e * 1.01, "{EDGE_PX} is more than 1% above {e}");
        let d = derived_depth_relative();
        assert!(DEPTH_RELATIVE >= d && DEPTH_RELATIVE < d * 1.01, "{d}");
    }

    #[test]
    fn snap_dominates_small_images() {
        // 96x72 at vfov 45: essentially the sqrt(2) 2^-8 snap.
        let e = edge_px_parts(96.0, 72.0, 72.0 / (2.0 * 0.41421356), 1.3, 8);
        let snap = 2f64.sqrt() / 256.0;
        assert!(e > snap && e < snap * 1.02, "{e}");
    }

    /// The vertex path in f32, emulated on the CPU as the GPU runs it
    /// (eye-relative upload, column-major matrix, divide, viewport), never
    /// moves a vertex by more than the pre-snap terms `e_x`, `e_y`.
    #[test]
    fn f32_vertex_path_stays_within_the_derived_error() {
        use crate::camera::{self, View};
        let views = [
            (
                [0.4, 1.2, 4.2],
                [-0.066, -0.086, -0.994],
                0.364,
                160u32,
                120u32,
            ),
            ([2.0e4, 10.0, -3.0e4], [0.6, -0.1, 0.79], 0.7, 1920, 1080),
            ([0.0, 0.0, 1.0], [0.0, 0.0, -1.0], 1.0, 4096, 4096),
        ];
        let mut worst: f64 = 0.0;
        let mut seed = 12345u64;
        let mut rnd = move || {
            seed = seed
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            ((seed >> 11) as f64) / ((1u64 << 53) as f64)
        };
        for (eye, f, tan, w, h) in views {
            let fl = camera::dot(f, f).sqrt();
            let forward = f.map(|c| c / fl);
            let r = camera::cross(forward, [0.0, 1.0, 0.0]);
            let rl = camera::dot(r, r).sqrt();
            let right = r.map(|c| c / rl);
            let view = View {
                eye,
                forward,
                right,
                up: camera::cross(right, forward),
                tan_half_vfov: tan,
                width: w,
                height: h,
                near: 1e-3,
                far: f64::INFINITY,
            };
            let m = camera::to_gpu(&view.projection_rotation(view.near / 2.0));
            let (wf, hf) = (f64::from(w), f64::from(h));
            let focal = hf / (2.0 * tan);
            for _ in 0..20000 {
                // A point inside the image, at depth 1e-2 .. 1e3 (log-uniform).
                let (sx, sy) = (2.0 * rnd() - 1.0, 2.0 * rnd() - 1.0);
                let depth = 10f64.powf(-2.0 + 5.0 * rnd());
                let dir = [0, 1, 2].map(|k| {
                    forward[k] + sx * view.aspect_tan() * right[k] + sy * tan * view.up[k]
                });
                let x: [f32; 3] = [0, 1, 2].map(|k| (eye[k] + depth * dir[k]) as f32);
                let xd = x.map(f64::from);
                // Exact (f64) framebuffer position of the f32 vertex.
                let clip = camera::mul(
                    &view.view_projection(view.near / 2.0),
                    [xd[0], xd[1], xd[2], 1.0],
                );
                let (px, py) = view.clip_to_pixel(clip).unwrap();
                // The GPU path in f32.
                let d = camera::sub(xd, eye).map(|c| c as f32);
                let row = |i: usize| m[0][i] * d[0] + m[1][i] * d[1] + m[2][i] * d[2] + m[3][i];
                let (cx, cy, cw) = (row(0), row(1), row(3));
                let gx = (cx / cw) * (w as f32 / 2.0) + w as f32 / 2.0;
                let gy = (cy / cw) * (-(h as f32) / 2.0) + h as f32 / 2.0;
                let s = (2.0 * px / wf - 1.0).abs();
                let t = (1.0 - 2.0 * py / hf).abs();
                let rho = camera::dot(camera::sub(xd, eye), camera::sub(xd, eye)).sqrt() / clip[3];
                let ex = gamma(6) * rho * (focal + s * wf / 2.0) + U * (wf / 2.0) * (3.0 * s + 1.0);
                let ey = gamma(6) * rho * (focal + t * hf / 2.0) + U * (hf / 2.0) * (3.0 * t + 1.0);
                assert!(
                    (f64::from(gx) - px).abs() <= ex,
                    "x {gx} vs {px}: bound {ex:e}"
                );
                assert!(
                    (f64::from(gy) - py).abs() <= ey,
                    "y {gy} vs {py}: bound {ey:e}"
                );
                worst = worst
                    .max((f64::from(gx) - px).abs() / ex)
                    .max((f64::from(gy) - py).abs() / ey);
            }
        }
        // A bound, not an estimate; but not a vacuous one either.
        eprintln!("worst f32 vertex error / derived bound: {worst:.3}");
        assert!(worst > 0.05, "{worst}");
    }

    #[test]
    fn fewer_bits_mean_a_wider_band() {
        assert!(edge_px_parts(64.0, 64.0, 32.0, 1.7, 4) > edge_px_parts(64.0, 64.0, 32.0, 1.7, 8));
    }
}

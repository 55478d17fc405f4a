//! The reducer's image step (docs/fuzzing.md): fewer pixels, through a
//! centered crop. The camera contract (docs/DESIGN.md) puts the principal
//! point at the image center and has no off-center window, so the only
//! smaller image whose pixels keep their rays is a centered one: `kx`
//! columns off each side and `ky` rows off the top and bottom, with the
//! vertical field of view narrowed so that the pixel pitch stays, that is
//! `tan(vfov'/2) / H' = tan(vfov/2) / H`.
//!
//! Why that keeps the rays: `camera.rs` puts column `x`'s centers at
//! `sx = (2 (x + 0.5) / W - 1) tan(vfov/2) W / H = (2x + 1 - W) tan(vfov/2) / H`.
//! Column `x' = x - kx` of the crop, with `W' = W - 2 kx`, has
//! `2x' + 1 - W' = 2x + 1 - W`, so the same `sx` exactly when
//! `tan(vfov'/2) / H' = tan(vfov/2) / H`; rows likewise with `y` and `H`.
//! A crop in width alone keeps `H`, so `vfov` stays (bit for bit). A crop in
//! height needs `vfov' = 2 atan(tan(vfov/2) H'/H)` in degrees, which the
//! scene file stores as an f64 and the core turns back into a tangent
//! (`camera::tan_half_deg`); that round trip cannot be exact in general, so
//! [`narrowed_vfov`] takes the f64 whose tangent lands nearest the target,
//! and every ray still moves by a few units in the last place (bounded in
//! the tests below). Whether a failure survives that is for the reducer's
//! interestingness test to say: it renders the crop again.

use super::literal::LiteralCamera;
use crate::camera::tan_half_deg;

/// How many f64 steps either side of `2 atan(target)` [`narrowed_vfov`]
/// looks at. One step of `vfov` (one unit in its last place) moves
/// `tan(vfov/2)` by `(pi/360)(1 + tan^2) ulp(vfov)`, about one unit in the
/// last place of the tangent (at most a few for fields of view up to 120
/// degrees), so the nearest tangent is within a step or two of the first
/// guess; 16 leaves room for `atan`'s and `tan`'s own rounding.
const VFOV_STEPS: usize = 16;

/// The vertical field of view (degrees) of a crop from `height` rows to
/// `new_height`, keeping the pixel pitch: the f64 near
/// `2 atan(tan(vfov/2) new_height / height)` whose `camera::tan_half_deg`
/// comes nearest that target (the first such, looking outward from the
/// first guess). Unchanged when the height is.
pub fn narrowed_vfov(vfov: f64, height: u32, new_height: u32) -> f64 {
    if new_height == height {
        return vfov;
    }
    let t = tan_half_deg(vfov);
    let (h, h2) = (f64::from(height), f64::from(new_height));
    let first = 2.0 * (t * h2 / h).atan().to_degrees();
    // Compared as tan' H - tan H' (no division): zero at the target.
    let miss = |v: f64| (tan_half_deg(v) * h - t * h2).abs();
    let mut best = (miss(first), first);
    let (mut down, mut up) = (first, first);
    for _ in 0..VFOV_STEPS {
        down = down.next_down();
        up = up.next_up();
        for v in [down, up] {
            let m = miss(v);
            if v > 0.0 && v < 180.0 && m < best.0 {
                best = (m, v);
            }
        }
    }
    best.1
}

/// The camera of the centered crop that drops `kx` columns from each side
/// and `ky` rows from the top and from the bottom; None when nothing would
/// be left.
pub fn crop(c: &LiteralCamera, kx: u32, ky: u32) -> Option<LiteralCamera> {
    let width = c.width.checked_sub(kx.checked_mul(2)?).filter(|&w| w > 0)?;
    let height = c
        .height
        .checked_sub(ky.checked_mul(2)?)
        .filter(|&h| h > 0)?;
    Some(LiteralCamera {
        width,
        height,
        vfov: narrowed_vfov(c.vfov, c.height, height),
        ..c.clone()
    })
}

/// The largest crop per side of an image side of `side` pixels (one pixel
/// or two left).
pub fn max_crop(side: u32) -> u32 {
    side.saturating_sub(1) / 2
}

/// Up to `n` crops to try strictly between `lo` (known to hold) and `hi`
/// (known not to, or past the largest), evenly spaced, largest first: the
/// reducer's search per axis takes the largest that holds, and looks again
/// between it and the next larger one tried. Every crop in between when
/// there are at most `n`.
pub fn probes(lo: u32, hi: u32, n: u32) -> Vec<u32> {
    let span = u64::from(hi.saturating_sub(lo));
    let mut out: Vec<u32> = (1..=u64::from(n))
        .map(|j| {
            // lo + ceil(span j / (n + 1)): in (lo, hi] and increasing in j.
            let step = (span * j).div_ceil(u64::from(n) + 1);
            lo + u32::try_from(step).unwrap_or(u32::MAX)
        })
        .filter(|&k| k > lo && k < hi)
        .collect();
    out.dedup();
    out.reverse();
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::camera::Camera;
    use glam::DVec3;

    /// f64's unit roundoff.
    const U: f64 = f64::EPSILON / 2.0;

    fn literal(vfov: f64, width: u32, height: u32, eye: [f64; 3]) -> LiteralCamera {
        LiteralCamera {
            eye,
            look_at: [eye[0] + 0.3, eye[1] - 0.2, eye[2] - 4.0],
            ..crate::fuzz::literal::test_scene(vfov, width, height, Vec::new()).camera
        }
    }

    fn core(c: &LiteralCamera) -> Camera {
        Camera::new(
            DVec3::from(c.eye),
            DVec3::from(c.look_at),
            DVec3::from(c.up),
            c.vfov,
            c.width,
            c.height,
            c.near,
            f64::INFINITY,
        )
        .unwrap()
    }

    /// Every pixel of a crop has the ray of the pixel it was in the
    /// original image, within the rounding derived here (u = 2^-53):
    ///
    /// * the basis is the same bits (same eye, look_at, up), so a ray
    ///   differs only through its screen point `(sx, sy)`;
    /// * `camera.rs` computes `sx = fl(fl(fl(n / W) - 1) A)` with `n = 2x + 1`
    ///   and `A = fl(T fl(W / H))`: `n / W` is off by at most `2u` (it is at
    ///   most 2), the subtraction adds `u` of a result under 1, `A` is off by
    ///   `2u` relative and the product by `u`: `|sx - X| <= 6u A0 + O(u^2)`,
    ///   taken as `7u A0`, against `X = (n - W) T / H`, `A0 = T W / H`;
    ///   `sy = fl(fl(1 - fl(m / H)) T)` likewise within `5u T`;
    /// * the crop's exact screen point is `X (1 + rho)` with
    ///   `1 + rho = (T' / H') / (T / H)`, the degree rounding, measured here
    ///   (and held to 16u by the nearest-tangent search: half a step of
    ///   `vfov`, at most about `1.6u` relative in the tangent at up to 90
    ///   degrees, plus the rounding of `to_radians` and `tan`, about `3.6u`,
    ///   plus `rho`'s own computation, `3u`);
    /// * a ray's direction is `dir = fl(fl(eye + d) - eye)` with
    ///   `d = fl(fl(f + fl(r sx)) + fl(u sy))`: per component within
    ///   `3u S + u (|eye| + S) + u S + O(u^2)`, taken as `6u S + 2u |eye|`,
    ///   `S = |f| + |r sx| + |u sy|`, for each of the two cameras.
    #[test]
    fn a_crop_keeps_each_kept_pixels_ray() {
        let cases = [
            // vfov 90 and powers of two (the pixel_centers family).
            (90.0, 64, 32, 16, 8, [0.0, 0.0, 1.0]),
            (45.0, 33, 17, 5, 3, [0.0, 0.0, 4.0]),
            (30.0, 128, 96, 60, 47, [1024.0, -2048.0, 3.0e4]),
            (72.5, 16, 96, 0, 20, [0.5, 0.25, 4.0]),
            (60.0, 100, 20, 49, 0, [0.0, 3.0, 4.0]),
        ];
        for (vfov, w, h, kx, ky, eye) in cases {
            let c0 = literal(vfov, w, h, eye);
            let c1 = crop(&c0, kx, ky).unwrap();
            assert_eq!((c1.width, c1.height), (w - 2 * kx, h - 2 * ky));
            if ky == 0 {
                assert_eq!(c1.vfov.to_bits(), vfov.to_bits());
            }
            let (a, b) = (core(&c0), core(&c1));
            assert_eq!(
                (a.forward, a.right, a.up_ortho),
                (b.forward, b.right, b.up_ortho)
            );
            let (t, t2) = (a.tan_half_vfov, b.tan_half_vfov);
            let (hf, h2) = (f64::from(h), f64::from(c1.height));
            let rho = ((t2 * hf) / (t * h2) - 1.0).abs();
            assert!(
                rho <= 16.0 * U,
                "vfov {vfov}, {h} -> {h2} rows: rho {rho:e}"
            );
            // rho as computed is off by at most 3u (three roundings).
            let rho = rho + 3.0 * U;
            let pitch = 2.0 * t / hf;
            let a0 = t * f64::from(w) / hf;
            let a1 = t2 * f64::from(c1.width) / h2;
            let mut worst_px = 0.0f64;
            for y2 in 0..c1.height {
                for x2 in 0..c1.width {
                    let (x, y) = (x2 + kx, y2 + ky);
                    let (sx, sy) = a.screen(x, y);
                    let (sx2, sy2) = b.screen(x2, y2);
                    // |X| <= |sx| + 7u A0 (and |Y| likewise).
                    let bound_x = 7.0 * U * (a0 + a1) + (sx.abs() + 7.0 * U * a0) * rho;
                    let bound_y = 5.0 * U * (t + t2) + (sy.abs() + 5.0 * U * t) * rho;
                    let (dx, dy) = ((sx2 - sx).abs(), (sy2 - sy).abs());
                    assert!(dx <= bound_x, "({x}, {y}): sx off by {dx:e} > {bound_x:e}");
                    assert!(dy <= bound_y, "({x}, {y}): sy off by {dy:e} > {bound_y:e}");
                    let (r0, r1) = (a.pixel_ray(x, y), b.pixel_ray(x2, y2));
                    for k in 0..3 {
                        let s = |sx: f64, sy: f64| {
                            a.forward[k].abs()
                                + (a.right[k] * sx).abs()
                                + (a.up_ortho[k] * sy).abs()
                        };
                        let e = a.eye[k].abs();
                        let bound = dx * a.right[k].abs()
                            + dy * a.up_ortho[k].abs()
                            + 6.0 * U * (s(sx, sy) + s(sx2, sy2))
                            + 4.0 * U * e;
                        let d = (r1.dir[k] - r0.dir[k]).abs();
                        assert!(d <= bound, "({x}, {y}) axis {k}: {d:e} > {bound:e}");
                        worst_px = worst_px.max(d / pitch);
                    }
                }
            }
            // What that is in pixels: far below any verifier's tolerance,
            // but not zero, so a failure that hangs on the last bits of a
            // ray may still vanish (the reducer then keeps the image).
            assert!(worst_px < 1e-6, "{worst_px:e} px");
        }
    }

    #[test]
    fn the_narrowed_field_of_view_keeps_the_tangent_per_row() {
        // Halving a 90-degree image: tan(vfov'/2) must be 1/2 to the last bits.
        let v = narrowed_vfov(90.0, 64, 32);
        assert!((tan_half_deg(v) - 0.5).abs() <= 2.0 * U, "{v}");
        // The same height: the same bits. Nothing left: no crop.
        assert_eq!(narrowed_vfov(37.0, 20, 20).to_bits(), 37f64.to_bits());
        let c = literal(40.0, 9, 8, [0.0, 0.0, 4.0]);
        assert!(crop(&c, 4, 0).is_some());
        assert!(crop(&c, 5, 0).is_none());
        assert!(crop(&c, 0, 4).is_none());
        assert_eq!((max_crop(9), max_crop(8), max_crop(1)), (4, 3, 0));
    }

    #[test]
    fn probes_are_spaced_largest_first_and_exhaustive_when_few() {
        assert_eq!(probes(0, 5, 12), vec![4, 3, 2, 1]);
        assert_eq!(probes(3, 4, 12), Vec::<u32>::new());
        let p = probes(0, 64, 12);
        assert_eq!(p.len(), 12);
        assert!(p.windows(2).all(|w| w[0] > w[1]));
        assert!(p[0] < 64 && *p.last().unwrap() > 0);
        // Gaps of at most ceil(64 / 13) = 5: the next search is over at most 4.
        assert!(p.windows(2).all(|w| w[0] - w[1] <= 5) && 64 - p[0] <= 5 && p[11] <= 5);
    }
}

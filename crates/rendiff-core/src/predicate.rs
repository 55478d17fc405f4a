//! The orientation predicate behind coverage: a fast f64 filter with Shewchuk's
//! error bound, and an exact fallback (the `robust` crate) when the filter cannot
//! decide. The sign is therefore always the exact sign of the determinant.

use glam::DVec3;

/// Shewchuk's `o3derrboundA = (7 + 56 eps) eps`, eps = 2^-53: if |det| exceeds
/// this times the permanent, the float sign is the exact sign.
pub(crate) const O3D_ERRBOUND_A: f64 = (7.0 + 56.0 * f64::EPSILON / 2.0) * (f64::EPSILON / 2.0);

/// An edge `(a, b)` seen from the eye: the plane through eye, a and b.
/// `n = (a - eye) x (b - eye)`; the orientation of a point P is `n . (P - eye)`.
#[derive(Debug, Clone, Copy)]
pub struct EdgePlane {
    /// The plane normal, rounded.
    pub n: DVec3,
    /// Per-component permanents |ay bz| + |az by| etc., for the error bound.
    pub perm: DVec3,
    /// Edge endpoints, for the exact fallback.
    pub a: DVec3,
    /// Second endpoint.
    pub b: DVec3,
}

impl EdgePlane {
    /// Sets up the edge `a -> b` seen from `eye`.
    #[inline]
    pub fn new(eye: DVec3, a: DVec3, b: DVec3) -> EdgePlane {
        let ad = a - eye;
        let bd = b - eye;
        let n = DVec3::new(
            ad.y * bd.z - ad.z * bd.y,
            ad.z * bd.x - ad.x * bd.z,
            ad.x * bd.y - ad.y * bd.x,
        );
        let perm = DVec3::new(
            (ad.y * bd.z).abs() + (ad.z * bd.y).abs(),
            (ad.z * bd.x).abs() + (ad.x * bd.z).abs(),
            (ad.x * bd.y).abs() + (ad.y * bd.x).abs(),
        );
        EdgePlane { n, perm, a, b }
    }

    /// Exact sign (-1, 0, +1) of `orient3d(a, b, q, eye) = n . (q - eye)`, where
    /// `qd = q - eye` has been rounded from the point `q`. Counts exact fallbacks.
    #[inline]
    pub fn sign(&self, eye: DVec3, q: DVec3, qd: DVec3, fallbacks: &mut u64) -> i8 {
        self.sign_with(eye, q, qd, Precision::Exact, fallbacks)
    }

    /// The f64 filter's determinant for the ray direction `(x, y, z)` and the
    /// bound its magnitude must clear for its sign to be exact: the one home
    /// of the formula, which [`EdgePlane::sign_with`] and the raster's
    /// all-pixels-at-once form (`raster::edges::ChunkOps::filter4`) evaluate.
    #[inline(always)]
    pub fn filter(&self, x: f64, y: f64, z: f64) -> (f64, f64) {
        let det = x * self.n.x + y * self.n.y + z * self.n.z;
        let bound = O3D_ERRBOUND_A
            * (x.abs() * self.perm.x + y.abs() * self.perm.y + z.abs() * self.perm.z);
        (det, bound)
    }

    /// [`EdgePlane::sign`] at a chosen precision: `FloatOnly` trusts the f64 value
    /// even inside the error bound (a speed/accuracy knob for benchmarks; the
    /// sign may then be wrong or zero where the exact one is not).
    #[inline]
    pub fn sign_with(
        &self,
        eye: DVec3,
        q: DVec3,
        qd: DVec3,
        precision: Precision,
        fallbacks: &mut u64,
    ) -> i8 {
        let (det, bound) = self.filter(qd.x, qd.y, qd.z);
        if det > bound {
            1
        } else if -det > bound {
            -1
        } else if precision == Precision::FloatOnly {
            (det > 0.0) as i8 - (det < 0.0) as i8
        } else {
            *fallbacks += 1;
            exact_sign(self.a, self.b, q, eye)
        }
    }
}

/// How orientation signs are decided.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Precision {
    /// Filter, then exact arithmetic when the filter cannot decide (always right).
    #[default]
    Exact,
    /// The f64 value only (faster on ties, wrong near edges): for measuring the trade.
    FloatOnly,
}

/// Exact sign of `orient3d(a, b, c, d)` = det[a-d, b-d, c-d], via adaptive
/// exact arithmetic.
pub fn exact_sign(a: DVec3, b: DVec3, c: DVec3, d: DVec3) -> i8 {
    let k = |v: DVec3| robust::Coord3D {
        x: v.x,
        y: v.y,
        z: v.z,
    };
    let det = robust::orient3d(k(a), k(b), k(c), k(d));
    if det > 0.0 {
        1
    } else if det < 0.0 {
        -1
    } else {
        0
    }
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;

    /// A tiny deterministic generator of values in [-1, 1) for predicate tests.
    pub(crate) fn lcg(seed: &mut u64) -> f64 {
        *seed = seed
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        ((*seed >> 11) as f64 / (1u64 << 53) as f64) * 2.0 - 1.0
    }

    #[test]
    fn filter_agrees_with_exact_on_random_and_near_degenerate_input() {
        let mut s = 7u64;
        let mut fb = 0;
        for i in 0..20000 {
            let eye = DVec3::new(lcg(&mut s), lcg(&mut s), lcg(&mut s) + 5.0);
            let a = DVec3::new(lcg(&mut s), lcg(&mut s), lcg(&mut s));
            let b = DVec3::new(lcg(&mut s), lcg(&mut s), lcg(&mut s));
            // Every 4th query lies (nearly) on the plane through eye, a, b.
            let q = if i % 4 == 0 {
                eye + (a - eye) * lcg(&mut s) + (b - eye) * lcg(&mut s)
            } else {
                DVec3::new(lcg(&mut s), lcg(&mut s), lcg(&mut s))
            };
            let e = EdgePlane::new(eye, a, b);
            assert_eq!(e.sign(eye, q, q - eye, &mut fb), exact_sign(a, b, q, eye));
        }
        assert!(fb > 0, "near-degenerate queries must reach the exact path");
    }

    #[test]
    fn exact_zero_on_the_plane() {
        let eye = DVec3::ZERO;
        let (a, b) = (DVec3::new(1.0, 0.0, 1.0), DVec3::new(0.0, 1.0, 1.0));
        let q = DVec3::new(0.5, 0.5, 1.0);
        let mut fb = 0;
        assert_eq!(EdgePlane::new(eye, a, b).sign(eye, q, q - eye, &mut fb), 0);
        assert_eq!(fb, 1);
    }

    /// Queries exactly on the plane through the eye and the edge whose f64
    /// determinant is not zero (the cross product rounds): only the error
    /// bound sends them to the exact path, which says 0. A smaller bound
    /// (a permanent term dropped, a sign flipped) lets the rounded value
    /// through as a wrong +1 or -1.
    #[test]
    fn the_error_bound_catches_rounded_determinants_of_exactly_coplanar_points() {
        let mut s = 11u64;
        let mut rounded = 0;
        for _ in 0..2000 {
            let a = DVec3::new(lcg(&mut s), lcg(&mut s), lcg(&mut s) + 3.0);
            let b = DVec3::new(lcg(&mut s), lcg(&mut s), lcg(&mut s) + 3.0);
            let e = EdgePlane::new(DVec3::ZERO, a, b);
            // 2a, -a/2 and 4b are exact scalings: on the plane through 0, a and b.
            for q in [a * 2.0, a * -0.5, b * 4.0] {
                let (det, bound) = e.filter(q.x, q.y, q.z);
                assert!(det.abs() <= bound, "{det} beyond {bound}");
                rounded += usize::from(det != 0.0);
                let mut fb = 0;
                assert_eq!(e.sign(DVec3::ZERO, q, q, &mut fb), 0);
                assert_eq!(fb, 1, "one exact fallback per undecided sign");
                let mut fb = 0;
                let float = e.sign_with(DVec3::ZERO, q, q, Precision::FloatOnly, &mut fb);
                assert_eq!(float, (det > 0.0) as i8 - (det < 0.0) as i8);
                assert_eq!(fb, 0, "FloatOnly never falls back");
            }
        }
        assert!(rounded > 100, "only {rounded} rounded determinants");
    }

    /// Points well off the plane are decided by the filter alone, with the
    /// exact sign: a larger bound (or one that grows with the wrong terms)
    /// sends them to the exact path, which the counter shows.
    #[test]
    fn clear_cases_are_decided_without_exact_arithmetic() {
        let mut s = 3u64;
        for _ in 0..2000 {
            let eye = DVec3::new(lcg(&mut s), lcg(&mut s), lcg(&mut s) + 5.0);
            let a = DVec3::new(lcg(&mut s), lcg(&mut s), lcg(&mut s));
            let b = DVec3::new(lcg(&mut s), lcg(&mut s), lcg(&mut s));
            let e = EdgePlane::new(eye, a, b);
            let n = (a - eye).cross(b - eye).normalize();
            // A point a unit off the plane through eye, a and b, on each side.
            for side in [1.0, -1.0] {
                let q = (a + b) * 0.5 + n * side;
                let mut fb = 0;
                let want = exact_sign(a, b, q, eye);
                assert_eq!(want, side as i8, "the exact sign of a point on side {side}");
                assert_eq!(e.sign(eye, q, q - eye, &mut fb), want);
                assert_eq!(
                    e.sign_with(eye, q, q - eye, Precision::FloatOnly, &mut fb),
                    want
                );
                assert_eq!(fb, 0, "decided by the filter");
            }
        }
    }

    #[test]
    fn the_plane_and_its_permanents_are_the_cross_product_terms() {
        let eye = DVec3::new(1.0, 2.0, 3.0);
        let (a, b) = (DVec3::new(3.0, 5.0, 7.0), DVec3::new(-1.0, 4.0, 11.0));
        let e = EdgePlane::new(eye, a, b);
        // ad = (2, 3, 4), bd = (-2, 2, 8).
        assert_eq!(
            e.n,
            DVec3::new(
                3.0 * 8.0 - 4.0 * 2.0,
                4.0 * -2.0 - 2.0 * 8.0,
                2.0 * 2.0 - 3.0 * -2.0
            )
        );
        assert_eq!(e.perm, DVec3::new(24.0 + 8.0, 8.0 + 16.0, 4.0 + 6.0));
        assert_eq!((e.a, e.b), (a, b));
        let (det, bound) = e.filter(1.0, -2.0, 0.5);
        assert_eq!(det, 16.0 + 48.0 + 5.0);
        assert_eq!(bound, O3D_ERRBOUND_A * (32.0 + 48.0 + 5.0));
        assert_eq!(
            O3D_ERRBOUND_A,
            (7.0 + 56.0 * 2f64.powi(-53)) * 2f64.powi(-53)
        );
    }

    #[test]
    fn exact_signs_of_both_sides_and_the_plane() {
        let (a, b, d) = (DVec3::X, DVec3::Y, DVec3::ZERO);
        assert_eq!(exact_sign(a, b, DVec3::Z, d), 1);
        assert_eq!(exact_sign(a, b, -DVec3::Z, d), -1);
        assert_eq!(exact_sign(a, b, DVec3::new(3.0, -1.0, 0.0), d), 0);
    }

    /// At the eye itself the determinant and its bound are both exactly 0:
    /// the filter must not decide (strictly greater, not greater or equal),
    /// and the float-only sign of a zero is 0.
    #[test]
    fn a_zero_determinant_with_a_zero_bound_is_undecided() {
        let eye = DVec3::new(0.25, -0.5, 2.0);
        let e = EdgePlane::new(eye, DVec3::X, DVec3::Y);
        assert_eq!(e.filter(0.0, 0.0, 0.0), (0.0, 0.0));
        let mut fb = 0;
        assert_eq!(e.sign(eye, eye, DVec3::ZERO, &mut fb), 0);
        assert_eq!(fb, 1);
        let mut fb = 0;
        assert_eq!(
            e.sign_with(eye, eye, DVec3::ZERO, Precision::FloatOnly, &mut fb),
            0
        );
        assert_eq!(fb, 0);
    }
}

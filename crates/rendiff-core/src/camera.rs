//! The pinhole camera of docs/DESIGN.md: pixel centers, row 0 at the top, planar depth.
//!
//! Both visibility loops get their pixel rays from [`Camera::pixel_ray`], the one
//! place where a pixel becomes a ray, so they cannot disagree on it.

use crate::scene::CameraSpec;
use glam::DVec3;

/// A resolved camera: orthonormal basis, field of view, image size, near/far.
#[derive(Debug, Clone, PartialEq)]
pub struct Camera {
    /// Center of projection.
    pub eye: DVec3,
    /// The point looked at (kept for exporters that want it).
    pub look_at: DVec3,
    /// The user's up vector (kept for exporters).
    pub up: DVec3,
    /// `f = normalize(look_at - eye)`.
    pub forward: DVec3,
    /// `r = normalize(f x up)`.
    pub right: DVec3,
    /// `u = r x f`.
    pub up_ortho: DVec3,
    /// Vertical field of view in degrees.
    pub vfov_deg: f64,
    /// tan(vfov/2), evaluated once (exactly 1 at 90 degrees) and shared with every backend.
    pub tan_half_vfov: f64,
    /// Image width in pixels.
    pub width: u32,
    /// Image height in pixels.
    pub height: u32,
    /// Nearest visible planar depth.
    pub near: f64,
    /// Farthest visible planar depth (+inf when unbounded).
    pub far: f64,
    /// How coverage signs are decided (exact unless a benchmark asks otherwise).
    pub precision: crate::predicate::Precision,
    /// `eye + right`, rounded once: the first tie-break perturbation direction.
    pub tie_right: DVec3,
    /// `eye + up_ortho`, rounded once: the second tie-break perturbation direction.
    pub tie_up: DVec3,
    aspect_tan: f64,
}

/// One pixel's ray, computed once and shared by the coverage predicate and the depth function.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PixelRay {
    /// The image-plane point `P = eye + d`, rounded once.
    pub p: DVec3,
    /// `D = P - eye`, rounded: the direction every ray query uses.
    pub dir: DVec3,
    /// Componentwise `1/D` (infinite where a component is 0).
    pub inv_dir: DVec3,
    /// `D . forward`: turns a ray parameter into planar depth.
    pub planar: f64,
}

/// tan(vfov/2) in degrees, exact at 90 degrees so that pixel centers of
/// power-of-two images land on exact dyadic coordinates (the fill-rule scene relies on it).
pub fn tan_half_deg(vfov: f64) -> f64 {
    if vfov == 90.0 {
        1.0
    } else {
        (vfov.to_radians() / 2.0).tan()
    }
}

impl Camera {
    /// Builds the camera from a validated spec; `scene_size` scales the default near plane.
    /// Errors are (field, problem).
    pub fn from_spec(spec: &CameraSpec, scene_size: f64) -> Result<Camera, (String, String)> {
        let pose = |field: &str| format!("camera.{field}");
        let missing = |f: &str| {
            (
                pose(f),
                "missing (a glTF camera must be mapped first)".into(),
            )
        };
        let eye = DVec3::from(spec.eye.ok_or_else(|| missing("eye"))?);
        let look_at = DVec3::from(spec.look_at.ok_or_else(|| missing("look_at"))?);
        let vfov = spec.vfov.ok_or_else(|| missing("vfov"))?;
        let size = if scene_size > 0.0 && scene_size.is_finite() {
            scene_size
        } else {
            (look_at - eye).length()
        };
        let near = spec.near.unwrap_or(1e-4 * size);
        let far = spec.far.unwrap_or(f64::INFINITY);
        if !(near > 0.0 && near.is_finite()) {
            return Err(("camera.near".into(), format!("must be > 0, got {near}")));
        }
        if far.partial_cmp(&near) != Some(std::cmp::Ordering::Greater) {
            return Err((
                "camera.far".into(),
                format!("must be greater than near ({near}), got {far}"),
            ));
        }
        Self::new(
            eye,
            look_at,
            DVec3::from(spec.up_or_default()),
            vfov,
            spec.width,
            spec.height,
            near,
            far,
        )
        .map_err(|p| ("camera".into(), p))
    }

    /// Builds a camera from its parts; checks the same conditions as scene validation.
    #[allow(clippy::too_many_arguments)]
    pub fn new(
        eye: DVec3,
        look_at: DVec3,
        up: DVec3,
        vfov_deg: f64,
        width: u32,
        height: u32,
        near: f64,
        far: f64,
    ) -> Result<Camera, String> {
        // The scenes' limits hold for every camera (a resized one too: an
        // image of 10^9 columns overflowed the raster's tile arithmetic).
        crate::scene::check_image_size(width, height)?;
        if !(vfov_deg > 0.0 && vfov_deg < 180.0) {
            return Err(format!("vfov must be in (0, 180), got {vfov_deg}"));
        }
        let forward = (look_at - eye).normalize_or_zero();
        let right = forward.cross(up).normalize_or_zero();
        if forward == DVec3::ZERO || right == DVec3::ZERO || !right.is_finite() {
            return Err(
                "degenerate camera basis (look_at == eye, or up parallel to the view)".into(),
            );
        }
        let up_ortho = right.cross(forward);
        let tan_half_vfov = tan_half_deg(vfov_deg);
        Ok(Camera {
            eye,
            look_at,
            up,
            forward,
            right,
            up_ortho,
            vfov_deg,
            tan_half_vfov,
            width,
            height,
            near,
            far,
            precision: crate::predicate::Precision::Exact,
            tie_right: eye + right,
            tie_up: eye + up_ortho,
            aspect_tan: tan_half_vfov * (f64::from(width) / f64::from(height)),
        })
    }

    /// Screen coordinates `(sx, sy)` of pixel `(x, y)`'s center (docs/DESIGN.md formula).
    #[inline]
    pub fn screen(&self, x: u32, y: u32) -> (f64, f64) {
        (self.screen_x(x), self.screen_y(y))
    }

    /// `sx` of column `x`'s pixel centers (a packet of rays shares a few columns).
    #[inline]
    pub fn screen_x(&self, x: u32) -> f64 {
        (2.0 * (f64::from(x) + 0.5) / f64::from(self.width) - 1.0) * self.aspect_tan
    }

    /// `sy` of row `y`'s pixel centers.
    #[inline]
    pub fn screen_y(&self, y: u32) -> f64 {
        (1.0 - 2.0 * (f64::from(y) + 0.5) / f64::from(self.height)) * self.tan_half_vfov
    }

    /// Unnormalized direction `d = f + sx r + sy u`; `t` along it is planar depth.
    #[inline]
    pub fn direction(&self, x: u32, y: u32) -> DVec3 {
        let (sx, sy) = self.screen(x, y);
        self.screen_direction(sx, sy)
    }

    /// Unnormalized direction through screen point `(sx, sy)`: the one formula
    /// behind pixel rays and Monte Carlo sample rays.
    #[inline(always)]
    pub fn screen_direction(&self, sx: f64, sy: f64) -> DVec3 {
        self.forward + self.right * sx + self.up_ortho * sy
    }

    /// Direction through a continuous image point (`fx` in [0, W), `fy` in [0, H), y down);
    /// pixel centers are at k + 0.5. Used for box-filtered Monte Carlo radiance.
    #[inline]
    pub fn direction_at(&self, fx: f64, fy: f64) -> DVec3 {
        let sx = (2.0 * fx / f64::from(self.width) - 1.0) * self.aspect_tan;
        let sy = (1.0 - 2.0 * fy / f64::from(self.height)) * self.tan_half_vfov;
        self.screen_direction(sx, sy)
    }

    /// The pixel's ray. The single definition both loops use.
    #[inline]
    pub fn pixel_ray(&self, x: u32, y: u32) -> PixelRay {
        let (sx, sy) = self.screen(x, y);
        self.screen_ray(sx, sy)
    }

    /// The ray through screen point `(sx, sy)` of [`Camera::screen`]: the rest
    /// of [`Camera::pixel_ray`], for callers that compute `sx` once per column
    /// and `sy` once per row.
    #[inline(always)]
    pub fn screen_ray(&self, sx: f64, sy: f64) -> PixelRay {
        let p = self.eye + self.screen_direction(sx, sy);
        let dir = p - self.eye;
        PixelRay {
            p,
            dir,
            inv_dir: DVec3::ONE / dir,
            planar: dir.dot(self.forward),
        }
    }

    /// Camera-space coordinates (along right, up, forward) of a world point.
    #[inline]
    pub fn to_camera(&self, v: DVec3) -> DVec3 {
        let q = v - self.eye;
        DVec3::new(q.dot(self.right), q.dot(self.up_ortho), q.dot(self.forward))
    }

    /// Continuous pixel coordinates of a camera-space point with z > 0
    /// (pixel centers are at k + 0.5, y down).
    #[inline]
    pub fn camera_to_pixel(&self, c: DVec3) -> (f64, f64) {
        let sx = c.x / c.z;
        let sy = c.y / c.z;
        let px = (sx / self.aspect_tan + 1.0) * 0.5 * f64::from(self.width);
        let py = (1.0 - sy / self.tan_half_vfov) * 0.5 * f64::from(self.height);
        (px, py)
    }

    /// Number of pixels.
    pub fn pixel_count(&self) -> usize {
        self.width as usize * self.height as usize
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cam() -> Camera {
        Camera::new(
            DVec3::new(0.0, 0.0, 5.0),
            DVec3::ZERO,
            DVec3::Y,
            60.0,
            64,
            48,
            1e-3,
            f64::INFINITY,
        )
        .unwrap()
    }

    #[test]
    fn basis_is_right_handed_and_orthonormal() {
        let c = cam();
        assert_eq!(c.forward, DVec3::new(0.0, 0.0, -1.0));
        assert_eq!(c.right, DVec3::X);
        assert_eq!(c.up_ortho, DVec3::Y);
    }

    #[test]
    fn pixel_centers_round_trip_through_projection() {
        let c = cam();
        for (x, y) in [(0, 0), (63, 47), (10, 30), (32, 24)] {
            let ray = c.pixel_ray(x, y);
            let world = c.eye + ray.dir * 3.7;
            let (px, py) = c.camera_to_pixel(c.to_camera(world));
            assert!((px - (f64::from(x) + 0.5)).abs() < 1e-9, "x {px}");
            assert!((py - (f64::from(y) + 0.5)).abs() < 1e-9, "y {py}");
            assert!((c.to_camera(world).z - 3.7).abs() < 1e-12, "planar depth");
        }
    }

    #[test]
    fn row_zero_is_the_top() {
        let c = cam();
        assert!(c.direction(0, 0).y > 0.0);
        assert!(c.direction(0, 47).y < 0.0);
        assert!(c.direction(0, 0).x < 0.0);
    }

    #[test]
    fn ninety_degrees_is_exact() {
        assert_eq!(tan_half_deg(90.0), 1.0);
        assert!((tan_half_deg(60.0) - (30f64).to_radians().tan()).abs() == 0.0);
    }

    #[test]
    fn degenerate_cameras_are_refused() {
        let e = DVec3::new(0.0, 0.0, 5.0);
        assert!(Camera::new(e, e, DVec3::Y, 60.0, 4, 4, 1e-3, 1.0).is_err());
        assert!(Camera::new(e, DVec3::ZERO, DVec3::Z, 60.0, 4, 4, 1e-3, 1.0).is_err());
        assert!(Camera::new(e, DVec3::ZERO, DVec3::Y, 180.0, 4, 4, 1e-3, 1.0).is_err());
        assert!(Camera::new(e, DVec3::ZERO, DVec3::Y, 60.0, 0, 4, 1e-3, 1.0).is_err());
        // Images no render could hold, as for scene files (a resized
        // camera of 2^32 - 1 columns overflowed the raster's tile arithmetic).
        let size = |w, h| Camera::new(e, DVec3::ZERO, DVec3::Y, 60.0, w, h, 1e-3, 1.0);
        assert!(size(u32::MAX, 4).unwrap_err().contains("per side"));
        assert!(size(16_384, 16_384).unwrap_err().contains("Mpixel"));
        assert!(size(16_384, 4_096).is_ok());
    }

    fn spec(near: Option<f64>, far: Option<f64>) -> CameraSpec {
        CameraSpec {
            eye: Some([0.0, 0.0, 5.0]),
            look_at: Some([0.0, 0.0, 1.0]),
            up: None,
            vfov: Some(90.0),
            width: 4,
            height: 2,
            near,
            far,
            gltf: None,
        }
    }

    #[test]
    fn a_spec_resolves_with_its_defaults_or_names_its_field() {
        let c = Camera::from_spec(&spec(None, None), 20.0).unwrap();
        assert_eq!((c.near, c.far), (1e-4 * 20.0, f64::INFINITY));
        assert_eq!((c.width, c.height, c.vfov_deg), (4, 2, 90.0));
        assert_eq!(c.up, DVec3::Y, "up defaults to +y");
        // Without a usable scene size the near plane scales with the view distance (4).
        for size in [0.0, -1.0, f64::INFINITY, f64::NAN] {
            let c = Camera::from_spec(&spec(None, None), size).unwrap();
            assert_eq!(c.near, 1e-4 * 4.0, "scene size {size}");
        }
        let c = Camera::from_spec(&spec(Some(0.5), Some(0.75)), 1.0).unwrap();
        assert_eq!((c.near, c.far), (0.5, 0.75));
        let field = |s: CameraSpec| Camera::from_spec(&s, 1.0).unwrap_err();
        for near in [0.0, -1.0, f64::INFINITY, f64::NAN] {
            let (f, why) = field(spec(Some(near), None));
            assert_eq!(f, "camera.near");
            assert!(why.starts_with("must be > 0"), "{why}");
        }
        for far in [0.5, 0.25, f64::NAN] {
            let (f, why) = field(spec(Some(0.5), Some(far)));
            assert_eq!(f, "camera.far");
            assert_eq!(why, format!("must be greater than near (0.5), got {far}"));
        }
        for (missing, name) in [(0, "eye"), (1, "look_at"), (2, "vfov")] {
            let mut s = spec(None, None);
            match missing {
                0 => s.eye = None,
                1 => s.look_at = None,
                _ => s.vfov = None,
            }
            assert_eq!(
                field(s),
                (
                    format!("camera.{name}"),
                    "missing (a glTF camera must be mapped first)".to_string()
                )
            );
        }
        let mut flat = spec(None, None);
        flat.up = Some([0.0, 0.0, 1.0]);
        assert_eq!(field(flat).0, "camera");
    }

    #[test]
    fn the_field_of_view_is_open_at_both_ends() {
        let e = DVec3::new(0.0, 0.0, 5.0);
        let at = |vfov| Camera::new(e, DVec3::ZERO, DVec3::Y, vfov, 4, 4, 1e-3, 1.0);
        for bad in [0.0, -10.0, 180.0, 200.0, f64::NAN] {
            assert!(
                at(bad).unwrap_err().starts_with("vfov must be in (0, 180)"),
                "{bad}"
            );
        }
        for good in [1e-9, 90.0, 179.9] {
            assert!(at(good).is_ok(), "{good}");
        }
    }

    /// The DESIGN.md formulas, evaluated by hand on a 4x2 image at 90
    /// degrees (tan = 1, aspect 2), eye off the origin so that no term vanishes.
    #[test]
    fn screen_coordinates_rays_and_projection_follow_the_formulas() {
        let eye = DVec3::new(1.0, 2.0, 3.0);
        let c = Camera::new(eye, eye - DVec3::Z, DVec3::Y, 90.0, 4, 2, 1e-3, 9.0).unwrap();
        assert_eq!(c.tan_half_vfov, 1.0);
        assert_eq!((c.tie_right, c.tie_up), (eye + DVec3::X, eye + DVec3::Y));
        // sx = (2 (x + 0.5) / W - 1) * tan * W/H; sy = (1 - 2 (y + 0.5) / H) * tan.
        assert_eq!(c.screen(0, 0), (-1.5, 0.5));
        assert_eq!(c.screen(3, 1), (1.5, -0.5));
        assert_eq!(c.screen_x(1), -0.5);
        assert_eq!(c.screen_y(1), -0.5);
        assert_eq!(c.direction(0, 0), DVec3::new(-1.5, 0.5, -1.0));
        assert_eq!(c.direction_at(0.5, 0.5), c.direction(0, 0));
        assert_eq!(c.direction_at(4.0, 0.0), DVec3::new(2.0, 1.0, -1.0));
        assert_eq!(
            c.screen_direction(0.25, -0.75),
            DVec3::new(0.25, -0.75, -1.0)
        );
        let r = c.pixel_ray(3, 1);
        assert_eq!(r.dir, DVec3::new(1.5, -0.5, -1.0));
        assert_eq!(r.p, eye + r.dir);
        assert_eq!(r.inv_dir, DVec3::new(1.0 / 1.5, -2.0, -1.0));
        assert_eq!(r.planar, 1.0);
        assert_eq!(c.screen_ray(1.5, -0.5), r);
        let q = eye + DVec3::new(3.0, -1.0, -2.0);
        assert_eq!(c.to_camera(q), DVec3::new(3.0, -1.0, 2.0));
        // x: (1.5 / 2 + 1) * 0.5 * 4 = 3.5; y: (1 - (-0.5)) * 0.5 * 2 = 1.5.
        assert_eq!(c.camera_to_pixel(DVec3::new(3.0, -1.0, 2.0)), (3.5, 1.5));
        assert_eq!(c.pixel_count(), 8);
    }

    /// Pixel centers through the continuous form, at 60 degrees (tan is not
    /// 1, so a factor of it cannot hide) on a 64x48 image.
    #[test]
    fn continuous_image_points_at_pixel_centers_are_the_pixel_rays() {
        let c = cam();
        for (x, y) in [(0, 0), (63, 47), (10, 30)] {
            let (fx, fy) = (f64::from(x) + 0.5, f64::from(y) + 0.5);
            assert_eq!(c.direction_at(fx, fy), c.direction(x, y), "({x}, {y})");
        }
    }
}

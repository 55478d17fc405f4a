//! The pinhole camera of docs/resolved-scene.md as a view-projection matrix,
//! built in f64 on the CPU.
//!
//! Conventions (docs/DESIGN.md): pixel `(x, y)` is sampled at its center
//! `(x + 0.5, y + 0.5)`, x right, y down, row 0 at the top; its ray is
//! `eye + t (forward + sx right + sy up_ortho)` with
//! `sx = (2(x+0.5)/W - 1) tan_half_vfov W/H` and `sy = (1 - 2(y+0.5)/H) tan_half_vfov`,
//! and `t` is the planar depth.
//!
//! wgpu's normalized device coordinates have y up and its framebuffer
//! coordinates y down (wgpu flips Vulkan's viewport for us), so NDC
//! `(sx / (tan W/H), sy / tan)` lands exactly on the pixel center above, with
//! no extra flip. Clip `w` is the planar depth `(X - eye) . forward`, and clip
//! `z` is the constant `near_clip`: a reversed, infinite projection
//! (`z/w = near_clip / depth`, 1 at the near plane, 0 at infinity), so Vulkan's
//! clip test `0 <= z <= w` is the near plane and nothing is far-clipped.

use crate::scene::CameraJson;

/// A 4x4 matrix in f64, row-major: `m[row][col]`, acting on column vectors.
pub type Mat4 = [[f64; 4]; 4];

/// The camera in f64, with the quantities every step needs.
#[derive(Debug, Clone, PartialEq)]
pub struct View {
    /// Center of projection.
    pub eye: [f64; 3],
    /// Unit view direction.
    pub forward: [f64; 3],
    /// Unit right vector.
    pub right: [f64; 3],
    /// Unit up vector, orthogonal to the other two.
    pub up: [f64; 3],
    /// `tan(vfov/2)` as exported.
    pub tan_half_vfov: f64,
    /// Image width in pixels.
    pub width: u32,
    /// Image height in pixels.
    pub height: u32,
    /// Nearest visible planar depth.
    pub near: f64,
    /// Farthest visible planar depth (+inf when unbounded).
    pub far: f64,
}

/// `a . b` in f64.
pub fn dot(a: [f64; 3], b: [f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

/// `a - b` in f64.
pub fn sub(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

/// `a x b` in f64.
pub fn cross(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

impl View {
    /// The camera of a resolved scene, as exported (no basis is recomputed).
    pub fn from_json(c: &CameraJson) -> View {
        View {
            eye: c.eye,
            forward: c.forward,
            right: c.right,
            up: c.up_ortho,
            tan_half_vfov: c.tan_half_vfov,
            width: c.width,
            height: c.height,
            near: c.near,
            far: c.far.unwrap_or(f64::INFINITY),
        }
    }

    /// `tan(vfov/2) W/H`: the horizontal half-extent of the image plane at distance 1.
    pub fn aspect_tan(&self) -> f64 {
        self.tan_half_vfov * (f64::from(self.width) / f64::from(self.height))
    }

    /// `sx` of column `x`'s pixel centers (the resolved-scene formula).
    pub fn screen_x(&self, x: u32) -> f64 {
        (2.0 * (f64::from(x) + 0.5) / f64::from(self.width) - 1.0) * self.aspect_tan()
    }

    /// `sy` of row `y`'s pixel centers.
    pub fn screen_y(&self, y: u32) -> f64 {
        (1.0 - 2.0 * (f64::from(y) + 0.5) / f64::from(self.height)) * self.tan_half_vfov
    }

    /// Pixel `(x, y)`'s unnormalized ray direction: `t` along it is planar depth.
    pub fn pixel_direction(&self, x: u32, y: u32) -> [f64; 3] {
        let (sx, sy) = (self.screen_x(x), self.screen_y(y));
        [
            self.forward[0] + sx * self.right[0] + sy * self.up[0],
            self.forward[1] + sx * self.right[1] + sy * self.up[1],
            self.forward[2] + sx * self.right[2] + sy * self.up[2],
        ]
    }

    /// Projection times rotation: maps an *eye-relative* point `X - eye` to
    /// clip space. This is what the vertex shader applies (in f32), because
    /// vertices are uploaded relative to the eye (see [`View::view_projection`]).
    pub fn projection_rotation(&self, near_clip: f64) -> Mat4 {
        let sx = 1.0 / self.aspect_tan();
        let sy = 1.0 / self.tan_half_vfov;
        let (r, u, f) = (self.right, self.up, self.forward);
        [
            [r[0] * sx, r[1] * sx, r[2] * sx, 0.0],
            [u[0] * sy, u[1] * sy, u[2] * sy, 0.0],
            [0.0, 0.0, 0.0, near_clip],
            [f[0], f[1], f[2], 0.0],
        ]
    }

    /// The full view-projection of world points: `projection_rotation` after
    /// the translation by `-eye`. The renderer never uploads this one: it
    /// subtracts the eye in f64 on the CPU instead ("camera-relative
    /// rendering"), so the f32 transform error scales with the distance from
    /// the eye, not from the world origin. Kept for tests and for users who
    /// prefer a single matrix.
    pub fn view_projection(&self, near_clip: f64) -> Mat4 {
        let mut m = self.projection_rotation(near_clip);
        for row in [0, 1, 3] {
            m[row][3] = -dot([m[row][0], m[row][1], m[row][2]], self.eye);
        }
        m
    }

    /// Continuous pixel coordinates (centers at k + 0.5, y down) of clip
    /// coordinates, by wgpu's viewport transform; `None` behind the eye.
    pub fn clip_to_pixel(&self, clip: [f64; 4]) -> Option<(f64, f64)> {
        if clip[3] <= 0.0 {
            return None;
        }
        let nx = clip[0] / clip[3];
        let ny = clip[1] / clip[3];
        Some((
            (nx + 1.0) * 0.5 * f64::from(self.width),
            (1.0 - ny) * 0.5 * f64::from(self.height),
        ))
    }
}

/// `m v` in f64.
pub fn mul(m: &Mat4, v: [f64; 4]) -> [f64; 4] {
    let mut out = [0.0; 4];
    for (o, row) in out.iter_mut().zip(m) {
        *o = row[0] * v[0] + row[1] * v[1] + row[2] * v[2] + row[3] * v[3];
    }
    out
}

/// The matrix as WGSL's `mat4x4<f32>` wants it: column-major, each entry
/// rounded once from f64.
pub fn to_gpu(m: &Mat4) -> [[f32; 4]; 4] {
    let mut cols = [[0f32; 4]; 4];
    for (c, col) in cols.iter_mut().enumerate() {
        for (r, v) in col.iter_mut().enumerate() {
            *v = m[r][c] as f32;
        }
    }
    cols
}

#[cfg(test)]
mod tests {
    use super::*;

    fn view(eye: [f64; 3], look: [f64; 3], tan: f64, w: u32, h: u32) -> View {
        let f = sub(look, eye);
        let fl = dot(f, f).sqrt();
        let f = [f[0] / fl, f[1] / fl, f[2] / fl];
        let r = cross(f, [0.0, 1.0, 0.0]);
        let rl = dot(r, r).sqrt();
        let r = [r[0] / rl, r[1] / rl, r[2] / rl];
        View {
            eye,
            forward: f,
            right: r,
            up: cross(r, f),
            tan_half_vfov: tan,
            width: w,
            height: h,
            near: 1e-3,
            far: f64::INFINITY,
        }
    }

    fn views() -> Vec<View> {
        vec![
            view(
                [0.0, 0.0, 5.0],
                [0.0, 0.0, 0.0],
                0.41421356237309503,
                64,
                48,
            ),
            view([0.0, 0.0, 1.0], [0.0, 0.0, 0.0], 1.0, 64, 64),
            view([3.0, -2.0, 7.5], [0.5, 1.0, -1.0], 0.2, 97, 31),
            view(
                [2.0e4, 10.0, -3.0e4],
                [2.0e4 + 1.0, 9.0, -3.0e4],
                0.7,
                320,
                240,
            ),
        ]
    }

    /// A point on pixel (x, y)'s ray projects back onto that pixel's center,
    /// and clip w is its planar depth `t`.
    #[test]
    fn pixel_rays_project_to_pixel_centers() {
        for v in views() {
            let m = v.view_projection(v.near);
            for &(x, y) in &[
                (0, 0),
                (v.width - 1, v.height - 1),
                (v.width / 3, 1),
                (5, v.height / 2),
            ] {
                let d = v.pixel_direction(x, y);
                for t in [0.01, 1.0, 3.7, 1e3] {
                    let p = [
                        v.eye[0] + t * d[0],
                        v.eye[1] + t * d[1],
                        v.eye[2] + t * d[2],
                    ];
                    let clip = mul(&m, [p[0], p[1], p[2], 1.0]);
                    let (px, py) = v.clip_to_pixel(clip).unwrap();
                    let tol = 1e-9 * (1.0 + dot(v.eye, v.eye).sqrt() / t);
                    assert!((px - (f64::from(x) + 0.5)).abs() < tol, "x: {px} vs {x}");
                    assert!((py - (f64::from(y) + 0.5)).abs() < tol, "y: {py} vs {y}");
                    assert!(
                        (clip[3] - t).abs() <= 1e-9 * t.max(1.0) * (1.0 + dot(v.eye, v.eye).sqrt()),
                        "w {} vs t {t}",
                        clip[3]
                    );
                    // Reversed infinite depth: near_clip / t.
                    let depth = clip[2] / clip[3];
                    assert!((depth - v.near / t).abs() <= tol * v.near / t, "{depth}");
                }
            }
        }
    }

    /// Row 0 is the top of the image: a point above the axis lands in a low row.
    #[test]
    fn row_zero_is_the_top_and_column_zero_the_left() {
        let v = views().remove(0);
        let m = v.view_projection(v.near);
        let up = mul(&m, [0.0, 1.0, 0.0, 1.0]);
        let (_, py) = v.clip_to_pixel(up).unwrap();
        assert!(py < f64::from(v.height) / 2.0);
        let left = mul(&m, [-1.0, 0.0, 0.0, 1.0]);
        let (px, _) = v.clip_to_pixel(left).unwrap();
        assert!(px < f64::from(v.width) / 2.0);
    }

    /// The uploaded matrix on eye-relative points equals the full
    /// view-projection on world points.
    #[test]
    fn camera_relative_matrix_agrees_with_the_full_one() {
        for v in views() {
            let full = v.view_projection(v.near);
            let rel = v.projection_rotation(v.near);
            for p in [
                [0.3, -0.2, 0.1],
                [1.0, 2.0, -3.0],
                [2.0e4 + 0.5, 10.0, -3.0e4 + 2.0],
            ] {
                let a = mul(&full, [p[0], p[1], p[2], 1.0]);
                let q = sub(p, v.eye);
                let b = mul(&rel, [q[0], q[1], q[2], 1.0]);
                let scale = 1.0 + dot(p, p).sqrt() + dot(v.eye, v.eye).sqrt();
                for k in 0..4 {
                    assert!((a[k] - b[k]).abs() < 1e-12 * scale, "{a:?} vs {b:?}");
                }
            }
        }
    }

    /// Projecting arbitrary points and casting the resolved-scene ray through
    /// the resulting (continuous) pixel position gives the point back.
    #[test]
    fn projection_inverts_the_ray_formula_off_center() {
        let v = views().remove(2);
        let m = v.view_projection(v.near);
        let p = [1.25, 0.5, 0.75];
        let clip = mul(&m, [p[0], p[1], p[2], 1.0]);
        let (px, py) = v.clip_to_pixel(clip).unwrap();
        let sx = (2.0 * px / f64::from(v.width) - 1.0) * v.aspect_tan();
        let sy = (1.0 - 2.0 * py / f64::from(v.height)) * v.tan_half_vfov;
        let t = clip[3];
        for (k, &pk) in p.iter().enumerate() {
            let q = v.eye[k] + t * (v.forward[k] + sx * v.right[k] + sy * v.up[k]);
            assert!((q - pk).abs() < 1e-12, "{q} vs {pk}");
        }
    }

    #[test]
    fn gpu_matrix_is_column_major() {
        let m: Mat4 = [
            [1.0, 2.0, 3.0, 4.0],
            [5.0, 6.0, 7.0, 8.0],
            [9.0, 10.0, 11.0, 12.0],
            [13.0, 14.0, 15.0, 16.0],
        ];
        let g = to_gpu(&m);
        assert_eq!(g[0], [1.0, 5.0, 9.0, 13.0]);
        assert_eq!(g[3], [4.0, 8.0, 12.0, 16.0]);
    }
}

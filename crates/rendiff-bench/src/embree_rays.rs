//! The primary rays the native Embree driver traces ([`crate::native_embree`]),
//! in f32, by the core binding's own definition ([`EmbreeRay`]: origin the
//! eye rounded to f32, direction the core's pixel ray rounded to f32,
//! `tnear`/`tfar` from the camera's `near`/`far`, widened by 1e-6 relative).
//!
//! One definition, [`CameraRays::fill`], makes them for a strip of rows. It
//! serves both ways the bench uses them: made strip by strip inside a timed
//! trace ([`crate::native_embree::NativeScene::trace_made`]), as an
//! application makes its rays every frame and as the core's tracer makes its
//! own inside its timed queries, so a per-frame comparison treats the two
//! alike; and prepared for the whole image once, outside timing
//! ([`PreparedRays`]), where a trace alone is measured (the sweep of entry
//! points, the check of the bench's binding against the driver).

use rayon::prelude::*;
use rendiff::backends::embree::EmbreeRay;
use rendiff::camera::Camera;

/// What turns a hit distance along a ray into the core's planar depth, and
/// the depth range a hit must fall in.
#[derive(Debug, Clone, Copy)]
pub(crate) struct RayDepth {
    /// `(org32 - eye)·forward`: the planar depth of the f32 origin.
    pub offset: f64,
    /// The camera's near plane.
    pub near: f64,
    /// The camera's far plane.
    pub far: f64,
}

/// A camera's rays, made on demand a strip of rows at a time.
pub struct CameraRays {
    cam: Camera,
    /// The eye rounded to f32: every ray's origin.
    pub(crate) org: [f32; 3],
    depth: RayDepth,
}

/// One strip's rays, row-major, in Embree's single-ray fields (reused from
/// strip to strip by a worker, so a frame allocates once per worker).
#[derive(Default)]
pub struct StripRays {
    pub(crate) dx: Vec<f32>,
    pub(crate) dy: Vec<f32>,
    pub(crate) dz: Vec<f32>,
    pub(crate) tnear: Vec<f32>,
    pub(crate) tfar: Vec<f32>,
    /// The image's `sx` per column.
    sx: Vec<f64>,
}

impl CameraRays {
    /// The camera's constants (nothing per pixel yet).
    pub fn new(cam: &Camera) -> CameraRays {
        let (org, offset) = EmbreeRay::origin(cam);
        CameraRays {
            cam: cam.clone(),
            org,
            depth: RayDepth {
                offset,
                near: cam.near,
                far: cam.far,
            },
        }
    }

    /// Pixels per row.
    pub fn width(&self) -> usize {
        self.cam.width as usize
    }

    /// Rows.
    pub fn height(&self) -> usize {
        self.cam.height as usize
    }

    /// Rays per frame (one per pixel).
    pub fn len(&self) -> usize {
        self.cam.pixel_count()
    }

    /// True for an image without pixels.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// What turns these rays' hit distances into planar depths.
    pub(crate) fn depth(&self) -> RayDepth {
        self.depth
    }

    /// The rays of rows `y0 .. y0 + rows` into `out` (row-major, `rows x
    /// width`), and each ray's `D32·forward` (planar depth per unit of `t`)
    /// into `planar` (as long): [`EmbreeRay::at`] for each pixel center.
    pub fn fill(&self, y0: usize, rows: usize, out: &mut StripRays, planar: &mut [f64]) {
        let cam = &self.cam;
        let w = self.width();
        let n = rows * w;
        assert!(y0 + rows <= self.height() && planar.len() == n);
        out.sx.clear();
        out.sx.extend((0..w).map(|x| cam.screen_x(x as u32)));
        for v in [
            &mut out.dx,
            &mut out.dy,
            &mut out.dz,
            &mut out.tnear,
            &mut out.tfar,
        ] {
            v.resize(n, 0.0);
        }
        let offset = self.depth.offset;
        for r in 0..rows {
            let sy = cam.screen_y((y0 + r) as u32);
            let at = r * w;
            for (x, &sx) in out.sx.iter().enumerate() {
                let p = at + x;
                let ray = EmbreeRay::at(cam, offset, sx, sy);
                [out.dx[p], out.dy[p], out.dz[p]] = ray.dir;
                out.tnear[p] = ray.tnear;
                out.tfar[p] = ray.tfar;
                planar[p] = ray.planar;
            }
        }
    }
}

/// Every pixel's ray, prepared once per camera (outside timing): the whole
/// image's [`CameraRays::fill`], made in parallel strips.
pub struct PreparedRays {
    pub(crate) width: u32,
    /// Read by the native driver only (absent without Embree's headers).
    #[cfg_attr(not(rendiff_native_embree), allow(dead_code))]
    pub(crate) height: u32,
    /// Read by the native driver only (absent without Embree's headers).
    #[cfg_attr(not(rendiff_native_embree), allow(dead_code))]
    pub(crate) org: [f32; 3],
    pub(crate) rays: StripRays,
    /// `D32·forward` per pixel.
    pub(crate) planar: Vec<f64>,
    pub(crate) depth: RayDepth,
}

impl PreparedRays {
    /// The camera's pixel rays in Embree's precision (the binding's convention).
    pub fn new(cam: &Camera) -> PreparedRays {
        let made = CameraRays::new(cam);
        let (w, n) = (made.width(), made.len());
        /// Rows per strip: enough work per task, and strips for every worker.
        const ROWS: usize = 16;
        let mut planar = vec![0.0; n];
        let strips: Vec<StripRays> = if w == 0 {
            Vec::new()
        } else {
            planar
                .par_chunks_mut(ROWS * w)
                .enumerate()
                .map(|(i, planar)| {
                    let mut s = StripRays::default();
                    made.fill(i * ROWS, planar.len() / w, &mut s, planar);
                    s
                })
                .collect()
        };
        let cat = |f: fn(&StripRays) -> &Vec<f32>| -> Vec<f32> {
            strips.iter().flat_map(|s| f(s).iter().copied()).collect()
        };
        PreparedRays {
            width: cam.width,
            height: cam.height,
            org: made.org,
            rays: StripRays {
                dx: cat(|s| &s.dx),
                dy: cat(|s| &s.dy),
                dz: cat(|s| &s.dz),
                tnear: cat(|s| &s.tnear),
                tfar: cat(|s| &s.tfar),
                sx: Vec::new(),
            },
            planar,
            depth: made.depth,
        }
    }

    /// Rays per frame (one per pixel).
    pub fn len(&self) -> usize {
        self.rays.dx.len()
    }

    /// True for an image without pixels.
    pub fn is_empty(&self) -> bool {
        self.rays.dx.is_empty()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::DVec3;

    /// Strips made at any offset are the whole image's rays, and each ray is
    /// the core's pixel ray rounded to f32 with the binding's `tnear` and
    /// `tfar` (written out here from backends/embree.rs's convention), for
    /// a finite and an infinite far plane and eyes whose f32 rounding moves
    /// them (a non-zero `offset`).
    #[test]
    fn strips_are_the_pixel_rays_in_f32() {
        for (eye, far) in [
            (DVec3::new(0.3, 0.7, 2.1), f64::INFINITY),
            (DVec3::new(1e5 + 0.1, -3.3, 7.7), 1e6),
        ] {
            let cam = Camera::new(eye, DVec3::ZERO, DVec3::Y, 50.0, 37, 29, 1e-3, far).unwrap();
            let whole = PreparedRays::new(&cam);
            let made = CameraRays::new(&cam);
            assert_eq!(whole.len(), 37 * 29);
            let offset = (cam.eye.as_vec3().as_dvec3() - cam.eye).dot(cam.forward);
            assert!(offset != 0.0, "the f32 eye is off the eye");
            let mut strip = StripRays::default();
            for (y0, rows) in [(0, 29), (5, 3), (28, 1)] {
                let mut planar = vec![0.0; rows * 37];
                made.fill(y0, rows, &mut strip, &mut planar);
                for r in 0..rows {
                    for x in 0..37 {
                        let (p, q) = (r * 37 + x, (y0 + r) * 37 + x);
                        let d = cam.pixel_ray(x as u32, (y0 + r) as u32).dir.as_vec3();
                        let pl = d.as_dvec3().dot(cam.forward);
                        let near = ((cam.near - offset) / pl * (1.0 - 1e-6)).max(0.0) as f32;
                        let far = if far.is_finite() {
                            ((far - offset) / pl * (1.0 + 1e-6)) as f32
                        } else {
                            f32::INFINITY
                        };
                        let got = [strip.dx[p], strip.dy[p], strip.dz[p], strip.tnear[p]];
                        let want = [d.x, d.y, d.z, near];
                        assert_eq!(got.map(f32::to_bits), want.map(f32::to_bits), "{x},{r}");
                        assert_eq!(strip.tfar[p].to_bits(), far.to_bits());
                        assert_eq!(planar[p].to_bits(), pl.to_bits());
                        let prepared = [
                            whole.rays.dx[q],
                            whole.rays.dy[q],
                            whole.rays.dz[q],
                            whole.rays.tnear[q],
                            whole.rays.tfar[q],
                        ];
                        let ours = [got[0], got[1], got[2], got[3], strip.tfar[p]];
                        assert_eq!(prepared.map(f32::to_bits), ours.map(f32::to_bits));
                        assert_eq!(whole.planar[q].to_bits(), pl.to_bits());
                    }
                }
            }
        }
    }
}

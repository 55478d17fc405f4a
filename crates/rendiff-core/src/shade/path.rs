//! Path tracing of the rendering equation for `global_illumination` scenes:
//! the pixel's box-filtered integral, next-event estimation on emissive
//! triangles and delta lights with MIS (power heuristic), Russian roulette, and
//! the variance of each pixel's mean for statistical comparison.

use super::direct::shade_point;
use super::lights::LightSet;
use super::{ray_epsilon, Bias, Features, Radiance, ShadeOptions, Surfaces};
use crate::scene::resolve::{scene_size, ResolvedScene};
use crate::trace::{Rays, Segment, TraceBvh};
use glam::DVec3;
use rand::{Rng, SeedableRng};
use rand_pcg::Pcg64Mcg;
use rayon::prelude::*;
use std::f64::consts::{FRAC_1_PI, PI};

/// Depth used for `OneBounceFewer` when the scene's max_depth is unlimited.
const BIASED_DEPTH: i32 = 6;

/// The random stream of one pixel: independent of thread scheduling.
fn pixel_rng(seed: u64, pixel: u64) -> Pcg64Mcg {
    let mut z = seed ^ pixel.wrapping_mul(0x9E37_79B9_7F4A_7C15);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    Pcg64Mcg::seed_from_u64(z ^ (z >> 31))
}

/// Orthonormal basis around `n` (Duff et al.).
fn basis(n: DVec3) -> (DVec3, DVec3) {
    let s = 1f64.copysign(n.z);
    let a = -1.0 / (s + n.z);
    let b = n.x * n.y * a;
    (
        DVec3::new(1.0 + s * n.x * n.x * a, s * b, -s * n.x),
        DVec3::new(b, s + n.y * n.y * a, -n.y),
    )
}

fn cosine_sample(n: DVec3, u1: f64, u2: f64) -> (DVec3, f64) {
    let r = u1.sqrt();
    let phi = 2.0 * PI * u2;
    let z = (1.0 - u1).max(0.0).sqrt();
    let (t, b) = basis(n);
    let wi = t * (r * phi.cos()) + b * (r * phi.sin()) + n * z;
    (wi, z * FRAC_1_PI)
}

fn power(a: f64, b: f64) -> f64 {
    let (a2, b2) = (a * a, b * b);
    if a2 + b2 == 0.0 {
        0.0
    } else {
        a2 / (a2 + b2)
    }
}

/// Path vertex from which Russian roulette may end a path (1 = the
/// primary hit): `depth > RR_DEPTH` below.
const RR_DEPTH: i32 = 3;

/// What every path of one render reads.
struct Tracer<'a> {
    scene: &'a ResolvedScene,
    /// The shading rays' SAH tree ([`TraceBvh::path_rays`]).
    rays: Rays<'a>,
    lights: LightSet,
    features: Features,
    surfaces: Surfaces,
    max_depth: i32,
    eps_scale: f64,
    bias: Option<Bias>,
}

impl Tracer<'_> {
    /// One path through the continuous image point (fx, fy).
    fn radiance(&self, fx: f64, fy: f64, rng: &mut Pcg64Mcg) -> DVec3 {
        let (scene, rays, lights, bias) = (self.scene, self.rays, &self.lights, self.bias);
        let max_depth = self.max_depth;
        let two_sided = self.features.two_sided;
        let cam = &scene.camera;
        let mut o = cam.eye;
        let mut d = cam.direction_at(fx, fy);
        let mut beta = DVec3::ONE;
        let mut l = DVec3::ZERO;
        let mut prev_bsdf_pdf: Option<f64> = None;
        let mut depth = 1;
        let mut tmin = 0.0;
        while let Some(hit) = rays.closest(Segment {
            o,
            d,
            tmin,
            tmax: f64::INFINITY,
        }) {
            let x = o + d * hit.t;
            let s = self.surfaces.at(hit.prim, x, d);
            if s.emission != DVec3::ZERO {
                let w = match prev_bsdf_pdf {
                    None => 1.0,
                    Some(pb) => {
                        let dist2 = (x - o).length_squared();
                        let cos_l = s.n.dot(-d.normalize()).abs();
                        let pl = lights.pdf_area(hit.prim) * dist2 / cos_l.max(1e-300);
                        power(pb, pl)
                    }
                };
                l += beta * s.emission * lights.emission_scale * w;
            }
            if (max_depth != -1 && depth >= max_depth) || s.albedo == DVec3::ZERO {
                break;
            }
            let eps = ray_epsilon(self.eps_scale, x);
            let origin = s.x + s.n * eps;
            // Next-event estimation: delta lights, then one emissive triangle.
            if !lights.deltas.is_empty() {
                let surf = super::Surface {
                    emission: DVec3::ZERO,
                    ..s
                };
                l += beta * shade_point(rays, lights, self.features, &surf, eps, bias);
            }
            if let Some((lp, y, nl, pa)) =
                lights.sample(scene, rng.random(), rng.random(), rng.random())
            {
                let v = y - origin;
                let dist2 = v.length_squared();
                let wi = v / dist2.sqrt();
                let cos_x = s.n.dot(wi);
                let cos_l_signed = nl.dot(-wi);
                let cos_l = if two_sided {
                    cos_l_signed.abs()
                } else {
                    cos_l_signed
                };
                if cos_x > 0.0
                    && cos_l > 0.0
                    && pa > 0.0
                    && !rays.occluded(Segment {
                        o: origin,
                        d: v,
                        tmin: 0.0,
                        tmax: 1.0 - 1e-7,
                    })
                {
                    let pl = pa * dist2 / cos_l;
                    let pb = cos_x * FRAC_1_PI;
                    let c = if bias == Some(Bias::MissingCosine) {
                        1.0
                    } else {
                        cos_x
                    };
                    l += beta * s.albedo * FRAC_1_PI * lights.emission(scene, lp) * c / pl
                        * power(pl, pb);
                }
            }
            // Continue the path by sampling the Lambert lobe: f cos / pdf = albedo.
            let (wi, pb) = cosine_sample(s.n, rng.random(), rng.random());
            if pb <= 0.0 {
                break;
            }
            beta *= s.albedo;
            prev_bsdf_pdf = Some(pb);
            o = origin;
            d = wi;
            tmin = 0.0;
            depth += 1;
            if depth > RR_DEPTH {
                let q = beta.max_element().min(0.95);
                if rng.random::<f64>() >= q {
                    break;
                }
                beta /= q;
            }
        }
        l
    }
}

/// Renders the box-filtered pixel integrals with `opts.spp` samples each.
pub fn render(scene: &ResolvedScene, bvh: &TraceBvh, opts: ShadeOptions) -> Radiance {
    let cam = &scene.camera;
    let mut max_depth = scene.integrator.max_depth;
    if opts.bias == Some(Bias::OneBounceFewer) {
        max_depth = if max_depth == -1 {
            BIASED_DEPTH
        } else {
            (max_depth - 1).max(1)
        };
    }
    let var_scale = match opts.bias {
        Some(Bias::VarianceHalved) => 0.5,
        Some(Bias::VarianceDoubled) => 2.0,
        _ => 1.0,
    };
    let tracer = Tracer {
        scene,
        rays: bvh.path_rays(scene),
        lights: LightSet::new(scene, opts.bias),
        features: Features::of(scene),
        surfaces: Surfaces::new(scene, Features::of(scene), opts.bias),
        max_depth,
        eps_scale: scene_size(&scene.triangles),
        bias: opts.bias,
    };
    let n = opts.spp.max(1);
    let w = cam.width as usize;
    let out: Vec<([f32; 3], [f32; 3])> = (0..cam.pixel_count())
        .into_par_iter()
        .map(|i| {
            if crate::deadline::past(opts.deadline) {
                return ([0.0; 3], [0.0; 3]);
            }
            let (px, py) = ((i % w) as f64, (i / w) as f64);
            let mut rng = pixel_rng(opts.seed, i as u64);
            let mut sum = DVec3::ZERO;
            let mut sum2 = DVec3::ZERO;
            for _ in 0..n {
                let (u, v): (f64, f64) = (rng.random(), rng.random());
                let li = tracer.radiance(px + u, py + v, &mut rng);
                sum += li;
                sum2 += li * li;
            }
            let nf = f64::from(n);
            let mean = sum / nf;
            let var = if n > 1 {
                ((sum2 - sum * sum / nf) / (nf - 1.0)).max(DVec3::ZERO) / nf * var_scale
            } else {
                DVec3::ZERO
            };
            (
                [mean.x as f32, mean.y as f32, mean.z as f32],
                [var.x as f32, var.y as f32, var.z as f32],
            )
        })
        .collect();
    let (rgb, var) = out.into_iter().unzip();
    Radiance {
        rgb,
        var: Some(var),
        spp: n,
        integrator: "path",
        seconds: 0.0,
    }
}

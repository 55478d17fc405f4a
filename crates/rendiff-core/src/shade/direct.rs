//! Local shading at pixel centers: emission plus point and directional lights
//! on Lambert surfaces, with shadow rays when the scene requires `shadows`.
//! Deterministic: one sample at the pixel center, the visibility buffers' hit.

use super::lights::{Delta, LightSet};
use super::{ray_epsilon, surface, Bias, Features, Radiance, ShadeOptions, Surface};
use crate::frame::{Frame, BACKGROUND_ID};
use crate::scene::resolve::{scene_size, ResolvedScene};
use crate::trace::{Rays, Segment, TraceBvh};
use glam::DVec3;
use rayon::prelude::*;
use std::f64::consts::FRAC_1_PI;

/// Radiance reflected toward the viewer from the delta lights (plus emission).
pub fn shade_point(
    rays: Rays<'_>,
    lights: &LightSet,
    features: Features,
    s: &Surface,
    eps: f64,
    bias: Option<Bias>,
) -> DVec3 {
    let mut l = s.emission;
    if s.albedo == DVec3::ZERO {
        return l;
    }
    let shadows = features.shadows;
    let origin = s.x + s.n * eps;
    for light in &lights.deltas {
        let (wi, dist, irradiance) = match *light {
            Delta::Point { p, i } => {
                let v = p - s.x;
                let r2 = v.length_squared();
                (v / r2.sqrt(), r2.sqrt(), i / r2)
            }
            Delta::Directional { dir, e } => (-dir, f64::INFINITY, e),
        };
        let cos = s.n.dot(wi);
        if cos <= 0.0 {
            continue;
        }
        if shadows {
            let tmax = if dist.is_finite() {
                (dist - eps) * (1.0 - 1e-9)
            } else {
                f64::INFINITY
            };
            if rays.occluded(Segment {
                o: origin,
                d: wi,
                tmin: 0.0,
                tmax,
            }) {
                continue;
            }
        }
        let c = if bias == Some(Bias::MissingCosine) {
            1.0
        } else {
            cos
        };
        l += s.albedo * FRAC_1_PI * irradiance * c;
    }
    l
}

/// Shades every visible pixel center of `frame`.
pub fn render(
    scene: &ResolvedScene,
    frame: &Frame,
    bvh: &TraceBvh,
    opts: ShadeOptions,
) -> Radiance {
    let cam = &scene.camera;
    let lights = LightSet::new(scene, opts.bias);
    let features = Features::of(scene);
    let size = scene_size(&scene.triangles);
    let w = cam.width as usize;
    let rays = bvh.rays(scene);
    let rgb: Vec<[f32; 3]> = frame
        .prim
        .par_iter()
        .enumerate()
        .map(|(i, &prim)| {
            if prim == BACKGROUND_ID || crate::deadline::past(opts.deadline) {
                return [0.0; 3];
            }
            let ray = cam.pixel_ray((i % w) as u32, (i / w) as u32);
            let [a, b, c] = scene.triangles[prim as usize].map(|v| v.as_dvec3());
            let ng = (b - a).cross(c - a);
            let t = ng.dot(a - cam.eye) / ng.dot(ray.dir);
            let x = cam.eye + ray.dir * t;
            let s = surface(scene, features, prim, x, ray.dir, opts.bias);
            let eps = ray_epsilon(size, x);
            let l = shade_point(rays, &lights, features, &s, eps, opts.bias);
            [l.x as f32, l.y as f32, l.z as f32]
        })
        .collect();
    Radiance {
        rgb,
        var: None,
        spp: 1,
        integrator: "direct",
        seconds: 0.0,
    }
}

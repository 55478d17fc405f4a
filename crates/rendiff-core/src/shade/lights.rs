//! The lights of a scene: delta lights from the scene file and, with
//! `area_light`, every emissive triangle, sampled in proportion to its power.

use super::Bias;
use crate::scene::resolve::ResolvedScene;
use crate::scene::LightSpec;
use glam::DVec3;

/// A point or directional light.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Delta {
    /// Radiant intensity `i` at `p`.
    Point {
        /// Position.
        p: DVec3,
        /// Intensity (W/sr per channel).
        i: DVec3,
    },
    /// Irradiance `e` arriving along the unit travel direction `dir`.
    Directional {
        /// Unit direction the light travels in.
        dir: DVec3,
        /// Irradiance at normal incidence.
        e: DVec3,
    },
}

/// All lights, with a sampler over emissive triangles.
#[derive(Debug, Clone, Default)]
pub struct LightSet {
    /// Point and directional lights.
    pub deltas: Vec<Delta>,
    /// Emissive triangles (prim ids), when the scene requires `area_light`.
    pub emitters: Vec<u32>,
    cdf: Vec<f64>,
    total: f64,
    /// Selection probability divided by area, indexed by prim (0 for
    /// non-emitters; empty without `area_light`). A vector, not a map: it
    /// is read at every path vertex that hits an emitter.
    pdf_area: Vec<f64>,
    /// 1, or pi under `Bias::LightTimesPi`.
    pub emission_scale: f64,
}

fn emission_of(scene: &ResolvedScene, prim: u32) -> DVec3 {
    let obj = &scene.objects[scene.object_ids[prim as usize] as usize];
    DVec3::from(scene.materials[obj.material as usize].emission)
}

/// Area of a triangle in f64.
pub fn area(scene: &ResolvedScene, prim: u32) -> f64 {
    let [a, b, c] = scene.triangles[prim as usize].map(|v| v.as_dvec3());
    0.5 * (b - a).cross(c - a).length()
}

impl LightSet {
    /// Collects the lights the scene requires (and only those).
    pub fn new(scene: &ResolvedScene, bias: Option<Bias>) -> LightSet {
        let k = if bias == Some(Bias::LightTimesPi) {
            std::f64::consts::PI
        } else {
            1.0
        };
        let mut set = LightSet {
            emission_scale: k,
            ..LightSet::default()
        };
        for l in &scene.lights {
            match *l {
                LightSpec::Point {
                    position,
                    intensity,
                } => set.deltas.push(Delta::Point {
                    p: position.into(),
                    i: DVec3::from(intensity) * k,
                }),
                LightSpec::Directional {
                    direction,
                    irradiance,
                } => set.deltas.push(Delta::Directional {
                    dir: DVec3::from(direction).normalize(),
                    e: DVec3::from(irradiance) * k,
                }),
            }
        }
        if scene.requires.contains("area_light") {
            for prim in 0..scene.triangles.len() as u32 {
                if scene.degenerate[prim as usize] {
                    continue;
                }
                let w = emission_of(scene, prim).max_element() * area(scene, prim);
                if w > 0.0 {
                    set.total += w;
                    set.emitters.push(prim);
                    set.cdf.push(set.total);
                }
            }
            if !set.emitters.is_empty() {
                set.pdf_area = vec![0.0; scene.triangles.len()];
            }
            for (i, &prim) in set.emitters.iter().enumerate() {
                let prev = if i == 0 { 0.0 } else { set.cdf[i - 1] };
                let sel = (set.cdf[i] - prev) / set.total;
                set.pdf_area[prim as usize] = sel / area(scene, prim);
            }
        }
        set
    }

    /// Probability density (per unit area) of sampling point on `prim` by [`LightSet::sample`].
    pub fn pdf_area(&self, prim: u32) -> f64 {
        self.pdf_area.get(prim as usize).copied().unwrap_or(0.0)
    }

    /// Picks an emissive triangle in proportion to its power and a uniform point on it.
    /// Returns (prim, point, unit geometric normal, pdf per unit area).
    pub fn sample(
        &self,
        scene: &ResolvedScene,
        u: f64,
        u1: f64,
        u2: f64,
    ) -> Option<(u32, DVec3, DVec3, f64)> {
        if self.emitters.is_empty() {
            return None;
        }
        let target = u * self.total;
        let i = self
            .cdf
            .partition_point(|&c| c <= target)
            .min(self.emitters.len() - 1);
        let prim = self.emitters[i];
        let [a, b, c] = scene.triangles[prim as usize].map(|v| v.as_dvec3());
        let su = u1.sqrt();
        let p = a * (1.0 - su) + b * (su * (1.0 - u2)) + c * (su * u2);
        let n = (b - a).cross(c - a).normalize();
        Some((prim, p, n, self.pdf_area(prim)))
    }

    /// Emitted radiance of `prim` (its material's emission, times the bias factor).
    pub fn emission(&self, scene: &ResolvedScene, prim: u32) -> DVec3 {
        emission_of(scene, prim) * self.emission_scale
    }
}

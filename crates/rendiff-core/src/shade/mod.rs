//! Shading: radiance for scenes that ask for it, and only then
//! (docs/radiance.md is the contract every backend follows).
//!
//! Local shading (`lambert` with point/directional lights, `emission`) is
//! deterministic and uses the visibility buffers of the render (pixel centers).
//! `global_illumination` is path tracing of the pixel's box-filtered integral
//! with next-event estimation, MIS and Russian roulette, and it reports the
//! variance of each pixel's mean so that comparisons can be statistical.

pub mod direct;
pub mod lights;
pub mod path;

use crate::frame::Frame;
use crate::scene::resolve::ResolvedScene;
use crate::trace::TraceBvh;
use glam::DVec3;

/// Deliberate errors, so the statistical gate's detection power can be tested.
/// Never used by a normal render.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Bias {
    /// Every albedo 2% too high.
    Albedo2Percent,
    /// The receiver's cosine left out of direct lighting.
    MissingCosine,
    /// Paths one vertex shorter than the scene's max_depth (or 6 when unlimited).
    OneBounceFewer,
    /// Light intensities and emitted radiance (area lights) off by a factor pi.
    LightTimesPi,
    /// Path tracing only: the reported variance of each pixel's mean halved (the
    /// mean is untouched), so a calibration test's power can be checked.
    VarianceHalved,
    /// Path tracing only: the reported variance of each pixel's mean doubled.
    VarianceDoubled,
}

impl crate::names::Named for Bias {
    const ALL: &'static [Self] = &[
        Self::Albedo2Percent,
        Self::MissingCosine,
        Self::OneBounceFewer,
        Self::LightTimesPi,
        Self::VarianceHalved,
        Self::VarianceDoubled,
    ];
    fn name(self) -> &'static str {
        match self {
            Self::Albedo2Percent => "albedo2-percent",
            Self::MissingCosine => "missing-cosine",
            Self::OneBounceFewer => "one-bounce-fewer",
            Self::LightTimesPi => "light-times-pi",
            Self::VarianceHalved => "variance-halved",
            Self::VarianceDoubled => "variance-doubled",
        }
    }
}

/// How to shade.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ShadeOptions {
    /// Samples per pixel for path tracing (ignored by local shading).
    pub spp: u32,
    /// Seed of the random sequence (per pixel streams derive from it).
    pub seed: u64,
    /// A deliberate error, for detection-power tests only.
    pub bias: Option<Bias>,
    /// Stop shading when this passes (`check --timeout`); the result is then partial.
    pub deadline: Option<std::time::Instant>,
}

/// Radiance buffers of one render.
#[derive(Debug, Clone, PartialEq)]
pub struct Radiance {
    /// Linear RGB radiance per pixel.
    pub rgb: Vec<[f32; 3]>,
    /// Variance of each pixel's mean estimate (Monte Carlo only).
    pub var: Option<Vec<[f32; 3]>>,
    /// Samples per pixel (1 for local shading).
    pub spp: u32,
    /// `direct` or `path`.
    pub integrator: &'static str,
    /// Seconds spent shading.
    pub seconds: f64,
}

/// True when the scene asks for radiance at all ([`crate::vocab::needs_shading`]).
pub fn needs_shading(scene: &ResolvedScene) -> bool {
    crate::vocab::needs_shading(scene.requires.iter().map(String::as_str))
}

/// Shades a frame whose visibility is already computed; `bvh` serves shadow and path rays.
pub fn shade(scene: &ResolvedScene, frame: &Frame, bvh: &TraceBvh, opts: ShadeOptions) -> Radiance {
    let start = std::time::Instant::now();
    let mut r = if scene.requires.contains("global_illumination") {
        path::render(scene, bvh, opts)
    } else {
        direct::render(scene, frame, bvh, opts)
    };
    r.seconds = start.elapsed().as_secs_f64();
    r
}

/// Surface data at a hit: what every shading model needs.
#[derive(Debug, Clone, Copy)]
pub struct Surface {
    /// Hit point.
    pub x: DVec3,
    /// Unit geometric normal, turned toward the viewer when two-sided.
    pub n: DVec3,
    /// True when the viewer sees the triangle's front (counter-clockwise) side.
    pub front: bool,
    /// Diffuse albedo.
    pub albedo: DVec3,
    /// Emitted radiance toward the viewer (0 on a one-sided emitter's back).
    pub emission: DVec3,
}

/// The scene's shading switches from its `requires`, read once per render:
/// a set lookup per hit was a twentieth of the path tracer's time.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Features {
    /// `two_sided`: shading and emission on both sides.
    pub two_sided: bool,
    /// `emission`: materials emit.
    pub emission: bool,
    /// `shadows`: delta lights are blocked.
    pub shadows: bool,
}

impl Features {
    /// The switches `scene` requires.
    pub fn of(scene: &ResolvedScene) -> Features {
        Features {
            two_sided: scene.requires.contains("two_sided"),
            emission: scene.requires.contains("emission"),
            shadows: scene.requires.contains("shadows"),
        }
    }
}

/// Evaluates the surface of `prim` hit at `x` by a ray travelling along `d`.
pub fn surface(
    scene: &ResolvedScene,
    features: Features,
    prim: u32,
    x: DVec3,
    d: DVec3,
    bias: Option<Bias>,
) -> Surface {
    let obj = &scene.objects[scene.object_ids[prim as usize] as usize];
    let look = Look::of(&scene.materials[obj.material as usize], features, bias);
    surface_at(normal_of(scene, prim), look, features, x, d)
}

/// The unit geometric normal `(b - a) x (c - a)` of `prim` (zero when degenerate).
fn normal_of(scene: &ResolvedScene, prim: u32) -> DVec3 {
    let [a, b, c] = scene.triangles[prim as usize].map(|v| v.as_dvec3());
    (b - a).cross(c - a).normalize_or_zero()
}

/// What a material looks like to shading: its albedo (with the bias) and
/// what it emits when the scene requires `emission`.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Look {
    albedo: DVec3,
    emission: DVec3,
}

impl Look {
    fn of(m: &crate::scene::resolve::Material, features: Features, bias: Option<Bias>) -> Look {
        let mut albedo = DVec3::from(m.albedo);
        if bias == Some(Bias::Albedo2Percent) {
            albedo *= 1.02;
        }
        let emission = if features.emission {
            DVec3::from(m.emission)
        } else {
            DVec3::ZERO
        };
        Look { albedo, emission }
    }
}

/// [`surface`] from the triangle's unit normal `ng` and its material's look.
#[inline]
fn surface_at(ng: DVec3, look: Look, features: Features, x: DVec3, d: DVec3) -> Surface {
    let front = ng.dot(d) < 0.0;
    let two_sided = features.two_sided;
    let n = if front || !two_sided { ng } else { -ng };
    let visible_side = front || two_sided;
    Surface {
        x,
        n,
        front,
        albedo: if visible_side {
            look.albedo
        } else {
            DVec3::ZERO
        },
        emission: if visible_side {
            look.emission
        } else {
            DVec3::ZERO
        },
    }
}

/// [`surface`] for one render's many hits: every triangle's unit normal
/// and material, and every material's look, taken once. The path tracer
/// evaluates a surface at every path vertex, and gathering the triangle,
/// its object and its material and normalizing the normal there was a
/// tenth of its time. Same values as [`surface`], bit for bit.
#[derive(Debug, Clone)]
pub struct Surfaces {
    /// Per triangle: its unit normal and its material's index in `looks`.
    prims: Vec<(DVec3, u32)>,
    looks: Vec<Look>,
    features: Features,
}

impl Surfaces {
    /// The table of `scene`'s triangles under `features` and `bias`.
    pub fn new(scene: &ResolvedScene, features: Features, bias: Option<Bias>) -> Surfaces {
        let prims = (0..scene.triangles.len() as u32)
            .map(|prim| {
                let obj = &scene.objects[scene.object_ids[prim as usize] as usize];
                (normal_of(scene, prim), obj.material)
            })
            .collect();
        let looks = scene
            .materials
            .iter()
            .map(|m| Look::of(m, features, bias))
            .collect();
        Surfaces {
            prims,
            looks,
            features,
        }
    }

    /// The surface of `prim` hit at `x` by a ray travelling along `d` ([`surface`]).
    #[inline]
    pub fn at(&self, prim: u32, x: DVec3, d: DVec3) -> Surface {
        let (ng, material) = self.prims[prim as usize];
        surface_at(ng, self.looks[material as usize], self.features, x, d)
    }
}

/// Offset for rays leaving a surface: 1e-7 of the scene's extent plus the point's magnitude.
pub fn ray_epsilon(scene_size: f64, x: DVec3) -> f64 {
    1e-7 * scene_size.max(1.0) + 1e-9 * x.abs().max_element()
}

//! One entry point for every renderer that runs in process: the core's two
//! loops and Embree. `rendiff render`, `check` and the isolated runner (a
//! child `rendiff render`) all come through here, so a scene is shaded the
//! same way whoever asks, and "which features does this backend model" has
//! one answer.

use crate::backends::embree::{self, EmbreeError, EmbreeMode};
use crate::frame::Frame;
use crate::loop_cost::{self, Choice, Loop};
use crate::raster::{self, RasterOptions};
use crate::scene::resolve::ResolvedScene;
use crate::shade::{self, Bias, Radiance, ShadeOptions};
use crate::trace::{self, BvhQuality, TraceKernel, TraceOptions};
use crate::vocab::Feature;
use std::time::Instant;

/// A renderer that runs in this process.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Backend {
    /// The core's rasterizer (outer loop over triangles).
    Raster,
    /// The core's ray tracer (outer loop over pixels).
    Trace,
    /// Embree's visibility queries.
    Embree(EmbreeMode),
}

impl Backend {
    /// The backend's name in run folders, reports and results.json.
    pub fn name(self) -> &'static str {
        match self {
            Backend::Raster => "raster",
            Backend::Trace => "trace",
            Backend::Embree(m) => m.name(),
        }
    }

    /// The scene features it models: the core every one, Embree visibility only.
    pub fn features(self) -> &'static [Feature] {
        match self {
            Backend::Raster | Backend::Trace => Feature::ALL,
            Backend::Embree(_) => Feature::VISIBILITY,
        }
    }

    /// Units of work the progress callback counts to: tiles, rows or nothing.
    pub fn progress_total(self, scene: &ResolvedScene) -> u64 {
        let cam = &scene.camera;
        match self {
            Backend::Raster => {
                u64::from(cam.width.div_ceil(raster::TILE) * cam.height.div_ceil(raster::TILE))
            }
            Backend::Trace => u64::from(cam.height),
            Backend::Embree(_) => 0,
        }
    }
}

/// The core loop [`loop_cost`] expects to render `scene` once sooner on
/// `threads` threads (`render --renderer core`, `check`'s reference), with
/// the estimates behind the pick. Both loops give the same buffers.
pub fn core_loop(scene: &ResolvedScene, threads: usize) -> (Backend, Choice) {
    let choice = loop_cost::choose(&loop_cost::workload(scene, threads));
    let backend = match choice.pick {
        Loop::Raster => Backend::Raster,
        Loop::Trace => Backend::Trace,
    };
    (backend, choice)
}

/// How to render: the tracer's knobs, shading's samples and seed, a time limit.
#[derive(Debug, Clone, Copy, Default)]
pub struct RenderOptions {
    /// BVH build quality (trace, and the shading BVH of a raster render).
    pub bvh: BvhQuality,
    /// Packets or single rays (trace).
    pub kernel: TraceKernel,
    /// Samples per pixel; default: the scene's `integrator.spp`.
    pub spp: Option<u32>,
    /// Seed of the path tracer.
    pub seed: u64,
    /// A deliberate shading error (detection-power tests only).
    pub bias: Option<Bias>,
    /// Stop when this passes (`check --timeout`): the result is then partial,
    /// which the caller detects with [`crate::deadline::past`].
    pub deadline: Option<Instant>,
}

/// Buffers of one render.
#[derive(Debug, Clone)]
pub struct Rendered {
    /// Visibility: depth, IDs, normals.
    pub frame: Frame,
    /// Radiance, when the scene asks for it and the backend shades.
    pub radiance: Option<Radiance>,
}

/// Why a render did not happen.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum NotRendered {
    /// The backend cannot model the scene or is not installed: skipped, with the reason.
    Skipped(String),
    /// The backend failed: an error the report must show.
    Failed(String),
}

impl std::fmt::Display for NotRendered {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            NotRendered::Skipped(why) => write!(f, "skipped: {why}"),
            NotRendered::Failed(why) => f.write_str(why),
        }
    }
}

/// Renders `scene` with `backend` on rayon's current pool. The core shades a
/// scene that asks for radiance (sharing the tracer's BVH); Embree renders
/// visibility only. `progress` counts [`Backend::progress_total`] units.
pub fn render(
    scene: &ResolvedScene,
    backend: Backend,
    opts: RenderOptions,
    progress: &(dyn Fn(u64) + Sync),
) -> Result<Rendered, NotRendered> {
    let missing: Vec<&str> = scene
        .requires
        .iter()
        .map(String::as_str)
        .filter(|r| {
            Feature::VISIBILITY.iter().any(|f| f.as_str() == *r)
                && !backend.features().iter().any(|f| f.as_str() == *r)
        })
        .collect();
    if !missing.is_empty() {
        return Err(NotRendered::Skipped(format!(
            "missing features: {}",
            missing.join(", ")
        )));
    }
    let (frame, traced_bvh) = match backend {
        Backend::Raster => {
            let o = RasterOptions {
                deadline: opts.deadline,
                ..RasterOptions::default()
            };
            (raster::render(scene, o, progress), None)
        }
        Backend::Trace => {
            let o = TraceOptions {
                bvh: opts.bvh,
                kernel: opts.kernel,
                count_coverage: false,
                deadline: opts.deadline,
            };
            let (f, b) = trace::render_keeping_bvh(scene, o, progress);
            (f, Some(b))
        }
        Backend::Embree(mode) => {
            let frame = embree::render(scene, mode).map_err(|e| match e {
                EmbreeError::Unavailable(why) => NotRendered::Skipped(why),
                e => NotRendered::Failed(e.to_string()),
            })?;
            return Ok(Rendered {
                frame,
                radiance: None,
            });
        }
    };
    // Past the deadline nothing more is done (the caller discards the frame).
    let radiance = if shade::needs_shading(scene) && !crate::deadline::past(opts.deadline) {
        let bvh = match traced_bvh {
            Some(b) => Some(b),
            None => trace::TraceBvh::build_until(scene, opts.bvh, opts.deadline),
        };
        bvh.map(|bvh| {
            let shading = ShadeOptions {
                spp: opts.spp.unwrap_or(scene.integrator.spp),
                seed: opts.seed,
                bias: opts.bias,
                deadline: opts.deadline,
            };
            shade::shade(scene, &frame, &bvh, shading)
        })
    } else {
        None
    };
    Ok(Rendered { frame, radiance })
}

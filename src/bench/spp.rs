//! The samples-per-pixel knobs of `bench knobs` and the path tracers shared
//! with `bench peers`: the core path tracer and Mitsuba (through the harness),
//! each timed and compared with the cached Monte Carlo reference. Separate
//! from the visibility knobs because its reference, error metric and external
//! renderer differ.

use super::harness::{number_at, Harness};
use super::knobs::{point, stem, Group, KnobsOptions};
use super::radiance::{self, RgbImage};
use crate::raster::{self, RasterOptions};
use crate::scene::resolve::ResolvedScene;
use crate::shade::{self, ShadeOptions};
use crate::trace::{BvhQuality, TraceBvh};
use anyhow::{bail, Result};
use serde_json::{json, Value};
use std::path::Path;
use std::time::Duration;

/// The radiance group: core spp settings, then Mitsuba's (unless external renderers are off).
pub fn radiance_group(opts: &KnobsOptions) -> Result<Group> {
    let scene = super::load_scene(&opts.gi_scene)?;
    if !scene.requires.contains("global_illumination") {
        bail!(
            "{}: the spp knobs need a global_illumination scene",
            opts.gi_scene.display()
        );
    }
    let reference = radiance::read_rgb(&opts.reference)?;
    let cam = &scene.camera;
    if (reference.width, reference.height) != (cam.width as usize, cam.height as usize) {
        bail!(
            "{}: reference is {}x{}, the scene {}x{}",
            opts.reference.display(),
            reference.width,
            reference.height,
            cam.width,
            cam.height
        );
    }
    let mut g = Group {
        id: format!("radiance-{}", stem(&opts.gi_scene)),
        title: format!("radiance: {} {}x{}", stem(&opts.gi_scene), cam.width, cam.height),
        scene: opts.gi_scene.display().to_string(),
        width: cam.width,
        height: cam.height,
        reference: format!("cached Mitsuba render {}", opts.reference.display()),
        time: "path tracing only (core: BVH build + shading; Mitsuba: scene build + radiance passes, Python start-up and its visibility pass excluded)".into(),
        error_metric: "RMSE vs reference (over pixels and RGB)".into(),
        points: Vec::new(),
        skipped: Vec::new(),
        facts: json!({}),
    };
    for &spp in &opts.core_spp {
        let (t, e) = core_path(&scene, &reference, spp, opts.seed, opts.common.runs)?;
        g.points.push(point(
            "core spp",
            &format!("core {spp} spp"),
            t.median_s,
            Some(e.rmse),
            json!({"timing": t.json(), "error": e, "spp": spp, "seed": opts.seed}),
        ));
    }
    if let Some(e) = g
        .points
        .first()
        .and_then(|p| p.details["error"]["reference_noise_rmse"].as_f64())
    {
        g.facts["reference_noise_rmse"] = json!(e);
    }
    if opts.mitsuba_spp.is_empty() {
        return Ok(g);
    }
    if opts.no_external {
        g.skipped.push(json!({"knob": "mitsuba spp", "reason": "external renderers off (--quick or --no-external)"}));
        return Ok(g);
    }
    let scratch = super::Scratch::new("knobs")?;
    let harness = match Harness::find(
        &opts.common.root,
        Duration::from_secs(opts.common.timeout_s),
        scratch.path(),
    ) {
        Ok(h) => h,
        Err(why) => {
            g.skipped
                .push(json!({"knob": "mitsuba spp", "reason": why}));
            return Ok(g);
        }
    };
    let resolved = match harness.export(&scene, scratch.path()) {
        Ok(r) => r,
        Err(why) => {
            g.skipped
                .push(json!({"knob": "mitsuba spp", "reason": why}));
            return Ok(g);
        }
    };
    for &spp in &opts.mitsuba_spp {
        match mitsuba_path(
            &harness,
            &resolved,
            &reference,
            spp,
            opts.seed,
            opts.common.runs,
        ) {
            Ok(m) => g.points.push(point(
                "mitsuba spp",
                &format!("mitsuba {spp} spp"),
                m.time_s,
                Some(m.error.rmse),
                m.details,
            )),
            Err(why) => g
                .skipped
                .push(json!({"knob": format!("mitsuba {spp} spp"), "reason": why})),
        }
    }
    Ok(g)
}

/// Times the core path tracer at `spp` (BVH build + shading) and its error.
pub fn core_path(
    scene: &ResolvedScene,
    reference: &RgbImage,
    spp: u32,
    seed: u64,
    runs: usize,
) -> Result<(super::Timed<shade::Radiance>, radiance::RgbError)> {
    let frame = raster::render(scene, RasterOptions::default(), &|_| {});
    let t = super::timed(runs, || {
        let bvh = TraceBvh::build(scene, BvhQuality::Medium);
        let opts = ShadeOptions {
            spp,
            seed,
            bias: None,
        };
        shade::shade(scene, &frame, &bvh, opts)
    });
    let e = radiance::error(reference, &t.last.rgb, t.last.var.as_deref())?;
    Ok((t, e))
}

/// One Mitsuba spp setting: median time from its info, error, and the raw timings.
pub struct MitsubaPoint {
    /// Median scene build + radiance render seconds.
    pub time_s: f64,
    /// Error of the last run's image (the seed is fixed, so every run's image is the same).
    pub error: radiance::RgbError,
    /// Timings and settings for the record.
    pub details: Value,
}

/// Renders with Mitsuba through the harness (warm-up + `runs`).
pub fn mitsuba_path(
    harness: &Harness,
    resolved: &Path,
    reference: &RgbImage,
    spp: u32,
    seed: u64,
    runs: usize,
) -> Result<MitsubaPoint, String> {
    let out = harness.scratch.join(format!("mitsuba-{spp}.exr"));
    let mut times = Vec::new();
    let mut harness_s = Vec::new();
    let mut wall = Vec::new();
    let mut last = None;
    for k in 0..=runs.max(1) {
        let r = harness.render("mitsuba", resolved, &out, Some(spp), Some(seed))?;
        let build = number_at(&r.info, &["radiance", "timings_s", "build"]).unwrap_or(0.0);
        let render = number_at(&r.info, &["radiance", "timings_s", "render"])
            .ok_or("mitsuba reported no radiance timings")?;
        if k > 0 {
            times.push(build + render);
            harness_s.push(r.time_s.unwrap_or(f64::NAN));
            wall.push(r.wall_s);
        }
        last = Some(r);
    }
    let last = last.ok_or("no run")?;
    let img = radiance::read_rgb(&out).map_err(|e| format!("{e:#}"))?;
    let error =
        radiance::error(reference, &img.rgb, img.var.as_deref()).map_err(|e| format!("{e:#}"))?;
    let time_s = super::median(&times);
    Ok(MitsubaPoint {
        time_s,
        error,
        details: json!({
            "timing": {"median_s": time_s, "runs_s": times,
                       "harness_time_s_median": super::median(&harness_s),
                       "subprocess_wall_s_median": super::median(&wall)},
            "error": error, "spp": spp, "seed": seed,
            "version": last.version,
            "radiance_info": last.info.get("radiance").map(|r| json!({
                "spp": r.get("spp"), "passes": r.get("passes"), "spp_per_pass": r.get("spp_per_pass"),
                "integrator": r.get("integrator"), "sampler": r.get("sampler"), "timings_s": r.get("timings_s"),
            })),
            "variant": last.info.get("variant"),
        }),
    })
}

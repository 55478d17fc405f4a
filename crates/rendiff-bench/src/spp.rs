//! The samples-per-pixel knobs of `bench knobs` and the path tracers shared
//! with `bench peers`: the core path tracer and Mitsuba (through the harness),
//! each timed and compared with the cached Monte Carlo reference. Mitsuba's
//! own settings (path length `max_depth`, variant scalar vs LLVM) are knobs
//! here too, at one spp. Separate
//! from the visibility knobs because its reference, error metric and external
//! renderer differ.

use super::harness::{number_at, Harness};
use super::knobs::{point, stem, Group, KnobsOptions};
use super::radiance::{self, RgbImage};
use anyhow::Result;
use rendiff::raster::{self, RasterOptions};
use rendiff::scene::resolve::ResolvedScene;
use rendiff::shade::{self, ShadeOptions};
use rendiff::trace::{BvhQuality, TraceBvh};
use serde_json::{json, Value};
use std::path::Path;
use std::time::Duration;

/// The radiance group: core spp settings, then Mitsuba's (unless external renderers are off).
pub fn radiance_group(opts: &KnobsOptions) -> Result<Group> {
    let (scene, reference) =
        radiance::gi_scene_and_reference(&opts.gi_scene, &opts.reference, "the spp knobs")?;
    let cam = &scene.camera;
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
    if opts.mitsuba_spp.is_empty()
        && opts.mitsuba_max_depth.is_empty()
        && opts.mitsuba_variants.is_empty()
    {
        return Ok(g);
    }
    if opts.no_external {
        g.skipped.push(json!({"knob": "mitsuba settings", "reason": "external renderers off (--quick or --no-external)"}));
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
                .push(json!({"knob": "mitsuba settings", "reason": why}));
            return Ok(g);
        }
    };
    let resolved = match harness.export(&scene, scratch.path()) {
        Ok(r) => r,
        Err(why) => {
            g.skipped
                .push(json!({"knob": "mitsuba settings", "reason": why}));
            return Ok(g);
        }
    };
    let mut configs: Vec<(&str, String, u32, Vec<String>)> = opts
        .mitsuba_spp
        .iter()
        .map(|&spp| ("mitsuba spp", format!("mitsuba {spp} spp"), spp, Vec::new()))
        .collect();
    let spp = opts.mitsuba_knob_spp;
    for d in &opts.mitsuba_max_depth {
        configs.push((
            "mitsuba max_depth",
            format!("mitsuba {spp} spp, max_depth {d}"),
            spp,
            vec!["--max-depth".into(), d.to_string()],
        ));
    }
    for v in &opts.mitsuba_variants {
        configs.push((
            "mitsuba variant",
            format!("mitsuba {spp} spp, {v}"),
            spp,
            vec!["--variant".into(), v.clone()],
        ));
    }
    for (i, (knob, label, spp, args)) in configs.into_iter().enumerate() {
        rendiff::errln!("knobs: {label}");
        let run = MitsubaRun {
            spp,
            seed: opts.seed,
            settings: &args,
            name: &format!("mitsuba-{i}"),
        };
        match mitsuba_path(&harness, &resolved, &reference, &run, opts.common.runs) {
            Ok(m) => g
                .points
                .push(point(knob, &label, m.time_s, Some(m.error.rmse), m.details)),
            Err(why) => g.skipped.push(json!({"knob": label, "reason": why})),
        }
    }
    Ok(g)
}

/// One Mitsuba configuration: spp, seed, the harness's quality options and a file name.
#[derive(Debug, Clone, Copy)]
pub struct MitsubaRun<'a> {
    /// Samples per pixel.
    pub spp: u32,
    /// Seed (not the reference's).
    pub seed: u64,
    /// Extra `render` options (`--max-depth`, `--variant`).
    pub settings: &'a [String],
    /// Output file stem in the scratch folder.
    pub name: &'a str,
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
            deadline: None,
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
    run: &MitsubaRun,
    runs: usize,
) -> Result<MitsubaPoint, String> {
    let (spp, seed) = (run.spp, run.seed);
    let out = harness.scratch.join(format!("{}.exr", run.name));
    let mut times = Vec::new();
    let mut harness_s = Vec::new();
    let mut wall = Vec::new();
    let mut last = None;
    for k in 0..=runs.max(1) {
        let r = harness.render_with(
            "mitsuba",
            resolved,
            &out,
            Some(spp),
            Some(seed),
            run.settings,
        )?;
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
            "error": error, "spp": spp, "seed": seed, "harness_options": run.settings,
            "version": last.version,
            "radiance_info": last.info.get("radiance").map(|r| json!({
                "spp": r.get("spp"), "passes": r.get("passes"), "spp_per_pass": r.get("spp_per_pass"),
                "integrator": r.get("integrator"), "sampler": r.get("sampler"), "timings_s": r.get("timings_s"),
                "max_depth": r.get("max_depth"),
            })),
            "variant": last.info.get("variant"),
        }),
    })
}

//! The direct-lighting radiance knobs of `bench knobs`: each external
//! renderer's own quality settings on a locally shaded scene (POV-Ray's
//! antialiasing and `+Q` quality level, pyrender's only configuration) next to
//! the core's own supersampling, all against one reference.
//!
//! Reference: the core's local shading (docs/radiance.md) at K×K pixel-center
//! samples per pixel (the scene rendered at K times the size), box-filtered:
//! the pixel's area integral that an antialiased image approximates. The
//! conformance contract (one sample at the pixel center) is itself a point
//! here, and each point's distance to it is recorded beside its error. The
//! reference's own error is estimated by the K/2 point (`reference_floor_rmse`).
//!
//! IDs and depth are never antialiased: the harness passes these settings to
//! POV-Ray's radiance passes only (harness/rendiff_harness/renderers/povray/backend.py).

use super::harness::{number_at, Harness, HarnessRun};
use super::knobs::{point, Group, SceneSpec};
use super::radiance::{self, RgbImage};
use anyhow::{bail, Result};
use rendiff::raster::{self, RasterOptions};
use rendiff::scene::resolve::ResolvedScene;
use rendiff::shade::{self, ShadeOptions};
use rendiff::trace::{BvhQuality, TraceBvh};
use serde_json::{json, Value};
use std::path::Path;
use std::time::Duration;

/// One external setting: which knob, its label, and the harness `render` options.
#[derive(Debug, Clone)]
pub struct Setting {
    /// Which knob (the plot's legend group).
    pub knob: &'static str,
    /// Backend name for the harness.
    pub backend: &'static str,
    /// Label in the table and plot.
    pub label: String,
    /// `render` options (numbers formatted here, validated again by the harness).
    pub args: Vec<String>,
}

fn povray(knob: &'static str, label: &str, args: &[&str]) -> Setting {
    Setting {
        knob,
        backend: "povray",
        label: format!("POV-Ray {label}"),
        args: args.iter().map(|s| s.to_string()).collect(),
    }
}

/// The external settings measured: POV-Ray's quality levels (0: quick colours
/// only, 2: no shadows, 4: shadows, default 9 = the contract) and its
/// antialiasing methods from cheap (adaptive, default threshold) to thorough
/// (every pixel supersampled), then pyrender, which has no setting to vary.
pub fn settings() -> Vec<Setting> {
    let aa = "povray antialiasing";
    let q = "povray quality";
    vec![
        povray(q, "-A (contract)", &[]),
        povray(q, "-A +Q0", &["--quality", "0"]),
        povray(q, "-A +Q2", &["--quality", "2"]),
        povray(q, "-A +Q4", &["--quality", "4"]),
        povray(aa, "+AM1 +A0.3 +R3", &["--aa-method", "1"]),
        povray(
            aa,
            "+AM1 +A0.1 +R3",
            &["--aa-method", "1", "--aa-threshold", "0.1"],
        ),
        povray(
            aa,
            "+AM1 +A0 +R3",
            &["--aa-method", "1", "--aa-threshold", "0"],
        ),
        povray(
            aa,
            "+AM1 +A0 +R5",
            &["--aa-method", "1", "--aa-threshold", "0", "--aa-depth", "5"],
        ),
        povray(
            aa,
            "+AM2 +A0.1 +R2",
            &[
                "--aa-method",
                "2",
                "--aa-threshold",
                "0.1",
                "--aa-depth",
                "2",
            ],
        ),
        povray(
            aa,
            "+AM2 +A0 +R3",
            &["--aa-method", "2", "--aa-threshold", "0", "--aa-depth", "3"],
        ),
        Setting {
            knob: "pyrender",
            backend: "pyrender",
            label: "pyrender (OSMesa, no MSAA)".into(),
            args: Vec::new(),
        },
    ]
}

/// What the direct-lighting group measures.
#[derive(Debug, Clone)]
pub struct DirectOptions<'a> {
    /// The scene (locally shaded: `lambert` or `emission`, no `global_illumination`).
    pub spec: &'a SceneSpec,
    /// Reference samples per pixel side (K×K per pixel); a power of two.
    pub supersample: u32,
    /// External settings (empty or `no_external`: core only).
    pub settings: &'a [Setting],
    /// Skip external renderers, recording why.
    pub no_external: bool,
    /// Timed runs after one warm-up.
    pub runs: usize,
    /// Repository root (the harness venv).
    pub root: &'a Path,
    /// Seconds before a renderer is killed.
    pub timeout_s: u64,
}

/// Box-filters a `(w·k)×(h·k)` image down to `w×h` (mean of each k×k block, in f64).
pub fn box_downsample(big: &[[f32; 3]], w: usize, h: usize, k: usize) -> Vec<[f32; 3]> {
    assert_eq!(big.len(), w * k * h * k, "image size");
    let inv = 1.0 / (k * k) as f64;
    let mut out = Vec::with_capacity(w * h);
    for y in 0..h {
        for x in 0..w {
            let mut acc = [0.0f64; 3];
            for j in 0..k {
                let row = (y * k + j) * w * k + x * k;
                for p in &big[row..row + k] {
                    for c in 0..3 {
                        acc[c] += f64::from(p[c]);
                    }
                }
            }
            out.push(acc.map(|v| (v * inv) as f32));
        }
    }
    out
}

/// The direct-lighting reference's K x K samples per pixel: a power of two
/// in 2..=64 (`--supersample`, checked before anything runs).
pub fn check_supersample(k: u32) -> Result<(), String> {
    if k.is_power_of_two() && (2..=64).contains(&k) {
        Ok(())
    } else {
        Err(format!("must be a power of two in 2..=64, got {k}"))
    }
}

/// The core's local shading with k×k pixel-center samples per pixel (raster,
/// BVH build for shadow rays, shading, all timed), box-filtered to the scene's size.
pub fn core_supersampled(
    scene: &ResolvedScene,
    k: u32,
    runs: usize,
) -> Result<super::Timed<Vec<[f32; 3]>>> {
    let (w, h) = (scene.camera.width, scene.camera.height);
    let big = super::resized(scene, w * k, h * k)?;
    let opts = ShadeOptions {
        spp: 1,
        seed: 0,
        bias: None,
        deadline: None,
    };
    let t = super::timed(runs, || {
        let frame = raster::render(&big, RasterOptions::default(), &|_| {});
        let bvh = TraceBvh::build(&big, BvhQuality::Medium);
        let rgb = shade::shade(&big, &frame, &bvh, opts).rgb;
        box_downsample(&rgb, w as usize, h as usize, k as usize)
    });
    Ok(t)
}

fn image(scene: &ResolvedScene, rgb: Vec<[f32; 3]>) -> RgbImage {
    RgbImage {
        width: scene.camera.width as usize,
        height: scene.camera.height as usize,
        rgb,
        var: None,
    }
}

/// The group for one locally shaded scene.
pub fn direct_group(opts: &DirectOptions) -> Result<Group> {
    let scene = opts.spec.load()?;
    let path = opts.spec.path.display();
    if scene.requires.contains("global_illumination") {
        bail!("{path}: a direct-lighting knob scene must not require global_illumination (that is --gi-scene)");
    }
    if !shade::needs_shading(&scene) {
        bail!("{path}: the direct-lighting knobs need a shaded scene (lambert or emission)");
    }
    let k_ref = opts.supersample;
    check_supersample(k_ref).map_err(|e| anyhow::anyhow!("--supersample: {e}"))?;
    let cam = &scene.camera;
    let mut g = Group {
        id: format!("radiance-direct-{}", opts.spec.stem()),
        title: format!(
            "direct lighting: {} {}x{}",
            opts.spec.stem(),
            cam.width,
            cam.height
        ),
        scene: path.to_string(),
        width: cam.width,
        height: cam.height,
        reference: format!(
            "core local shading, {k_ref}x{k_ref} pixel-center samples per pixel, box filter (the pixel's area integral)"
        ),
        time: "radiance only: core = raster + BVH build + shading at k×k samples; POV-Ray = its radiance passes (process wall: start-up, parse, trace; ID and depth passes excluded); pyrender = its lit pass (context, upload, draw, read-back)".into(),
        error_metric: "RMSE vs reference (over pixels and RGB)".into(),
        points: Vec::new(),
        skipped: Vec::new(),
        facts: json!({}),
    };
    rendiff::errln!("knobs: direct-lighting reference ({k_ref}x{k_ref} per pixel) on {path}");
    let reference_t = core_supersampled(&scene, k_ref, opts.runs)?;
    let reference = image(&scene, reference_t.last.clone());
    let mut contract: Option<RgbImage> = None;
    let mut k = 1;
    while k <= k_ref {
        let t = if k == k_ref {
            reference_t.clone()
        } else {
            core_supersampled(&scene, k, opts.runs)?
        };
        let e = radiance::error(&reference, &t.last, None)?;
        let label = if k == 1 {
            "core 1x1 (contract: pixel center)".to_string()
        } else {
            format!("core {k}x{k}")
        };
        // The reference itself has no measurable error (only its floor, below):
        // it is shown with its time but never ranked.
        let (error, note) = if k == k_ref {
            (None, "the reference itself: time only, not ranked")
        } else {
            (Some(e.rmse), "")
        };
        g.points.push(point(
            "core supersampling",
            &label,
            t.median_s,
            error,
            json!({"timing": t.json(), "error": e, "samples_per_pixel": k * k, "note": note}),
        ));
        if k == 1 {
            contract = Some(image(&scene, t.last));
        } else if 2 * k == k_ref {
            g.facts["reference_floor_rmse"] = json!(e.rmse);
        }
        k *= 2;
    }
    let contract = contract.expect("k = 1 is always measured");
    g.facts["contract_vs_reference_rmse"] =
        json!(radiance::error(&reference, &contract.rgb, None)?.rmse);
    if opts.settings.is_empty() {
        return Ok(g);
    }
    if opts.no_external {
        g.skipped.push(json!({"knob": "external renderers' settings", "reason": "external renderers off (--quick or --no-external)"}));
        return Ok(g);
    }
    let scratch = super::Scratch::new("direct")?;
    let harness = Harness::find(
        opts.root,
        Duration::from_secs(opts.timeout_s),
        scratch.path(),
    )
    .and_then(|h| h.export(&scene, scratch.path()).map(|r| (h, r)));
    let (harness, resolved) = match harness {
        Ok(x) => x,
        Err(why) => {
            g.skipped
                .push(json!({"knob": "external renderers' settings", "reason": why}));
            return Ok(g);
        }
    };
    for (i, s) in opts.settings.iter().enumerate() {
        rendiff::errln!("knobs: {} {}", s.backend, s.label);
        let out = harness.scratch.join(format!("direct-{i}.exr"));
        match external(&harness, s, &resolved, &out, opts.runs) {
            Ok((time_s, times, last)) => {
                let img = match radiance::read_rgb(&out) {
                    Ok(img) => img,
                    Err(e) => {
                        g.skipped
                            .push(json!({"knob": s.label, "reason": format!("{e:#}")}));
                        continue;
                    }
                };
                let e = radiance::error(&reference, &img.rgb, None)?;
                let vs_contract = radiance::error(&contract, &img.rgb, None)?;
                if s.backend == "pyrender" {
                    if let Some(m) = last.info.get("msaa") {
                        g.skipped.push(json!({"knob": "pyrender MSAA",
                            "reason": format!("not a setting: pyrender has no sample-count parameter and on OSMesa draws single-sampled (measured: {})", super::page::compact(m))}));
                    }
                }
                g.points.push(point(
                    s.knob,
                    &s.label,
                    time_s,
                    Some(e.rmse),
                    json!({
                        "timing": {"median_s": time_s, "runs_s": times, "subprocess_wall_s": last.wall_s},
                        "error": e, "vs_contract_rmse": vs_contract.rmse,
                        "harness_options": s.args, "version": last.version,
                        "radiance_info": last.info.get("radiance"),
                        "radiance_flags": last.info.get("radiance_flags"),
                    }),
                ));
            }
            Err(why) => g.skipped.push(json!({"knob": s.label, "reason": why})),
        }
    }
    Ok(g)
}

/// Seconds of the radiance work inside one harness render (see the group's `time`).
fn radiance_seconds(backend: &str, info: &Value) -> Option<f64> {
    match backend {
        "povray" => {
            let passes: Vec<f64> = ["lit", "emission"]
                .iter()
                .filter_map(|p| number_at(info, &["passes", p, "povray_s"]))
                .collect();
            (!passes.is_empty()).then(|| passes.iter().sum())
        }
        "pyrender" => number_at(info, &["radiance", "seconds"]),
        _ => None,
    }
}

/// Warm-up plus `runs` harness renders: (median radiance seconds, every run, the last run).
fn external(
    h: &Harness,
    s: &Setting,
    resolved: &Path,
    out: &Path,
    runs: usize,
) -> Result<(f64, Vec<f64>, HarnessRun), String> {
    let mut times = Vec::new();
    let mut last = None;
    for k in 0..=runs.max(1) {
        let r = h.render_with(s.backend, resolved, out, None, None, &s.args)?;
        let t = radiance_seconds(s.backend, &r.info)
            .ok_or_else(|| format!("{}: reported no radiance timings", s.backend))?;
        if k > 0 {
            times.push(t);
        }
        last = Some(r);
    }
    let last = last.ok_or("no run")?;
    Ok((super::median(&times), times, last))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn box_downsample_averages_each_block() {
        // 4x2 image, k = 2 -> 2x1: blocks {0,1,4,5} and {2,3,6,7}.
        let big: Vec<[f32; 3]> = (0..8).map(|v| [v as f32, 1.0, 2.0 * v as f32]).collect();
        let small = box_downsample(&big, 2, 1, 2);
        assert_eq!(small, vec![[2.5, 1.0, 5.0], [4.5, 1.0, 9.0]]);
        assert_eq!(box_downsample(&big, 4, 2, 1), big);
    }
}

//! `rendiff bench knobs`: every knob that trades time for accuracy, measured
//! in one run against one reference per scene (docs/DESIGN.md "Speed versus
//! accuracy"), as time-vs-error groups with their Pareto fronts.
//!
//! - Visibility (per scene; reference: the core raster with exact predicates,
//!   same camera): raster vs trace, BVH build quality (build + trace),
//!   predicate precision (exact vs float-only), Embree default/robust ×
//!   single/packet. Error = `id.prim` mismatches; depth differences and
//!   hit/miss mismatches are recorded beside it.
//! - Resolution (first scene): time and time per pixel at scaled sizes. A
//!   smaller image is not a wrong one, so it has no error and no Pareto rank.
//! - Direct lighting (per locally shaded scene; reference: the core's local
//!   shading supersampled K×K per pixel, box-filtered): the core's
//!   supersampling, POV-Ray's antialiasing and quality level, pyrender (no
//!   setting to vary; its missing MSAA is recorded as measured), error = RMSE
//!   (measured in [`super::direct`]).
//! - Radiance (a global-illumination scene; reference: the cached high-spp
//!   Mitsuba render): the core path tracer's spp and Mitsuba's own spp,
//!   max_depth and variant, error = RMSE over pixels and channels (measured
//!   in [`super::spp`]).

use super::page::{num, Page};
use super::plot::{scatter, ScatterPoint};
use super::{measure, pareto, visibility_error, Common};
use anyhow::{Context, Result};
use rendiff::backends::embree::{EmbreeError, EmbreeMode, EmbreeQuery};
use rendiff::predicate::Precision;
use rendiff::scene::resolve::ResolvedScene;
use rendiff::trace::{BvhQuality, TraceBvh};
use serde_json::{json, Value};
use std::path::{Path, PathBuf};
use std::str::FromStr;

/// A scene file, optionally at another resolution: `PATH[@WxH]`.
#[derive(Debug, Clone, PartialEq)]
pub struct SceneSpec {
    /// Scene file.
    pub path: PathBuf,
    /// Resolution override.
    pub size: Option<(u32, u32)>,
}

impl FromStr for SceneSpec {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s.rsplit_once('@') {
            Some((p, size)) => Ok(SceneSpec {
                path: PathBuf::from(p),
                size: Some(parse_size(size)?),
            }),
            None => Ok(SceneSpec {
                path: PathBuf::from(s),
                size: None,
            }),
        }
    }
}

/// Parses `WIDTHxHEIGHT` (1..=16384 per side).
pub fn parse_size(s: &str) -> Result<(u32, u32), String> {
    let (w, h) = s
        .split_once('x')
        .ok_or_else(|| format!("expected WIDTHxHEIGHT, got {s:?}"))?;
    let p = |v: &str| v.parse::<u32>().map_err(|e| format!("{v:?}: {e}"));
    let (w, h) = (p(w)?, p(h)?);
    rendiff::scene::check_image_size(w, h)?;
    Ok((w, h))
}

/// `--scales K`: a resolution factor, finite and positive (the sizes it
/// gives are checked against the image limits once the scene is loaded,
/// before anything runs: [`scaled_size`]).
pub fn parse_scale(s: &str) -> Result<f64, String> {
    let k: f64 = s.parse().map_err(|_| format!("{s:?} is not a number"))?;
    if k.is_finite() && k > 0.0 {
        Ok(k)
    } else {
        Err(format!(
            "a resolution factor must be finite and > 0, got {s}"
        ))
    }
}

/// A `w0` x `h0` image scaled by `k` (rounded), within the image limits.
pub fn scaled_size(w0: u32, h0: u32, k: f64) -> Result<(u32, u32)> {
    let side = |v: u32| (f64::from(v) * k).round().min(f64::from(u32::MAX)) as u32;
    let (w, h) = (side(w0), side(h0));
    rendiff::scene::check_image_size(w, h)
        .map_err(|e| anyhow::anyhow!("--scales {k} of {w0}x{h0}: {e}"))?;
    Ok((w, h))
}

impl SceneSpec {
    /// The resolved scene at the requested size.
    pub fn load(&self) -> Result<ResolvedScene> {
        let s = super::load_scene(&self.path)?;
        match self.size {
            Some((w, h)) => super::resized(&s, w, h),
            None => Ok(s),
        }
    }

    /// File stem, for names.
    pub fn stem(&self) -> String {
        stem(&self.path)
    }
}

/// A file stem, for names.
pub fn stem(p: &Path) -> String {
    p.file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_else(|| "scene".into())
}

/// What `bench knobs` measures.
#[derive(Debug, Clone)]
pub struct KnobsOptions {
    /// Shared options (runs, output, quick).
    pub common: Common,
    /// Scenes for the visibility knobs (the first also gets the resolution table).
    pub scenes: Vec<SceneSpec>,
    /// Resolution factors of the first scene's size.
    pub resolution_scales: Vec<f64>,
    /// Global-illumination scene for the spp knobs.
    pub gi_scene: PathBuf,
    /// Its cached reference EXR (R,G,B, var.*).
    pub reference: PathBuf,
    /// Core path tracer spp settings.
    pub core_spp: Vec<u32>,
    /// Mitsuba spp settings (empty: skipped).
    pub mitsuba_spp: Vec<u32>,
    /// Mitsuba's spp for its max_depth and variant knobs.
    pub mitsuba_knob_spp: u32,
    /// Mitsuba max_depth settings (-1 = unlimited, or >= 1).
    pub mitsuba_max_depth: Vec<i32>,
    /// Mitsuba variants (`scalar_rgb`, `llvm_ad_rgb`).
    pub mitsuba_variants: Vec<String>,
    /// Locally shaded scenes for the direct-lighting knobs.
    pub direct_scenes: Vec<SceneSpec>,
    /// Their reference's samples per pixel side (a power of two).
    pub supersample: u32,
    /// Seed of both path tracers: not the reference's (0), so no samples are shared with it.
    pub seed: u64,
    /// Worker threads (the core's rayon pool and Embree's device).
    pub threads: usize,
    /// Skip external renderers (Mitsuba), recording why.
    pub no_external: bool,
}

/// One configuration: a knob's setting with its time and error.
#[derive(Debug, Clone, serde::Serialize)]
pub struct Point {
    /// Which knob.
    pub knob: String,
    /// Its setting.
    pub setting: String,
    /// Median seconds (what the group's `time` says).
    pub time_s: f64,
    /// Error against the group's reference (None: not comparable).
    pub error: Option<f64>,
    /// On the group's Pareto front.
    pub pareto: bool,
    /// Everything else measured.
    pub details: Value,
}

/// Points that share a reference and an error metric, with their Pareto front.
#[derive(Debug, Clone, serde::Serialize)]
pub struct Group {
    /// Stable identifier (also the SVG file name).
    pub id: String,
    /// Heading.
    pub title: String,
    /// Scene file.
    pub scene: String,
    /// Image size.
    pub width: u32,
    /// Image size.
    pub height: u32,
    /// What every point is compared with.
    pub reference: String,
    /// What `time_s` covers.
    pub time: String,
    /// What `error` counts.
    pub error_metric: String,
    /// The configurations.
    pub points: Vec<Point>,
    /// Knobs not measured, with why.
    pub skipped: Vec<Value>,
    /// Group-level facts (e.g. raster == trace).
    pub facts: Value,
}

impl Group {
    /// Marks the non-dominated points (time, error); points without an error are never on it.
    pub fn mark_pareto(&mut self) {
        let pts: Vec<(f64, f64)> = self
            .points
            .iter()
            .map(|p| (p.time_s, p.error.unwrap_or(f64::NAN)))
            .collect();
        let front = pareto::front(&pts);
        for (i, p) in self.points.iter_mut().enumerate() {
            p.pareto = front.contains(&i);
        }
    }

    fn scatter_svg(&self) -> String {
        let pts: Vec<ScatterPoint> = self
            .points
            .iter()
            .filter_map(|p| {
                Some(ScatterPoint {
                    label: p.setting.clone(),
                    group: p.knob.clone(),
                    x: p.time_s,
                    y: p.error?,
                    pareto: p.pareto,
                })
            })
            .collect();
        scatter(
            &self.title,
            &format!("time, s ({})", self.time),
            &self.error_metric,
            &pts,
        )
    }
}

/// A point not yet ranked (the group marks its Pareto front at the end).
pub fn point(knob: &str, setting: &str, time_s: f64, error: Option<f64>, details: Value) -> Point {
    Point {
        knob: knob.into(),
        setting: setting.into(),
        time_s,
        error,
        pareto: false,
        details,
    }
}

/// Runs every knob and returns the JSON record, the page and the SVGs.
pub fn run(opts: &KnobsOptions) -> Result<super::Output> {
    let mut record = json!({
        "benchmark": "knobs",
        "environment": super::environment(),
        "config": {
            "runs": opts.common.runs,
            "quick": opts.common.quick,
            "threads": opts.threads,
            "scenes": opts.scenes.iter().map(|s| json!({"path": s.path, "size": s.size})).collect::<Vec<_>>(),
            "resolution_scales": opts.resolution_scales,
            "gi_scene": opts.gi_scene,
            "reference": opts.reference,
            "core_spp": opts.core_spp,
            "mitsuba_spp": opts.mitsuba_spp,
            "mitsuba_knob_spp": opts.mitsuba_knob_spp,
            "mitsuba_max_depth": opts.mitsuba_max_depth,
            "mitsuba_variants": opts.mitsuba_variants,
            "direct_scenes": opts.direct_scenes.iter().map(|s| json!({"path": s.path, "size": s.size})).collect::<Vec<_>>(),
            "supersample": opts.supersample,
            "drjit_libllvm_path": std::env::var("DRJIT_LIBLLVM_PATH").ok(),
            "seed": opts.seed,
            "timing": "median of `runs` timed runs after one untimed warm-up",
        },
    });
    let pool = super::pool(opts.threads)?;
    let mut groups = Vec::new();
    let mut resolution = Value::Null;
    for (i, spec) in opts.scenes.iter().enumerate() {
        let scene = spec
            .load()
            .with_context(|| format!("{}: cannot load", spec.path.display()))?;
        if i == 0 {
            // Every resolution of the table, before the first timed run.
            let (w0, h0) = (scene.camera.width, scene.camera.height);
            for &k in &opts.resolution_scales {
                scaled_size(w0, h0, k)?;
            }
        }
        rendiff::errln!(
            "knobs: visibility on {} ({}x{}, {} triangles)",
            spec.path.display(),
            scene.camera.width,
            scene.camera.height,
            scene.triangles.len()
        );
        let g = pool.install(|| visibility_group(spec, &scene, opts.common.runs));
        groups.push(g);
        if i == 0 {
            rendiff::errln!("knobs: resolution on {}", spec.path.display());
            resolution = pool.install(|| resolution_table(&scene, opts))?;
        }
    }
    let settings = super::direct::settings();
    for spec in &opts.direct_scenes {
        let d = super::direct::DirectOptions {
            spec,
            supersample: opts.supersample,
            settings: &settings,
            no_external: opts.no_external,
            runs: opts.common.runs,
            root: &opts.common.root,
            timeout_s: opts.common.timeout_s,
        };
        let g = pool
            .install(|| super::direct::direct_group(&d))
            .with_context(|| format!("{}: direct-lighting knobs", spec.path.display()))?;
        groups.push(g);
    }
    rendiff::errln!("knobs: radiance on {}", opts.gi_scene.display());
    let g = pool.install(|| super::spp::radiance_group(opts))?;
    groups.push(g);
    for g in &mut groups {
        g.mark_pareto();
    }
    record["groups"] = serde_json::to_value(&groups)?;
    record["resolution"] = resolution.clone();
    super::finish_environment(&mut record);
    let svgs: Vec<(String, String)> = groups
        .iter()
        .map(|g| (g.id.clone(), g.scatter_svg()))
        .collect();
    let html = page(&record, &groups, &resolution, &svgs);
    Ok(super::Output { record, html, svgs })
}

fn visibility_group(spec: &SceneSpec, scene: &ResolvedScene, runs: usize) -> Group {
    let cam = &scene.camera;
    let mut g = Group {
        id: format!("visibility-{}", spec.stem()),
        title: format!("visibility: {} {}x{}", spec.stem(), cam.width, cam.height),
        scene: spec.path.display().to_string(),
        width: cam.width,
        height: cam.height,
        reference: "core raster, exact predicates, same camera".into(),
        time:
            "raster: whole render; trace and Embree: BVH build + tracing, device creation excluded"
                .into(),
        error_metric: "id.prim mismatches (pixels)".into(),
        points: Vec::new(),
        skipped: Vec::new(),
        facts: json!({}),
    };
    let raster = measure::raster(scene, runs);
    let reference = &raster.last;
    g.points.push(point(
        "loop",
        "raster",
        raster.median_s,
        Some(0.0),
        json!({"timing": raster.json(), "counters": reference.counters, "note": "the reference itself"}),
    ));
    let mut all_identical = true;
    let mut medium: Option<TraceBvh> = None;
    let mut medium_build_s = f64::NAN;
    for q in [
        BvhQuality::Linear,
        BvhQuality::Fastest,
        BvhQuality::Fast,
        BvhQuality::Medium,
        BvhQuality::Slow,
    ] {
        let t = measure::trace(scene, q, runs);
        let e = visibility_error(reference, &t.trace.last);
        all_identical &= e.identical();
        let name = format!("{q:?}").to_lowercase();
        g.points.push(point(
            if q == BvhQuality::Medium {
                "loop"
            } else {
                "bvh quality"
            },
            &format!("trace, BVH {name}"),
            t.total_s(),
            Some(e.id_mismatches as f64),
            json!({"timing": t.json(), "vs_raster": e, "identical_to_raster": e.identical()}),
        ));
        if q == BvhQuality::Medium {
            medium_build_s = t.build.median_s;
            medium = Some(t.build.last);
        }
    }
    g.facts["raster_equals_trace_every_bvh"] = json!(all_identical);
    g.facts["exact_fallbacks_in_reference"] = json!(reference.counters.exact_fallbacks);
    g.facts["ties_in_reference"] = json!(reference.counters.ties);
    // Predicate precision: the same loops with the f64 value only.
    let mut fo = scene.clone();
    fo.camera.precision = Precision::FloatOnly;
    let r = measure::raster(&fo, runs);
    let er = visibility_error(reference, &r.last);
    g.points.push(point(
        "precision",
        "raster, float-only",
        r.median_s,
        Some(er.id_mismatches as f64),
        json!({"timing": r.json(), "vs_exact_raster": er, "speedup_vs_exact": raster.median_s / r.median_s}),
    ));
    if let Some(bvh) = &medium {
        let t = measure::trace_with(&fo, bvh, runs);
        let et = visibility_error(reference, &t.last);
        let self_consistent = visibility_error(&r.last, &t.last);
        g.points.push(point(
            "precision",
            "trace, float-only",
            medium_build_s + t.median_s,
            Some(et.id_mismatches as f64),
            json!({"timing": t.json(), "bvh_build_s": medium_build_s, "vs_exact_raster": et,
                   "float_only_raster_equals_trace": self_consistent.identical()}),
        ));
    }
    for mode in [EmbreeMode::Default, EmbreeMode::Robust] {
        for query in [EmbreeQuery::Single, EmbreeQuery::Packet8] {
            let name = measure::embree_name(mode, query);
            match measure::embree(scene, mode, query, runs) {
                Ok((f, st)) => {
                    let e = visibility_error(reference, &f);
                    g.points.push(point(
                        "embree",
                        &name,
                        st.build_plus_trace_s,
                        Some(e.id_mismatches as f64),
                        json!({"timing": st, "vs_raster": e,
                               "mrays_per_s": st.rays as f64 / st.trace_s / 1e6}),
                    ));
                }
                Err(EmbreeError::Unavailable(why)) => {
                    g.skipped.push(json!({"knob": name, "reason": why}));
                }
                Err(e) => g
                    .skipped
                    .push(json!({"knob": name, "reason": format!("error: {e}")})),
            }
        }
    }
    g
}

fn resolution_table(scene: &ResolvedScene, opts: &KnobsOptions) -> Result<Value> {
    let runs = opts.common.runs;
    let (w0, h0) = (scene.camera.width, scene.camera.height);
    let bvh = measure::trace(scene, BvhQuality::Medium, runs);
    let mut rows = Vec::new();
    for &k in &opts.resolution_scales {
        let (w, h) = scaled_size(w0, h0, k)?;
        let s = super::resized(scene, w, h)?;
        // The BVH depends on the eye only, not on the image size.
        let r = measure::raster(&s, runs);
        let t = measure::trace_with(&s, &bvh.build.last, runs);
        let px = f64::from(w) * f64::from(h);
        rows.push(json!({
            "scale": k, "width": w, "height": h, "pixels": px,
            "raster_s": r.median_s, "raster_ns_per_pixel": r.median_s / px * 1e9,
            "trace_s": t.median_s, "trace_ns_per_pixel": t.median_s / px * 1e9,
            "bvh_build_s": bvh.build.median_s,
            "raster_equals_trace": visibility_error(&r.last, &t.last).identical(),
            "raster_counters": r.last.counters, "trace_counters": t.last.counters,
        }));
    }
    Ok(json!({
        "scene": scene.source, "base": [w0, h0],
        "error": "none: a smaller image is a different image, not a wrong one; no Pareto rank",
        "rows": rows,
    }))
}

fn page(record: &Value, groups: &[Group], resolution: &Value, svgs: &[(String, String)]) -> String {
    let mut p = Page::new("rendiff bench knobs: speed versus accuracy");
    p.para("Every knob that trades time for accuracy, in one run, each against one reference. Times are medians after a warm-up; the Pareto front (ringed, joined by the dashed staircase) holds the settings that no other setting beats on both time and error.")
        .command("rendiff bench knobs");
    for (g, (name, svg)) in groups.iter().zip(svgs) {
        p.heading(&g.title);
        p.para(&format!(
            "Reference: {}. Time: {}. Error: {}.",
            g.reference, g.time, g.error_metric
        ));
        p.svg(svg, Some(&format!("knobs-{name}.svg")));
        let rows: Vec<Vec<String>> = g
            .points
            .iter()
            .map(|pt| {
                vec![
                    pt.knob.clone(),
                    pt.setting.clone(),
                    num(Some(pt.time_s), 4),
                    num(pt.error, 4),
                    if pt.pareto {
                        "yes".into()
                    } else {
                        String::new()
                    },
                    point_note(pt),
                ]
            })
            .collect();
        p.table(
            &["knob", "setting", "time (s)", "error", "Pareto", "notes"],
            &rows,
        );
        if let Some(f) = g.facts.as_object().filter(|m| !m.is_empty()) {
            let rows: Vec<Vec<String>> = f
                .iter()
                .map(|(k, v)| vec![k.clone(), super::page::compact(v)])
                .collect();
            p.table(&["fact", "value"], &rows);
        }
        for s in &g.skipped {
            p.note(&format!(
                "not measured: {}: {}",
                super::page::compact(&s["knob"]),
                super::page::compact(&s["reason"])
            ));
        }
    }
    if let Some(rows) = resolution["rows"].as_array() {
        p.heading("resolution");
        p.para(&format!(
            "Scene {} scaled from {}. {}",
            super::page::compact(&resolution["scene"]),
            super::page::compact(&resolution["base"]),
            super::page::compact(&resolution["error"])
        ));
        let t: Vec<Vec<String>> = rows
            .iter()
            .map(|r| {
                let f = |k: &str| r[k].as_f64();
                vec![
                    num(f("scale"), 3),
                    format!("{}x{}", r["width"], r["height"]),
                    num(f("raster_s"), 4),
                    num(f("raster_ns_per_pixel"), 4),
                    num(f("trace_s"), 4),
                    num(f("trace_ns_per_pixel"), 4),
                    num(f("bvh_build_s"), 4),
                    super::page::compact(&r["raster_equals_trace"]),
                ]
            })
            .collect();
        p.table(
            &[
                "scale",
                "size",
                "raster s",
                "raster ns/px",
                "trace s",
                "trace ns/px",
                "BVH build s (once)",
                "raster == trace",
            ],
            &t,
        );
    }
    p.environment(&record["environment"]);
    p.finish()
}

fn point_note(pt: &Point) -> String {
    let d = &pt.details;
    let mut notes = Vec::new();
    if let Some(n) = d["note"].as_str().filter(|n| !n.is_empty()) {
        notes.push(n.to_string());
    }
    for key in ["vs_raster", "vs_exact_raster"] {
        if let Some(v) = d.get(key) {
            notes.push(format!(
                "hit/miss {}, Z bits differ {}, max Z rel {}",
                super::page::compact(&v["mask_mismatches"]),
                super::page::compact(&v["z_bit_differences"]),
                num(v["max_z_rel"].as_f64(), 3)
            ));
        }
    }
    if let Some(b) = d["timing"]["build"]["median_s"].as_f64() {
        notes.push(format!("build {} s", num(Some(b), 3)));
    }
    if let Some(b) = d["timing"]["build_s"].as_f64() {
        notes.push(format!(
            "build {} s, trace {} s",
            num(Some(b), 3),
            num(d["timing"]["trace_s"].as_f64(), 3)
        ));
    }
    if let Some(e) = d["vs_contract_rmse"].as_f64() {
        notes.push(format!("RMSE vs pixel-center contract {}", num(Some(e), 3)));
    }
    if let Some(e) = d["error"]["relative_rmse"].as_f64() {
        notes.push(format!("relative RMSE {}", num(Some(e), 3)));
    }
    if let Some(e) = d["error"]["rmse_over_expected"].as_f64() {
        notes.push(format!("RMSE / noise-only RMSE {}", num(Some(e), 3)));
    }
    if let Some(e) = d["timing"]["subprocess_wall_s_median"].as_f64() {
        notes.push(format!("subprocess wall {} s", num(Some(e), 3)));
    }
    notes.join("; ")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn scene_specs_parse() {
        let s: SceneSpec = "scenes/a.toml@64x48".parse().unwrap();
        assert_eq!(s.size, Some((64, 48)));
        assert_eq!(s.stem(), "a");
        let s: SceneSpec = "scenes/a.toml".parse().unwrap();
        assert_eq!(s.size, None);
        assert!("a.toml@0x4".parse::<SceneSpec>().is_err());
    }
}

//! `bench peers`' two tables (issue 39): what a user of each renderer pays.
//!
//! - *Per frame*: another frame of the same scene from a new camera. Both
//!   sides make their rays inside their timed frame: Embree's f32 rays are
//!   made strip by strip right before each strip is traced
//!   ([`NativeScene::trace_made`]), the core makes its own inside its timed
//!   queries. Embree's BVH does not depend on the camera, so its "new
//!   camera" cost is zero; the core's tree needs a camera set-up
//!   ([`TraceBvh::aim`]: eye-relative node boxes, per-triangle edge data and
//!   pixel rectangles, packet frustum planes), timed as its own column and
//!   counted in the per-frame ratio. Embree's trace alone, on the same rays
//!   prepared outside timing, is timed in the same rounds and kept beside.
//! - *Time to first image*: the scene in memory to the frame's buffers out,
//!   every build and set-up included: the core raster, the core tracer at
//!   each BVH quality (its tree and camera set-up recorded apart), and the
//!   native driver's configuration with the least build + trace (its build,
//!   its rays made and traced, and frame assembly).
//!
//! Every ratio comes from paired rounds in alternating order
//! ([`alternate_all`]) with a bootstrap interval
//! ([`measure::bootstrap_median_interval`]) on the median of the per-round
//! ratios.

use super::measure::{self, BOOTSTRAP_SEED};
use super::native_embree::{CameraRays, Config, Hits, NativeScene, PreparedRays};
use super::page::{compact, num, Page};
use rendiff::names::Named;
use rendiff::raster::{self, RasterOptions};
use rendiff::render::{Backend, RenderOptions};
use rendiff::scene::resolve::ResolvedScene;
use rendiff::trace::{self, BvhQuality, TraceBvh, TraceOptions};
use serde_json::{json, Map, Value};
use std::time::Instant;

/// One untimed call of each contender, then `rounds` rounds, each running
/// every contender once: in the listed order in even rounds, reversed in odd
/// ones (ABBA for two; ABC CBA for three), so a drift linear over two rounds
/// hits every contender alike. Each call returns the seconds of its own
/// timed phase; the result has one series per contender, in round order.
pub fn alternate_all(rounds: usize, contenders: &mut [&mut dyn FnMut() -> f64]) -> Vec<Vec<f64>> {
    for c in contenders.iter_mut() {
        c();
    }
    let n = contenders.len();
    let mut out = vec![Vec::with_capacity(rounds); n];
    for round in 0..rounds.max(1) {
        for k in 0..n {
            let i = if round % 2 == 0 { k } else { n - 1 - k };
            out[i].push(contenders[i]());
        }
    }
    out
}

/// Median and 95% bootstrap interval of per-round ratios, as JSON.
fn ratio_json(ratios: &[f64]) -> Value {
    json!({
        "median": super::median(ratios),
        "interval_95": measure::bootstrap_median_interval(ratios, BOOTSTRAP_SEED),
        "per_round": ratios,
    })
}

/// Per-round ratios `num[i] / den[i]` (a speed ratio when both are times:
/// above 1, the `den` side is faster).
fn per_round(num: &[f64], den: &[f64]) -> Vec<f64> {
    num.iter().zip(den).map(|(n, d)| n / d).collect()
}

/// The per-frame table's arithmetic, from paired rounds: the core's camera
/// set-up and trace seconds and Embree's trace seconds per round (the same
/// rays per frame on both sides). The headline ratio counts the core's new
/// camera: Embree's seconds over the core's set-up plus trace, per round,
/// then the median; the trace-only ratio is kept beside it.
pub fn per_frame_summary(camera_s: &[f64], trace_s: &[f64], embree_s: &[f64], rays: u64) -> Value {
    let frame_s: Vec<f64> = camera_s.iter().zip(trace_s).map(|(c, t)| c + t).collect();
    let mrays = |s: &[f64]| rays as f64 / super::median(s) / 1e6;
    json!({
        "rounds": trace_s.len(),
        "rays_per_frame": rays,
        "core": {
            "new_camera_s": camera_s, "trace_s": trace_s, "frame_with_new_camera_s": frame_s,
            "new_camera_s_median": super::median(camera_s),
            "trace_s_median": super::median(trace_s),
            "frame_with_new_camera_s_median": super::median(&frame_s),
            "mrays_per_s": mrays(trace_s),
            "mrays_per_s_new_camera_counted": mrays(&frame_s),
        },
        "embree": {
            "new_camera_s_median": 0.0, "trace_s": embree_s,
            "trace_s_median": super::median(embree_s),
            "mrays_per_s": mrays(embree_s),
        },
        "core_over_embree_new_camera_counted": ratio_json(&per_round(embree_s, &frame_s)),
        "core_over_embree_same_camera": ratio_json(&per_round(embree_s, trace_s)),
    })
}

/// The native driver's configuration a time-to-first-image user would pick:
/// the least build + trace over the sweep's rows (`rows` keyed by
/// [`Config::name`], each with `timing.build_s` and `timing.trace_s`).
pub fn least_build_plus_trace(rows: &Map<String, Value>) -> Option<(Config, f64)> {
    Config::all()
        .into_iter()
        .filter_map(|c| {
            let t = &rows.get(&c.name())?["timing"];
            Some((c, t["build_s"].as_f64()? + t["trace_s"].as_f64()?))
        })
        .min_by(|a, b| a.1.total_cmp(&b.1))
}

/// The per-frame table on one scene at rayon's current pool: the core's
/// new camera ([`TraceBvh::aim`]) and queries through `bvh`, the native
/// driver's `config` making its rays inside the timed call
/// ([`NativeScene::trace_made`]), and the same on `rays` prepared outside
/// it (the trace alone), in alternating rounds.
pub fn per_frame(
    scene: &ResolvedScene,
    bvh: &mut TraceBvh,
    quality: BvhQuality,
    native: Option<(&NativeScene, &PreparedRays, Config, f64)>,
    rounds: usize,
) -> Value {
    let Some((built, rays, config, prepare_s)) = native else {
        return json!({"skipped": "the native Embree driver is unavailable"});
    };
    let opts = TraceOptions::default();
    let made = CameraRays::new(&scene.camera);
    let mut hits = Hits::for_camera(&made);
    let mut prepared_hits = Hits::new(rays);
    let (mut camera_s, mut trace_s) = (Vec::new(), Vec::new());
    let mut core = || {
        let c = bvh.aim(scene);
        let t0 = Instant::now();
        let keys = trace::trace_keys(scene, bvh, opts, &|_| {});
        let t = t0.elapsed().as_secs_f64();
        std::hint::black_box(keys);
        camera_s.push(c);
        trace_s.push(t);
        c + t
    };
    let mut embree = || built.trace_made(&made, config.entry, config.coherent, &mut hits);
    let mut embree_alone = || built.trace(rays, config.entry, config.coherent, &mut prepared_hits);
    let series = alternate_all(rounds, &mut [&mut core, &mut embree, &mut embree_alone]);
    // The warm-up's entries are dropped: the series hold the timed rounds.
    let skip = camera_s.len() - series[0].len();
    let mut v = per_frame_summary(
        &camera_s[skip..],
        &trace_s[skip..],
        &series[1],
        rays.len() as u64,
    );
    v["core"]["bvh_quality"] = json!(quality.name());
    v["core"]["rays"] = json!("made inside the timed queries from the camera (f64 pixel rays)");
    v["embree"]["config"] = json!(config.name());
    v["embree"]["entry_point"] = json!(config.entry.entry_point());
    v["embree"]["rays"] = json!(
        "made inside the timed region, strip by strip, from the camera (the core's f64 pixel rays rounded to f32), as the core makes its own"
    );
    v["embree"]["trace_alone_s"] = json!(series[2]);
    v["embree"]["trace_alone_s_median"] = json!(super::median(&series[2]));
    v["embree"]["trace_alone"] = json!(
        "the same configuration on the same rays prepared once per camera outside the timed region (rays_prepared_s, not counted): what making the rays adds is the difference"
    );
    v["embree"]["rays_prepared_s"] = json!(prepare_s);
    v["order"] = json!("alternating: core, Embree, Embree on prepared rays in even rounds, the reverse in odd ones, after one untimed frame of each");
    v
}

/// The time-to-first-image table on one scene at rayon's current pool
/// (`threads` threads): every contender from the scene in memory to its
/// frame's buffers, in alternating rounds; each ratio is Embree's
/// configuration with the least build + trace over the contender's time.
pub fn first_image(
    scene: &ResolvedScene,
    threads: usize,
    native: Option<Config>,
    rounds: usize,
) -> Value {
    // Each contender's sub-timings per call (the warm-up's first), by index.
    let parts = std::cell::RefCell::new(vec![
        Vec::<Map<String, Value>>::new();
        3 + BvhQuality::ALL.len()
    ]);
    let parts = &parts;
    let mut names: Vec<String> = vec!["core raster".into()];
    let mut contenders: Vec<Box<dyn FnMut() -> f64 + '_>> = Vec::new();
    contenders.push(Box::new(move || {
        let t0 = Instant::now();
        let f = raster::render(scene, RasterOptions::default(), &|_| {});
        let s = t0.elapsed().as_secs_f64();
        std::hint::black_box(f);
        parts.borrow_mut()[0].push(Map::new());
        s
    }));
    // What `render --renderer core` runs: the cost model's decision (its
    // pass over the scene) and then the loop it picks, all timed.
    names.push(COST_MODEL_PICK_ROW.into());
    contenders.push(Box::new(move || {
        let t0 = Instant::now();
        let (backend, _) = rendiff::render::core_loop(scene, threads);
        let decide_s = t0.elapsed().as_secs_f64();
        let f = rendiff::render::render(scene, backend, RenderOptions::default(), &|_| {});
        let s = t0.elapsed().as_secs_f64();
        // A render that did not happen is no time: a NaN round shows it.
        let Ok(f) = f else { return f64::NAN };
        std::hint::black_box(f);
        let mut m = Map::new();
        m.insert("decide_s".into(), json!(decide_s));
        m.insert("loop".into(), json!(backend.name()));
        parts.borrow_mut()[1].push(m);
        s
    }));
    for &q in BvhQuality::ALL {
        names.push(format!("core trace ({} BVH)", q.name()));
        let i = contenders.len();
        contenders.push(Box::new(move || {
            let t0 = Instant::now();
            let bvh = TraceBvh::build(scene, q);
            let f = trace::render_with_bvh(scene, &bvh, TraceOptions::default(), &|_| {});
            let s = t0.elapsed().as_secs_f64();
            std::hint::black_box(f);
            let mut m = Map::new();
            m.insert("tree_s".into(), json!(bvh.tree_seconds));
            m.insert("camera_setup_s".into(), json!(bvh.camera_seconds));
            parts.borrow_mut()[i].push(m);
            s
        }));
    }
    let embree_index = native.map(|config| {
        names.push(format!("embree ({})", config.name()));
        let i = contenders.len();
        contenders.push(Box::new(move || {
            let t0 = Instant::now();
            let built = match NativeScene::build(scene, config.quality, false, threads) {
                Ok(b) => b,
                // Unreachable after the sweep built it; a NaN round shows it.
                Err(_) => return f64::NAN,
            };
            let tb = t0.elapsed().as_secs_f64();
            let rays = CameraRays::new(&scene.camera);
            let mut hits = Hits::for_camera(&rays);
            let trace_s = built.trace_made(&rays, config.entry, config.coherent, &mut hits);
            let tt = t0.elapsed().as_secs_f64();
            let (f, _) = hits.frame_made(scene, &rays);
            let s = t0.elapsed().as_secs_f64();
            std::hint::black_box(f);
            let mut m = Map::new();
            m.insert("build_s".into(), json!(tb));
            m.insert("rays_and_trace_s".into(), json!(trace_s));
            m.insert("frame_s".into(), json!(s - tt));
            parts.borrow_mut()[i].push(m);
            s
        }));
        i
    });
    let mut refs: Vec<&mut dyn FnMut() -> f64> = contenders
        .iter_mut()
        .map(|b| &mut **b as &mut dyn FnMut() -> f64)
        .collect();
    let series = alternate_all(rounds, &mut refs);
    drop(refs);
    drop(contenders);
    let parts = parts.borrow();
    first_image_summary(scene, threads, &names, &series, &parts, embree_index)
}

/// The time-to-first-image record from the rounds: each contender's
/// seconds, their medians and sub-timings (the untimed warm-up's dropped),
/// its ratio against Embree and the raster's against every tracer.
pub fn first_image_summary(
    scene: &ResolvedScene,
    threads: usize,
    names: &[String],
    series: &[Vec<f64>],
    parts: &[Vec<Map<String, Value>>],
    embree: Option<usize>,
) -> Value {
    let mut rows = Vec::new();
    for (i, name) in names.iter().enumerate() {
        let s = &series[i];
        let skip = parts[i].len().saturating_sub(s.len());
        let mut sub = Map::new();
        for m in &parts[i][skip..] {
            for (k, v) in m {
                if let Some(a) = sub
                    .entry(k.clone())
                    .or_insert_with(|| json!([]))
                    .as_array_mut()
                {
                    a.push(v.clone());
                }
            }
        }
        // Medians of the numeric parts (not of a label such as the loop run).
        let sub_medians: Map<String, Value> = sub
            .iter()
            .filter_map(|(k, v)| {
                let xs: Vec<f64> = v
                    .as_array()
                    .into_iter()
                    .flatten()
                    .filter_map(Value::as_f64)
                    .collect();
                (!xs.is_empty()).then(|| (k.clone(), json!(super::median(&xs))))
            })
            .collect();
        let mut row = json!({
            "name": name, "seconds": s, "median_s": super::median(s),
            "parts_s": sub, "parts_median_s": sub_medians,
        });
        if let Some(e) = embree.filter(|&e| e != i) {
            row["over_embree"] = ratio_json(&per_round(&series[e], s));
        }
        if i > 0 && name.starts_with("core trace") {
            row["raster_over_this"] = ratio_json(&per_round(s, &series[0]));
        }
        rows.push(row);
    }
    // The loop `render --renderer core` runs here, by the cost model (its
    // row alone, without the decision, is `cost_model_loop`).
    // The same call as the row's, so the decision has one spelling here.
    let (backend, choice) = rendiff::render::core_loop(scene, threads);
    let picked_loop = match backend {
        Backend::Raster => "core raster".to_string(),
        Backend::Trace => format!("core trace ({} BVH)", BvhQuality::default().name()),
        Backend::Embree(_) => unreachable!("core_loop picks one of the core's loops"),
    };
    json!({
        "threads": threads,
        "rounds": series.first().map_or(0, Vec::len),
        "order": "alternating: the listed order in even rounds, reversed in odd ones, after one untimed run of each",
        "includes": "scene in memory to the frame's buffers (depth, IDs, normals): the raster whole; the cost model's pick with its decision (a pass over the scene's vertices) and the loop it picks; the tracer's BVH build (tree, then camera set-up) and trace; Embree's device and BVH build, f32 rays made and traced, keys and buffers",
        "rows": rows,
        "embree": embree.map(|e| names[e].clone()),
        "cost_model_pick": COST_MODEL_PICK_ROW,
        "cost_model_loop": picked_loop,
        "cost_model": choice,
    })
}

/// The time-to-first-image row of `render --renderer core`: the cost
/// model's decision, then the loop it picks (`rendiff::render::core_loop`).
pub const COST_MODEL_PICK_ROW: &str = "core, the cost model's pick (decision included)";

/// Side of the square image of the two-screen-filling-triangles check.
const TWO_TRIANGLES_SIZE: u32 = 1024;

/// The raster against the tracer on two triangles filling the image
/// ([`super::crossover::grid_scene`] with one cell), where the raster has
/// the least work per pixel, in alternating rounds on rayon's current pool,
/// twice: each from the scene in memory to its frame (the tracer's BVH build
/// included), and the visibility passes alone (the BVH built before, as
/// `bench crossover` and the README's goal, "raster at least 10x the tracer",
/// measure them: the frame's buffers, the same work for both loops, dilute the
/// first-image ratio).
pub fn two_triangles(threads: usize, rounds: usize) -> Value {
    let scene = match super::crossover::grid_scene(1, TWO_TRIANGLES_SIZE, false) {
        Ok(s) => s,
        Err(e) => return json!({"skipped": format!("{e:#}")}),
    };
    let mut raster = || {
        let t0 = Instant::now();
        std::hint::black_box(raster::render(&scene, RasterOptions::default(), &|_| {}));
        t0.elapsed().as_secs_f64()
    };
    let mut tracer = || {
        let t0 = Instant::now();
        let bvh = TraceBvh::build(&scene, BvhQuality::default());
        std::hint::black_box(trace::render_with_bvh(
            &scene,
            &bvh,
            TraceOptions::default(),
            &|_| {},
        ));
        t0.elapsed().as_secs_f64()
    };
    let s = alternate_all(rounds, &mut [&mut raster, &mut tracer]);
    let bvh = TraceBvh::build(&scene, BvhQuality::default());
    let passes = measure::raster_vs_trace(&scene, &bvh, rounds);
    let seconds = |k: &str| -> Vec<f64> {
        passes[k]
            .as_array()
            .into_iter()
            .flatten()
            .filter_map(Value::as_f64)
            .collect()
    };
    let (raster_pass, trace_pass) = (seconds("raster_keys_s"), seconds("trace_keys_s"));
    json!({
        "threads": threads, "size": TWO_TRIANGLES_SIZE, "triangles": scene.triangles.len(),
        "raster_s": s[0], "trace_s": s[1],
        "includes": "scene in memory to the frame's buffers; the tracer's BVH build (its default quality) and camera set-up included",
        "raster_over_trace": ratio_json(&per_round(&s[1], &s[0])),
        "pass": {
            "raster_keys_s": raster_pass, "trace_keys_s": trace_pass,
            "includes": "the visibility passes alone (keys), the BVH built and its leaves set up before",
            "raster_over_trace": ratio_json(&per_round(&trace_pass, &raster_pass)),
        },
    })
}

/// A harness renderer's time to first image (all CPUs, its own threads):
/// `runs` renders of the exported scene, each subprocess's wall time and the
/// harness's `time_s` (the backend's render call) recorded.
pub fn external(
    h: &super::harness::Harness,
    backend: &str,
    resolved: &std::path::Path,
    runs: usize,
) -> Value {
    let out = h.scratch.join(format!("first-image-{backend}.exr"));
    let (mut wall, mut call) = (Vec::new(), Vec::new());
    for _ in 0..runs.max(1) {
        match h.render(backend, resolved, &out) {
            Ok(r) => {
                wall.push(r.wall_s);
                call.push(r.time_s.unwrap_or(f64::NAN));
            }
            Err(why) => return json!({"skipped": why}),
        }
    }
    json!({
        "backend": backend, "runs": wall.len(),
        "render_call_s": call, "render_call_s_median": super::median(&call),
        "subprocess_wall_s": wall, "subprocess_wall_s_median": super::median(&wall),
        "includes": "render_call_s: the harness's time_s, the backend's render call: reading the exported scene, the renderer's own scene and BVH build, the render and writing the EXR (Python start-up and imports excluded); subprocess_wall_s: the whole harness process",
        "paired": "no: an external process on all CPUs, run after the paired rounds; no ratio is formed",
    })
}

/// A goal row: the measured median ratio and its interval against the
/// target, "met" when the median reaches it (the interval says how sure).
pub fn goal(what: &str, ratio: &Value, target: f64) -> Value {
    let m = ratio["median"].as_f64();
    let lo = ratio["interval_95"][0].as_f64();
    json!({
        "what": what, "target": target, "median": m, "interval_95": ratio["interval_95"],
        "verdict": match m {
            Some(x) if x >= target => "met",
            Some(_) => "not met",
            None => "not measured",
        },
        "interval_clears_target": lo.map(|l| l >= target),
    })
}

/// The issue-39 goals from a scene's per-thread rows (`per_frame`,
/// `time_to_first_image`), labelled with the scene: core per frame with the
/// new camera counted >= 1x Embree's best; core trace's first image (the
/// default BVH) >= 1x Embree's least build + trace; the loop the cost model
/// picks >= 5x; the raster faster than the tracer.
pub fn goals_of(scene: &str, rows: &[Value]) -> Vec<Value> {
    let mut out = Vec::new();
    let trace_default = format!("core trace ({} BVH)", BvhQuality::default().name());
    for r in rows {
        let th = &r["threads"];
        let pf = &r["per_frame"]["core_over_embree_new_camera_counted"];
        let mut g = goal(
            &format!(
                "{scene}, {th} thread(s), per frame: core (new camera counted) / Embree's best"
            ),
            pf,
            1.0,
        );
        g["table"] = json!("per frame");
        out.push(g);
        let t = &r["time_to_first_image"];
        let row = |name: &str| {
            t["rows"]
                .as_array()
                .into_iter()
                .flatten()
                .find(|x| x["name"] == name)
                .cloned()
                .unwrap_or(Value::Null)
        };
        let pick = t["cost_model_pick"].as_str().unwrap_or("");
        for (what, name, target, key) in [
            (
                "core trace (its default BVH) / Embree's least build + trace",
                trace_default.as_str(),
                1.0,
                "over_embree",
            ),
            (
                "the loop the cost model picks / Embree's least build + trace",
                pick,
                5.0,
                "over_embree",
            ),
            (
                "core raster / core trace (its default BVH)",
                trace_default.as_str(),
                1.0,
                "raster_over_this",
            ),
        ] {
            let mut g = goal(
                &format!("{scene}, {th} thread(s), time to first image: {what}"),
                &row(name)[key],
                target,
            );
            g["table"] = json!("time to first image");
            g["row"] = json!(name);
            out.push(g);
        }
    }
    out
}

/// "x [lo, hi]" of a recorded ratio (median and interval).
pub fn ratio_text(r: &Value) -> String {
    let iv = &r["interval_95"];
    match (iv[0].as_f64(), iv[1].as_f64()) {
        (Some(lo), Some(hi)) => format!(
            "{} [{}, {}]",
            num(r["median"].as_f64(), 3),
            num(Some(lo), 3),
            num(Some(hi), 3)
        ),
        _ => format!("{} (no interval)", num(r["median"].as_f64(), 3)),
    }
}

/// One scene's two tables on the page: per frame, then time to first image,
/// each thread count's rows with their ratios and intervals.
pub fn page_tables(p: &mut Page, scene: &str, per_threads: &Value) {
    let rows_of = || per_threads.as_array().into_iter().flatten();
    p.heading(&format!("per frame table: {scene}"));
    p.para("A new frame of the same scene from a new camera. Embree: its fastest configuration in the native driver, no camera set-up, its f32 rays made strip by strip inside its timed frame (its trace alone, on rays prepared outside timing, is shown beside). Core: its camera set-up (eye-relative node boxes, edge data, pixel rectangles, frustum planes) timed as \"new camera\", its rays made inside its timed queries. Ratios are Embree's seconds over the core's per round (above 1: the core is faster), median with 95% bootstrap interval.");
    let mut rows = Vec::new();
    for r in rows_of() {
        let th = compact(&r["threads"]);
        let f = &r["per_frame"];
        if let Some(why) = f["skipped"].as_str() {
            rows.push(vec![
                th,
                "not measured".into(),
                why.into(),
                String::new(),
                String::new(),
                String::new(),
            ]);
            continue;
        }
        rows.push(vec![
            th.clone(),
            format!("core trace ({} BVH)", compact(&f["core"]["bvh_quality"])),
            num(f["core"]["new_camera_s_median"].as_f64(), 4),
            num(f["core"]["trace_s_median"].as_f64(), 4),
            num(f["core"]["frame_with_new_camera_s_median"].as_f64(), 4),
            format!(
                "{} new camera counted; {} same camera",
                ratio_text(&f["core_over_embree_new_camera_counted"]),
                ratio_text(&f["core_over_embree_same_camera"])
            ),
        ]);
        rows.push(vec![
            th,
            format!("embree {}", compact(&f["embree"]["config"])),
            "0".into(),
            num(f["embree"]["trace_s_median"].as_f64(), 4),
            num(f["embree"]["trace_s_median"].as_f64(), 4),
            format!(
                "rays made inside its frame; on rays prepared outside it, {} s",
                num(f["embree"]["trace_alone_s_median"].as_f64(), 4)
            ),
        ]);
    }
    p.table(
        &[
            "threads",
            "renderer",
            "new camera s",
            "frame s",
            "frame + new camera s",
            "core / Embree (rounds' median [95%])",
        ],
        &rows,
    );
    p.heading(&format!("time to first image table: {scene}"));
    p.para("The scene in memory to the frame's buffers (depth, IDs, normals), every build and set-up included. Embree: the native driver's configuration with the least build + trace in the sweep (device, BVH build, f32 rays made and traced, keys and buffers). Ratios: Embree's seconds over the row's per round (above 1: the row is sooner).");
    let mut rows = Vec::new();
    for r in rows_of() {
        let t = &r["time_to_first_image"];
        let th = compact(&r["threads"]);
        for row in t["rows"].as_array().into_iter().flatten() {
            let name = row["name"].as_str().unwrap_or("");
            let mark = if Some(name) == t["cost_model_loop"].as_str() {
                " (the loop the cost model picks, without its decision)"
            } else {
                ""
            };
            rows.push(vec![
                th.clone(),
                format!("{name}{mark}"),
                num(row["median_s"].as_f64(), 4),
                compact(&row["parts_median_s"]),
                if row["over_embree"].is_object() {
                    ratio_text(&row["over_embree"])
                } else {
                    "-".into()
                },
                if row["raster_over_this"].is_object() {
                    ratio_text(&row["raster_over_this"])
                } else {
                    "-".into()
                },
            ]);
        }
        if t["embree"].is_null() {
            p.note(&format!(
                "{th} thread(s): no Embree row (native driver unavailable), so no ratio against it"
            ));
        }
    }
    p.table(
        &[
            "threads",
            "renderer",
            "seconds (median)",
            "parts (medians, s)",
            "this / Embree",
            "raster / this",
        ],
        &rows,
    );
}

/// The goals section: every issue-39 goal with its table, value, interval,
/// target and verdict.
pub fn page_goals(p: &mut Page, goals: &Value) {
    p.heading("issue 39 goals (measured, never fitted)");
    let rows: Vec<Vec<String>> = goals
        .as_array()
        .into_iter()
        .flatten()
        .map(|g| {
            vec![
                compact(&g["table"]),
                compact(&g["what"]),
                ratio_text(g),
                num(g["target"].as_f64(), 2),
                compact(&g["verdict"]),
            ]
        })
        .collect();
    p.table(
        &["table", "goal", "measured [95%]", "target", "verdict"],
        &rows,
    );
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Listed order in even rounds, reversed in odd ones, after one warm-up
    /// of each; the series come back per contender in round order.
    #[test]
    fn alternate_all_reverses_the_order_every_other_round() {
        let log = std::cell::RefCell::new(String::new());
        let tick = |c: char| {
            log.borrow_mut().push(c);
            log.borrow().len() as f64
        };
        let (mut a, mut b, mut c) = (|| tick('a'), || tick('b'), || tick('c'));
        let s = alternate_all(3, &mut [&mut a, &mut b, &mut c]);
        assert_eq!(log.into_inner(), "abcabccbaabc");
        assert_eq!(
            s,
            vec![
                vec![4.0, 9.0, 10.0],
                vec![5.0, 8.0, 11.0],
                vec![6.0, 7.0, 12.0]
            ]
        );
        // Two contenders: the ABBA order of `measure::alternate`.
        let log = std::cell::RefCell::new(String::new());
        let tick = |c: char| {
            log.borrow_mut().push(c);
            0.0
        };
        let (mut a, mut b) = (|| tick('a'), || tick('b'));
        alternate_all(4, &mut [&mut a, &mut b]);
        assert_eq!(log.into_inner(), "ababbaabba");
    }

    /// The per-frame ratio counts the core's new camera round by round:
    /// Embree's seconds over the core's set-up plus trace, then the median
    /// (here 1, 0.5, 0.25 -> 0.5), not the trace alone (2, 1, 0.5 -> 1) nor
    /// a ratio of medians; Embree's new camera is zero.
    #[test]
    fn per_frame_ratio_counts_the_new_camera() {
        let v = per_frame_summary(&[1.0, 2.0, 4.0], &[1.0, 2.0, 4.0], &[2.0, 2.0, 2.0], 100);
        let counted = &v["core_over_embree_new_camera_counted"];
        assert_eq!(counted["per_round"], json!([1.0, 0.5, 0.25]));
        assert_eq!(counted["median"], 0.5);
        let same = &v["core_over_embree_same_camera"];
        assert_eq!(same["median"], 1.0);
        assert_eq!(v["embree"]["new_camera_s_median"], 0.0);
        assert_eq!(v["core"]["new_camera_s_median"], 2.0);
        assert_eq!(v["core"]["frame_with_new_camera_s_median"], 4.0);
        // 100 rays in the median frame of 4 s counted, 2 s not.
        assert_eq!(
            v["core"]["mrays_per_s_new_camera_counted"],
            100.0 / 4.0 / 1e6
        );
        assert_eq!(v["core"]["mrays_per_s"], 100.0 / 2.0 / 1e6);
        // Every ratio has its interval, bracketing the median.
        let [lo, hi] = [0, 1].map(|i| counted["interval_95"][i].as_f64().unwrap());
        assert!(lo <= 0.5 && 0.5 <= hi, "{lo}..{hi}");
        // A free camera set-up leaves the trace-only ratio.
        let free = per_frame_summary(&[0.0; 3], &[1.0, 2.0, 4.0], &[2.0; 3], 100);
        assert_eq!(
            free["core_over_embree_new_camera_counted"]["median"],
            free["core_over_embree_same_camera"]["median"]
        );
    }

    /// Embree's time-to-first-image configuration is the least build +
    /// trace, not the fastest trace.
    #[test]
    fn first_image_picks_the_least_build_plus_trace() {
        let all = Config::all();
        let (fast_trace, cheap_build) = (all[0], all[all.len() - 1]);
        let mut rows = Map::new();
        rows.insert(
            fast_trace.name(),
            json!({"timing": {"build_s": 2.0, "trace_s": 0.1}}),
        );
        rows.insert(
            cheap_build.name(),
            json!({"timing": {"build_s": 0.5, "trace_s": 0.3}}),
        );
        rows.insert(
            "not a config".into(),
            json!({"timing": {"build_s": 0.0, "trace_s": 0.0}}),
        );
        let (c, s) = least_build_plus_trace(&rows).unwrap();
        assert_eq!((c, s), (cheap_build, 0.8));
        assert_eq!(least_build_plus_trace(&Map::new()), None);
    }

    /// Each contender's ratio against Embree is per round (Embree's seconds
    /// over its own), the warm-up's sub-timings are dropped, and the
    /// raster's ratio against each tracer is kept.
    #[test]
    fn first_image_ratios_are_paired_per_round() {
        let scene = ResolvedScene::from_triangles(
            rendiff::camera::Camera::new(
                glam::DVec3::new(0.0, 0.0, 3.0),
                glam::DVec3::ZERO,
                glam::DVec3::Y,
                40.0,
                8,
                8,
                0.1,
                f64::INFINITY,
            )
            .unwrap(),
            vec![[
                glam::Vec3::new(-1.0, -1.0, 0.0),
                glam::Vec3::new(1.0, -1.0, 0.0),
                glam::Vec3::new(0.0, 1.0, 0.0),
            ]],
        );
        let names: Vec<String> = ["core raster", "core trace (medium BVH)", "embree (x)"]
            .map(String::from)
            .to_vec();
        let series = vec![
            vec![1.0, 1.0, 1.0],
            vec![4.0, 2.0, 8.0],
            vec![2.0, 2.0, 4.0],
        ];
        let part = |x: f64| {
            let mut m = Map::new();
            m.insert("tree_s".into(), json!(x));
            m
        };
        // Four entries: the warm-up's (99) first, then the three rounds'.
        let parts = vec![
            vec![Map::new(); 4],
            vec![part(99.0), part(1.0), part(3.0), part(2.0)],
            vec![Map::new(); 4],
        ];
        let v = first_image_summary(&scene, 1, &names, &series, &parts, Some(2));
        let rows = v["rows"].as_array().unwrap();
        assert_eq!(rows[1]["over_embree"]["per_round"], json!([0.5, 1.0, 0.5]));
        assert_eq!(rows[1]["over_embree"]["median"], 0.5);
        assert_eq!(rows[0]["over_embree"]["per_round"], json!([2.0, 2.0, 4.0]));
        assert_eq!(rows[1]["raster_over_this"]["median"], 4.0);
        assert_eq!(rows[1]["parts_s"]["tree_s"], json!([1.0, 3.0, 2.0]));
        assert_eq!(rows[1]["parts_median_s"]["tree_s"], 2.0);
        assert!(rows[2].get("over_embree").is_none());
        assert_eq!(v["rounds"], 3);
        // The goal's row is the one that times the decision too; the loop
        // it picks is named beside it (this one-triangle scene: the raster).
        assert_eq!(v["cost_model_pick"], COST_MODEL_PICK_ROW);
        assert_eq!(v["cost_model_loop"], "core raster");
    }
}

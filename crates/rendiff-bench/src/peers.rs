//! `rendiff bench peers`: the core next to established renderers on identical
//! work, in one run, as ratios.
//!
//! - Trace throughput: core trace vs Embree on the same primary rays (Embree
//!   traces the core's own pixel rays), per thread count, through every Embree
//!   entry point that fits primary rays (rtcIntersect1/4/8/16, the 1M and NM
//!   streams) with both intersect-context flags (incoherent, coherent) and
//!   both scene flags (default, robust). Every row is kept; the fastest is
//!   named and the core's ratio against it reported, so the core is compared
//!   with Embree at its best, not at a convenient setting. BVH builds are
//!   excluded from Mrays/s and recorded beside it. Both the core and Embree
//!   allocate their key buffer per frame, so freed memory is kept in the
//!   process ([`super::keep_freed_memory`], recorded as `config.allocator`):
//!   neither pays 16 MB of fresh-page faults per 1080p frame, and neither's
//!   time depends on what the allocator happened to return to the system.
//! - Embree at its own best: a native driver ([`super::native_embree`], C
//!   against Embree's headers) runs every entry point, context flag and
//!   build quality on the same rays in the same run; the binding's fastest
//!   row is checked against the driver's fastest in paired rounds (red on
//!   the page beyond 5%), and the headline takes the fastest row of either,
//!   its ratio from paired rounds in alternating order with a bootstrap
//!   interval (docs/embree-fastest-path.md).
//! - Raster: core raster vs pyrender (OpenGL on Mesa llvmpipe), depth + IDs;
//!   pyrender's time is its own per-pass sub-timing (scene upload, draw and
//!   read-back; Python start-up excluded), and a one-triangle render's
//!   subprocess time is recorded as the start-up it excludes.
//! - Path tracing at equal time: Mitsuba at a fixed spp, the core at the spp
//!   that takes as long; both errors against the cached reference.

use super::harness::{number_at, Harness};
use super::knobs::SceneSpec;
use super::native_embree::{self, Config, NativeScene, PreparedRays, Quality};
use super::page::{num, Page};
use super::peer_tables;
use super::spp::{core_path, mitsuba_path, MitsubaPoint, MitsubaRun};
use super::{measure, radiance, visibility_error, Common};
use anyhow::Result;
use glam::{DVec3, Vec3};
use rendiff::backends::embree::{self, EmbreeBuild, EmbreeCoherence, EmbreeMode, EmbreeQuery};
use rendiff::camera::Camera;
use rendiff::exr_io::read_buffers;
use rendiff::names::Named;
use rendiff::report::svg::{backend_color, time_bars, Bar};
use rendiff::scene::resolve::ResolvedScene;
use rendiff::trace::{BvhQuality, TraceBvh, TraceKernel};
use serde_json::{json, Map, Value};
use std::path::PathBuf;
use std::time::Duration;

/// What `bench peers` measures.
#[derive(Debug, Clone)]
pub struct PeersOptions {
    /// Shared options.
    pub common: Common,
    /// Throughput scene (default: million at 1920x1080).
    pub scene: SceneSpec,
    /// A real scanned mesh whose trace throughput is measured the same way
    /// (default: the Nefertiti scan at 1920x1080): a tracer tuned to the
    /// million grid's regular triangles must show it holds on a real mesh.
    pub scanned_scene: Option<SceneSpec>,
    /// Thread counts for the trace and raster throughput.
    pub threads: Vec<usize>,
    /// Global-illumination scene for the equal-time comparison.
    pub gi_scene: PathBuf,
    /// Its cached reference.
    pub reference: PathBuf,
    /// Mitsuba's spp in the equal-time comparison.
    pub mitsuba_spp: u32,
    /// Seed of both path tracers (not the reference's).
    pub seed: u64,
    /// Skip external renderers (pyrender, Mitsuba), recording why.
    pub no_external: bool,
    /// Paired rounds (alternating order) behind each core-vs-Embree ratio
    /// and behind the check of Embree's numbers against the native driver.
    pub rounds: usize,
}

/// Runs the comparisons and returns the JSON record, the page and the SVGs.
pub fn run(opts: &PeersOptions) -> Result<super::Output> {
    let environment = super::environment();
    let allocator = super::keep_freed_memory();
    let scene = opts.scene.load()?;
    let cam = &scene.camera;
    let runs = opts.common.runs;
    rendiff::errln!(
        "peers: {} at {}x{} ({} triangles)",
        opts.scene.path.display(),
        cam.width,
        cam.height,
        scene.triangles.len()
    );
    // The two-triangle check first, before the heavy tables, the Embree
    // builds and the harness's subprocesses: run last (Nov 30 22:20), both of
    // its passes took 1.4-1.9x their time in a fresh process (the raster's
    // 0.90 ms against 0.47-0.51 ms on 2 threads, 11 rounds), which moved its
    // ratio from 11.7-12.3x to 8.7x; a fresh process that first built and
    // traced `million` and ran Embree's per-frame rounds still gave 11.8x.
    let two_triangles = opts
        .threads
        .iter()
        .map(|&t| Ok(super::pool(t)?.install(|| peer_tables::two_triangles(t, opts.rounds))))
        .collect::<Result<Vec<Value>>>()?;
    let per_threads = throughput(&scene, &opts.threads, runs, opts.rounds)?;
    let scanned = match &opts.scanned_scene {
        Some(spec) => {
            let s = spec.load()?;
            rendiff::errln!(
                "peers: scanned mesh {} at {}x{} ({} triangles)",
                spec.path.display(),
                s.camera.width,
                s.camera.height,
                s.triangles.len()
            );
            json!({"scene": spec.path, "width": s.camera.width, "height": s.camera.height,
                   "triangles": s.triangles.len(),
                   "trace_throughput": throughput(&s, &opts.threads, runs, opts.rounds)?})
        }
        None => json!({"skipped": "no scanned scene (--quick without --scanned-scene)"}),
    };
    let externals = if opts.no_external {
        Err("external renderers off (--quick or --no-external)".to_string())
    } else {
        Ok(())
    };
    let scratch = super::Scratch::new("peers")?;
    let harness = externals.and_then(|_| {
        Harness::find(
            &opts.common.root,
            Duration::from_secs(opts.common.timeout_s),
            scratch.path(),
        )
    });
    let all_threads = super::cpus();
    let core_raster_all = super::pool(all_threads)?.install(|| measure::raster(&scene, runs));
    let pyrender = match &harness {
        Ok(h) => pyrender(h, &scene, &core_raster_all, runs),
        Err(why) => json!({"skipped": why}),
    };
    let equal_time = match &harness {
        Ok(h) => super::pool(all_threads)?
            .install(|| equal_time(h, opts, runs))
            .unwrap_or_else(|e| json!({"skipped": format!("{e:#}")})),
        Err(why) => json!({"skipped": why}),
    };
    let first_image_external = match &harness {
        Ok(h) => match h.export(&scene, &scratch.path().join("first-image")) {
            Ok(resolved) => {
                rendiff::errln!("peers: time to first image, mitsuba (visibility)");
                json!({
                    "mitsuba": peer_tables::external(h, "mitsuba", &resolved, runs),
                    "pyrender": {
                        "render_call_s_median": pyrender["pyrender"]["harness_time_s_median"],
                        "subprocess_wall_s_median": pyrender["pyrender"]["subprocess_wall_s_median"],
                        "includes": "raster_vs_pyrender's runs: the harness's time_s (reading the exported scene, upload, depth + ID passes, read-back, EXR write; Python start-up and imports excluded) and the whole subprocess",
                        "paired": "no: an external process on all CPUs; no ratio is formed",
                    },
                })
            }
            Err(why) => json!({"skipped": why}),
        },
        Err(why) => json!({"skipped": why}),
    };
    let mut record = json!({
        "benchmark": "peers",
        "environment": environment,
        "config": {
            "scene": opts.scene.path, "width": cam.width, "height": cam.height,
            "triangles": scene.triangles.len(), "threads": opts.threads, "runs": runs,
            "quick": opts.common.quick, "gi_scene": opts.gi_scene, "reference": opts.reference,
            "mitsuba_spp": opts.mitsuba_spp, "seed": opts.seed, "allocator": allocator,
            "timing": "median of `runs` timed runs after one untimed warm-up",
            "rays": "primary rays through pixel centers, the core's own (Embree gets them rounded to f32: in the sweeps, prepared once per camera before its trace is timed, in the binding and the native driver alike; in the per-frame and first-image tables, made inside the native driver's timed frame, as the core makes its rays inside its timed queries)",
            "embree_version": embree::version().ok(),
            "embree_features": embree::features().ok(),
            "embree_best": "highest Mrays/s over every Embree row at that thread count: the binding's (entry point x context flag x scene flags x build quality) and the native driver's (entry point x context flag x build quality)",
            "embree_native": "native/embree_driver.c: Embree's own headers and ray layouts, f32 rays (prepared before timing in the sweep, made inside the timed frame in the per-frame and first-image tables), FTZ/DAZ set while tracing (docs/embree-fastest-path.md)",
            "paired_rounds": opts.rounds,
            "paired_rounds_note": if opts.common.quick { "--quick: fewer paired rounds than the 11 of a full run" } else { "a full run's rounds" },
            "agreement": format!("the binding's best must be within {:.0}% of the native driver's best in paired rounds, or the page says so in red", measure::AGREEMENT * 100.0),
        },
        "trace_throughput": per_threads,
        "scanned_mesh": scanned,
        "raster_vs_pyrender": pyrender,
        "path_tracing_equal_time": equal_time,
        "two_screen_filling_triangles": two_triangles,
        "time_to_first_image_external": first_image_external,
    });
    record["headline"] = headline(&record);
    record["goals"] = goals(&record);
    Ok(super::Output::with_plot(record, "times", bars, page))
}

/// Trace throughput per thread count on one scene: the core's packet and
/// single-ray kernels (queries alone, then whole renders), its raster, and
/// every Embree configuration, each row with its ratios.
fn throughput(
    scene: &ResolvedScene,
    thread_counts: &[usize],
    runs: usize,
    rounds: usize,
) -> Result<Vec<Value>> {
    let pixels = scene.camera.pixel_count() as f64;
    let mut per_threads = Vec::new();
    for &threads in thread_counts {
        let pool = super::pool(threads)?;
        per_threads.push(pool.install(|| -> Value {
    // Whole renders (keys plus the frame's buffers) for the record, and
        // the queries alone for Mrays/s, as Embree's trace_s times them.
        let core = measure::trace(scene, BvhQuality::Medium, runs);
        let packets_medium =
            measure::trace_queries(scene, &core.build.last, TraceKernel::Packets, runs);
        let single = measure::trace_queries(scene, &core.build.last, TraceKernel::SingleRays, runs);
        // The core at its best too: obvhs' slow (higher-quality) build,
        // its build time apart as Embree's is, and the faster BVH counts.
        let slow_bvh = TraceBvh::build(scene, BvhQuality::Slow);
        let packets_slow = measure::trace_queries(scene, &slow_bvh, TraceKernel::Packets, runs);
        let medium_mrays = pixels / packets_medium.median_s / 1e6;
        let slow_mrays = pixels / packets_slow.median_s / 1e6;
        let (packets, core_bvh, best_bvh) = if slow_mrays > medium_mrays {
            (&packets_slow, BvhQuality::Slow, &slow_bvh)
        } else {
            (&packets_medium, BvhQuality::Medium, &core.build.last)
        };
        let raster = measure::raster(scene, runs);
        rendiff::errln!("peers: {threads} thread(s), raster and trace passes in alternation");
        let raster_vs_trace = measure::raster_vs_trace(scene, best_bvh, runs);
        let core_mrays = pixels / packets.median_s / 1e6;
        let single_mrays = pixels / single.median_s / 1e6;
        let mut embree = Map::new();
        let mut skipped = Vec::new();
        let mut configs = std::collections::HashMap::new();
        // The binding's reference keys (single rays, incoherent, default
        // scene, medium build): the native driver must reproduce them.
        let mut binding_single: Option<rendiff::frame::Frame> = None;
        for config in [EmbreeMode::Default, EmbreeMode::Robust]
            .into_iter()
            .flat_map(|m| EmbreeBuild::ALL.map(|b| (m, b)))
        {
            let (mode, build) = config;
            // The reference path (single rays, incoherent context) comes
            // first; every other path must reproduce its keys.
            let mut reference: Option<rendiff::frame::Frame> = None;
            for query in EmbreeQuery::ALL {
                for coherence in EmbreeCoherence::ALL {
                    let name = measure::embree_name_with(config, query, coherence);
                    configs.insert(name.clone(), (config, query, coherence));
                    rendiff::errln!("peers: {threads} thread(s), {name}");
                    match measure::embree_with(scene, config, query, coherence, runs) {
                        Ok((f, st)) => {
                            let mrays = st.rays as f64 / st.trace_s / 1e6;
                            let vs_single = reference.as_ref().map(|r| visibility_error(r, &f));
                            embree.insert(
                                name,
                                json!({"source": "binding", "mode": mode.name(), "build_quality": build.name(),
                                       "query": query.name(),
                                       "entry_point": query.entry_point(), "layout": query.layout(),
                                       "context": coherence.name(),
                                       "timing": st, "mrays_per_s": mrays,
                                       "core_over_embree": core_mrays / mrays,
                                       "core_single_rays_over_embree": single_mrays / mrays,
                                       "vs_core_raster": visibility_error(&raster.last, &f),
                                       "vs_embree_single": vs_single,
                                       "same_keys_as_embree_single": vs_single.map(|e| e.identical())}),
                            );
                            if (query, coherence)
                                == (EmbreeQuery::Single, EmbreeCoherence::Incoherent)
                            {
                                if config == (EmbreeMode::Default, EmbreeBuild::Medium) {
                                    binding_single = Some(f.clone());
                                }
                                reference = Some(f);
                            }
                        }
                        Err(e) => skipped.push(json!({"what": name, "reason": e.to_string()})),
                    }
                }
            }
        }
        // Embree as a native application runs it, on the same rays: the
        // yardstick for the binding's rows, and a candidate for the best.
        let mut native = native_sweep(
            scene,
            threads,
            &raster.last,
            binding_single.as_ref(),
            (core_mrays, single_mrays),
            runs,
        );
        native_runoff(scene, threads, &mut native, rounds);
        let native_best = native.best.and_then(|(config, _)| {
            let rays = native.rays.as_ref()?;
            match NativeScene::build(scene, config.quality, false, threads) {
                Ok(b) => Some((config, b, rays)),
                Err(e) => {
                    skipped.push(json!({"what": config.name(), "reason": e}));
                    None
                }
            }
        });
        // The check: the binding's fastest against the driver's fastest,
        // in alternating rounds.
        let check = match (fastest(&embree, None), &native_best) {
            (Some((k, _)), Some((config, built, rays))) => {
                let name = k.clone();
                rendiff::errln!("peers: {threads} thread(s), {name} and {} in alternation", config.name());
                let binding = configs[&name];
                match measure::binding_vs_native(scene, binding, (built, rays), *config, rounds) {
                    Ok(mut v) => {
                        v["binding_best"] = json!(name);
                        v["native_best"] = json!(config.name());
                        v["native_best_by"] = json!(if native.runoff["winner"].is_string() {
                            "runoff: the least median of the sweep's fastest rows in paired rounds (embree_native.runoff)"
                        } else {
                            "the sweep's fastest row"
                        });
                        v
                    }
                    Err(e) => json!({"error": e.to_string()}),
                }
            }
            (_, None) => json!({"skipped": native.skipped.clone().unwrap_or_else(|| "no native row".into())}),
            (None, _) => json!({"skipped": "no binding row (Embree unavailable)"}),
        };
        // The headline ratio: the core and Embree's fastest configuration
        // (over the binding's rows and the driver's) in alternating rounds
        // (the sweep's medians were taken minutes apart).
        let binding_fastest = fastest(&embree, None);
        let native_fastest = native.best_name.as_ref().and_then(|n| native.rows.get_key_value(n));
        let native_wins = match (binding_fastest, native_fastest) {
            (Some((_, b)), Some((_, n))) => n["mrays_per_s"].as_f64() >= b["mrays_per_s"].as_f64(),
            (None, Some(_)) => true,
            _ => false,
        };
        let best = if native_wins {
            native_fastest.zip(native_best.as_ref()).map(|((k, v), (config, built, rays))| {
                rendiff::errln!("peers: {threads} thread(s), core and {k} in alternation");
                let paired = measure::paired_with_native(
                    scene,
                    best_bvh,
                    TraceKernel::Packets,
                    (built, rays),
                    *config,
                    rounds,
                );
                best_json(k, v, core_mrays, single_mrays, Some(Ok(paired)))
            })
        } else {
            binding_fastest.map(|(k, v)| {
                let paired = configs.get(k).map(|&(config, query, coherence)| {
                    rendiff::errln!("peers: {threads} thread(s), core and {k} in alternation");
                    measure::paired_with_embree(
                        scene,
                        best_bvh,
                        TraceKernel::Packets,
                        config,
                        query,
                        coherence,
                        rounds,
                    )
                });
                best_json(k, v, core_mrays, single_mrays, paired)
            })
        };
        rendiff::errln!("peers: {threads} thread(s), per-frame table");
        let per_frame = {
            let mut bvh = TraceBvh::build(scene, core_bvh);
            let native = native_best.as_ref().map(|(c, b, r)| (b, *r, *c, native.prepare_s));
            peer_tables::per_frame(scene, &mut bvh, core_bvh, native, rounds)
        };
        drop(native_best);
        rendiff::errln!("peers: {threads} thread(s), time-to-first-image table");
        let first_config = peer_tables::least_build_plus_trace(&native.rows).map(|(c, _)| c);
        let first_image = peer_tables::first_image(scene, threads, first_config, rounds);
        let best_robust = fastest(&embree, Some(EmbreeMode::Robust.name()))
            .map(|(k, v)| best_json(k, v, core_mrays, single_mrays, None));
        let ratio = |k: &str| embree.get(k).and_then(|v| v["core_over_embree"].as_f64());
        let ratio1 =
            |k: &str| embree.get(k).and_then(|v| v["core_single_rays_over_embree"].as_f64());
        let field = |b: &Option<Value>, k: &str| b.as_ref().map_or(Value::Null, |b| b[k].clone());
        json!({
            "threads": threads,
            "core_trace": {"kernel": packets_label(), "mrays_per_s": core_mrays,
                           "bvh_quality": core_bvh.name(),
                           "mrays_per_s_by_bvh_quality": {"medium": medium_mrays, "slow": slow_mrays},
                           "queries": packets.json(), "timing": core.json(),
                           "raster_equals_trace": visibility_error(&raster.last, &core.trace.last).identical()
                               && visibility_error(&raster.last, &packets_medium.last).identical()
                               && visibility_error(&raster.last, &packets_slow.last).identical()},
            "core_trace_single_rays": {"mrays_per_s": single_mrays, "queries": single.json(),
                           "raster_equals_trace": visibility_error(&raster.last, &single.last).identical()},
            "core_raster": {"timing": raster.json(), "mpixels_per_s": pixels / raster.median_s / 1e6,
                            "counters": raster.last.counters},
            "raster_vs_trace_passes": raster_vs_trace,
            "embree": embree,
            "embree_native": native.json(),
            "embree_check": check,
            "embree_best": best,
            "embree_best_robust": best_robust,
            "per_frame": per_frame,
            "time_to_first_image": first_image,
            "ratios": {
                "core_trace_over_embree_single": ratio("embree single"),
                "core_trace_over_embree_packet8": ratio("embree packet8"),
                "core_trace_over_embree_robust_single": ratio("embree_robust single"),
                "core_single_rays_over_embree_single": ratio1("embree single"),
                "core_single_rays_over_embree_packet8": ratio1("embree packet8"),
                "embree_best": field(&best, "name"),
                "embree_best_source": field(&best, "source"),
                "core_over_embree_best": field(&best, "core_over_embree_best"),
                "core_single_rays_over_embree_best": field(&best, "core_single_rays_over_embree_best"),
                "embree_best_robust": field(&best_robust, "name"),
                "core_over_embree_best_robust": field(&best_robust, "core_over_embree_best"),
            },
            "skipped": skipped,
        })
        }));
    }
    Ok(per_threads)
}

/// The fastest Embree row (highest Mrays/s), optionally of one mode only.
fn fastest<'a>(
    embree: &'a Map<String, Value>,
    mode: Option<&str>,
) -> Option<(&'a String, &'a Value)> {
    embree
        .iter()
        .filter(|(_, v)| mode.is_none_or(|m| v["mode"] == m))
        .filter_map(|(k, v)| Some((k, v, v["mrays_per_s"].as_f64()?)))
        .max_by(|a, b| a.2.total_cmp(&b.2))
        .map(|(k, v, _)| (k, v))
}

/// The native driver's rows on one scene at one thread count.
struct NativeSweep {
    /// Every configuration's row, by [`Config::name`].
    rows: Map<String, Value>,
    /// The prepared rays (None when the driver is unavailable).
    rays: Option<PreparedRays>,
    /// The fastest configuration and its Mrays/s.
    best: Option<(Config, f64)>,
    /// Its row name.
    best_name: Option<String>,
    /// Why there are no rows.
    skipped: Option<String>,
    /// Seconds preparing the rays took (once per camera, outside timing).
    prepare_s: f64,
    /// Build seconds per quality.
    build_s: Map<String, Value>,
    /// The paired rounds that chose `best` among the sweep's fastest.
    runoff: Value,
}

impl NativeSweep {
    fn json(&self) -> Value {
        match &self.skipped {
            Some(why) => json!({"skipped": why}),
            None => json!({
                "rows": self.rows,
                "best": self.best_name,
                "rays_prepare_s": self.prepare_s,
                "build_s": self.build_s,
                "runoff": self.runoff,
                "version": native_embree::version().ok(),
            }),
        }
    }
}

/// Every configuration of the native driver (entry point x context flag x
/// build quality, default scene flags) on `scene` at `threads`: one build
/// per quality, then each configuration's frames, with the same ratios and
/// agreement checks as the binding's rows.
fn native_sweep(
    scene: &ResolvedScene,
    threads: usize,
    raster: &rendiff::frame::Frame,
    binding_single: Option<&rendiff::frame::Frame>,
    (core_mrays, single_mrays): (f64, f64),
    runs: usize,
) -> NativeSweep {
    let mut sweep = NativeSweep {
        rows: Map::new(),
        rays: None,
        best: None,
        best_name: None,
        skipped: None,
        prepare_s: 0.0,
        build_s: Map::new(),
        runoff: Value::Null,
    };
    if let Err(why) = native_embree::version() {
        sweep.skipped = Some(why);
        return sweep;
    }
    let t = std::time::Instant::now();
    let rays = PreparedRays::new(&scene.camera);
    sweep.prepare_s = t.elapsed().as_secs_f64();
    for quality in Quality::ALL {
        rendiff::errln!(
            "peers: {threads} thread(s), native driver, {} build",
            quality.name()
        );
        let built = match NativeScene::build(scene, quality, false, threads) {
            Ok(b) => b,
            Err(e) => {
                sweep
                    .build_s
                    .insert(quality.name().into(), json!({"error": e}));
                continue;
            }
        };
        sweep
            .build_s
            .insert(quality.name().into(), json!(built.build_s));
        for config in Config::all().into_iter().filter(|c| c.quality == quality) {
            let (times, hits) = measure::native_frames(&built, &rays, config, runs);
            let median_s = super::median(&times);
            let mrays = rays.len() as f64 / median_s / 1e6;
            let (frame, in_front) = hits.frame(scene, &rays);
            let vs_binding = binding_single.map(|r| visibility_error(r, &frame));
            sweep.rows.insert(
                config.name(),
                json!({"source": "native driver", "mode": "embree",
                       "build_quality": quality.name(), "query": config.entry.name(),
                       "entry_point": config.entry.entry_point(),
                       "context": if config.coherent { "coherent" } else { "incoherent" },
                       "timing": {"trace_s": median_s, "runs_s": times, "build_s": built.build_s},
                       "mrays_per_s": mrays,
                       "core_over_embree": core_mrays / mrays,
                       "core_single_rays_over_embree": single_mrays / mrays,
                       "vs_core_raster": visibility_error(raster, &frame),
                       "vs_embree_single": vs_binding,
                       "same_keys_as_embree_single": vs_binding.map(|e| e.identical()),
                       "hits_in_front_of_near": in_front}),
            );
            if sweep.best.is_none_or(|(_, m)| mrays > m) {
                sweep.best = Some((config, mrays));
                sweep.best_name = Some(config.name());
            }
        }
    }
    sweep.rays = Some(rays);
    sweep
}

/// Configurations of the sweep's fastest that [`native_runoff`] times again.
const RUNOFF: usize = 6;

/// The sweep times each configuration in a few frames minutes apart from
/// the others, so its fastest is not always the fastest (Dec 1: the
/// binding's `packet16` ran 1.07x the sweep's fastest native row, `NM16`,
/// in paired rounds). The [`RUNOFF`] fastest rows are timed again on the
/// same prepared rays in `rounds` alternating rounds, and the least median
/// becomes the sweep's best: the configuration the check and the per-frame
/// table hold the core to.
fn native_runoff(scene: &ResolvedScene, threads: usize, sweep: &mut NativeSweep, rounds: usize) {
    let Some(rays) = sweep.rays.as_ref() else {
        return;
    };
    let mut ranked: Vec<(Config, f64)> = Config::all()
        .into_iter()
        .filter_map(|c| Some((c, sweep.rows.get(&c.name())?["mrays_per_s"].as_f64()?)))
        .collect();
    ranked.sort_by(|a, b| b.1.total_cmp(&a.1));
    ranked.truncate(RUNOFF);
    let mut builds: Vec<(Quality, NativeScene)> = Vec::new();
    for &(c, _) in &ranked {
        if !builds.iter().any(|(q, _)| *q == c.quality) {
            match NativeScene::build(scene, c.quality, false, threads) {
                Ok(b) => builds.push((c.quality, b)),
                Err(e) => {
                    sweep.runoff = json!({"error": e});
                    return;
                }
            }
        }
    }
    let mut hits: Vec<native_embree::Hits> = ranked
        .iter()
        .map(|_| native_embree::Hits::new(rays))
        .collect();
    let mut contenders: Vec<Box<dyn FnMut() -> f64 + '_>> = ranked
        .iter()
        .zip(hits.iter_mut())
        .map(|(&(c, _), h)| {
            let built = &builds
                .iter()
                .find(|(q, _)| *q == c.quality)
                .expect("built")
                .1;
            Box::new(move || built.trace(rays, c.entry, c.coherent, h)) as Box<dyn FnMut() -> f64>
        })
        .collect();
    let mut refs: Vec<&mut dyn FnMut() -> f64> = contenders
        .iter_mut()
        .map(|b| &mut **b as &mut dyn FnMut() -> f64)
        .collect();
    rendiff::errln!(
        "peers: {threads} thread(s), native runoff of {} configurations",
        ranked.len()
    );
    let series = peer_tables::alternate_all(rounds, &mut refs);
    let medians: Vec<f64> = series.iter().map(|s| super::median(s)).collect();
    let Some(win) = (0..ranked.len()).min_by(|&a, &b| medians[a].total_cmp(&medians[b])) else {
        return;
    };
    let mrays = |s: f64| rays.len() as f64 / s / 1e6;
    sweep.runoff = json!({
        "what": format!("the sweep's {} fastest rows timed again on the same prepared rays in alternating rounds; the least median is the best", ranked.len()),
        "rounds": rounds,
        "candidates": ranked.iter().zip(&medians).zip(&series).map(|((&(c, sweep_mrays), &m), s)| json!({
            "name": c.name(), "sweep_mrays_per_s": sweep_mrays,
            "trace_s_median": m, "mrays_per_s": mrays(m), "trace_s": s,
        })).collect::<Vec<_>>(),
        "winner": ranked[win].0.name(),
        "sweep_fastest": ranked[0].0.name(),
    });
    sweep.best = Some((ranked[win].0, mrays(medians[win])));
    sweep.best_name = Some(ranked[win].0.name());
}

/// What a thread count's record says about its fastest Embree configuration.
/// With `paired` rounds (the fastest overall), `core_over_embree_best` is
/// their median per-round ratio and the sweep's ratio is kept beside it as
/// `core_over_embree_best_sweep`; without (the fastest robust one), it is
/// the sweep's ratio, and the record says so.
fn best_json(
    name: &str,
    row: &Value,
    core_mrays: f64,
    single_mrays: f64,
    paired: Option<Result<measure::Paired, rendiff::backends::embree::EmbreeError>>,
) -> Value {
    let mrays = row["mrays_per_s"].as_f64().unwrap_or(f64::NAN);
    let sweep = core_mrays / mrays;
    let (ratio, basis, paired) = match paired {
        Some(Ok(p)) => (json!(p.ratio()), "paired rounds", p.json()),
        Some(Err(e)) => (
            Value::Null,
            "paired rounds failed",
            json!({"error": e.to_string()}),
        ),
        None => (json!(sweep), "sweep medians", Value::Null),
    };
    let interval = paired["core_over_embree_interval_95"].clone();
    json!({
        "name": name,
        "source": row["source"],
        "mode": row["mode"], "query": row["query"], "entry_point": row["entry_point"],
        "context": row["context"], "build_quality": row["build_quality"],
        "core_over_embree_best_interval_95": interval,
        "mrays_per_s": mrays,
        "core_over_embree_best": ratio,
        "core_over_embree_best_basis": basis,
        "core_over_embree_best_sweep": sweep,
        "paired": paired,
        "core_single_rays_over_embree_best": single_mrays / mrays,
        "same_keys_as_embree_single": row["same_keys_as_embree_single"],
    })
}

/// The measured goals (never asserted): core trace vs Embree single-ray and vs
/// Embree's fastest configuration, core raster vs llvmpipe.
fn goals(record: &Value) -> Value {
    let t = record["trace_throughput"]
        .as_array()
        .cloned()
        .unwrap_or_default();
    let single: Vec<Value> = t
        .iter()
        .map(|r| json!({"threads": r["threads"], "core_trace_over_embree_single": r["ratios"]["core_trace_over_embree_single"]}))
        .collect();
    let best: Vec<Value> = t.iter().map(best_goal).collect();
    let scanned: Vec<Value> = record["scanned_mesh"]["trace_throughput"]
        .as_array()
        .into_iter()
        .flatten()
        .map(best_goal)
        .collect();
    let raster_vs_trace: Vec<Value> = t
        .iter()
        .map(|r| json!({"threads": r["threads"],
                        "raster_speedup_over_trace": r["raster_vs_trace_passes"]["raster_speedup_over_trace"]}))
        .collect();
    let mut issue_39 = peer_tables::goals_of(&scene_name(&record["config"]["scene"]), &t);
    issue_39.extend(peer_tables::goals_of(
        &scene_name(&record["scanned_mesh"]["scene"]),
        record["scanned_mesh"]["trace_throughput"]
            .as_array()
            .map_or(&[][..], Vec::as_slice),
    ));
    for r in record["two_screen_filling_triangles"]
        .as_array()
        .into_iter()
        .flatten()
    {
        // The goal is the passes' ratio (the README's and `bench
        // crossover`'s); the first image's is on the page beside it.
        let mut g = peer_tables::goal(
            &format!(
                "two screen-filling triangles, {} thread(s), visibility pass: raster / trace",
                r["threads"]
            ),
            &r["pass"]["raster_over_trace"],
            10.0,
        );
        g["table"] = json!("visibility pass");
        issue_39.push(g);
    }
    json!({
        "issue_39": issue_39,
        "core_raster_vs_trace_passes": raster_vs_trace,
        "core_trace_vs_embree_single_ray": single,
        "core_trace_vs_embree_best": best,
        "core_trace_vs_embree_best_scanned_mesh": scanned,
        "core_raster_vs_llvmpipe_speedup": record["raster_vs_pyrender"]["speedup_core_over_pyrender_pass"],
        "equal_time_error_ratio_mitsuba_over_core": record["path_tracing_equal_time"]["rmse_ratio_mitsuba_over_core"],
        "equal_time_error_ratio_paired_rounds": super::equal_time::goal(&record["path_tracing_equal_time"]["paired_rounds"]),
    })
}

/// A scene's short name in goals and headings: its file's stem ("million").
fn scene_name(path: &Value) -> String {
    let p = path.as_str().unwrap_or("scene");
    std::path::Path::new(p)
        .file_stem()
        .map_or(p.to_string(), |s| s.to_string_lossy().into_owned())
}

/// The headline: the main scene's per-frame ratio (the core's new camera
/// counted) against Embree's best per thread count, and its time-to-first-
/// image ratio, each naming its table.
fn headline(record: &Value) -> Value {
    let rows = record["trace_throughput"]
        .as_array()
        .cloned()
        .unwrap_or_default();
    let trace_default = format!("core trace ({} BVH)", BvhQuality::default().name());
    let per: Vec<Value> = rows
        .iter()
        .map(|r| {
            let first = r["time_to_first_image"]["rows"]
                .as_array()
                .into_iter()
                .flatten()
                .find(|x| x["name"] == trace_default.as_str())
                .map_or(Value::Null, |x| x["over_embree"].clone());
            json!({"threads": r["threads"],
                   "per_frame_table": {"what": "core trace (new camera counted) / Embree's fastest",
                                       "ratio": r["per_frame"]["core_over_embree_new_camera_counted"]},
                   "time_to_first_image_table": {"what": format!("{trace_default} / Embree's least build + trace"),
                                                 "ratio": first}})
        })
        .collect();
    json!({"scene": record["config"]["scene"], "rows": per})
}

/// The headline as page text, each figure with its table's name.
fn headline_text(h: &Value) -> String {
    let r = peer_tables::ratio_text;
    let parts: Vec<String> = h["rows"]
        .as_array()
        .into_iter()
        .flatten()
        .map(|x| {
            format!(
                "{} thread(s): per frame table, {} = {}; time to first image table, {} = {}",
                x["threads"],
                super::page::compact(&x["per_frame_table"]["what"]),
                r(&x["per_frame_table"]["ratio"]),
                super::page::compact(&x["time_to_first_image_table"]["what"]),
                r(&x["time_to_first_image_table"]["ratio"]),
            )
        })
        .collect();
    format!(
        "Headline on {} (medians of paired rounds' ratios, 95% bootstrap intervals; above 1 the core is faster): {}.",
        super::page::compact(&h["scene"]),
        parts.join("; ")
    )
}

/// One thread count's core-vs-Embree-best goal row.
fn best_goal(r: &Value) -> Value {
    json!({"threads": r["threads"], "embree_best": r["embree_best"]["name"],
           "embree_best_source": r["embree_best"]["source"],
           "embree_best_mrays_per_s": r["embree_best"]["mrays_per_s"],
           "core_over_embree_best_interval_95": r["embree_best"]["core_over_embree_best_interval_95"],
           "binding_over_native_best": r["embree_check"]["binding_over_native"],
           "binding_within_5_percent_of_native": r["embree_check"]["within_5_percent"],
           "core_trace_mrays_per_s": r["core_trace"]["mrays_per_s"],
           "core_over_embree_best": r["embree_best"]["core_over_embree_best"],
           "core_over_embree_best_basis": r["embree_best"]["core_over_embree_best_basis"],
           "paired": r["embree_best"]["paired"]})
}

fn pyrender(
    h: &Harness,
    scene: &ResolvedScene,
    core: &super::Timed<rendiff::frame::Frame>,
    runs: usize,
) -> Value {
    let dir = h.scratch.join("pyrender");
    let resolved = match h.export(scene, &dir) {
        Ok(r) => r,
        Err(why) => return json!({"skipped": why}),
    };
    let out = dir.join("pyrender.exr");
    let (mut pass, mut total, mut harness_s, mut wall) = (vec![], vec![], vec![], vec![]);
    let mut info = Value::Null;
    for k in 0..=runs.max(1) {
        let r = match h.render("pyrender", &resolved, &out) {
            Ok(r) => r,
            Err(why) => return json!({"skipped": why}),
        };
        if k > 0 {
            pass.push(
                r.info["depth_passes"][0]["seconds"]
                    .as_f64()
                    .unwrap_or(f64::NAN),
            );
            total.push(number_at(&r.info, &["timings_s", "render"]).unwrap_or(f64::NAN));
            harness_s.push(r.time_s.unwrap_or(f64::NAN));
            wall.push(r.wall_s);
        }
        info = r.info;
    }
    // Start-up the sub-timings exclude: the same call on one triangle at the same size.
    let tiny = one_triangle(scene);
    let startup = h
        .export(&tiny, &dir.join("tiny"))
        .and_then(|r| h.render("pyrender", &r, &dir.join("tiny.exr")))
        .map(|r| json!({"subprocess_wall_s": r.wall_s, "harness_time_s": r.time_s}))
        .unwrap_or_else(|why| json!({"skipped": why}));
    let agreement = read_buffers(&out).ok().and_then(|b| b.prim).map(|p| {
        p.iter()
            .zip(&core.last.prim)
            .filter(|(a, b)| a != b)
            .count()
    });
    let pass_s = super::median(&pass);
    json!({
        "core_raster": {"threads": super::cpus(), "timing": core.json()},
        "pyrender": {
            "pass_s_median": pass_s, "pass_runs_s": pass,
            "render_s_median": super::median(&total),
            "harness_time_s_median": super::median(&harness_s),
            "subprocess_wall_s_median": super::median(&wall),
            "passes": info["depth_passes"].as_array().map(|a| a.len()),
            "gl_renderer": info["gl_renderer"], "platform": info["platform"],
            "threads": "llvmpipe's own (LP_NUM_THREADS unset: one per CPU)",
            "timing": "first depth+ID pass from its info (scene upload, draw, read-back); a second pass with refined planes, when it runs, is in render_s",
        },
        "one_triangle_startup": startup,
        "id_mismatches_vs_core_raster": agreement,
        "speedup_core_over_pyrender_pass": pass_s / core.median_s,
        "speedup_core_over_pyrender_render": super::median(&total) / core.median_s,
    })
}

/// One small triangle in front of the same camera: a render whose time is nearly all fixed cost.
fn one_triangle(scene: &ResolvedScene) -> ResolvedScene {
    let c: &Camera = &scene.camera;
    let p = c.eye + c.forward * 2.0;
    let v = |d: DVec3| (p + d * 0.1).as_vec3();
    let tri: [Vec3; 3] = [
        v(-c.right - c.up_ortho),
        v(c.right - c.up_ortho),
        v(c.up_ortho),
    ];
    ResolvedScene::from_triangles(c.clone(), vec![tri])
}

/// Mitsuba's CPU variants: `llvm_ad_rgb` (JIT-compiled, vectorized) is its
/// documented fast path on CPUs, `scalar_rgb` the default.
const MITSUBA_CPU_VARIANTS: [&str; 2] = ["scalar_rgb", "llvm_ad_rgb"];

fn equal_time(h: &Harness, opts: &PeersOptions, runs: usize) -> Result<Value> {
    let scene = super::load_scene(&opts.gi_scene)?;
    let reference = radiance::read_rgb(&opts.reference)?;
    let resolved = h
        .export(&scene, &h.scratch.join("gi"))
        .map_err(anyhow::Error::msg)?;
    // Mitsuba at its fastest: every CPU variant at the same spp, the
    // quickest is the one the core is matched against; all are recorded.
    let mut variants = Map::new();
    let mut best: Option<(&str, MitsubaPoint)> = None;
    for variant in MITSUBA_CPU_VARIANTS {
        let settings = ["--variant".to_string(), variant.to_string()];
        let name = format!("mitsuba-equal-time-{variant}");
        let run = MitsubaRun {
            spp: opts.mitsuba_spp,
            seed: opts.seed,
            settings: &settings,
            name: &name,
        };
        rendiff::errln!("peers: equal time, mitsuba {variant}");
        match mitsuba_path(h, &resolved, &reference, &run, runs) {
            Ok(m) => {
                variants.insert(
                    variant.into(),
                    json!({"time_s": m.time_s, "error": m.error, "details": m.details}),
                );
                if best.as_ref().is_none_or(|(_, b)| m.time_s < b.time_s) {
                    best = Some((variant, m));
                }
            }
            Err(e) => {
                variants.insert(variant.into(), json!({"skipped": e}));
            }
        }
    }
    let Some((variant, m)) = best else {
        anyhow::bail!("no Mitsuba variant ran: {}", Value::Object(variants));
    };
    // Calibrate the core's seconds per spp, then match Mitsuba's time.
    let calib_spp = 16;
    let (calib, _) = core_path(&scene, &reference, calib_spp, opts.seed, runs)?;
    let per_spp = calib.median_s / f64::from(calib_spp);
    let spp = ((m.time_s / per_spp).round() as u32).max(1);
    let (t, e) = core_path(&scene, &reference, spp, opts.seed, runs)?;
    let pairing = super::equal_time::Pairing {
        variant,
        mitsuba_spp: opts.mitsuba_spp,
        core_spp: spp,
        seed: opts.seed,
        rounds: opts.rounds,
    };
    let paired = super::equal_time::paired(h, &resolved, &scene, &reference, pairing);
    Ok(json!({
        "paired_rounds": paired,
        "mitsuba": {"spp": opts.mitsuba_spp, "variant": variant, "time_s": m.time_s, "error": m.error, "details": m.details},
        "mitsuba_variants": variants,
        "core": {"spp": spp, "time_s": t.median_s, "timing": t.json(), "error": e,
                 "calibration": {"spp": calib_spp, "time_s": calib.median_s}},
        "time_ratio_core_over_mitsuba": t.median_s / m.time_s,
        "spp_ratio_core_over_mitsuba": f64::from(spp) / f64::from(opts.mitsuba_spp),
        "rmse_ratio_mitsuba_over_core": m.error.rmse / e.rmse,
        "threads": format!("core: {} rayon workers; Mitsuba {variant}: its own pool (one per CPU)", super::cpus()),
    }))
}

fn bars(record: &Value) -> String {
    let mut groups: Vec<(String, Vec<Bar>)> = Vec::new();
    for r in record["trace_throughput"].as_array().into_iter().flatten() {
        let mut b: Vec<Bar> = vec![(
            "core trace".into(),
            backend_color(0),
            r["core_trace"]["queries"]["median_s"].as_f64(),
        )];
        // Embree's fastest configuration (overall and robust), then the
        // default-context rows earlier records showed; every row is in the table.
        let mut shown: Vec<(String, String)> = Vec::new();
        for (what, best) in [
            ("best", "embree_best"),
            ("best robust", "embree_best_robust"),
        ] {
            if let Some(name) = r[best]["name"].as_str() {
                // The robust best is often the best overall: one bar, not two.
                if shown.iter().all(|(_, n)| n != name) {
                    shown.push((format!("embree {what}: {name}"), name.to_string()));
                }
            }
        }
        for name in ["embree single", "embree packet8", "embree_robust single"] {
            if shown.iter().all(|(_, n)| n != name) {
                shown.push((name.to_string(), name.to_string()));
            }
        }
        for (i, (label, name)) in shown.into_iter().enumerate() {
            if let Some(row) = embree_row(r, &name) {
                b.push((
                    label,
                    backend_color(i + 1),
                    row["timing"]["trace_s"].as_f64(),
                ));
            }
        }
        b.push((
            "core raster".into(),
            backend_color(6),
            r["core_raster"]["timing"]["median_s"].as_f64(),
        ));
        groups.push((
            format!(
                "{} thread(s), tracing / raster",
                super::page::compact(&r["threads"])
            ),
            b,
        ));
    }
    let p = &record["raster_vs_pyrender"];
    if p["pyrender"].is_object() {
        groups.push((
            "all CPUs, depth + IDs".into(),
            vec![
                (
                    "core raster".into(),
                    backend_color(6),
                    p["core_raster"]["timing"]["median_s"].as_f64(),
                ),
                (
                    "pyrender pass".into(),
                    backend_color(7),
                    p["pyrender"]["pass_s_median"].as_f64(),
                ),
            ],
        ));
    }
    let e = &record["path_tracing_equal_time"];
    if e["core"].is_object() {
        groups.push((
            "path tracing, equal time".into(),
            vec![
                (
                    format!("core {} spp", e["core"]["spp"]),
                    backend_color(0),
                    e["core"]["time_s"].as_f64(),
                ),
                (
                    format!("mitsuba {} spp", e["mitsuba"]["spp"]),
                    backend_color(8),
                    e["mitsuba"]["time_s"].as_f64(),
                ),
            ],
        ));
    }
    time_bars(&groups)
}

fn page(record: &Value, svg: &str) -> String {
    let mut p = Page::new("rendiff bench peers: the core next to Embree, pyrender and Mitsuba");
    let c = &record["config"];
    p.para(&format!(
        "Scene {} at {}x{} ({} triangles). Times are medians after a warm-up. Ratios above 1 mean the core is faster (throughput) or more accurate (error).",
        super::page::compact(&c["scene"]),
        c["width"],
        c["height"],
        c["triangles"]
    ))
    .command("rendiff bench peers");
    p.para(&headline_text(&record["headline"]));
    p.para(&format!(
        "Paired rounds: {} ({}).",
        c["paired_rounds"],
        super::page::compact(&c["paired_rounds_note"])
    ));
    peer_tables::page_goals(&mut p, &record["goals"]["issue_39"]);
    peer_tables::page_tables(
        &mut p,
        &scene_name(&c["scene"]),
        &record["trace_throughput"],
    );
    if record["scanned_mesh"]["trace_throughput"].is_array() {
        peer_tables::page_tables(
            &mut p,
            &scene_name(&record["scanned_mesh"]["scene"]),
            &record["scanned_mesh"]["trace_throughput"],
        );
    }
    two_and_external(&mut p, record);
    p.svg(svg, Some("peers-times.svg"));
    p.heading("trace throughput (Mrays/s, primary rays, BVH builds excluded)");
    p.para(&format!(
        "Embree runs every entry point that fits primary rays (rtcIntersect1 per pixel; \
         rtcIntersect4/8/16 on 2x2, 4x2, 4x4 tiles; rtcIntersect1M and rtcIntersectNM \
         streams), each with the incoherent (Embree's default) and the coherent \
         intersect-context flag, on default and robust scenes; {}. Native packet support: {}.",
        super::page::compact(&c["embree_version"]),
        super::page::compact(&c["embree_features"])
    ));
    throughput_table(&mut p, &record["trace_throughput"]);
    let sc = &record["scanned_mesh"];
    if let Some(why) = sc["skipped"].as_str() {
        p.note(&format!("scanned mesh: not measured: {why}"));
    } else {
        p.heading(&format!(
            "trace throughput on a real scanned mesh: {} at {}x{} ({} triangles)",
            super::page::compact(&sc["scene"]),
            sc["width"],
            sc["height"],
            sc["triangles"]
        ));
        throughput_table(&mut p, &sc["trace_throughput"]);
    }
    p.heading("raster: core vs pyrender (llvmpipe), depth + IDs");
    let pr = &record["raster_vs_pyrender"];
    if let Some(why) = pr["skipped"].as_str() {
        p.note(&format!("not measured: {why}"));
    } else {
        p.table(
            &["what", "seconds", "note"],
            &[
                vec![
                    "core raster (all CPUs)".into(),
                    num(pr["core_raster"]["timing"]["median_s"].as_f64(), 4),
                    String::new(),
                ],
                vec![
                    "pyrender, one pass".into(),
                    num(pr["pyrender"]["pass_s_median"].as_f64(), 4),
                    super::page::compact(&pr["pyrender"]["timing"]),
                ],
                vec![
                    "pyrender, render (all passes)".into(),
                    num(pr["pyrender"]["render_s_median"].as_f64(), 4),
                    format!("passes: {}", pr["pyrender"]["passes"]),
                ],
                vec![
                    "pyrender subprocess".into(),
                    num(pr["pyrender"]["subprocess_wall_s_median"].as_f64(), 4),
                    "Python start-up, imports, export read, EXR write included".into(),
                ],
                vec![
                    "one-triangle subprocess".into(),
                    num(pr["one_triangle_startup"]["subprocess_wall_s"].as_f64(), 4),
                    "fixed cost excluded from the pass time".into(),
                ],
                vec![
                    "speed-up core / pyrender pass".into(),
                    num(pr["speedup_core_over_pyrender_pass"].as_f64(), 3),
                    String::new(),
                ],
                vec![
                    "ID mismatches vs core".into(),
                    super::page::compact(&pr["id_mismatches_vs_core_raster"]),
                    "edges: different fill rules, not classified here".into(),
                ],
            ],
        );
    }
    p.heading("path tracing at equal time (vs the cached reference)");
    let e = &record["path_tracing_equal_time"];
    if let Some(why) = e["skipped"].as_str() {
        p.note(&format!("not measured: {why}"));
    } else {
        p.table(
            &["renderer", "spp", "time s", "RMSE", "relative RMSE"],
            &[
                vec![
                    format!(
                        "mitsuba {} (its fastest variant here)",
                        super::page::compact(&e["mitsuba"]["variant"])
                    ),
                    super::page::compact(&e["mitsuba"]["spp"]),
                    num(e["mitsuba"]["time_s"].as_f64(), 4),
                    num(e["mitsuba"]["error"]["rmse"].as_f64(), 4),
                    num(e["mitsuba"]["error"]["relative_rmse"].as_f64(), 4),
                ],
                vec![
                    "core".into(),
                    super::page::compact(&e["core"]["spp"]),
                    num(e["core"]["time_s"].as_f64(), 4),
                    num(e["core"]["error"]["rmse"].as_f64(), 4),
                    num(e["core"]["error"]["relative_rmse"].as_f64(), 4),
                ],
            ],
        );
        for (v, row) in e["mitsuba_variants"].as_object().into_iter().flatten() {
            p.note(&format!(
                "mitsuba {v}: {}",
                match row["time_s"].as_f64() {
                    Some(t) => format!("{} s at {} spp", num(Some(t), 4), e["mitsuba"]["spp"]),
                    None => super::page::compact(&row["skipped"]),
                }
            ));
        }
        p.para(&format!(
            "RMSE ratio Mitsuba / core at equal time: {}; time ratio core / Mitsuba: {}; {}.",
            num(e["rmse_ratio_mitsuba_over_core"].as_f64(), 3),
            num(e["time_ratio_core_over_mitsuba"].as_f64(), 3),
            super::page::compact(&e["threads"])
        ));
    }
    p.heading("goals (measured, never asserted)");
    p.table(
        &["goal", "value"],
        &record["goals"]
            .as_object()
            .into_iter()
            .flatten()
            .map(|(k, v)| vec![k.clone(), super::page::compact(v)])
            .collect::<Vec<_>>(),
    );
    p.environment(&record["environment"]);
    p.finish()
}

/// The two-triangle check and the external renderers' first images.
fn two_and_external(p: &mut Page, record: &Value) {
    p.heading("time to first image: two screen-filling triangles, and the harness's renderers");
    for r in record["two_screen_filling_triangles"]
        .as_array()
        .into_iter()
        .flatten()
    {
        let ratio = peer_tables::ratio_text;
        p.note(&format!(
            "{} thread(s), {} triangles at {}x{}: raster / trace, first image (BVH build included) = {}; visibility pass (the goal's ratio) = {}; over {} rounds",
            r["threads"], r["triangles"], r["size"], r["size"],
            ratio(&r["raster_over_trace"]),
            ratio(&r["pass"]["raster_over_trace"]),
            r["raster_s"].as_array().map_or(0, Vec::len),
        ));
    }
    let e = &record["time_to_first_image_external"];
    if let Some(why) = e["skipped"].as_str() {
        p.note(&format!("external renderers not measured: {why}"));
        return;
    }
    let mut rows = Vec::new();
    for k in ["pyrender", "mitsuba"] {
        let v = &e[k];
        rows.push(vec![
            k.to_string(),
            num(v["render_call_s_median"].as_f64(), 4),
            num(v["subprocess_wall_s_median"].as_f64(), 4),
            super::page::compact(
                v.get("includes")
                    .or(v.get("skipped"))
                    .unwrap_or(&Value::Null),
            ),
        ]);
    }
    p.table(
        &[
            "renderer (all CPUs, not paired)",
            "render call s",
            "subprocess s",
            "includes",
        ],
        &rows,
    );
}

/// The throughput table of one scene (every Embree row, fastest first, with
/// the core's ratio) and its notes.
fn throughput_table(p: &mut Page, per_threads: &Value) {
    let mut rows = Vec::new();
    for r in per_threads.as_array().into_iter().flatten() {
        let th = super::page::compact(&r["threads"]);
        rows.push(vec![
            th.clone(),
            "core trace".into(),
            num(r["core_trace"]["mrays_per_s"].as_f64(), 4),
            "1".into(),
            num(r["core_trace"]["timing"]["build"]["median_s"].as_f64(), 3),
            format!(
                "raster == trace: {}",
                r["core_trace"]["raster_equals_trace"]
            ),
        ]);
        // Every Embree row (the binding's and the native driver's), fastest
        // first; the best is marked.
        let mut variants: Vec<(&String, &Value)> = r["embree"]
            .as_object()
            .into_iter()
            .flatten()
            .chain(r["embree_native"]["rows"].as_object().into_iter().flatten())
            .collect();
        variants.sort_by(|a, b| {
            let m = |v: &Value| v["mrays_per_s"].as_f64().unwrap_or(f64::NEG_INFINITY);
            m(b.1).total_cmp(&m(a.1))
        });
        let best = r["embree_best"]["name"].as_str();
        for (k, v) in variants {
            let same = match v["same_keys_as_embree_single"].as_bool() {
                Some(true) => "same keys as single".to_string(),
                Some(false) => format!(
                    "DIFFERS from single at {} px",
                    v["vs_embree_single"]["id_mismatches"]
                ),
                None => "the reference path".to_string(),
            };
            rows.push(vec![
                th.clone(),
                if Some(k.as_str()) == best {
                    format!("{k} (best, {})", super::page::compact(&v["entry_point"]))
                } else {
                    format!("{k} ({})", super::page::compact(&v["entry_point"]))
                },
                num(v["mrays_per_s"].as_f64(), 4),
                num(v["core_over_embree"].as_f64(), 3),
                num(v["timing"]["build_s"].as_f64(), 3),
                format!(
                    "ID mismatches vs core {}, hit/miss {}, max Z rel {}; {same}",
                    v["vs_core_raster"]["id_mismatches"],
                    v["vs_core_raster"]["mask_mismatches"],
                    num(v["vs_core_raster"]["max_z_rel"].as_f64(), 3)
                ),
            ]);
        }
        if let Some(name) = best {
            let ratio = r["embree_best"]["core_over_embree_best"].as_f64();
            let verdict = match ratio {
                Some(x) if x >= 1.0 => "the core is faster than Embree at its best",
                Some(_) => "the core is SLOWER than Embree at its best",
                None => "no ratio",
            };
            let pr = &r["embree_best"]["paired"];
            p.note(&format!(
                "{th} thread(s): Embree's fastest configuration is {name} ({}) at {} Mrays/s; \
                 core trace / Embree best = {} (95% interval {}; {}: {} rounds in alternating \
                 order, core {} Mrays/s against {} Mrays/s; the sweep's medians gave {}): \
                 {verdict}. Fastest robust: {} at {} Mrays/s.",
                super::page::compact(&r["embree_best"]["source"]),
                num(r["embree_best"]["mrays_per_s"].as_f64(), 4),
                num(ratio, 3),
                interval(&r["embree_best"]["core_over_embree_best_interval_95"]),
                super::page::compact(&r["embree_best"]["core_over_embree_best_basis"]),
                super::page::compact(&pr["rounds"]),
                num(pr["core_mrays_per_s"].as_f64(), 4),
                num(pr["embree_mrays_per_s"].as_f64(), 4),
                num(r["embree_best"]["core_over_embree_best_sweep"].as_f64(), 3),
                super::page::compact(&r["embree_best_robust"]["name"]),
                num(r["embree_best_robust"]["mrays_per_s"].as_f64(), 4),
            ));
        }
        check_note(p, &th, &r["embree_check"]);
        let rt = &r["raster_vs_trace_passes"];
        p.note(&format!(
            "{th} thread(s): the raster's visibility pass is {}x the tracer's speed \
             (median of {} alternating rounds' ratios; trace / raster time per round: {}).",
            num(rt["raster_speedup_over_trace"].as_f64(), 3),
            super::page::compact(&rt["rounds"]),
            rt["trace_over_raster_per_round"]
                .as_array()
                .into_iter()
                .flatten()
                .map(|v| num(v.as_f64(), 3))
                .collect::<Vec<_>>()
                .join(", ")
        ));
        p.note(&format!(
            "{th} thread(s): core Mrays/s time the ray queries up to per-pixel hit keys, \
             as Embree's trace_s does; the whole core render, filling the depth, ID, \
             object-ID and normal buffers too, took {} s.",
            num(r["core_trace"]["timing"]["trace"]["median_s"].as_f64(), 4)
        ));
        for s in r["skipped"].as_array().into_iter().flatten() {
            p.note(&format!(
                "{}: {}",
                super::page::compact(&s["what"]),
                super::page::compact(&s["reason"])
            ));
        }
    }
    p.table(
        &[
            "threads",
            "renderer",
            "Mrays/s",
            "core / this",
            "BVH build s",
            "agreement",
        ],
        &rows,
    );
}

/// The core kernel's name in the JSON: its packet size, from the core.
fn packets_label() -> String {
    let [w, h] = rendiff_core::trace::PACKET_PIXELS;
    format!("packets ({w}x{h})")
}

/// A row of either Embree table (the binding's or the native driver's) by name.
fn embree_row<'a>(r: &'a Value, name: &str) -> Option<&'a Value> {
    r["embree"]
        .get(name)
        .or_else(|| r["embree_native"]["rows"].get(name))
}

/// "[lo, hi]" of a recorded interval, or "none".
fn interval(v: &Value) -> String {
    match (v[0].as_f64(), v[1].as_f64()) {
        (Some(lo), Some(hi)) => format!("[{}, {}]", num(Some(lo), 3), num(Some(hi), 3)),
        _ => "none".into(),
    }
}

/// The check of the binding's Embree numbers against the native driver: a
/// plain note when they agree, red when they do not, and why when it could
/// not run.
fn check_note(p: &mut Page, th: &str, c: &Value) {
    if let Some(why) = c["skipped"].as_str().or(c["error"].as_str()) {
        p.alarm(&format!(
            "{th} thread(s): Embree's numbers were NOT checked against the native driver: {why}"
        ));
        return;
    }
    let text = format!(
        "{th} thread(s): the binding's fastest ({}) runs at {} of the native driver's \
         fastest ({}, by {}) (95% interval {}, {} rounds in alternating order)",
        super::page::compact(&c["binding_best"]),
        num(c["binding_over_native"].as_f64(), 3),
        super::page::compact(&c["native_best"]),
        super::page::compact(&c["native_best_by"]),
        interval(&c["binding_over_native_interval_95"]),
        super::page::compact(&c["rounds"]),
    );
    if c["within_5_percent"].as_bool() == Some(true) {
        p.note(&format!(
            "{text}: within 5%, Embree's numbers are its own best."
        ));
    } else {
        p.alarm(&format!(
            "{text}: OUTSIDE 5%: the binding's Embree rows are not Embree at its best; \
             the headline uses the fastest row of either."
        ));
    }
}

//! `rendiff bench [SCENE]` (no subcommand): raster and trace timed on one
//! scene, per thread count, as medians after a warm-up, with throughput and
//! operation counts, as JSON. Kept as the quick single-scene measurement; the
//! subcommands (knobs, peers, crossover, stability) build on the same helpers.

use anyhow::{Context, Result};
use rendiff::raster::{self, RasterOptions};
use rendiff::scene::resolve::ResolvedScene;
use rendiff::trace::{self, BvhQuality, TraceBvh};
use serde_json::{json, Value};

/// What to measure.
#[derive(Debug, Clone)]
pub struct BenchOptions {
    /// Override the scene's resolution.
    pub size: Option<(u32, u32)>,
    /// Thread counts to measure.
    pub threads: Vec<usize>,
    /// Timed runs per configuration (after one warm-up).
    pub runs: usize,
    /// BVH quality for the tracer.
    pub bvh: BvhQuality,
}

fn timed<T>(runs: usize, f: impl FnMut() -> T) -> (f64, Vec<f64>, T) {
    let t = super::timed(runs, f);
    (t.median_s, t.runs_s, t.last)
}

/// Runs the benchmark and returns its JSON record.
pub fn run(scene: &ResolvedScene, label: &str, opts: &BenchOptions) -> Result<Value> {
    let environment = super::environment();
    let mut scene = scene.clone();
    if let Some((w, h)) = opts.size {
        scene = super::resized(&scene, w, h)?;
    }
    let cam = &scene.camera;
    let pixels = cam.pixel_count() as f64;
    let tris = scene.triangles.len() as f64;
    let mut rows = Vec::new();
    for &threads in &opts.threads {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .context("cannot start worker threads")?;
        pool.install(|| {
            let (raster_s, raster_all, rf) = timed(opts.runs, || {
                raster::render(&scene, RasterOptions::default(), &|_| {})
            });
            let (build_s, build_all, bvh) = timed(opts.runs, || TraceBvh::build(&scene, opts.bvh));
            let (trace_s, trace_all, tf) = timed(opts.runs, || {
                trace::render_with_bvh(&scene, &bvh, trace::TraceOptions::default(), &|_| {})
            });
            let identical = rf.prim == tf.prim
                && rf
                    .z
                    .iter()
                    .zip(&tf.z)
                    .all(|(a, b)| a.to_bits() == b.to_bits());
            rows.push(json!({
                "threads": threads,
                "raster": {
                    "median_s": raster_s, "runs_s": raster_all,
                    "mtris_per_s": tris / raster_s / 1e6,
                    "mpixels_per_s": pixels / raster_s / 1e6,
                    "counters": rf.counters,
                },
                "trace": {
                    "bvh_build_median_s": build_s, "bvh_build_runs_s": build_all,
                    "median_s": trace_s, "runs_s": trace_all,
                    "mrays_per_s": pixels / trace_s / 1e6,
                    "counters": tf.counters,
                },
                "raster_equals_trace": identical,
            }));
        });
    }
    let mut record = json!({
        "benchmark": "core-visibility",
        "environment": environment,
        "scene": label,
        "width": cam.width, "height": cam.height,
        "triangles": scene.triangles.len(),
        "bvh": opts.bvh,
        "runs": opts.runs,
        "cpu": std::thread::available_parallelism().map(|n| n.get()).unwrap_or(1),
        "rendiff_version": env!("CARGO_PKG_VERSION"),
        "results": rows,
    });
    super::finish_environment(&mut record);
    Ok(record)
}

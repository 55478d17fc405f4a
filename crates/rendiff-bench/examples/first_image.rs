//! `bench peers`' time-to-first-image table alone, on one scene: the core
//! raster, the core tracer at every BVH quality (build, camera set-up and
//! trace) and one native Embree configuration (its build included), in the
//! bench's paired, alternating rounds ([`rendiff_bench::peer_tables::first_image`]).
//! The full `bench peers` sweeps every Embree configuration first and takes
//! many minutes; this measures the one table a change to the build moves.
//!
//! `cargo run --release -p rendiff-bench --example first_image -- \
//!   [SCENE@WxH] [ROUNDS] [THREADS,..] [EMBREE CONFIG NAME]`
//! (defaults: scenes/million.toml@1920x1080, 11, 1,2, the configuration
//! with the least build + trace per thread count in the Nov 29 record of
//! docs/benchmarks.md). `--json=FILE` (anywhere) also writes each thread
//! count's table as `bench peers` records it, with the machine's load and
//! the other processes' share of the CPU during it.
//!
//! `... --example first_image -- phases QUALITY N [SCENE@WxH] [THREADS]`
//! instead runs N first images of the tracer at QUALITY on THREADS threads
//! (default 1), printing each part's seconds (for a profile under `perf
//! record`); QUALITY `raster` runs the raster's instead.

use anyhow::{Context, Result};
use rendiff::names::Named;
use rendiff::trace::{self, TraceBvh, TraceOptions};
use rendiff_bench::example_args::ExampleArgs;
use rendiff_bench::knobs::SceneSpec;
use rendiff_bench::{machine_cpu, peer_tables};
use std::time::Instant;

const MILLION: &str = "scenes/million.toml@1920x1080";

fn main() -> Result<()> {
    let args = ExampleArgs::from_env();
    let arg = |i: usize, d: &str| args.get(i, d);
    // As `bench peers` does before its tables.
    let allocator = rendiff_bench::keep_freed_memory();
    if arg(0, "") == "phases" {
        return phases(
            &arg(1, "medium"),
            arg(2, "5").parse().context("N")?,
            &arg(3, MILLION),
            arg(4, "1").parse().context("THREADS")?,
        );
    }
    let spec: SceneSpec = arg(0, MILLION).parse().map_err(anyhow::Error::msg)?;
    let rounds: usize = arg(1, "11").parse().context("ROUNDS")?;
    let threads = args.counts(2, "1,2", "THREADS")?;
    let scene = spec.load()?;
    let mut record = serde_json::Map::new();
    for &t in &threads {
        // The least build + trace in the Nov 29 record, per thread count.
        let default = if t == 1 {
            "native stream1M coherent low"
        } else {
            "native streamNM16 coherent low"
        };
        let config = args.embree(3, default)?;
        let load_before = rendiff_bench::load_average();
        let cpu_before = machine_cpu::read();
        let v = rendiff_bench::pool(t)?
            .install(|| peer_tables::first_image(&scene, t, Some(config), rounds));
        let cpu = match (cpu_before, machine_cpu::read()) {
            (Some(a), Some(b)) => machine_cpu::shares(&a, &b),
            _ => serde_json::Value::Null,
        };
        let load_after = rendiff_bench::load_average();
        println!(
            "{t} thread(s), {} ({} rounds): load {load_before:?} -> {load_after:?}, cpu {cpu}",
            spec.path.display(),
            v["rounds"]
        );
        for row in v["rows"].as_array().into_iter().flatten() {
            println!(
                "  {:<28} {:.4} s  over Embree {:.3}x {}  parts {}",
                row["name"].as_str().unwrap_or("?"),
                row["median_s"].as_f64().unwrap_or(f64::NAN),
                row["over_embree"]["median"].as_f64().unwrap_or(f64::NAN),
                row["over_embree"]["interval_95"],
                row["parts_median_s"],
            );
        }
        println!("  cost model picks: {}", v["cost_model_pick"]);
        record.insert(
            format!("{t}_threads"),
            serde_json::json!({
                "embree_configuration": config.name(),
                "load_average_before": load_before,
                "load_average_after": load_after,
                "cpu_during_run": cpu,
                "time_to_first_image": v,
            }),
        );
    }
    if let Some(path) = &args.json_out {
        let out = serde_json::json!({
            "benchmark": "first_image example (bench peers' time-to-first-image table on one scene)",
            "scene": format!("{}", spec.path.display()),
            "rounds": rounds,
            "allocator": allocator,
            "tables": record,
        });
        rendiff_bench::write_json_file(path, &out)?;
        eprintln!("wrote {path}");
    }
    Ok(())
}

/// `n` first images of the tracer at `quality` on `threads` threads, each
/// part's seconds printed.
fn phases(quality: &str, n: usize, scene: &str, threads: usize) -> Result<()> {
    if quality == "raster" {
        return raster_only(n, scene, threads);
    }
    let quality = rendiff_bench::example_args::bvh_quality(quality)?;
    let spec: SceneSpec = scene.parse().map_err(anyhow::Error::msg)?;
    let scene = spec.load()?;
    rendiff_bench::pool(threads)?.install(|| {
        for _ in 0..n {
            let t0 = Instant::now();
            let bvh = TraceBvh::build(&scene, quality);
            let built = t0.elapsed().as_secs_f64();
            let f = trace::render_with_bvh(&scene, &bvh, TraceOptions::default(), &|_| {});
            let all = t0.elapsed().as_secs_f64();
            std::hint::black_box(f);
            println!(
                "{}: tree {:.4} s, camera {:.4} s, trace + buffers {:.4} s, first image {:.4} s; load {:?}",
                quality.name(),
                bvh.tree_seconds,
                bvh.camera_seconds,
                all - built,
                all,
                rendiff_bench::load_average()
            );
        }
    });
    Ok(())
}

/// `n` first images of the raster on `threads` threads, each one's seconds
/// printed.
fn raster_only(n: usize, scene: &str, threads: usize) -> Result<()> {
    let spec: SceneSpec = scene.parse().map_err(anyhow::Error::msg)?;
    let scene = spec.load()?;
    rendiff_bench::pool(threads)?.install(|| {
        for _ in 0..n {
            let t0 = Instant::now();
            let f = rendiff::raster::render(&scene, Default::default(), &|_| {});
            let s = t0.elapsed().as_secs_f64();
            std::hint::black_box(f);
            println!("raster: first image {s:.4} s");
        }
    });
    Ok(())
}

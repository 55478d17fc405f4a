//! `bench peers`' per-frame table alone, on one scene: the core tracer's new
//! camera ([`TraceBvh::aim`]) plus trace against one native Embree
//! configuration, in the bench's paired, alternating rounds
//! ([`rendiff_bench::peer_tables::per_frame`]). The full `bench peers`
//! sweeps every Embree configuration first and takes many minutes; this
//! measures the one table a change to the camera set-up moves, in seconds.
//!
//! `cargo run --release -p rendiff-bench --example per_frame -- \
//!   [SCENE@WxH] [ROUNDS] [THREADS,..] [BVH] [EMBREE CONFIG NAME]`
//! (defaults: scenes/million.toml@1920x1080, 11, 1,2, slow, the per-frame
//! table's fastest configuration in docs/benchmarks.md per thread count).
//! A sixth argument `aim-only` times ROUNDS camera set-ups alone (for a
//! profile of [`TraceBvh::aim`]); `frame-cpu` times ROUNDS new-camera frames
//! (set-up, then a frame of pixel rays) in this thread's CPU seconds, each
//! part apart, with no Embree (on 1 thread the whole frame runs on this
//! worker, so a machine shared with other jobs disturbs it less than wall
//! time; a frame now sets up the leaves it reaches inside its trace). `--json=FILE` (anywhere) also writes each
//! thread count's table, as `bench peers` records it, with the machine's
//! load, so a figure quoted from this run links to its record.

use anyhow::{Context, Result};
use rendiff::trace::TraceBvh;
use rendiff_bench::example_args::ExampleArgs;
use rendiff_bench::knobs::SceneSpec;
use rendiff_bench::native_embree::{NativeScene, PreparedRays};
use rendiff_bench::peer_tables;
use std::time::Instant;

fn main() -> Result<()> {
    let mut record = serde_json::Map::new();
    let args = ExampleArgs::from_env();
    let arg = |i: usize, d: &str| args.get(i, d);
    let spec: SceneSpec = arg(0, "scenes/million.toml@1920x1080")
        .parse()
        .map_err(anyhow::Error::msg)?;
    let rounds: usize = arg(1, "11").parse().context("ROUNDS")?;
    let threads = args.counts(2, "1,2", "THREADS")?;
    let quality = args.bvh(3, "slow")?;
    let scene = spec.load()?;
    for &t in &threads {
        // The fastest per frame in the Nov 29 record, per thread count.
        let default = if t == 1 {
            "native streamNM16 coherent medium"
        } else {
            "native stream1M coherent high"
        };
        let config = args.embree(4, default)?;
        rendiff_bench::pool(t)?.install(|| -> Result<()> {
            let t0 = Instant::now();
            let mut bvh = TraceBvh::build(&scene, quality);
            eprintln!(
                "{t} thread(s): tree {:.3} s, first aim {:.3} s ({:.1} s wall)",
                bvh.tree_seconds,
                bvh.camera_seconds,
                t0.elapsed().as_secs_f64()
            );
            if arg(5, "") == "aim-only" {
                // For a profile of the set-up alone: `rounds` aims, no trace.
                // On 1 thread the set-up runs on this worker alone, so its
                // CPU time is what it costs on a machine shared with others.
                let mut s = Vec::new();
                let mut cpu = Vec::new();
                for _ in 0..rounds {
                    let c0 = thread_cpu_s();
                    s.push(bvh.aim(&scene));
                    cpu.push(thread_cpu_s() - c0);
                }
                s.sort_by(f64::total_cmp);
                cpu.sort_by(f64::total_cmp);
                println!(
                    "{t} thread(s): aim median {:.4} s, min {:.4} s; this thread's CPU median {:.4} s",
                    s[s.len() / 2],
                    s[0],
                    cpu[cpu.len() / 2]
                );
                return Ok(());
            }
            if arg(5, "") == "frame-cpu" {
                let (mut aim, mut frame) = (Vec::new(), Vec::new());
                for _ in 0..rounds {
                    let c0 = thread_cpu_s();
                    bvh.aim(&scene);
                    let c1 = thread_cpu_s();
                    let keys = rendiff::trace::trace_keys(
                        &scene,
                        &bvh,
                        rendiff::trace::TraceOptions::default(),
                        &|_| {},
                    );
                    std::hint::black_box(keys);
                    aim.push(c1 - c0);
                    frame.push(thread_cpu_s() - c1);
                }
                let med = |v: &mut Vec<f64>| {
                    v.sort_by(f64::total_cmp);
                    v[v.len() / 2]
                };
                println!(
                    "{t} thread(s): this thread's CPU medians: new camera {:.4} s, trace {:.4} s; load {:?}",
                    med(&mut aim),
                    med(&mut frame),
                    rendiff_bench::load_average()
                );
                return Ok(());
            }
            let built = NativeScene::build(&scene, config.quality, false, t)
                .map_err(anyhow::Error::msg)?;
            let t1 = Instant::now();
            let rays = PreparedRays::new(&scene.camera);
            let prepare_s = t1.elapsed().as_secs_f64();
            let v = peer_tables::per_frame(
                &scene,
                &mut bvh,
                quality,
                Some((&built, &rays, config, prepare_s)),
                rounds,
            );
            let c = &v["core"];
            let r = &v["core_over_embree_new_camera_counted"];
            let s = &v["core_over_embree_same_camera"];
            println!(
                "{t} thread(s), {}: new camera {:.4} s, trace {:.4} s, Embree {:.4} s \
                 (on rays prepared outside: {:.4} s) ({}); \
                 new camera counted {:.3}x {}, same camera {:.3}x {}; load {:?}",
                spec.path.display(),
                c["new_camera_s_median"].as_f64().unwrap_or(f64::NAN),
                c["trace_s_median"].as_f64().unwrap_or(f64::NAN),
                v["embree"]["trace_s_median"].as_f64().unwrap_or(f64::NAN),
                v["embree"]["trace_alone_s_median"].as_f64().unwrap_or(f64::NAN),
                config.name(),
                r["median"].as_f64().unwrap_or(f64::NAN),
                r["interval_95"],
                s["median"].as_f64().unwrap_or(f64::NAN),
                s["interval_95"],
                rendiff_bench::load_average(),
            );
            println!("  new camera per round: {}", c["new_camera_s"]);
            record.insert(
                format!("{t}_threads"),
                serde_json::json!({
                    "embree_configuration": config.name(),
                    "bvh": arg(3, "slow"),
                    "load_average": rendiff_bench::load_average(),
                    "per_frame": v,
                }),
            );
            Ok(())
        })?;
    }
    if let Some(path) = &args.json_out {
        let out = serde_json::json!({
            "benchmark": "per_frame example (bench peers' per-frame table on one scene)",
            "scene": format!("{}", spec.path.display()),
            "rounds": rounds,
            "tables": record,
        });
        rendiff_bench::write_json_file(path, &out)?;
        eprintln!("wrote {path}");
    }
    Ok(())
}

/// This thread's CPU seconds so far.
fn thread_cpu_s() -> f64 {
    let mut ts = libc::timespec {
        tv_sec: 0,
        tv_nsec: 0,
    };
    // SAFETY: `ts` is a valid, writable timespec for the call's duration.
    unsafe { libc::clock_gettime(libc::CLOCK_THREAD_CPUTIME_ID, &mut ts) };
    ts.tv_sec as f64 + ts.tv_nsec as f64 * 1e-9
}

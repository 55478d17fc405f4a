//! A manual timing loop for the packet kernel (`#[ignore]`d: no timed
//! assertions). Run with
//! `TRACE_SCENE=scenes/million.toml TRACE_SIZE=1920x1080 cargo test --release
//! -p rendiff-core trace::timing -- --ignored --nocapture` (`TRACE_BVH=slow`
//! for obvhs' slow build, as `bench peers` also measures; `TRACE_SCENE=grid:N`
//! for `bench crossover`'s grid, as in `raster_timing`); it prints the BVH
//! build time, the keys-only Mrays/s per thread count, and a hash of the keys
//! (so two builds of the kernel can be compared bit for bit).

#[cfg(test)]
mod tests {
    use crate::raster_timing::tests::{median, scene};
    use crate::trace::{trace_keys, BvhQuality, TraceBvh, TraceOptions};
    use std::time::Instant;

    /// Prints build time, Mrays/s and a key hash for one scene.
    #[test]
    #[ignore]
    fn time_packet_kernel() {
        let env = |k: &str, d: &str| std::env::var(k).unwrap_or_else(|_| d.to_string());
        let path = env("TRACE_SCENE", "scenes/million.toml");
        let size = env("TRACE_SIZE", "1920x1080");
        let runs: usize = env("TRACE_RUNS", "5").parse().unwrap();
        let threads: Vec<usize> = env("TRACE_THREADS", "1,2")
            .split(',')
            .map(|t| t.parse().unwrap())
            .collect();
        let scene = scene(&path, &size);
        let pixels = scene.camera.pixel_count() as f64;
        for &t in &threads {
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(t)
                .build()
                .unwrap();
            pool.install(|| {
                let mut builds = Vec::new();
                let quality = if std::env::var("TRACE_BVH").as_deref() == Ok("slow") {
                    BvhQuality::Slow
                } else {
                    BvhQuality::Medium
                };
                let mut bvh = TraceBvh::build(&scene, quality);
                for _ in 0..3 {
                    let st = Instant::now();
                    bvh = TraceBvh::build(&scene, quality);
                    builds.push(st.elapsed().as_secs_f64());
                }
                let opts = TraceOptions::default();
                let mut keys = trace_keys(&scene, &bvh, opts, &|_| {});
                let mut times = Vec::new();
                for _ in 0..runs {
                    let st = Instant::now();
                    keys = trace_keys(&scene, &bvh, opts, &|_| {});
                    times.push(st.elapsed().as_secs_f64());
                }
                let hash = keys.keys.iter().fold(0xcbf29ce484222325u64, |h, &k| {
                    (h ^ k).wrapping_mul(0x100000001b3)
                });
                let med = median(&mut times);
                println!(
                    "TIMING {path} {size} threads={t} build_s={:.4} trace_s={med:.4} mrays={:.2} hash={hash:016x} nodes={} cov={}",
                    median(&mut builds),
                    pixels / med / 1e6,
                    keys.counters.bvh_nodes_visited,
                    keys.counters.coverage_tests,
                );
            });
        }
    }
}

//! A manual timing loop for the packet kernel (`#[ignore]`d: no timed
//! assertions). Run with
//! `TRACE_SCENE=scenes/million.toml TRACE_SIZE=1920x1080 cargo test --release
//! -p rendiff-core trace::timing -- --ignored --nocapture` (`TRACE_BVH=slow`
//! for obvhs' slow build, as `bench peers` also measures; `TRACE_BUILD=once`
//! builds it once, untimed, for profiling the kernel; `TRACE_SCENE=grid:N`
//! for `bench crossover`'s grid, as in `raster::timing`); it prints the BVH
//! build time, the keys-only Mrays/s per thread count, and a hash of the keys
//! (so two builds of the kernel can be compared bit for bit).

#[cfg(test)]
mod tests {
    use crate::raster::timing::tests::{key_hash, TimingLoop};
    use crate::trace::{trace_keys, BvhQuality, TraceBvh, TraceOptions};

    /// Prints build time, Mrays/s and a key hash for one scene.
    #[test]
    #[ignore]
    fn time_packet_kernel() {
        let lp = TimingLoop::from_env("TRACE", 5);
        let quality = if std::env::var("TRACE_BVH").as_deref() == Ok("slow") {
            BvhQuality::Slow
        } else {
            BvhQuality::Medium
        };
        let pixels = lp.scene.camera.pixel_count() as f64;
        lp.per_thread_count(|t| {
            // The build once, untimed, under TRACE_BUILD=once (profiling the kernel).
            let (build_s, bvh) = if std::env::var("TRACE_BUILD").as_deref() == Ok("once") {
                (f64::NAN, TraceBvh::build(&lp.scene, quality))
            } else {
                let (med, _, bvh) = lp.timed(|| TraceBvh::build(&lp.scene, quality));
                (med, bvh)
            };
            let opts = TraceOptions::default();
            let (med, least, keys) = lp.timed(|| trace_keys(&lp.scene, &bvh, opts, &|_| {}));
            println!(
                "TIMING {} {} threads={t} build_s={build_s:.4} trace_ms={:.3} min_ms={:.3} mrays={:.2} hash={:016x} nodes={} cov={}",
                lp.path,
                lp.size,
                med * 1e3,
                least * 1e3,
                pixels / med / 1e6,
                key_hash(&keys.keys),
                keys.counters.bvh_nodes_visited,
                keys.counters.coverage_tests,
            );
        });
    }
}

//! A manual timing loop for the rasterizer's visibility pass (`#[ignore]`d:
//! no timed assertions), the raster's twin of `trace::timing`. Run with
//! `RASTER_SCENE=scenes/million.toml RASTER_SIZE=1920x1080 cargo test
//! --release -p rendiff-core raster_timing -- --ignored --nocapture`
//! (`RASTER_SCENE=grid:1` is `bench crossover`'s two-triangle grid, `grid:N`
//! its `2 N²`-triangle one); it prints the pass's median time per thread
//! count, its counts, and a hash of the keys (so two builds of the raster can
//! be compared bit for bit, and with the tracer's hash).

#[cfg(test)]
pub(crate) mod tests {
    use crate::raster::{render_keys, RasterOptions};
    use crate::scene::generators::crossover_grid;
    use crate::scene::resolve::ResolvedScene;
    use std::time::Instant;

    /// The median (sorts `v`).
    pub(crate) fn median(v: &mut [f64]) -> f64 {
        v.sort_by(f64::total_cmp);
        v[v.len() / 2]
    }

    /// The scene a timing loop names (a path from the repository root, or
    /// `grid:N`), at `WxH`.
    pub(crate) fn scene(path: &str, size: &str) -> ResolvedScene {
        let (w, h) = size.split_once('x').unwrap();
        let (w, h): (u32, u32) = (w.parse().unwrap(), h.parse().unwrap());
        if let Some(nx) = path.strip_prefix("grid:") {
            return crossover_grid(nx.parse().unwrap(), w, false).unwrap();
        }
        let file = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("../..")
            .join(path);
        let s = crate::scene::Scene::load(&file).unwrap();
        ResolvedScene::resolve(&s).unwrap().resized(w, h).unwrap()
    }

    /// Prints the pass's time, counts and key hash for one scene.
    #[test]
    #[ignore]
    fn time_raster_pass() {
        let env = |k: &str, d: &str| std::env::var(k).unwrap_or_else(|_| d.to_string());
        let path = env("RASTER_SCENE", "scenes/million.toml");
        let size = env("RASTER_SIZE", "1920x1080");
        let runs: usize = env("RASTER_RUNS", "9").parse().unwrap();
        let threads: Vec<usize> = env("RASTER_THREADS", "1,2")
            .split(',')
            .map(|t| t.parse().unwrap())
            .collect();
        let scene = scene(&path, &size);
        for &t in &threads {
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(t)
                .build()
                .unwrap();
            pool.install(|| {
                let opts = RasterOptions::default();
                let mut keys = render_keys(&scene, opts, &|_| {});
                let mut times = Vec::new();
                for _ in 0..runs {
                    let st = Instant::now();
                    keys = render_keys(&scene, opts, &|_| {});
                    times.push(st.elapsed().as_secs_f64());
                }
                let hash = keys.keys.iter().fold(0xcbf29ce484222325u64, |h, &k| {
                    (h ^ k).wrapping_mul(0x100000001b3)
                });
                let c = keys.counters;
                println!(
                    "TIMING {path} {size} threads={t} raster_ms={:.3} hash={hash:016x} setups={} cov={} fast={} hidden={}",
                    median(&mut times) * 1e3,
                    c.triangle_setups,
                    c.coverage_tests,
                    c.fast_decided,
                    c.hidden_skipped,
                );
            });
        }
    }
}

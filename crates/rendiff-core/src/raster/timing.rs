//! A manual timing loop for the rasterizer's visibility pass (`#[ignore]`d:
//! no timed assertions), the raster's twin of `trace::timing`. Run with
//! `RASTER_SCENE=scenes/million.toml RASTER_SIZE=1920x1080 cargo test
//! --release -p rendiff-core raster::timing -- --ignored --nocapture`
//! (`RASTER_SCENE=grid:1` is `bench crossover`'s two-triangle grid, `grid:N`
//! its `2 N²`-triangle one); it prints the pass's median time per thread
//! count, its counts, and a hash of the keys (so two builds of the raster can
//! be compared bit for bit, and with the tracer's hash). The harness both
//! loops share lives here ([`tests::TimingLoop`]).

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

    /// FNV-1a over a pass's keys: equal hashes, equal keys (in practice).
    pub(crate) fn key_hash(keys: &[u64]) -> u64 {
        keys.iter().fold(0xcbf29ce484222325u64, |h, &k| {
            (h ^ k).wrapping_mul(0x100000001b3)
        })
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

    /// What a timing loop reads from `PREFIX_SCENE`, `PREFIX_SIZE`,
    /// `PREFIX_RUNS` and `PREFIX_THREADS`, and the scene it names.
    pub(crate) struct TimingLoop {
        /// The scene as named.
        pub path: String,
        /// `WxH`.
        pub size: String,
        /// Timed runs after the warm-up.
        pub runs: usize,
        /// Thread counts, one pool each.
        pub threads: Vec<usize>,
        /// The scene at that size.
        pub scene: ResolvedScene,
    }

    impl TimingLoop {
        /// The settings under `prefix`, with `runs` timed runs by default.
        pub(crate) fn from_env(prefix: &str, runs: usize) -> TimingLoop {
            let env = |k: &str, d: &str| {
                std::env::var(format!("{prefix}_{k}")).unwrap_or_else(|_| d.to_string())
            };
            let (path, size) = (
                env("SCENE", "scenes/million.toml"),
                env("SIZE", "1920x1080"),
            );
            let scene = scene(&path, &size);
            TimingLoop {
                runs: env("RUNS", &runs.to_string()).parse().unwrap(),
                threads: env("THREADS", "1,2")
                    .split(',')
                    .map(|t| t.parse().unwrap())
                    .collect(),
                path,
                size,
                scene,
            }
        }

        /// `body(threads)` inside a pool of each thread count.
        pub(crate) fn per_thread_count(&self, body: impl Fn(usize) + Sync + Send) {
            for &t in &self.threads {
                let pool = rayon::ThreadPoolBuilder::new()
                    .num_threads(t)
                    .build()
                    .unwrap();
                pool.install(|| body(t));
            }
        }

        /// `pass` once to warm up, then `runs` times: the median seconds, the
        /// least (what a shared machine's stolen time disturbs least, for
        /// comparing two builds) and the last result.
        pub(crate) fn timed<T>(&self, mut pass: impl FnMut() -> T) -> (f64, f64, T) {
            let mut last = pass();
            let mut times = Vec::new();
            for _ in 0..self.runs {
                let st = Instant::now();
                last = pass();
                times.push(st.elapsed().as_secs_f64());
            }
            let least = times.iter().copied().fold(f64::INFINITY, f64::min);
            (median(&mut times), least, last)
        }
    }

    /// Prints the pass's time, counts and key hash for one scene.
    #[test]
    #[ignore]
    fn time_raster_pass() {
        let lp = TimingLoop::from_env("RASTER", 9);
        lp.per_thread_count(|t| {
            let opts = RasterOptions::default();
            let (med, least, keys) = lp.timed(|| render_keys(&lp.scene, opts, &|_| {}));
            let c = keys.counters;
            println!(
                "TIMING {} {} threads={t} raster_ms={:.3} min_ms={:.3} hash={:016x} setups={} cov={} fast={} hidden={}",
                lp.path,
                lp.size,
                med * 1e3,
                least * 1e3,
                key_hash(&keys.keys),
                c.triangle_setups,
                c.coverage_tests,
                c.fast_decided,
                c.hidden_skipped,
            );
        });
    }
}

//! `rendiff bench`: speed measured against accuracy (docs/DESIGN.md "Speed versus
//! accuracy"), in one run per question, written as JSON plus an HTML page with
//! SVG plots under `reports/bench/`.
//!
//! - [`core_loops`]: raster and trace on one scene per thread count (the plain `rendiff bench`).
//! - [`knobs`]: every knob that trades time for error, against one reference, with the Pareto front
//!   (the renderers' own quality settings in [`direct`] and [`spp`]).
//! - [`peers`]: the core against Embree, pyrender and Mitsuba on identical work, as ratios
//!   (Embree held to its best by the native driver in [`native_embree`]).
//! - [`crossover`]: raster against trace as triangles shrink from a few large to millions of tiny.
//! - [`stability`]: scene families pushed to numerical extremes through `rendiff check`.
//! - [`fuzz`]: generated scenes a minute through `rendiff fuzz`, start-up shares, reduction time per finding.
//! - [`variance`]: whether the path tracer's variance-of-the-mean estimate is calibrated, and its bias.
//!
//! Everything here is a measurement, never an assertion: tests only check that
//! the benchmarks run and write well-formed output. Timings are medians of
//! several runs after a warm-up, and each record carries the machine's load
//! average before and after and how its CPU time divided among the
//! benchmark, other processes and the hypervisor ([`machine_cpu`]), because a
//! busy machine skews every number.

pub mod cli;
pub mod core_loops;
pub mod crossover;
pub mod direct;
pub mod embree_rays;
pub mod equal_time;
pub mod example_args;
pub mod fuzz;
pub mod harness;
pub mod knobs;
pub mod machine_cpu;
pub mod measure;
pub mod native_embree;
pub mod outputs;
pub mod page;
pub mod pareto;
pub mod peer_tables;
pub mod peers;
pub mod plot;
pub mod radiance;
pub mod scale;
pub mod spp;
pub mod stability;
pub mod variance;
pub mod variance_stats;
pub mod which_loop;

pub use core_loops::{run, BenchOptions};

use anyhow::{Context, Result};
use rendiff::frame::Frame;
use rendiff::scene::resolve::ResolvedScene;
use serde_json::{json, Value};
use std::path::{Path, PathBuf};
use std::time::Instant;

/// The `rendiff` binary beside this one (both are built into one target
/// folder): benchmarks that time or isolate whole `rendiff` commands run it.
pub fn rendiff_binary() -> Result<PathBuf> {
    let exe = std::env::current_exe().context("cannot find the running binary")?;
    let bin = exe.with_file_name("rendiff");
    if bin.is_file() {
        Ok(bin)
    } else {
        anyhow::bail!(
            "{}: not built (cargo build --release -p rendiff)",
            bin.display()
        )
    }
}

/// One timed `rendiff` command: wall seconds, its exit status (1, a verdict
/// failed, is measured all the same) and its standard output.
#[derive(Debug)]
pub struct RendiffRun {
    /// Wall seconds.
    pub seconds: f64,
    /// Exit status: 0 or 1.
    pub code: Option<i32>,
    /// Standard output.
    pub stdout: String,
}

/// Runs `rendiff ARGS` as `rendiff check` runs a renderer: in a process
/// group of its own registered with the shutdown handler (an interrupted
/// benchmark kills it, instead of leaving it writing into the removed
/// scratch folder), dying with this process, its output captured under
/// `logs`, with no limit of its own (each renderer has `--timeout`). With
/// `venv_of`, that checkout's `.venv/bin` (where it exists) goes first on
/// PATH: planted renderers run as `python3` scripts needing numpy. Exit 0
/// or 1 (failures found) is a run, anything else an error.
pub fn run_rendiff(args: &[String], venv_of: Option<&Path>, logs: &Path) -> Result<RendiffRun> {
    let exe = rendiff_binary()?;
    let mut cmd = std::process::Command::new(&exe);
    cmd.args(args);
    if let Some(venv) = venv_of.map(|root| root.join(".venv/bin")) {
        if venv.is_dir() {
            let path = std::env::var_os("PATH").unwrap_or_default();
            let mut dirs = vec![venv];
            dirs.extend(std::env::split_paths(&path));
            cmd.env(
                "PATH",
                std::env::join_paths(dirs).context("cannot build PATH")?,
            );
        }
    }
    let o = rendiff::check::process::run_with_timeout(
        cmd,
        std::time::Duration::from_secs(30 * 24 * 3600),
        logs,
    )
    .with_context(|| format!("cannot run {}", exe.display()))?;
    if !matches!(o.code, Some(0) | Some(1)) {
        anyhow::bail!(
            "rendiff {} failed ({}): {}",
            args.join(" "),
            o.how(),
            o.stderr_tail(4).lines().collect::<Vec<_>>().join(" | ")
        );
    }
    Ok(RendiffRun {
        seconds: o.seconds,
        code: o.code,
        stdout: o.stdout,
    })
}

/// Options every subcommand shares.
#[derive(Debug, Clone)]
pub struct Common {
    /// Timed runs per configuration (after one warm-up).
    pub runs: usize,
    /// Tiny configuration (small images, few settings): for smoke tests, not for numbers.
    pub quick: bool,
    /// Output folder for JSON, HTML and SVG.
    pub out_dir: PathBuf,
    /// Repository root (scenes, references, the Python harness's venv).
    pub root: PathBuf,
    /// Seconds before an external renderer subprocess is killed.
    pub timeout_s: u64,
}

/// Median of a sample (the mean of the two middle values for an even count).
pub fn median(v: &[f64]) -> f64 {
    if v.is_empty() {
        return f64::NAN;
    }
    let mut v = v.to_vec();
    v.sort_by(f64::total_cmp);
    let n = v.len();
    if n % 2 == 1 {
        v[n / 2]
    } else {
        (v[n / 2 - 1] + v[n / 2]) / 2.0
    }
}

/// A timed measurement: median and every run, plus the last run's result.
#[derive(Debug, Clone)]
pub struct Timed<T> {
    /// Median wall-clock seconds.
    pub median_s: f64,
    /// Every timed run, in order.
    pub runs_s: Vec<f64>,
    /// What the last run returned (results are deterministic, so any run would do).
    pub last: T,
}

impl<T> Timed<T> {
    /// Median and runs as JSON, for the records.
    pub fn json(&self) -> Value {
        json!({"median_s": self.median_s, "runs_s": self.runs_s})
    }
}

/// Runs `f` once untimed (caches, page faults, lazy initialisation), then
/// `runs` times timed; the median is robust to one disturbed run.
pub fn timed<T>(runs: usize, mut f: impl FnMut() -> T) -> Timed<T> {
    let mut last = f();
    let mut times = Vec::with_capacity(runs.max(1));
    for _ in 0..runs.max(1) {
        let t = Instant::now();
        last = f();
        times.push(t.elapsed().as_secs_f64());
    }
    Timed {
        median_s: median(&times),
        runs_s: times,
        last,
    }
}

/// The scene with its camera at another resolution (same eye, field of view, near and far).
pub fn resized(scene: &ResolvedScene, w: u32, h: u32) -> Result<ResolvedScene> {
    scene.resized(w, h).map_err(anyhow::Error::msg)
}

/// Loads and resolves a scene file.
pub fn load_scene(path: &Path) -> Result<ResolvedScene> {
    let scene = rendiff::scene::Scene::load(path)?;
    Ok(ResolvedScene::resolve(&scene)?)
}

/// A rayon pool of exactly `threads` workers, so thread counts are what the record says.
pub fn pool(threads: usize) -> Result<rayon::ThreadPool> {
    rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .context("cannot start worker threads")
}

/// Logical CPUs available to this process.
pub fn cpus() -> usize {
    std::thread::available_parallelism()
        .map(|n| n.get())
        .unwrap_or(1)
}

/// The 1, 5 and 15 minute load averages (Linux), or None elsewhere: a number
/// above the idle level means other work competed with the benchmark, or
/// (after the run) counts the benchmark's own threads; `cpu_during_run` says which.
pub fn load_average() -> Option<[f64; 3]> {
    let text = std::fs::read_to_string("/proc/loadavg").ok()?;
    let mut it = text.split_whitespace().map(|w| w.parse::<f64>().ok());
    Some([it.next()??, it.next()??, it.next()??])
}

fn cpu_model() -> Option<String> {
    let text = std::fs::read_to_string("/proc/cpuinfo").ok()?;
    text.lines()
        .find(|l| l.starts_with("model name"))
        .and_then(|l| l.split_once(':'))
        .map(|(_, v)| v.trim().to_string())
}

/// Where and when a benchmark ran: what a reader needs to trust or discount its numbers.
pub fn environment() -> Value {
    json!({
        "cpus": cpus(),
        "cpu_model": cpu_model(),
        "load_average_before": load_average(),
        CPU_AT_START: machine_cpu::read(),
        "rendiff_version": env!("CARGO_PKG_VERSION"),
        "build": if cfg!(debug_assertions) { "debug assertions on (not for numbers)" } else { "release" },
        "unix_time": std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map(|d| d.as_secs())
            .unwrap_or(0),
    })
}

/// Keeps freed memory in the process (glibc's allocator: blocks up to its
/// 32 MiB ceiling from the heap, the heap never trimmed), so that repeated
/// runs of a loop that allocates its frame reuse the same pages. Without
/// it, whether a run's buffers came back as fresh pages (a fault and
/// zeroing per 4 KiB: 1-2 ms on a 512x512 frame's 8 MB) depended on the
/// allocator's history, and `bench crossover`'s whole-frame times were
/// bimodal run to run. Applies to every loop timed afterwards alike;
/// returns what was set, for the record.
pub fn keep_freed_memory() -> Value {
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    {
        const MMAP_THRESHOLD: i32 = 32 << 20;
        // SAFETY: mallopt only changes allocator parameters; called before
        // the timed work, with values glibc documents as valid.
        let ok = unsafe {
            libc::mallopt(libc::M_MMAP_THRESHOLD, MMAP_THRESHOLD) == 1
                && libc::mallopt(libc::M_TRIM_THRESHOLD, i32::MAX) == 1
        };
        if ok {
            return json!("glibc mallopt: M_MMAP_THRESHOLD 32 MiB, M_TRIM_THRESHOLD 2 GiB (freed buffers reused, no page faults after the warm-up)");
        }
        json!("glibc mallopt refused: the allocator's defaults")
    }
    #[cfg(not(all(target_os = "linux", target_env = "gnu")))]
    json!("the platform allocator's defaults")
}

/// Where [`environment`] keeps the CPU counters read at the start, until
/// [`finish_environment`] turns them into the run's shares.
const CPU_AT_START: &str = "cpu_counters_at_start";

/// Closes a record: the load average after the run, next to the one before,
/// and how the machine's CPU time divided while it ran (`cpu_during_run`,
/// null where the counters cannot be read).
pub fn finish_environment(record: &mut Value) {
    let Some(env) = record.get_mut("environment").and_then(Value::as_object_mut) else {
        return;
    };
    env.insert("load_average_after".into(), json!(load_average()));
    let start = env
        .remove(CPU_AT_START)
        .and_then(|v| serde_json::from_value::<machine_cpu::CpuCounters>(v).ok());
    let during = match (start, machine_cpu::read()) {
        (Some(a), Some(b)) => machine_cpu::shares(&a, &b),
        _ => Value::Null,
    };
    env.insert("cpu_during_run".into(), during);
}

/// A scratch folder removed when dropped, and registered with the shutdown
/// handler while it lives, so that an interrupted benchmark removes it too
/// (the `tempfile` crate is a test-only dependency, and benchmark scratch
/// needs nothing more than this).
pub struct Scratch {
    dir: PathBuf,
    _registered: rendiff::shutdown::PathGuard,
}

impl std::fmt::Debug for Scratch {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_tuple("Scratch").field(&self.dir).finish()
    }
}

impl Scratch {
    /// Creates a fresh, empty folder under the system's temporary directory.
    pub fn new(what: &str) -> Result<Scratch> {
        use std::sync::atomic::{AtomicU64, Ordering};
        static NEXT: AtomicU64 = AtomicU64::new(0);
        let dir = std::env::temp_dir().join(format!(
            "rendiff-bench-{what}-{}-{}",
            std::process::id(),
            NEXT.fetch_add(1, Ordering::Relaxed)
        ));
        let _ = std::fs::remove_dir_all(&dir);
        let guard = rendiff::shutdown::track_path(&dir);
        std::fs::create_dir_all(&dir)
            .with_context(|| format!("{}: cannot create scratch folder", dir.display()))?;
        Ok(Scratch {
            dir,
            _registered: guard,
        })
    }

    /// The folder.
    pub fn path(&self) -> &Path {
        &self.dir
    }
}

impl Drop for Scratch {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.dir);
    }
}

/// How a visibility render differs from a reference render of the same camera.
#[derive(Debug, Clone, Copy, Default, PartialEq, serde::Serialize)]
pub struct VisError {
    /// Pixels whose `id.prim` differs.
    pub id_mismatches: usize,
    /// Pixels that are a hit on one side only.
    pub mask_mismatches: usize,
    /// Pixels whose `Z` bits differ.
    pub z_bit_differences: usize,
    /// Largest relative depth difference over pixels both hit.
    pub max_z_rel: f64,
    /// Pixels compared.
    pub pixels: usize,
}

impl VisError {
    /// True when both buffers are identical bit for bit.
    pub fn identical(&self) -> bool {
        self.id_mismatches == 0 && self.z_bit_differences == 0
    }
}

/// Compares `test` with `reference` (same size): IDs exactly, depth bit for bit and relatively.
pub fn visibility_error(reference: &Frame, test: &Frame) -> VisError {
    let d = rendiff::compare_depth(&reference.z, &test.z);
    VisError {
        id_mismatches: reference
            .prim
            .iter()
            .zip(&test.prim)
            .filter(|(a, b)| a != b)
            .count(),
        mask_mismatches: d.mask_mismatches,
        z_bit_differences: d.bit_differences,
        max_z_rel: d.max_rel,
        pixels: reference.prim.len(),
    }
}

/// What one benchmark produces: the JSON record, its HTML page and its plots
/// as (name, SVG) pairs (also written as standalone files).
#[derive(Debug, Clone)]
pub struct Output {
    /// The machine-readable record.
    pub record: Value,
    /// The page for people.
    pub html: String,
    /// Plots, by file-name suffix.
    pub svgs: Vec<(String, String)>,
}

impl Output {
    /// A benchmark's output with one plot: `record` closed
    /// ([`finish_environment`]), the plot `name` drawn by `plot` and the page
    /// by `page` from the closed record (and the plot).
    pub fn with_plot(
        mut record: Value,
        name: &str,
        plot: impl FnOnce(&Value) -> String,
        page: impl FnOnce(&Value, &str) -> String,
    ) -> Output {
        finish_environment(&mut record);
        let svg = plot(&record);
        let html = page(&record, &svg);
        Output {
            record,
            html,
            svgs: vec![(name.into(), svg)],
        }
    }
}

/// Writes one example's JSON record to `path` whole or not at all (a
/// temporary file beside it, then a rename), so a record a figure links to
/// is never half written.
pub fn write_json_file(path: &str, record: &Value) -> Result<()> {
    let tmp = format!("{path}.tmp");
    std::fs::write(&tmp, serde_json::to_string_pretty(record)? + "\n")
        .with_context(|| format!("{tmp}: cannot write"))?;
    std::fs::rename(&tmp, path).with_context(|| format!("{path}: cannot write"))?;
    Ok(())
}

/// Writes `STEM.json`, `STEM.html`, each `(name, svg)` as a standalone
/// file `STEM-NAME.svg` and the folder's refreshed index page, as one set
/// ([`outputs::write_set`]: all or nothing, the benchmark's plots of an
/// earlier run that this one does not write removed); returns the paths
/// written, index aside.
pub fn write_outputs(
    dir: &Path,
    stem: &str,
    record: &Value,
    html: &str,
    svgs: &[(String, String)],
) -> Result<Vec<PathBuf>> {
    let mut files = vec![
        (
            format!("{stem}.json"),
            serde_json::to_vec_pretty(record)?
                .into_iter()
                .chain([b'\n'])
                .collect(),
        ),
        (format!("{stem}.html"), html.as_bytes().to_vec()),
    ];
    for (name, svg) in svgs {
        files.push((
            format!("{stem}-{name}.svg"),
            plot::standalone(svg).into_bytes(),
        ));
    }
    let n = files.len();
    files.push((
        "index.html".into(),
        page::index_html(dir, Some(stem)).into_bytes(),
    ));
    let mut written = outputs::write_set(dir, stem, &files)?;
    written.truncate(n);
    Ok(written)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn median_of_odd_and_even_samples() {
        assert_eq!(median(&[3.0, 1.0, 2.0]), 2.0);
        assert_eq!(median(&[4.0, 1.0, 2.0, 3.0]), 2.5);
        assert!(median(&[]).is_nan());
    }

    #[test]
    fn timed_warms_up_then_counts_runs() {
        let mut calls = 0;
        let t = timed(3, || {
            calls += 1;
            calls
        });
        assert_eq!(calls, 4);
        assert_eq!(t.runs_s.len(), 3);
        assert_eq!(t.last, 4);
    }
}

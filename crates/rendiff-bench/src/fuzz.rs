//! `rendiff bench fuzz`: how many small generated scenes a minute `rendiff
//! fuzz` gets through (issue 37's goal: at least 30 a minute through every
//! built-in renderer on 2 cores), through all the backends together and
//! through each alone; what share of a renderer's time per scene is its
//! fixed start-up; and how long reducing one finding takes.
//!
//! * **Throughput**: `rendiff fuzz --seed S --count N --no-calibration
//!   --reduce-budget 0` run `runs` times through every backend, then through
//!   each backend alone (`--only B`, with the raster reference, which always
//!   runs), each a child process timed whole (generation, the check with its
//!   harness start, grouping, the findings page). Scenes per minute are
//!   `60 N / wall`; the interval is the 95% bootstrap interval of the median
//!   over the runs ([`crate::measure::bootstrap_median_interval`]).
//!   Calibration is left out: a fuzz run calibrates once, not per scene
//!   (docs/fuzzing.md), a fixed cost the record times apart.
//! * **Start-up share**: one check of [`PROBES`] copies of a one-triangle
//!   16x16 probe scene per run; the median render time per backend is what
//!   a render costs with nothing to draw, and its ratio to the backend's mean render time on the generated
//!   scenes is the share start-up takes (POV-Ray's front end is most of it).
//! * **Reduction time per finding**: a fuzz run through a planted command
//!   renderer (`tests/fuzz_renderers/renderers.toml`, the renderers
//!   tests/fuzz_planted.rs finds), then `rendiff reduce` timed on each of its
//!   first findings' smallest scene, with the sizes before and after.
//!
//! Nothing here asserts a time: the numbers go to `fuzz.json` and its page.

use super::measure::{bootstrap_median_interval, BOOTSTRAP_SEED};
use super::page::{self, Page};
use super::plot;
use super::{environment, median, run_rendiff, Common, Output, Scratch};
use anyhow::{Context, Result};
use serde_json::{json, Value};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

/// Issue 37's goal: small scenes a minute through every built-in renderer.
pub const GOAL_SCENES_PER_MINUTE: f64 = 30.0;

/// The planted renderers' declarations, in rendiff's checkout.
pub const PLANTED_RENDERERS: &str = "tests/fuzz_renderers/renderers.toml";

/// What `bench fuzz` runs.
#[derive(Debug, Clone)]
pub struct FuzzBenchOptions {
    /// Runs, output folder, root, timeout.
    pub common: Common,
    /// The generator's seed.
    pub seed: u64,
    /// Scenes per timed fuzz run.
    pub count: u64,
    /// Only these backends (None: every one the harness has).
    pub only: Option<Vec<String>>,
    /// `--jobs` of every fuzz run.
    pub jobs: usize,
    /// Planted renderers whose findings are reduced (empty: no reduction timed).
    pub planted: Vec<String>,
    /// Their declarations (`--renderers`).
    pub planted_renderers: PathBuf,
    /// Scenes of the fuzz run through each planted renderer.
    pub planted_count: u64,
    /// Findings reduced per planted renderer, at most.
    pub reductions: usize,
    /// Each reduction's `--budget`, seconds.
    pub reduce_budget_s: u64,
}

/// The arguments of one timed fuzz run into `out`.
pub fn fuzz_args(
    seed: u64,
    count: u64,
    only: Option<&[String]>,
    jobs: usize,
    timeout_s: u64,
    out: &Path,
) -> Vec<String> {
    let mut a: Vec<String> = [
        "fuzz",
        "--seed",
        &seed.to_string(),
        "--count",
        &count.to_string(),
        "--no-calibration",
        "--reduce-budget",
        "0",
        "--jobs",
        &jobs.to_string(),
        "--timeout",
        &timeout_s.to_string(),
        "--quiet",
    ]
    .iter()
    .map(|s| s.to_string())
    .collect();
    if let Some(only) = only {
        a.extend(["--only".into(), only.join(",")]);
    }
    a.extend(["-o".into(), out.display().to_string()]);
    a
}

/// Scenes per minute of each run, their median, range and 95% interval.
pub fn rates(scenes: u64, runs_s: &[f64]) -> Value {
    let per_min: Vec<f64> = runs_s.iter().map(|s| 60.0 * scenes as f64 / s).collect();
    let lo = per_min.iter().copied().fold(f64::INFINITY, f64::min);
    let hi = per_min.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    json!({
        "median": median(&per_min),
        "runs": per_min,
        "range": [lo, hi],
        "interval95": bootstrap_median_interval(&per_min, BOOTSTRAP_SEED),
    })
}

/// Render seconds per backend over a run's manifest: count, mean, median,
/// largest and sum of `time_s` of its successful renders.
pub fn render_times(manifest: &Value) -> BTreeMap<String, Value> {
    let mut by: BTreeMap<String, Vec<f64>> = BTreeMap::new();
    for s in manifest["scenes"].as_array().into_iter().flatten() {
        for r in s["renders"].as_array().into_iter().flatten() {
            if r["status"] != "ok" {
                continue;
            }
            if let (Some(b), Some(t)) = (r["backend"].as_str(), r["time_s"].as_f64()) {
                by.entry(b.to_string()).or_default().push(t);
            }
        }
    }
    by.into_iter()
        .map(|(b, t)| {
            let sum: f64 = t.iter().sum();
            let max = t.iter().copied().fold(0.0, f64::max);
            let v = json!({"renders": t.len(), "mean_s": sum / t.len() as f64,
                           "median_s": median(&t), "max_s": max, "sum_s": sum});
            (b, v)
        })
        .collect()
}

fn read_json(path: &Path) -> Result<Value> {
    let text = std::fs::read_to_string(path)
        .with_context(|| format!("{}: cannot read", path.display()))?;
    serde_json::from_str(&text).with_context(|| format!("{}: not JSON", path.display()))
}

/// Start-up share per backend: the probe's render time over the mean render
/// time on the generated scenes (both from manifests).
pub fn startup_shares(
    probe: &BTreeMap<String, Value>,
    scenes: &BTreeMap<String, Value>,
) -> BTreeMap<String, Value> {
    probe
        .iter()
        .map(|(b, p)| {
            let start = p["median_s"].as_f64();
            let mean = scenes.get(b).and_then(|s| s["mean_s"].as_f64());
            let share = match (start, mean) {
                (Some(s), Some(m)) if m > 0.0 => Some((s / m).min(1.0)),
                _ => None,
            };
            (
                b.clone(),
                json!({"probe_render_s": start, "mean_scene_render_s": mean, "startup_share": share}),
            )
        })
        .collect()
}

/// Copies of the probe checked together: the median of their render times
/// is a warm worker's (the first copy may pay a worker's own start).
pub const PROBES: usize = 5;

/// The probe: one 16x16 triangle, nothing else (a render of it is start-up).
pub const PROBE_SCENE: &str = r#"description = "bench fuzz's start-up probe: one triangle, 16x16"
requires = ["depth", "ids"]

[camera]
eye = [0.0, 0.0, 4.0]
look_at = [0.0, 0.0, 0.0]
vfov = 45.0
width = 16
height = 16

[[objects]]
name = "probe"
shape = { kind = "triangles", vertices = [[-1.0, -1.0, 0.0], [1.0, -1.0, 0.0], [0.0, 1.0, 0.0]] }
"#;

/// The generated scenes' sizes: width, height and triangles, smallest and largest.
pub fn scene_sizes(seed: u64, count: u64) -> Value {
    let (mut w, mut h, mut t) = (Vec::new(), Vec::new(), Vec::new());
    for i in 0..count {
        let g = rendiff::fuzz::grammar::generate(seed, i);
        w.push(g.scene.camera.width);
        h.push(g.scene.camera.height);
        t.push(g.scene.triangle_count());
    }
    let span = |v: &[u32]| json!([v.iter().min(), v.iter().max()]);
    let tris: Vec<f64> = t.iter().map(|&n| n as f64).collect();
    json!({
        "width": span(&w),
        "height": span(&h),
        "triangles": [t.iter().min(), median(&tris), t.iter().max()],
    })
}

/// `N check runs, M candidates` from `rendiff reduce`'s summary line.
pub fn reduce_counts(stdout: &str) -> (Option<u64>, Option<u64>) {
    let before = |word: &str| {
        let at = stdout.find(word)?;
        let head = stdout[..at].trim_end();
        let start = head
            .rfind(|c: char| !c.is_ascii_digit())
            .map_or(0, |i| i + 1);
        head[start..].parse().ok()
    };
    (before(" check runs"), before(" candidates"))
}

fn triangles_in(path: &Path) -> Option<usize> {
    let s = rendiff::scene::Scene::load(path).ok()?;
    let r = rendiff::scene::resolve::ResolvedScene::resolve(&s).ok()?;
    Some(r.triangles.len())
}

/// Fuzzes through one planted renderer, then times `rendiff reduce` on each
/// of its first findings' smallest scene.
fn planted(opts: &FuzzBenchOptions, backend: &str, dir: &Path, logs: &Path) -> Result<Value> {
    let root = &opts.common.root;
    let folder = dir.join(format!("planted-{backend}"));
    let only = [backend.to_string()];
    let mut args = fuzz_args(
        opts.seed,
        opts.planted_count,
        Some(&only[..]),
        opts.jobs,
        opts.common.timeout_s,
        &folder,
    );
    let renderers = opts.planted_renderers.display().to_string();
    args.extend(["--renderers".into(), renderers.clone()]);
    rendiff::errln!(
        "fuzz: {} scenes through planted {backend}",
        opts.planted_count
    );
    let fuzz = run_rendiff(&args, Some(root), logs)?;
    let ledger = read_json(&folder.join("findings.json"))?;
    let mut rows = Vec::new();
    for f in ledger["findings"]
        .as_array()
        .into_iter()
        .flatten()
        .take(opts.reductions)
    {
        let size = |s: &&Value| {
            let name = s.as_str().unwrap_or("");
            std::fs::metadata(folder.join("scenes").join(format!("{name}.toml")))
                .map_or(u64::MAX, |m| m.len())
        };
        let Some(scene) = f["scenes"]
            .as_array()
            .and_then(|s| s.iter().min_by_key(size))
            .and_then(Value::as_str)
        else {
            continue;
        };
        let id = f["id"].as_str().unwrap_or("F");
        let buffer = f["signature"]["buffer"].as_str().unwrap_or("id");
        let out = dir.join("reduced").join(format!("{backend}-{id}.toml"));
        let rargs: Vec<String> = vec![
            "reduce".into(),
            folder.join("run").display().to_string(),
            scene.to_string(),
            "--backend".into(),
            backend.to_string(),
            "--buffer".into(),
            buffer.to_string(),
            "--renderers".into(),
            renderers.clone(),
            "--jobs".into(),
            opts.jobs.to_string(),
            "--budget".into(),
            opts.reduce_budget_s.to_string(),
            "-o".into(),
            out.display().to_string(),
        ];
        rendiff::errln!("fuzz: reducing {id} ({scene}) of planted {backend}");
        let t = run_rendiff(&rargs, Some(root), logs)?;
        let (runs, candidates) = reduce_counts(&t.stdout);
        rows.push(json!({
            "finding": id,
            "buffer": buffer,
            "class": f["signature"]["class"],
            "scene": scene,
            "seconds": t.seconds,
            "triangles_before": triangles_in(&folder.join("scenes").join(format!("{scene}.toml"))),
            "triangles_after": triangles_in(&out),
            "check_runs": runs,
            "candidates": candidates,
            "budget_ran_out": t.stdout.contains("budget ran out"),
        }));
    }
    Ok(json!({
        "backend": backend,
        "scenes": opts.planted_count,
        "fuzz_s": fuzz.seconds,
        "scenes_per_minute": 60.0 * opts.planted_count as f64 / fuzz.seconds,
        "findings": ledger["findings"].as_array().map_or(0, Vec::len),
        "reductions": rows,
    }))
}

/// Times `runs` fuzz runs of one configuration; its record.
fn configuration(
    opts: &FuzzBenchOptions,
    name: &str,
    only: Option<&[String]>,
    dir: &Path,
    logs: &Path,
) -> Result<Value> {
    let out = dir.join(format!("cfg-{name}"));
    let args = fuzz_args(
        opts.seed,
        opts.count,
        only,
        opts.jobs,
        opts.common.timeout_s,
        &out,
    );
    let mut runs_s = Vec::new();
    let mut code = None;
    for k in 0..opts.common.runs.max(1) {
        rendiff::errln!(
            "fuzz: {} scenes through {name} (run {} of {})",
            opts.count,
            k + 1,
            opts.common.runs.max(1)
        );
        let t = run_rendiff(&args, Some(&opts.common.root), logs)?;
        runs_s.push(t.seconds);
        code = t.code;
    }
    let manifest = read_json(&out.join("run/manifest.json"))?;
    Ok(json!({
        "name": name,
        "only": only,
        "runs_s": runs_s,
        "median_s": median(&runs_s),
        "scenes_per_minute": rates(opts.count, &runs_s),
        "exit_code": code,
        "render_s": render_times(&manifest),
    }))
}

/// The backends a run rendered, the reference aside.
fn backends_of(manifest: &Value) -> Vec<String> {
    let reference = manifest["reference"].as_str().unwrap_or("raster");
    let mut out: Vec<String> = Vec::new();
    for s in manifest["scenes"].as_array().into_iter().flatten() {
        for r in s["renders"].as_array().into_iter().flatten() {
            if let Some(b) = r["backend"].as_str() {
                if b != reference && !out.iter().any(|o| o == b) {
                    out.push(b.to_string());
                }
            }
        }
    }
    out
}

/// Runs the benchmark.
pub fn run(opts: &FuzzBenchOptions) -> Result<Output> {
    let scratch = Scratch::new("fuzz")?;
    let dir = scratch.path();
    let logs = dir.join("logs");
    let mut record = json!({
        "benchmark": "fuzz",
        "environment": environment(),
        "seed": opts.seed,
        "scenes": opts.count,
        "jobs": opts.jobs,
        "runs": opts.common.runs.max(1),
        "scene_sizes": scene_sizes(opts.seed, opts.count),
        "calibration": "off in every timed run (--no-calibration): a fuzz run calibrates once, not per scene; calibration_s is its cost",
        "goal_scenes_per_minute": GOAL_SCENES_PER_MINUTE,
    });

    // Warm-up (untimed, two scenes): caches, and which backends there are.
    // The two-scene run of the warm-up and of calibration's cost, into `out`.
    let two_scenes = |out: &Path| {
        fuzz_args(
            opts.seed,
            2,
            opts.only.as_deref(),
            opts.jobs,
            opts.common.timeout_s,
            out,
        )
    };
    let warm = dir.join("warm");
    rendiff::errln!("fuzz: warm-up");
    run_rendiff(&two_scenes(&warm), Some(&opts.common.root), &logs)?;
    let backends = backends_of(&read_json(&warm.join("run/manifest.json"))?);
    record["backends"] = json!(backends);

    let mut configs = vec![configuration(
        opts,
        "all",
        opts.only.as_deref(),
        dir,
        &logs,
    )?];
    for b in &backends {
        configs.push(configuration(
            opts,
            b,
            Some(std::slice::from_ref(b)),
            dir,
            &logs,
        )?);
    }
    let all = configs[0]["scenes_per_minute"]["median"].as_f64();
    record["goal_met"] = json!(all.map(|r| r >= GOAL_SCENES_PER_MINUTE));

    // Start-up: PROBES copies of the probe scene in one check, `runs` times;
    // the median render time of each backend (its workers warm after the
    // first copy, as in a fuzz run).
    let mut probe_files = Vec::new();
    for k in 0..PROBES {
        let f = dir.join(format!("probe{k}.toml"));
        std::fs::write(&f, PROBE_SCENE)
            .with_context(|| format!("{}: cannot write", f.display()))?;
        probe_files.push(f.display().to_string());
    }
    let mut probe_times: BTreeMap<String, Vec<f64>> = BTreeMap::new();
    let mut probe_wall = Vec::new();
    for k in 0..opts.common.runs.max(1) {
        let out = dir.join(format!("probe-{k}"));
        let mut args = vec!["check".to_string()];
        args.extend(probe_files.iter().cloned());
        args.extend([
            "--no-calibration".to_string(),
            "--quiet".into(),
            "--jobs".into(),
            opts.jobs.to_string(),
            "--timeout".into(),
            opts.common.timeout_s.to_string(),
        ]);
        if let Some(only) = &opts.only {
            args.extend(["--only".into(), only.join(",")]);
        }
        args.extend(["-o".into(), out.display().to_string()]);
        rendiff::errln!("fuzz: start-up probe");
        probe_wall.push(run_rendiff(&args, Some(&opts.common.root), &logs)?.seconds);
        for (b, v) in render_times(&read_json(&out.join("manifest.json"))?) {
            if let Some(t) = v["median_s"].as_f64() {
                probe_times.entry(b).or_default().push(t);
            }
        }
    }
    let probe: BTreeMap<String, Value> = probe_times
        .into_iter()
        .map(|(b, t)| (b, json!({"median_s": median(&t), "runs_s": t})))
        .collect();
    let scene_times: BTreeMap<String, Value> =
        serde_json::from_value(configs[0]["render_s"].clone()).unwrap_or_default();
    record["startup"] = json!({
        "check_of_the_probes_s": {"median_s": median(&probe_wall), "runs_s": probe_wall},
        "per_backend": startup_shares(&probe, &scene_times),
    });
    record["configurations"] = json!(configs);

    // Calibration's once-per-run cost: the same two scenes with and without it.
    let cal = dir.join("calibrated");
    let mut args = two_scenes(&cal);
    args.retain(|a| a != "--no-calibration");
    rendiff::errln!("fuzz: calibration's cost");
    let with = run_rendiff(&args, Some(&opts.common.root), &logs)?.seconds;
    let without = run_rendiff(&two_scenes(&warm), Some(&opts.common.root), &logs)?.seconds;
    record["calibration_s"] = json!(with - without);

    let mut planted_rows = Vec::new();
    for p in &opts.planted {
        planted_rows.push(planted(opts, p, dir, &logs)?);
    }
    let per_finding: Vec<f64> = planted_rows
        .iter()
        .flat_map(|p| p["reductions"].as_array().cloned().unwrap_or_default())
        .filter_map(|r| r["seconds"].as_f64())
        .collect();
    record["reduction"] = json!({
        "renderers": opts.planted_renderers.display().to_string(),
        "budget_s": opts.reduce_budget_s,
        "planted": planted_rows,
        "seconds_per_finding": if per_finding.is_empty() { Value::Null } else {
            json!({"median": median(&per_finding), "runs": per_finding})
        },
    });
    Ok(Output::with_plot(record, "startup", startup_plot, html))
}

/// Each backend's start-up (the probe's render) against its mean render
/// time on the generated scenes: a point near the diagonal is a renderer
/// whose time per scene is mostly start-up.
fn startup_plot(r: &Value) -> String {
    let pts: Vec<plot::ScatterPoint> = r["startup"]["per_backend"]
        .as_object()
        .into_iter()
        .flatten()
        .filter_map(|(b, v)| {
            Some(plot::ScatterPoint {
                label: b.clone(),
                group: "backend".into(),
                x: v["mean_scene_render_s"].as_f64()?,
                y: v["probe_render_s"].as_f64()?,
                pareto: false,
            })
        })
        .collect();
    plot::scatter(
        "Start-up against time per generated scene",
        "mean render s per generated scene",
        "render s of the one-triangle probe (start-up)",
        &pts,
    )
}

fn html(r: &Value, svg: &str) -> String {
    let mut p = Page::new("rendiff bench fuzz: generated scenes a minute");
    let sizes = &r["scene_sizes"];
    p.para(&format!(
        "Each row is `rendiff fuzz --seed {} --count {}` (no calibration, no reduction, --jobs {}) timed whole, {} run(s); \
         scenes {} to {} pixels wide, {} to {} high, {} triangles (fewest, median, most).",
        r["seed"],
        r["scenes"],
        r["jobs"],
        r["runs"],
        sizes["width"][0],
        sizes["width"][1],
        sizes["height"][0],
        sizes["height"][1],
        page::compact(&sizes["triangles"]),
    ));
    let rows: Vec<Vec<String>> = r["configurations"]
        .as_array()
        .into_iter()
        .flatten()
        .map(|c| {
            let spm = &c["scenes_per_minute"];
            vec![
                c["name"].as_str().unwrap_or("").to_string(),
                page::num(c["median_s"].as_f64(), 1),
                page::num(spm["median"].as_f64(), 1),
                page::compact(&spm["interval95"]),
                page::compact(&spm["range"]),
            ]
        })
        .collect();
    p.table(
        &[
            "backends",
            "wall s (median)",
            "scenes / minute",
            "95% interval",
            "range",
        ],
        &rows,
    );
    p.para(&format!(
        "Goal: {} scenes a minute through every backend; met: {}. Calibration adds {} s once per fuzz run.",
        r["goal_scenes_per_minute"],
        r["goal_met"],
        page::num(r["calibration_s"].as_f64(), 1)
    ));
    p.heading("Start-up share of a render");
    let rows: Vec<Vec<String>> = r["startup"]["per_backend"]
        .as_object()
        .into_iter()
        .flatten()
        .map(|(b, v)| {
            vec![
                b.clone(),
                page::num(v["probe_render_s"].as_f64(), 3),
                page::num(v["mean_scene_render_s"].as_f64(), 3),
                page::num(v["startup_share"].as_f64(), 2),
            ]
        })
        .collect();
    p.table(
        &[
            "backend",
            "probe render s",
            "mean render s (generated scenes)",
            "start-up share",
        ],
        &rows,
    );
    p.svg(svg, Some("fuzz-startup.svg"));
    p.heading("Reduction time per finding");
    let rows: Vec<Vec<String>> = r["reduction"]["planted"]
        .as_array()
        .into_iter()
        .flatten()
        .flat_map(|pl| {
            let backend = pl["backend"].as_str().unwrap_or("").to_string();
            pl["reductions"]
                .as_array()
                .cloned()
                .unwrap_or_default()
                .into_iter()
                .map(move |x| {
                    vec![
                        backend.clone(),
                        format!(
                            "{} {} {}",
                            x["finding"].as_str().unwrap_or(""),
                            x["buffer"].as_str().unwrap_or(""),
                            x["class"].as_str().unwrap_or("")
                        ),
                        page::num(x["seconds"].as_f64(), 1),
                        format!("{} -> {}", x["triangles_before"], x["triangles_after"]),
                        page::compact(&x["check_runs"]),
                    ]
                })
        })
        .collect();
    p.table(
        &[
            "planted renderer",
            "finding",
            "seconds",
            "triangles",
            "check runs",
        ],
        &rows,
    );
    p.environment(&r["environment"]);
    p.finish()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rates_are_scenes_per_minute_with_an_interval() {
        let r = rates(50, &[100.0, 50.0, 25.0]);
        assert_eq!(r["runs"], json!([30.0, 60.0, 120.0]));
        assert_eq!(r["median"], json!(60.0));
        assert_eq!(r["range"], json!([30.0, 120.0]));
        let [lo, hi] = [r["interval95"][0].as_f64(), r["interval95"][1].as_f64()];
        assert!(lo.unwrap() >= 30.0 && hi.unwrap() <= 120.0, "{r}");
        // One run has no spread to resample.
        assert_eq!(rates(50, &[60.0])["interval95"], Value::Null);
    }

    #[test]
    fn render_times_and_startup_shares_come_from_manifests() {
        let m = json!({"reference": "raster", "scenes": [
            {"renders": [{"backend": "raster", "status": "ok", "time_s": 0.01},
                         {"backend": "povray", "status": "ok", "time_s": 1.0}]},
            {"renders": [{"backend": "raster", "status": "ok", "time_s": 0.03},
                         {"backend": "povray", "status": "ok", "time_s": 0.5},
                         {"backend": "mitsuba", "status": "error", "time_s": 600.0}]},
        ]});
        let t = render_times(&m);
        assert_eq!(t.len(), 2, "errors are not render times: {t:?}");
        assert_eq!(t["povray"]["renders"], 2);
        assert_eq!(t["povray"]["mean_s"], json!(0.75));
        assert_eq!(t["raster"]["max_s"], json!(0.03));
        assert_eq!(backends_of(&m), vec!["povray", "mitsuba"]);
        let probe: BTreeMap<String, Value> = [("povray".to_string(), json!({"median_s": 0.375}))]
            .into_iter()
            .collect();
        let s = startup_shares(&probe, &t);
        assert_eq!(s["povray"]["startup_share"], json!(0.5));
    }

    #[test]
    fn fuzz_arguments_and_reduce_summary() {
        let a = fuzz_args(
            3,
            50,
            Some(&["trace".to_string(), "povray".to_string()][..]),
            2,
            60,
            Path::new("o"),
        );
        let line = a.join(" ");
        assert_eq!(
            line,
            "fuzz --seed 3 --count 50 --no-calibration --reduce-budget 0 --jobs 2 --timeout 60 --quiet --only trace,povray -o o"
        );
        let out = "coplanar_bias fails id with class interior: 3 -> 2 triangles, 1 -> 1 objects, 890 -> 671 bytes (7 check runs, 37 candidates)\n";
        assert_eq!(reduce_counts(out), (Some(7), Some(37)));
        assert_eq!(reduce_counts("nothing"), (None, None));
    }

    #[test]
    fn scene_sizes_span_the_generated_scenes() {
        let s = scene_sizes(1, 20);
        let w = s["width"].as_array().unwrap();
        assert!(w[0].as_u64().unwrap() >= 16 && w[1].as_u64().unwrap() <= 128);
        assert!(s["triangles"][0].as_u64().unwrap() >= 1);
        // The probe scene resolves to one triangle.
        let p = rendiff::scene::Scene::parse(Path::new("probe.toml"), PROBE_SCENE).unwrap();
        let r = rendiff::scene::resolve::ResolvedScene::resolve(&p).unwrap();
        assert_eq!(r.triangles.len(), 1);
    }
}

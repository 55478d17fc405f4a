//! `rendiff bench scale`: what the main job (`rendiff check` on the starter
//! scenes and the corpus) costs, and what each way of spreading it buys, in
//! one run on one machine:
//!
//! * a process per render, one render at a time (`--no-workers --jobs 1`):
//!   how `check` ran before the job pool and the workers;
//! * the default: long-lived harness workers, `--jobs` = the cores, as many
//!   wait slots for renders that mostly wait (check/pool.rs);
//! * the default without wait slots (`--wait-slots 0`), the path before them;
//! * N shards (`--shard K/N`, dealt by the default run's recorded costs) run
//!   one after another, then `merge`: the slowest shard plus the merge is the
//!   wall time N machines would take at best (each would also pay its own
//!   set-up), so T(default) / that is an upper bound of the speed-up;
//! * time per scene per renderer, from the default run's manifest.
//!
//! Each configuration is a whole `check` (minutes), run as a child process of
//! this binary, after one untimed default run that warms the caches. Nothing
//! here asserts a time.

use super::page::{self, Page};
use super::plot;
use super::{environment, median, run_rendiff, Common, Output, Scratch};
use anyhow::{Context, Result};
use serde_json::{json, Value};
use std::path::{Path, PathBuf};

/// What `bench scale` runs.
#[derive(Debug, Clone)]
pub struct ScaleOptions {
    /// Runs, output folder, root.
    pub common: Common,
    /// Shard counts to measure (1 is the default run itself).
    pub shards: Vec<u32>,
    /// Scene files or folders (default: the main job's, `scenes` and `scenes/corpus`).
    pub scenes: Vec<PathBuf>,
}

fn check_args(opts: &ScaleOptions, out: &Path, extra: &[&str]) -> Vec<String> {
    let mut a = vec!["check".to_string(), "--quiet".into()];
    a.extend(opts.scenes.iter().map(|s| s.display().to_string()));
    a.extend(["--timeout".into(), opts.common.timeout_s.to_string()]);
    a.extend(extra.iter().map(|s| s.to_string()));
    a.extend(["-o".into(), out.display().to_string()]);
    a
}

/// Times `args` `runs` times; the median and every run.
fn timed(runs: usize, args: &[String], logs: &Path) -> Result<(f64, Vec<f64>, Option<i32>)> {
    let mut times = Vec::new();
    let mut code = None;
    for _ in 0..runs.max(1) {
        let t = run_rendiff(args, None, logs)?;
        times.push(t.seconds);
        code = t.code;
    }
    Ok((median(&times), times, code))
}

/// Seconds per scene per renderer in a run's manifest.
fn per_scene(run: &Path) -> Result<Value> {
    let path = run.join("manifest.json");
    let m: Value = serde_json::from_str(
        &std::fs::read_to_string(&path).with_context(|| format!("{}", path.display()))?,
    )
    .with_context(|| format!("{}: unreadable", path.display()))?;
    let mut out = serde_json::Map::new();
    for s in m["scenes"].as_array().into_iter().flatten() {
        let mut row = serde_json::Map::new();
        for r in s["renders"].as_array().into_iter().flatten() {
            if let (Some(b), Some(t)) = (r["backend"].as_str(), r["time_s"].as_f64()) {
                row.insert(b.to_string(), json!(t));
            }
        }
        if let Some(name) = s["scene"].as_str() {
            out.insert(name.to_string(), Value::Object(row));
        }
    }
    Ok(Value::Object(out))
}

/// Wall seconds per scene of the default run, and each renderer's share of
/// the render seconds summed over every scene and renderer (what the pool's
/// slots spend; POV-Ray's is the figure).
fn shares(per_scene: &Value, default_s: f64) -> Value {
    let mut by_renderer = std::collections::BTreeMap::<String, f64>::new();
    let rows = per_scene.as_object().cloned().unwrap_or_default();
    for row in rows.values() {
        for (r, t) in row.as_object().into_iter().flatten() {
            *by_renderer.entry(r.clone()).or_default() += t.as_f64().unwrap_or(0.0);
        }
    }
    let total: f64 = by_renderer.values().sum();
    json!({
        "scenes": rows.len(),
        "wall_s_per_scene": default_s / rows.len().max(1) as f64,
        "render_s": by_renderer,
        "render_share": by_renderer.iter().map(|(r, t)| (r.clone(), json!(t / total))).collect::<serde_json::Map<_, _>>(),
    })
}

/// Runs the benchmark.
pub fn run(opts: &ScaleOptions) -> Result<Output> {
    let scratch = Scratch::new("scale")?;
    let runs = opts.common.runs;
    let mut record = json!({
        "benchmark": "scale",
        "environment": environment(),
        "scenes": opts.scenes.iter().map(|s| s.display().to_string()).collect::<Vec<_>>(),
        "jobs": super::cpus(),
        "runs": runs,
    });
    let main_run = scratch.path().join("default");
    let logs = scratch.path().join("logs");
    rendiff::errln!("scale: warm-up (one default check run, untimed)");
    run_rendiff(&check_args(opts, &main_run, &[]), None, &logs)?;

    let mut configs = Vec::new();
    let plans: [(&str, &str, &[&str]); 3] = [
        (
            "process_per_render_sequential",
            "a harness process per render, one at a time (--no-workers --jobs 1 --wait-slots 0)",
            &["--no-workers", "--jobs", "1", "--wait-slots", "0"],
        ),
        (
            "default",
            "long-lived workers, --jobs = the cores, as many wait slots (the default)",
            &[],
        ),
        (
            "no_wait_slots",
            "the default before wait slots: every render holds a --jobs slot (--wait-slots 0)",
            &["--wait-slots", "0"],
        ),
    ];
    for (name, what, extra) in plans {
        rendiff::errln!("scale: {what}");
        let out = scratch.path().join(name);
        let (m, all, code) = timed(runs, &check_args(opts, &out, extra), &logs)?;
        configs.push(
            json!({"name": name, "what": what, "median_s": m, "runs_s": all, "exit_code": code}),
        );
    }
    let before = configs[0]["median_s"].as_f64().unwrap_or(f64::NAN);
    let after = configs[1]["median_s"].as_f64().unwrap_or(f64::NAN);
    record["configurations"] = json!(configs);
    record["speedup_default_over_sequential"] = json!(before / after);
    let without = configs[2]["median_s"].as_f64().unwrap_or(f64::NAN);
    record["speedup_default_over_no_wait_slots"] = json!(without / after);
    record["per_scene_s"] = per_scene(&scratch.path().join("default"))?;
    record["shares"] = shares(&record["per_scene_s"], after);

    let mut shard_rows = Vec::new();
    for &n in &opts.shards {
        let mut times = Vec::new();
        let mut runs_dirs = Vec::new();
        for k in 1..=n {
            let out = scratch.path().join(format!("shards{n}-{k}"));
            let spec = format!("{k}/{n}");
            let costs = main_run.display().to_string();
            let args = check_args(opts, &out, &["--shard", &spec, "--shard-costs", &costs]);
            rendiff::errln!("scale: shard {spec}");
            times.push(run_rendiff(&args, None, &logs)?.seconds);
            runs_dirs.push(out);
        }
        let merged = scratch.path().join(format!("merged{n}"));
        let mut margs = vec!["merge".to_string()];
        margs.extend(runs_dirs.iter().map(|d| d.display().to_string()));
        margs.extend(["-o".into(), merged.display().to_string()]);
        let merge_s = run_rendiff(&margs, None, &logs)?.seconds;
        let slowest = times.iter().cloned().fold(0.0, f64::max);
        shard_rows.push(json!({
            "shards": n,
            "shard_s": times,
            "merge_s": merge_s,
            "sum_s": times.iter().sum::<f64>() + merge_s,
            "slowest_plus_merge_s": slowest + merge_s,
            "speedup_bound": after / (slowest + merge_s),
        }));
    }
    record["shards"] = json!(shard_rows);
    Ok(Output::with_plot(record, "shards", shards_plot, html))
}

/// Wall time against the number of shards: the slowest shard plus the merge
/// (what N machines take), the sum (one machine, shard after shard), and the
/// unsharded default for reference.
fn shards_plot(r: &Value) -> String {
    let rows: Vec<&Value> = r["shards"].as_array().into_iter().flatten().collect();
    let at = |key: &str| -> Vec<(f64, f64)> {
        rows.iter()
            .filter_map(|s| Some((s["shards"].as_f64()?, s[key].as_f64()?)))
            .collect()
    };
    let default_s = r["configurations"][1]["median_s"]
        .as_f64()
        .unwrap_or(f64::NAN);
    let series = [
        plot::Series {
            name: "slowest shard + merge".into(),
            points: at("slowest_plus_merge_s"),
            dashed: false,
        },
        plot::Series {
            name: "all shards + merge".into(),
            points: at("sum_s"),
            dashed: true,
        },
        plot::Series {
            name: "one run (default)".into(),
            points: rows
                .iter()
                .filter_map(|s| Some((s["shards"].as_f64()?, default_s)))
                .collect(),
            dashed: true,
        },
    ];
    plot::lines(
        "The main job split into shards",
        "shards",
        "wall seconds",
        &series,
        &[],
    )
}

fn html(r: &Value, svg: &str) -> String {
    let mut p = Page::new("rendiff bench scale: the main job's wall time");
    p.para("Each row is a whole `rendiff check` of the main job's scenes on this machine, in one benchmark run.");
    let rows: Vec<Vec<String>> = r["configurations"]
        .as_array()
        .into_iter()
        .flatten()
        .map(|c| {
            vec![
                c["what"].as_str().unwrap_or("").to_string(),
                page::num(c["median_s"].as_f64(), 1),
            ]
        })
        .collect();
    p.table(&["configuration", "wall s (median)"], &rows);
    p.para(&format!(
        "Speed-up of the default over a process per render, one at a time: {}x; over the default without wait slots: {}x.",
        page::num(r["speedup_default_over_sequential"].as_f64(), 2),
        page::num(r["speedup_default_over_no_wait_slots"].as_f64(), 2)
    ));
    let sh = &r["shares"];
    p.para(&format!(
        "{} scenes: {} wall s per scene (default); POV-Ray's share of the summed render seconds: {}.",
        sh["scenes"],
        page::num(sh["wall_s_per_scene"].as_f64(), 2),
        page::num(sh["render_share"]["povray"].as_f64(), 2)
    ));
    p.heading("Shards run one after another, then merged");
    let rows: Vec<Vec<String>> = r["shards"]
        .as_array()
        .into_iter()
        .flatten()
        .map(|s| {
            vec![
                s["shards"].to_string(),
                page::compact(&s["shard_s"]),
                page::num(s["merge_s"].as_f64(), 1),
                page::num(s["slowest_plus_merge_s"].as_f64(), 1),
                page::num(s["speedup_bound"].as_f64(), 2),
            ]
        })
        .collect();
    p.table(
        &[
            "shards",
            "each shard s",
            "merge s",
            "slowest + merge s",
            "speed-up bound",
        ],
        &rows,
    );
    p.svg(svg, Some("scale-shards.svg"));
    p.note("The speed-up bound is the default run's time over the slowest shard plus the merge: what N machines could give at best.");
    p.environment(&r["environment"]);
    p.finish()
}

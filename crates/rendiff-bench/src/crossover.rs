//! `rendiff bench crossover`: where ray tracing starts to beat rasterization.
//!
//! A screen-filling grid of `2·nx²` triangles, from two triangles covering
//! the whole image to millions smaller than a pixel, rendered by both loops at
//! one resolution. The raster's cost grows with triangle setups and bounding-box
//! coverage tests; the tracer's with BVH nodes visited and (once) its build.
//! Times and operation counts are recorded per size, the crossover sizes are
//! interpolated (with and without the BVH build), and raster == trace is
//! checked at every size.
//!
//! Each loop is timed three ways: its visibility pass alone (hit keys per
//! pixel: `raster_keys_s`, `trace_keys_s`, as `bench peers` times the
//! tracer's queries), the frame assembly both share (keys to depth, ID and
//! normal buffers: `assembly_s`, one figure as it is the same code on the
//! same keys), and the whole frame (`raster_s`, `trace_s`). The crossover
//! sizes are interpolated on the visibility passes (the like-for-like
//! comparison of the two loops) and on whole frames. The process keeps
//! freed memory for the sweep ([`super::keep_freed_memory`]): both loops
//! allocate their frames per run, and fresh pages made whole-frame times
//! bimodal (a spurious whole-frame crossing at 3 triangles).

use super::page::{num, Page};
use super::plot::{lines, Series};
use super::{measure, visibility_error, Common};
use anyhow::Result;
use rendiff::scene::generators::crossover_grid;
use rendiff::scene::resolve::ResolvedScene;
use rendiff::trace::{BvhQuality, TraceKernel};
use serde_json::{json, Value};

/// What `bench crossover` measures.
#[derive(Debug, Clone)]
pub struct CrossoverOptions {
    /// Shared options.
    pub common: Common,
    /// Image size (square images keep the grid exactly screen-filling).
    pub size: u32,
    /// Grid subdivisions per side.
    pub nx: Vec<u32>,
    /// Worker threads.
    pub threads: usize,
    /// Scene files or folders the loop-choice model is also checked on
    /// ([`super::which_loop`]); the error says why there are none (no rendiff
    /// checkout to take the default corpus from), and the record says so too.
    pub corpus: std::result::Result<Vec<std::path::PathBuf>, String>,
}

/// The sweep's scene ([`rendiff::scene::generators::crossover_grid`]).
pub fn grid_scene(nx: u32, size: u32, aligned: bool) -> Result<ResolvedScene> {
    crossover_grid(nx, size, aligned).map_err(anyhow::Error::msg)
}

/// Where `a - b` changes sign between consecutive rows, interpolated in log-log space.
pub fn crossings(xs: &[f64], a: &[f64], b: &[f64]) -> Vec<f64> {
    let mut out = Vec::new();
    for i in 1..xs.len() {
        let d0 = a[i - 1].ln() - b[i - 1].ln();
        let d1 = a[i].ln() - b[i].ln();
        if d0.is_finite() && d1.is_finite() && d0 * d1 < 0.0 {
            let t = d0 / (d0 - d1);
            out.push((xs[i - 1].ln() + t * (xs[i].ln() - xs[i - 1].ln())).exp());
        }
    }
    out
}

/// Seconds of paired rounds each size gets at least (unless `--quick`):
/// a two-triangle round takes a few milliseconds, and five such rounds on a
/// machine whose speed moves within seconds left the raster's speed-up at
/// 7.7x in one run and 11.6x in the next; at 8M triangles a round takes
/// about 0.3 s and `runs` already fills this.
const PAIRED_SECONDS: f64 = 1.0;

/// At most this many paired rounds per size.
const PAIRED_MAX_ROUNDS: usize = 201;

/// Paired rounds for a size whose raster and trace passes take `round_s`
/// together: `runs`, or as many more as fill [`PAIRED_SECONDS`] (up to
/// [`PAIRED_MAX_ROUNDS`]).
pub fn paired_rounds(runs: usize, round_s: f64, quick: bool) -> usize {
    let runs = runs.max(1);
    // (NaN, zero or negative: no estimate to fill from.)
    if quick || round_s.is_nan() || round_s <= 0.0 {
        return runs;
    }
    let fill = (PAIRED_SECONDS / round_s).ceil();
    // `fill` is positive and finite here, or +inf (saturates) for tiny rounds.
    (fill.min(PAIRED_MAX_ROUNDS as f64) as usize).max(runs)
}

/// Times both loops on one grid (visibility pass, shared assembly, whole
/// frame), their passes again in alternation (the ratio each round takes
/// on one machine state, [`measure::raster_vs_trace`]), and records their
/// operation counts.
fn row(scene: &ResolvedScene, nx: u32, size: u32, runs: usize, quick: bool) -> Value {
    let threads = rayon::current_num_threads();
    // Each loop's phases back to back (its frames, then its pass alone), so
    // that one loop's allocations (an 8M-triangle BVH) do not sit in the
    // middle of the other's measurements.
    let r = measure::raster(scene, runs);
    let rk = measure::raster_keys(scene, runs);
    let asm = measure::assembly(scene, &rk.last, runs);
    let mut t = measure::trace(scene, BvhQuality::default(), runs);
    let tk = measure::trace_queries(scene, &t.build.last, TraceKernel::Packets, runs);
    let rounds = paired_rounds(runs, rk.median_s + tk.median_s, quick);
    let paired = measure::raster_vs_trace(scene, &t.build.last, rounds);
    let leaf_set_up_s = measure::leaf_set_up(scene, &mut t.build.last, runs.max(5));
    let tris = scene.triangles.len() as f64;
    let px = f64::from(size) * f64::from(size);
    let ratio = paired["raster_speedup_over_trace"]
        .as_f64()
        .unwrap_or(f64::NAN);
    let which_loop = super::which_loop::measured_row(
        &rendiff::loop_cost::workload(scene, threads),
        (rk.median_s, ratio),
        t.build.median_s,
        leaf_set_up_s,
    );
    json!({
        "which_loop": which_loop,
        "leaf_set_up_s": leaf_set_up_s,
        "nx": nx,
        "triangles": tris,
        "pixels_per_triangle": px / tris,
        "raster_s": r.median_s,
        "trace_s": t.trace.median_s,
        "raster_keys_s": rk.median_s,
        "trace_keys_s": tk.median_s,
        "assembly_s": asm.median_s,
        "trace_keys_total_s": t.build.median_s + tk.median_s,
        "raster_keys_runs_s": rk.runs_s,
        "trace_keys_runs_s": tk.runs_s,
        "bvh_build_s": t.build.median_s,
        "trace_total_s": t.total_s(),
        "raster_runs_s": r.runs_s,
        "trace_runs_s": t.trace.runs_s,
        "raster_counters": r.last.counters,
        "trace_counters": t.trace.last.counters,
        "raster_speedup_paired": paired["raster_speedup_over_trace"],
        "paired": paired,
        "raster_equals_trace": visibility_error(&r.last, &t.trace.last).identical()
            && visibility_error(&rk.last, &tk.last).identical(),
    })
}

/// Runs the sweep and returns the JSON record, the page and the SVGs.
pub fn run(opts: &CrossoverOptions) -> Result<super::Output> {
    // Every size of the sweep, before the first one runs (minutes may pass).
    for &nx in &opts.nx {
        rendiff::scene::generators::check_crossover_grid(nx, opts.size)
            .map_err(|e| anyhow::anyhow!("--nx {nx} --size {}: {e}", opts.size))?;
    }
    let environment = super::environment();
    let allocator = super::keep_freed_memory();
    let pool = super::pool(opts.threads)?;
    let runs = opts.common.runs;
    let sweep = |aligned: bool| -> Result<Vec<Value>> {
        let mut rows = Vec::new();
        for &nx in &opts.nx {
            let scene = grid_scene(nx, opts.size, aligned)?;
            rendiff::errln!(
                "crossover: nx {nx} ({} triangles){}",
                scene.triangles.len(),
                if aligned { ", pixel-aligned" } else { "" }
            );
            rows.push(pool.install(|| row(&scene, nx, opts.size, runs, opts.common.quick)));
        }
        Ok(rows)
    };
    let rows = sweep(false)?;
    let aligned_rows = sweep(true)?;
    let (corpus, corpus_not_run) = match &opts.corpus {
        Ok(paths) => {
            let files = super::which_loop::corpus_files(paths)?;
            let rows = pool.install(|| {
                super::which_loop::corpus_rows(&files, opts.threads, runs, opts.common.quick)
            });
            (Value::Array(rows), Value::Null)
        }
        Err(why) => {
            eprintln!("crossover: the loop-choice table over the corpus is not run: {why}");
            (Value::Array(Vec::new()), Value::String(why.clone()))
        }
    };
    let judged: Vec<&Value> = rows
        .iter()
        .map(|r| &r["which_loop"])
        .chain(corpus.as_array().into_iter().flatten())
        .collect();
    let which_summary = super::which_loop::summary(&judged);
    let col = |k: &str| -> Vec<f64> {
        rows.iter()
            .map(|r| r[k].as_f64().unwrap_or(f64::NAN))
            .collect()
    };
    let tris = col("triangles");
    let with_build = crossings(&tris, &col("raster_keys_s"), &col("trace_keys_total_s"));
    let trace_only = crossings(&tris, &col("raster_keys_s"), &col("trace_keys_s"));
    let frames_with_build = crossings(&tris, &col("raster_s"), &col("trace_total_s"));
    let frames_trace_only = crossings(&tris, &col("raster_s"), &col("trace_s"));
    // Where the paired rounds' median speed-up passes 1.
    let paired_crossing = crossings(&tris, &vec![1.0; tris.len()], &col("raster_speedup_paired"));
    let mut record = json!({
        "benchmark": "crossover",
        "environment": environment,
        "config": {
            "scene": "grid at z=0 seen from (0,0,1), vfov 90, overhanging the image by small non-dyadic margins: screen-filling at every nx, few ties",
            "size": [opts.size, opts.size], "nx": opts.nx, "threads": opts.threads,
            "runs": runs, "quick": opts.common.quick, "bvh": rendiff::names::Named::name(BvhQuality::default()),
            "timing": "median of `runs` timed runs after one untimed warm-up; `paired`: the two visibility passes again in alternation, one of each per round after a warm-up of each, `runs` rounds or as many more as fill PAIRED_SECONDS (at most PAIRED_MAX_ROUNDS), the raster's speed-up being the median of the rounds' trace / raster ratios",
            "paired_seconds": if opts.common.quick { 0.0 } else { PAIRED_SECONDS },
            "paired_max_rounds": PAIRED_MAX_ROUNDS,
            "allocator": allocator,
            "phases": "raster_keys_s / trace_keys_s: each loop's visibility pass alone (hit keys per pixel; the tracer's packet kernel through a built BVH); assembly_s: keys to depth, ID and normal buffers, shared code timed once; raster_s / trace_s: whole frames (pass + assembly); bvh_build_s apart; leaf_set_up_s: a new camera's first pass over a steady one (its leaves set up as traversal first reaches them), which the one-frame verdict counts with the build",
        },
        "rows": rows,
        "aligned_rows": aligned_rows,
        "aligned": "the same sweep on a grid exactly over [-1,1]^2: edges, diagonals and (at nx = size) vertices through pixel centers, so the exact predicate's ties and fallbacks dominate",
        "crossover_triangles": {
            "raster_vs_trace_with_build": with_build,
            "raster_vs_trace_without_build": trace_only,
            "raster_vs_trace_paired": paired_crossing,
            "whole_frames_with_build": frames_with_build,
            "whole_frames_without_build": frames_trace_only,
            "compared": "visibility passes (keys); whole_frames_*: frames including the shared assembly",
        },
        "which_loop": {
            "model": "rendiff::loop_cost (docs/benchmarks.md, \"Which loop\")",
            "grid": "rows[].which_loop",
            "corpus": corpus,
            "corpus_not_run": corpus_not_run,
            "summary": which_summary,
        },
        "raster_equals_trace_everywhere": rows.iter().chain(&aligned_rows).all(|r| r["raster_equals_trace"] == json!(true)),
    });
    super::finish_environment(&mut record);
    let marks: Vec<(f64, String)> = with_build
        .iter()
        .map(|x| (*x, "crossover (build incl.)".to_string()))
        .chain(
            trace_only
                .iter()
                .map(|x| (*x, "crossover (trace only)".to_string())),
        )
        .collect();
    let series = |name: &str, k: &str, dashed: bool| Series {
        name: name.into(),
        points: tris.iter().copied().zip(col(k)).collect(),
        dashed,
    };
    let aligned_series = |name: &str, k: &str| Series {
        name: name.into(),
        points: record["aligned_rows"]
            .as_array()
            .into_iter()
            .flatten()
            .map(|r| {
                (
                    r["triangles"].as_f64().unwrap_or(f64::NAN),
                    r[k].as_f64().unwrap_or(f64::NAN),
                )
            })
            .collect(),
        dashed: true,
    };
    let times = lines(
        &format!("time vs triangle count ({0}x{0})", opts.size),
        "triangles (screen-filling grid)",
        "seconds",
        &[
            series("raster visibility pass", "raster_keys_s", false),
            series("trace pass + BVH build", "trace_keys_total_s", false),
            series("trace pass only", "trace_keys_s", true),
            series("BVH build", "bvh_build_s", true),
            series("frame assembly (shared)", "assembly_s", true),
            series("raster whole frame", "raster_s", true),
            series("trace whole frame", "trace_s", true),
            aligned_series("raster pass, pixel-aligned grid", "raster_keys_s"),
            aligned_series("trace pass only, pixel-aligned grid", "trace_keys_s"),
        ],
        &marks,
    );
    let counter = |name: &str, side: &str, k: &str, dashed: bool| Series {
        name: name.into(),
        points: rows
            .iter()
            .map(|r| {
                (
                    r["triangles"].as_f64().unwrap_or(f64::NAN),
                    r[side][k].as_f64().unwrap_or(f64::NAN),
                )
            })
            .collect(),
        dashed,
    };
    let ops = lines(
        "operation counts vs triangle count",
        "triangles (screen-filling grid)",
        "operations per frame",
        &[
            counter(
                "raster coverage tests",
                "raster_counters",
                "coverage_tests",
                false,
            ),
            counter(
                "raster triangle setups",
                "raster_counters",
                "triangle_setups",
                false,
            ),
            counter(
                "trace coverage tests",
                "trace_counters",
                "coverage_tests",
                true,
            ),
            counter(
                "trace BVH nodes visited",
                "trace_counters",
                "bvh_nodes_visited",
                true,
            ),
        ],
        &marks,
    );
    let svgs = vec![
        ("times".to_string(), times),
        ("operations".to_string(), ops),
    ];
    let html = page(&record, &svgs);
    Ok(super::Output { record, html, svgs })
}

fn page(record: &Value, svgs: &[(String, String)]) -> String {
    let mut p = Page::new("rendiff bench crossover: raster vs trace as triangles shrink");
    p.para(&format!(
        "{}. Times are medians after a warm-up. Each loop's visibility pass (hit keys per pixel) is timed alone, the frame assembly both loops share (keys to depth, ID and normal buffers) apart, and whole frames too; then the two passes again in alternation, one of each per round, whose per-round ratios give the raster's paired speed-up (the median; both passes met the same machine state). Crossover of the visibility passes (interpolated, triangles): with the BVH build {}; tracing alone {}; paired rounds {}. Of whole frames: with the build {}; tracing alone {}. Raster == trace at every size: {}.",
        super::page::compact(&record["config"]["scene"]),
        list(&record["crossover_triangles"]["raster_vs_trace_with_build"]),
        list(&record["crossover_triangles"]["raster_vs_trace_without_build"]),
        list(&record["crossover_triangles"]["raster_vs_trace_paired"]),
        list(&record["crossover_triangles"]["whole_frames_with_build"]),
        list(&record["crossover_triangles"]["whole_frames_without_build"]),
        record["raster_equals_trace_everywhere"]
    ))
    .command("rendiff bench crossover");
    for (name, svg) in svgs {
        p.svg(svg, Some(&format!("crossover-{name}.svg")));
    }
    p.heading("generic grid (few ties)");
    table(&mut p, &record["rows"]);
    p.heading("pixel-aligned grid (ties everywhere)");
    p.para(&super::page::compact(&record["aligned"]));
    table(&mut p, &record["aligned_rows"]);
    if let Some(why) = record["which_loop"]["corpus_not_run"].as_str() {
        p.para(&format!("The corpus table was not run: {why}"));
    }
    super::which_loop::page_section(
        &mut p,
        &record["which_loop"]["corpus"],
        &record["which_loop"]["summary"],
    );
    p.environment(&record["environment"]);
    p.finish()
}

fn table(p: &mut Page, rows: &Value) {
    let rows: Vec<Vec<String>> = rows
        .as_array()
        .into_iter()
        .flatten()
        .map(|r| {
            let f = |k: &str| r[k].as_f64();
            let c = |side: &str, k: &str| super::page::compact(&r[side][k]);
            vec![
                super::page::compact(&r["nx"]),
                super::page::compact(&r["triangles"]),
                num(f("pixels_per_triangle"), 3),
                num(f("raster_keys_s"), 4),
                num(f("trace_keys_s"), 4),
                paired_cell(&r["paired"]),
                num(f("assembly_s"), 4),
                num(f("raster_s"), 4),
                num(f("trace_s"), 4),
                num(f("bvh_build_s"), 4),
                c("raster_counters", "triangle_setups"),
                c("raster_counters", "coverage_tests"),
                c("raster_counters", "fast_decided"),
                c("trace_counters", "coverage_tests"),
                c("trace_counters", "bvh_nodes_visited"),
                format!(
                    "{} / {}",
                    c("raster_counters", "exact_fallbacks"),
                    c("trace_counters", "exact_fallbacks")
                ),
                super::page::compact(&r["raster_equals_trace"]),
                super::which_loop::cell(&r["which_loop"]["one_frame"]),
                super::which_loop::cell(&r["which_loop"]["bvh_shared"]),
            ]
        })
        .collect();
    p.table(
        &[
            "nx",
            "triangles",
            "px/triangle",
            "raster pass s",
            "trace pass s",
            "raster speed-up, paired: median [95% interval] (rounds; range)",
            "assembly s (shared)",
            "raster frame s",
            "trace frame s",
            "BVH build s",
            "raster setups",
            "raster coverage tests",
            "of which decided by the edge-function fast path",
            "trace coverage tests",
            "BVH nodes visited",
            "exact fallbacks raster / trace",
            "raster == trace",
            "one frame: model picked / faster / ratio",
            "BVH shared: model picked / faster / ratio",
        ],
        &rows,
    );
}

/// The paired rounds' median speed-up, its 95% interval, their count and their range.
fn paired_cell(p: &Value) -> String {
    let per_round: Vec<f64> = p["trace_over_raster_per_round"]
        .as_array()
        .into_iter()
        .flatten()
        .filter_map(Value::as_f64)
        .collect();
    let (lo, hi) = per_round
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), &x| {
            (lo.min(x), hi.max(x))
        });
    let ci = &p["raster_speedup_over_trace_interval_95"];
    match p["raster_speedup_over_trace"].as_f64() {
        Some(m) if !per_round.is_empty() => format!(
            "{} [{}, {}] ({}; {}-{})",
            num(Some(m), 3),
            num(ci[0].as_f64(), 3),
            num(ci[1].as_f64(), 3),
            per_round.len(),
            num(Some(lo), 3),
            num(Some(hi), 3)
        ),
        _ => "-".to_string(),
    }
}

fn list(v: &Value) -> String {
    let xs: Vec<String> = v
        .as_array()
        .into_iter()
        .flatten()
        .map(|x| num(x.as_f64(), 3))
        .collect();
    if xs.is_empty() {
        "none in the measured range".into()
    } else {
        xs.join(", ")
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn crossings_interpolate_in_log_space() {
        let x = [1.0, 100.0, 10000.0];
        let a = [1.0, 10.0, 100.0];
        let b = [10.0, 10.0 * 10f64.sqrt(), 10.0];
        let c = crossings(&x, &a, &b);
        assert_eq!(c.len(), 1);
        assert!(c[0] > 100.0 && c[0] < 10000.0);
        assert!(crossings(&x, &a, &a.map(|v| v * 2.0)).is_empty());
    }

    /// Every phase is recorded, and the passes agree with the frames.
    #[test]
    fn rows_time_passes_assembly_and_frames() {
        let s = grid_scene(2, 16, false).unwrap();
        let r = row(&s, 2, 16, 1, false);
        for k in [
            "raster_keys_s",
            "trace_keys_s",
            "assembly_s",
            "raster_s",
            "trace_s",
            "bvh_build_s",
        ] {
            assert!(r[k].as_f64().is_some_and(|v| v >= 0.0), "{k}: {}", r[k]);
        }
        assert_eq!(r["raster_equals_trace"], json!(true));
        // The paired rounds: as many as fill the budget on a tiny grid, each
        // with both passes, and the speed-up their ratios' median.
        let p = &r["paired"];
        let rounds = p["rounds"].as_u64().unwrap() as usize;
        assert!(rounds > 1, "{p}");
        let per_round: Vec<f64> = p["trace_over_raster_per_round"]
            .as_array()
            .unwrap()
            .iter()
            .map(|v| v.as_f64().unwrap())
            .collect();
        assert_eq!(per_round.len(), rounds);
        assert_eq!(p["raster_keys_s"].as_array().unwrap().len(), rounds);
        assert_eq!(
            r["raster_speedup_paired"].as_f64(),
            Some(crate::median(&per_round))
        );
        assert!(
            paired_cell(p).contains(&format!("({rounds}; ")),
            "{}",
            paired_cell(p)
        );
    }

    /// `runs` rounds at least; more where rounds are short, up to the cap;
    /// `--quick` and unusable times take `runs`.
    #[test]
    fn paired_rounds_fill_the_budget_within_bounds() {
        assert_eq!(paired_rounds(5, 0.3, false), 5);
        assert_eq!(paired_rounds(5, PAIRED_SECONDS / 50.0, false), 50);
        assert_eq!(paired_rounds(5, 1e-9, false), PAIRED_MAX_ROUNDS);
        assert_eq!(paired_rounds(5, 0.0, false), 5);
        assert_eq!(paired_rounds(5, f64::NAN, false), 5);
        assert_eq!(paired_rounds(5, 1e-3, true), 5);
        assert_eq!(paired_rounds(0, 10.0, false), 1);
        assert_eq!(paired_rounds(500, 1e-9, false), 500);
    }

    #[test]
    fn grid_fills_the_image() {
        let s = grid_scene(2, 8, false).unwrap();
        assert_eq!(s.triangles.len(), 8);
        let f = rendiff::raster::render(&s, Default::default(), &|_| {});
        assert!(f.prim.iter().all(|&p| p != u32::MAX));
    }
}

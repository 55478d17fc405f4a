//! The tracer's BVH build on copies of one triangle against the same number
//! of distinct triangles (issue 39: 40k duplicates must build in under 10x
//! the time of 40k distinct ones). obvhs's PLOC merges mutually nearest
//! clusters; among clusters with one box every distance ties and the build
//! goes quadratic (20k copies took 24 s before `trace::same_box` grouped them).
//!
//! `cargo run --release -p rendiff-bench --example duplicate_build -- \
//!   [N] [ROUNDS] [THREADS,..] [BVH] [NEAR,..] [--json=FILE]`
//! (defaults: 40000, 11, 1,2, medium (the default), 5000,10000).
//!
//! - **distinct**: the first N triangles of the crossover bench's grid
//!   (`crossover_grid`, 2 triangles per cell, in general position);
//! - **copies**: N copies of one screen-filling triangle, (-1, -1, 0),
//!   (1, -1, 0), (0, 1, 0), bit for bit;
//! - both built whole (`TraceBvh::build`: tree and first camera, what a
//!   render waits for) in paired rounds, in alternating order
//!   (`peer_tables::alternate_all`), the ratio per round, its median and 95%
//!   bootstrap interval;
//! - **near copies** (shown, not a goal): NEAR copies of that triangle, copy
//!   `i` moved by `i * 1e-6` along x (`tests/build_timeout.rs`' scene), boxes
//!   a few f32 steps apart, which `same_box` does not group: one build per
//!   size, to show the growth that remains.

use anyhow::{Context, Result};
use rendiff::names::Named;
use rendiff::scene::generators::crossover_grid;
use rendiff::scene::resolve::ResolvedScene;
use rendiff::trace::{BvhQuality, TraceBvh};
use rendiff_bench::example_args::ExampleArgs;
use rendiff_bench::measure::{bootstrap_median_interval, BOOTSTRAP_SEED};
use rendiff_bench::peer_tables::alternate_all;
use serde_json::{json, Value};
use std::time::Instant;

/// The goal: copies build in under this many times the distinct ones' time.
const GOAL_RATIO: f64 = 10.0;

fn main() -> Result<()> {
    let args = ExampleArgs::from_env();
    let arg = |i: usize, d: &str| args.get(i, d);
    let n: usize = arg(0, "40000").parse().context("N")?;
    let rounds: usize = arg(1, "11").parse().context("ROUNDS")?;
    let threads = args.counts(2, "1,2", "THREADS")?;
    let quality = args.bvh(3, "medium")?;
    let near_sizes = args.counts(4, "5000,10000", "NEAR")?;
    anyhow::ensure!(
        n >= 2 && rounds >= 1,
        "N must be at least 2 and ROUNDS at least 1"
    );

    let distinct = grid_prefix(n)?;
    let first = one_triangle();
    let copies = with_triangles(&distinct, (0..n).map(|_| first).collect());
    let mut tables = serde_json::Map::new();
    for &t in &threads {
        let table = rendiff_bench::pool(t)?.install(|| -> Result<Value> {
            let load_before = rendiff_bench::load_average();
            let mut build_distinct = || build_s(&distinct, quality);
            let mut build_copies = || build_s(&copies, quality);
            let series = alternate_all(rounds, &mut [&mut build_distinct, &mut build_copies]);
            let (d, c) = (&series[0], &series[1]);
            let ratios: Vec<f64> = c.iter().zip(d).map(|(c, d)| c / d).collect();
            let median = rendiff_bench::median(&ratios);
            let near: Vec<Value> = near_sizes
                .iter()
                .map(|&m| {
                    let s = near_copies(&distinct, m);
                    json!({"triangles": m, "build_s": build_s(&s, quality)})
                })
                .collect();
            println!(
                "{t} thread(s), {n} triangles: distinct {:.4} s, copies {:.4} s (medians): \
                 copies / distinct {median:.2}x {:?} (goal under {GOAL_RATIO}x); near copies {}; load {:?}",
                rendiff_bench::median(d),
                rendiff_bench::median(c),
                bootstrap_median_interval(&ratios, BOOTSTRAP_SEED),
                near.iter()
                    .map(|v| format!("{} in {:.3} s", v["triangles"], v["build_s"].as_f64().unwrap_or(f64::NAN)))
                    .collect::<Vec<_>>()
                    .join(", "),
                rendiff_bench::load_average(),
            );
            Ok(json!({
                "distinct_build_s": d,
                "copies_build_s": c,
                "distinct_build_s_median": rendiff_bench::median(d),
                "copies_build_s_median": rendiff_bench::median(c),
                "copies_over_distinct": {
                    "median": median,
                    "interval_95": bootstrap_median_interval(&ratios, BOOTSTRAP_SEED),
                    "per_round": ratios,
                },
                "goal": {"what": format!("copies build in under {GOAL_RATIO}x the distinct ones' time"),
                         "met": median < GOAL_RATIO},
                "near_copies_shown_not_a_goal": near,
                "load_average_before": load_before,
                "load_average_after": rendiff_bench::load_average(),
            }))
        })?;
        tables.insert(format!("{t}_threads"), table);
    }
    if let Some(path) = &args.json_out {
        let out = json!({
            "benchmark": "duplicate_build example: the tracer's BVH build (tree and first camera) on N copies of one triangle against N distinct ones, paired alternating rounds",
            "triangles": n,
            "rounds": rounds,
            "bvh": quality.name(),
            "distinct": "the first N triangles of crossover_grid (256x256 image), general position",
            "copies": "N bit-identical copies of the screen-filling triangle (-1,-1,0) (1,-1,0) (0,1,0)",
            "near_copies": "copies of it, copy i moved by i * 1e-6 along x (boxes a few f32 steps apart: not grouped)",
            "environment": rendiff_bench::environment(),
            "tables": tables,
        });
        rendiff_bench::write_json_file(path, &out)?;
        eprintln!("wrote {path}");
    }
    Ok(())
}

/// Seconds of one whole build (tree and first camera).
fn build_s(scene: &ResolvedScene, quality: BvhQuality) -> f64 {
    let t0 = Instant::now();
    let bvh = TraceBvh::build(scene, quality);
    let s = t0.elapsed().as_secs_f64();
    drop(std::hint::black_box(bvh));
    s
}

/// The crossover grid with enough cells for `n` triangles, cut to the first `n`.
fn grid_prefix(n: usize) -> Result<ResolvedScene> {
    let nx = ((n as f64 / 2.0).sqrt().ceil() as u32).max(1);
    let grid = crossover_grid(nx, 256, false).map_err(anyhow::Error::msg)?;
    let tris = grid.triangles[..n].to_vec();
    Ok(with_triangles(&grid, tris))
}

/// `scene` with other triangles, all in its first object.
fn with_triangles(
    scene: &ResolvedScene,
    triangles: Vec<rendiff::scene::resolve::Tri>,
) -> ResolvedScene {
    let mut s = scene.clone();
    s.degenerate = triangles
        .iter()
        .map(rendiff::scene::resolve::is_degenerate)
        .collect();
    s.object_ids = vec![0; triangles.len()];
    s.triangles = triangles;
    s
}

/// The triangle copied: it fills the grid's view, as `tests/build_timeout.rs`' does its own.
fn one_triangle() -> rendiff::scene::resolve::Tri {
    use glam::Vec3;
    [
        Vec3::new(-1.0, -1.0, 0.0),
        Vec3::new(1.0, -1.0, 0.0),
        Vec3::new(0.0, 1.0, 0.0),
    ]
}

/// `m` copies of [`one_triangle`], copy `i` moved by `i * 1e-6` along x.
fn near_copies(scene: &ResolvedScene, m: usize) -> ResolvedScene {
    let first = one_triangle();
    let tris = (0..m)
        .map(|i| first.map(|v| v + glam::Vec3::new(i as f32 * 1e-6, 0.0, 0.0)))
        .collect();
    with_triangles(scene, tris)
}

//! Fit data for the loop cost model (`rendiff::loop_cost`, docs/benchmarks.md
//! "Which loop"): for each scene, the model's inputs
//! ([`rendiff::loop_cost::workload`]) and the raster's and the tracer's
//! visibility passes in paired, alternating rounds (the BVH built and aimed
//! before, as `bench crossover`'s "BVH shared" budget counts them), one JSON
//! object per line on stdout.
//!
//! Scenes: every `*.toml` of the folders given (default `scenes` and
//! `scenes/corpus`), each at its own size and at 4x its pixels, plus shapes
//! the crossover grid does not have: the grid tilted away from the camera,
//! folded, and stacked in layers (depth complexity 1 to 8).
//!
//! `cargo run --release -p rendiff-bench --example loop_fit -- [THREADS] [ROUNDS] [FOLDER..]`
//! (defaults 2, 7) measures; `loop_fit fit FILE..` fits the tracer-over-raster
//! ratio of [`rendiff::loop_cost::trace_over_raster`] to one or more runs'
//! lines (the same rows in the same order: each row's median ratio over the
//! runs), and prints the coefficients, how many rows the fit and the model
//! in the build pick right, and how many a fit without the row's scene
//! (both its sizes, or every size of a grid shape) picks right.

use anyhow::{Context, Result};
use rendiff::loop_cost;
use rendiff::scene::generators::crossover_grid;
use rendiff::scene::resolve::ResolvedScene;
use rendiff::trace::{BvhQuality, TraceBvh};
use rendiff_bench::measure;
use serde_json::json;
use std::path::PathBuf;

/// One line: the scene's name, the model's inputs and the paired passes,
/// through the default BVH (the tree `render` and `check` build).
fn row(name: &str, scene: &ResolvedScene, threads: usize, rounds: usize) {
    let bvh = TraceBvh::build(scene, BvhQuality::default());
    let paired = measure::raster_vs_trace(scene, &bvh, rounds);
    let med = |k: &str| {
        rendiff_bench::median(
            &paired[k]
                .as_array()
                .into_iter()
                .flatten()
                .filter_map(|v| v.as_f64())
                .collect::<Vec<_>>(),
        )
    };
    let w = loop_cost::workload(scene, threads);
    let (area, boxes, behind, tiles) = projected(scene);
    let rc = rendiff::raster::render_keys(scene, Default::default(), &|_| {}).counters;
    let tc = rendiff::trace::trace_keys(scene, &bvh, Default::default(), &|_| {}).counters;
    println!(
        "{}",
        json!({
            "scene": name,
            "workload": w,
            "area": area,
            "boxes": boxes,
            "behind": behind,
            "tiles": tiles,
            "raster_counters": rc,
            "trace_counters": tc,
            "raster_s": med("raster_keys_s"),
            "trace_s": med("trace_keys_s"),
            "trace_over_raster": med("trace_over_raster_per_round"),
        })
    );
}

/// Summed projected area and summed clipped pixel-box area of the
/// non-degenerate triangles wholly in front of the eye, in pixels, and how
/// many triangles reach behind it.
fn projected(scene: &ResolvedScene) -> (f64, f64, u64, f64) {
    let cam = &scene.camera;
    let (wf, hf) = (f64::from(cam.width), f64::from(cam.height));
    let aspect_tan = cam.tan_half_vfov * wf / hf;
    let (mut area, mut boxes, mut behind, mut tiles) = (0.0, 0.0, 0u64, 0.0);
    for (t, &d) in scene.triangles.iter().zip(&scene.degenerate) {
        if d {
            continue;
        }
        let mut q = [[0.0f64; 2]; 3];
        let mut ok = true;
        for (k, v) in t.iter().enumerate() {
            let p = v.as_dvec3() - cam.eye;
            let z = p.dot(cam.forward);
            if z.is_nan() || z <= 0.0 {
                ok = false;
                break;
            }
            q[k] = [
                (p.dot(cam.right) / z / aspect_tan + 1.0) * 0.5 * wf,
                (1.0 - p.dot(cam.up_ortho) / z / cam.tan_half_vfov) * 0.5 * hf,
            ];
        }
        if !ok {
            behind += 1;
            continue;
        }
        let cross =
            (q[1][0] - q[0][0]) * (q[2][1] - q[0][1]) - (q[2][0] - q[0][0]) * (q[1][1] - q[0][1]);
        let (x0, x1) = (
            q.iter().map(|v| v[0]).fold(f64::INFINITY, f64::min),
            q.iter().map(|v| v[0]).fold(f64::NEG_INFINITY, f64::max),
        );
        let (y0, y1) = (
            q.iter().map(|v| v[1]).fold(f64::INFINITY, f64::min),
            q.iter().map(|v| v[1]).fold(f64::NEG_INFINITY, f64::max),
        );
        let bw = (x1.min(wf) - x0.max(0.0)).max(0.0);
        let bh = (y1.min(hf) - y0.max(0.0)).max(0.0);
        if bw > 0.0 && bh > 0.0 {
            // The area inside the image, estimated by the clipped box's share.
            let full = (x1 - x0) * (y1 - y0);
            area += 0.5 * cross.abs() * if full > 0.0 { bw * bh / full } else { 1.0 };
            boxes += bw * bh;
            let t = 32.0;
            let tx = (x1.min(wf - 1e-9) / t).floor() - (x0.max(0.0) / t).floor() + 1.0;
            let ty = (y1.min(hf - 1e-9) / t).floor() - (y0.max(0.0) / t).floor() + 1.0;
            tiles += tx * ty;
        }
    }
    (area, boxes, behind, tiles)
}

/// The crossover grid with each vertex moved by `f(x, y) -> z`.
fn shaped(nx: u32, size: u32, f: impl Fn(f32, f32) -> f32) -> Result<ResolvedScene> {
    let g = crossover_grid(nx, size, false).map_err(anyhow::Error::msg)?;
    let tris = g
        .triangles
        .iter()
        .map(|t| t.map(|v| glam::Vec3::new(v.x, v.y, f(v.x, v.y))))
        .collect();
    Ok(ResolvedScene::from_triangles(g.camera.clone(), tris))
}

/// `layers` copies of the crossover grid, 0.01 apart in depth.
fn stacked(nx: u32, size: u32, layers: u32) -> Result<ResolvedScene> {
    let g = crossover_grid(nx, size, false).map_err(anyhow::Error::msg)?;
    let mut tris = Vec::new();
    for l in 0..layers {
        let dz = -0.01 * l as f32;
        tris.extend(
            g.triangles
                .iter()
                .map(|t| t.map(|v| v + glam::Vec3::Z * dz)),
        );
    }
    Ok(ResolvedScene::from_triangles(g.camera.clone(), tris))
}

/// Least squares `x` of `a x = b` through the normal equations (4 unknowns,
/// well-conditioned inputs: logs of counts), by Gaussian elimination with
/// partial pivoting.
fn least_squares(a: &[[f64; 4]], b: &[f64]) -> [f64; 4] {
    let mut m = [[0.0f64; 5]; 4];
    for (row, &y) in a.iter().zip(b) {
        for i in 0..4 {
            for j in 0..4 {
                m[i][j] += row[i] * row[j];
            }
            m[i][4] += row[i] * y;
        }
    }
    for c in 0..4 {
        let p = (c..4)
            .max_by(|&i, &j| m[i][c].abs().total_cmp(&m[j][c].abs()))
            .unwrap_or(c);
        m.swap(c, p);
        for r in 0..4 {
            if r != c && m[c][c] != 0.0 {
                let f = m[r][c] / m[c][c];
                let pivot = m[c];
                for (v, p) in m[r].iter_mut().zip(pivot).skip(c) {
                    *v -= f * p;
                }
            }
        }
    }
    std::array::from_fn(|i| m[i][4] / m[i][i])
}

/// `loop_fit fit FILE..`: see the module comment.
fn fit(files: &[String]) -> Result<()> {
    let runs: Vec<Vec<serde_json::Value>> = files
        .iter()
        .map(|f| {
            let text = std::fs::read_to_string(f).with_context(|| format!("{f}: cannot read"))?;
            text.lines()
                .map(|l| serde_json::from_str(l).with_context(|| format!("{f}: not JSON lines")))
                .collect()
        })
        .collect::<Result<_>>()?;
    let rows = &runs[0];
    let mut x = Vec::new();
    let mut y = Vec::new();
    let mut groups = Vec::new();
    let mut model_right = 0;
    for (i, r) in rows.iter().enumerate() {
        let w: loop_cost::Workload = serde_json::from_value(r["workload"].clone())?;
        let ratios: Vec<f64> = runs
            .iter()
            .filter_map(|run| run.get(i)?["trace_over_raster"].as_f64())
            .collect();
        let ratio = rendiff_bench::median(&ratios);
        x.push(loop_cost::ratio_features(&w));
        y.push(ratio.ln());
        let name = r["scene"].as_str().unwrap_or_default();
        groups.push(name.split('@').next().unwrap_or_default().to_string());
        let shared = loop_cost::Workload {
            bvh_needed_anyway: true,
            ..w
        };
        let pick = loop_cost::choose(&shared).pick;
        model_right += usize::from((pick == loop_cost::Loop::Trace) == (ratio < 1.0));
    }
    let right = |c: &[f64; 4], i: usize| {
        let e: f64 = c.iter().zip(&x[i]).map(|(c, x)| c * x).sum();
        (e < 0.0) == (y[i] < 0.0)
    };
    let c = least_squares(&x, &y);
    let fit_right = (0..x.len()).filter(|&i| right(&c, i)).count();
    let held_out = (0..x.len())
        .filter(|&i| {
            let keep: Vec<usize> = (0..x.len()).filter(|&j| groups[j] != groups[i]).collect();
            let xs: Vec<[f64; 4]> = keep.iter().map(|&j| x[j]).collect();
            let ys: Vec<f64> = keep.iter().map(|&j| y[j]).collect();
            right(&least_squares(&xs, &ys), i)
        })
        .count();
    println!(
        "{}",
        json!({
            "rows": x.len(),
            "runs": runs.len(),
            "coefficients": c,
            "fit_right": fit_right,
            "held_out_right": held_out,
            "model_in_this_build_right": model_right,
        })
    );
    Ok(())
}

fn main() -> Result<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    if args.first().map(String::as_str) == Some("fit") {
        return fit(&args[1..]);
    }
    let threads: usize = args
        .first()
        .map_or(Ok(2), |s| s.parse())
        .context("THREADS")?;
    let rounds: usize = args.get(1).map_or(Ok(7), |s| s.parse()).context("ROUNDS")?;
    let folders: Vec<PathBuf> = if args.len() > 2 {
        args[2..].iter().map(PathBuf::from).collect()
    } else {
        vec!["scenes".into(), "scenes/corpus".into()]
    };
    rendiff_bench::pool(threads)?.install(|| -> Result<()> {
        // The same scene list `bench crossover` checks the model on.
        for p in rendiff_bench::which_loop::corpus_files(&folders)? {
            let name = p.file_stem().unwrap_or_default().to_string_lossy();
            let s = rendiff_bench::load_scene(&p)?;
            eprintln!("{name}");
            row(&name, &s, threads, rounds);
            let (w, h) = (s.camera.width * 2, s.camera.height * 2);
            let big = rendiff_bench::resized(&s, w, h)?;
            row(&format!("{name}@{w}x{h}"), &big, threads, rounds);
        }
        for size in [256u32, 512] {
            for nx in [4u32, 32, 128, 512] {
                eprintln!("grids {nx} {size}");
                row(
                    &format!("tilted_{nx}@{size}"),
                    &shaped(nx, size, |_, y| 0.8 * y)?,
                    threads,
                    rounds,
                );
                row(
                    &format!("folded_{nx}@{size}"),
                    &shaped(nx, size, |x, _| -0.8 * x.abs())?,
                    threads,
                    rounds,
                );
                for layers in [2u32, 4, 8] {
                    row(
                        &format!("stacked{layers}_{nx}@{size}"),
                        &stacked(nx, size, layers)?,
                        threads,
                        rounds,
                    );
                }
                let flat = crossover_grid(nx, size, false).map_err(anyhow::Error::msg)?;
                row(&format!("grid_{nx}@{size}"), &flat, threads, rounds);
            }
        }
        Ok(())
    })
}

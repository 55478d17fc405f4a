//! Which of the core's two loops renders a scene sooner: a cost model fitted
//! to `bench crossover`'s measurements (docs/benchmarks.md, "Which loop").
//!
//! Raster and trace give the same buffers bit for bit (tests/raster_vs_trace.rs
//! holds them to it, on the loop this model picks too), so the choice changes
//! time, never a verdict. `render --renderer core` and `check`'s reference
//! render ask here; `--renderer raster|trace` still forces one.
//!
//! The model: the raster's visibility pass costs `P_cov * g(N / P_cov)`, with
//! `P_cov` the covered pixels (estimated by [`covered_pixels`]) and
//! `g(density)` the measured seconds per covered pixel at that many triangles
//! per covered pixel, interpolated piecewise linearly in log-log space between
//! the crossover grid's sizes (and extended along the end segments). The
//! tracer's pass is the raster's times a ratio, `exp(c . [1, ln P, ln N,
//! ln(P_cov / P)])`, fitted by least squares to the paired
//! passes of 126 workloads ([`RATIO_1T`], [`RATIO_2T`]): the grid alone,
//! fitted as a table, got the corpus's closed meshes wrong, where the tracer
//! leads. The tracer adds its BVH build (camera
//! set-up included), `N * b(N)` from the crossover runs, unless the BVH is
//! built anyway (a shaded scene traces shadow or path rays through it) or is
//! shared by many frames. Threads: the 1-thread tables for one, the 2-thread
//! ones (the raster's scaled by `2 / threads`) for more (the passes scale
//! about linearly on the crossover runs; the build barely does, so its table
//! is not scaled).

use crate::scene::resolve::ResolvedScene;

/// The loop a budget picks.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Loop {
    /// Outer loop over triangles.
    Raster,
    /// Outer loop over pixels (BVH).
    Trace,
}

impl Loop {
    /// The loop's name, as `--renderer` spells it.
    pub fn name(self) -> &'static str {
        match self {
            Loop::Raster => "raster",
            Loop::Trace => "trace",
        }
    }
}

/// What a render will cost: the model's inputs.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Workload {
    /// Triangles the loops see (degenerate ones excluded).
    pub triangles: u64,
    /// Pixels in the image.
    pub pixels: u64,
    /// Pixels the geometry covers (an estimate, at most `pixels`).
    pub covered: u64,
    /// Worker threads.
    pub threads: usize,
    /// Frames rendered with the same BVH (the build is paid once for them).
    pub frames: u32,
    /// The BVH is built whichever loop renders (shading traces through it).
    pub bvh_needed_anyway: bool,
}

/// The model's verdict and the estimates behind it.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct Choice {
    /// The loop with the smaller estimate (the raster on a tie).
    pub pick: Loop,
    /// Estimated seconds of the raster's passes for all frames.
    pub raster_s: f64,
    /// Estimated seconds of the tracer's passes for all frames plus the BVH
    /// build it alone would pay.
    pub trace_s: f64,
    /// Estimated seconds of the BVH build (camera set-up included).
    pub build_s: f64,
}

/// Triangles per covered pixel at the crossover grid's sizes (2 to 8.4M
/// triangles on 512x512 pixels, all covered).
const DENSITY: [f64; 10] = [
    2.0 / 262144.0,
    8.0 / 262144.0,
    32.0 / 262144.0,
    512.0 / 262144.0,
    2048.0 / 262144.0,
    32768.0 / 262144.0,
    131072.0 / 262144.0,
    524288.0 / 262144.0,
    2097152.0 / 262144.0,
    8388608.0 / 262144.0,
];

/// The raster's pass seconds at each [`DENSITY`], 512x512, 1 thread. From
/// the quiet runs of Nov 27 12:03 (build 45265b6, docs/benchmarks.md
/// "Crossover", separate medians).
const RASTER_PASS_1T: [f64; 10] = [
    0.346e-3, 0.689e-3, 1.01e-3, 4.65e-3, 5.25e-3, 17.6e-3, 22.3e-3, 39.0e-3, 87.1e-3, 198e-3,
];

/// The same at 2 threads (reports/bench/crossover.json of that run).
const RASTER_PASS_2T: [f64; 10] = [
    0.255e-3, 0.530e-3, 0.800e-3, 2.93e-3, 4.31e-3, 9.85e-3, 14.0e-3, 34.7e-3, 61.4e-3, 158e-3,
];

/// ln(trace pass / raster pass) = `c . [1, ln P, ln N, ln(P_cov / P)]` on 1
/// thread: least squares over the paired passes of
/// `examples/loop_fit.rs` (every scene of `scenes/` and `scenes/corpus/` at
/// its own size and at 4x its pixels, and the crossover grid flat, tilted,
/// folded and stacked 2, 4 and 8 deep at 4 to 512 cells a side on 256² and
/// 512²: 126 rows), Nov 30, AMD EPYC, the data in
/// reports/bench/which-loop/fit/ (`loop_fit fit 1-thread.jsonl` and
/// `loop_fit fit 2-threads-{a,b,c}.jsonl` recompute these). The
/// passes were timed through obvhs medium's tree, the default until Nov 30
/// 15:27; a refit through today's default (`linear`, 22:38-22:40,
/// `fit/default-bvh-*`) picked better on small scenes but moved the flat
/// grid's crossover with the BVH shared from 2.1M down to 131,072 triangles,
/// where the raster's pass still leads by 1.3x, so it was not taken
/// (docs/benchmarks.md, "Which loop").
const RATIO_1T: [f64; 4] = [-1.3933, 0.2698, -0.1466, 0.0048];

/// The same at 2 threads (the median of three runs' paired ratios per row).
const RATIO_2T: [f64; 4] = [-1.5062, 0.2538, -0.1241, 0.0407];

/// The ratio model's inputs for `w`, in [`RATIO_1T`]'s order.
pub fn ratio_features(w: &Workload) -> [f64; 4] {
    let pixels = w.pixels.max(1) as f64;
    let covered = (w.covered.clamp(1, w.pixels.max(1))) as f64;
    let n = w.triangles.max(1) as f64;
    [1.0, pixels.ln(), n.ln(), (covered / pixels).ln()]
}

/// Estimated trace pass / raster pass on `w` (above 1: the raster leads).
pub fn trace_over_raster(w: &Workload) -> f64 {
    let c = if w.threads <= 1 { &RATIO_1T } else { &RATIO_2T };
    let x = ratio_features(w);
    c.iter().zip(x).map(|(c, x)| c * x).sum::<f64>().exp()
}

/// Triangles at which the BVH build was timed (the same grid).
const BUILD_TRIANGLES: [f64; 10] = [
    2.0, 8.0, 32.0, 512.0, 2048.0, 32768.0, 131072.0, 524288.0, 2097152.0, 8388608.0,
];

/// Build seconds of the default BVH (`BvhQuality::Linear`, plus the camera
/// set-up: `TraceBvh::build`) at each [`BUILD_TRIANGLES`], 2 threads: the
/// medians of `bench crossover --threads 2` on the which-loop grid sizes,
/// Nov 30 15:27, AMD EPYC, quiet (other processes 0.4% of the CPU). One
/// thread built `million` in 1.27x the time of two (0.095 s against 0.075),
/// so one table serves both. (Until then: obvhs medium's, 2.5-19x slower.)
const BUILD_S: [f64; 10] = [
    7.25e-6, 7.40e-6, 8.65e-6, 2.38e-5, 6.83e-5, 8.56e-4, 3.65e-3, 1.99e-2, 9.74e-2, 0.472,
];

/// A new camera's leaf set-up per triangle, which the tracer's first pass
/// pays on top of a steady one (its leaves are set up as traversal first
/// reaches them, so [`BUILD_S`] does not hold it): `bench crossover`'s
/// `leaf_set_up_s` over the grid's triangles at 2 threads, the median of the
/// five sizes from 32,768 to 8.4M triangles (8.1 to 26.7 ns each), Nov 30
/// 19:43, AMD EPYC, quiet. Below 32,768 triangles the difference of two
/// passes is within their noise (0 to 50 µs), so a rate from the large sizes
/// stands for all.
const LEAF_SET_UP_S_PER_TRIANGLE: f64 = 9.3e-9;

/// `y(x)` interpolated linearly in log-log space through `(xs, ys)`, and
/// extended along the first and last segments.
fn log_interp(xs: &[f64], ys: &[f64], x: f64) -> f64 {
    let lx = x.max(f64::MIN_POSITIVE).ln();
    let n = xs.len();
    let i = match xs.iter().position(|&v| v.ln() >= lx) {
        Some(0) => 0,
        Some(i) => i - 1,
        None => n - 2,
    };
    let (x0, x1) = (xs[i].ln(), xs[i + 1].ln());
    let (y0, y1) = (ys[i].ln(), ys[i + 1].ln());
    (y0 + (y1 - y0) * (lx - x0) / (x1 - x0)).exp()
}

/// Estimated seconds of one visibility pass of `l` on `w`.
pub fn pass_seconds(l: Loop, w: &Workload) -> f64 {
    let covered = w.covered.clamp(1, w.pixels.max(1)) as f64;
    let density = w.triangles.max(1) as f64 / covered;
    let (table, scale) = if w.threads <= 1 {
        (&RASTER_PASS_1T, 1.0)
    } else {
        (&RASTER_PASS_2T, 2.0 / w.threads as f64)
    };
    let per_pixel = log_interp(&DENSITY, &table.map(|s| s / 262144.0), density);
    let raster = covered * per_pixel * scale;
    match l {
        Loop::Raster => raster,
        Loop::Trace => raster * trace_over_raster(w),
    }
}

/// Estimated seconds of the tracer's BVH build for `triangles`, with what a
/// new camera adds to its first pass (its leaves' set-up): what one frame
/// pays beyond a steady pass.
pub fn build_seconds(triangles: u64) -> f64 {
    if triangles == 0 {
        return 0.0;
    }
    log_interp(&BUILD_TRIANGLES, &BUILD_S, triangles as f64)
        + triangles as f64 * LEAF_SET_UP_S_PER_TRIANGLE
}

/// The loop the model expects to finish `w` sooner.
pub fn choose(w: &Workload) -> Choice {
    let frames = f64::from(w.frames.max(1));
    let build_s = build_seconds(w.triangles);
    let raster_s = frames * pass_seconds(Loop::Raster, w);
    let own_build = if w.bvh_needed_anyway { 0.0 } else { build_s };
    let trace_s = frames * pass_seconds(Loop::Trace, w) + own_build;
    let pick = if trace_s < raster_s {
        Loop::Trace
    } else {
        Loop::Raster
    };
    Choice {
        pick,
        raster_s,
        trace_s,
        build_s,
    }
}

/// Pixels whose centers the scene's geometry may cover: the image area inside
/// the projection of the non-degenerate triangles' bounding box (all of it
/// when the box reaches behind the eye). An upper bound, exact for a
/// screen-filling scene; cheap (one pass over the vertices).
pub fn covered_pixels(scene: &ResolvedScene) -> u64 {
    let cam = &scene.camera;
    let pixels = u64::from(cam.width) * u64::from(cam.height);
    let Some((lo, hi)) = triangle_bounds(scene) else {
        return 0;
    };
    let (mut x0, mut x1, mut y0, mut y1) = (
        f64::INFINITY,
        f64::NEG_INFINITY,
        f64::INFINITY,
        f64::NEG_INFINITY,
    );
    let aspect_tan = cam.tan_half_vfov * f64::from(cam.width) / f64::from(cam.height);
    for k in 0..8 {
        let p = glam::DVec3::new(
            if k & 1 == 0 { lo.x } else { hi.x },
            if k & 2 == 0 { lo.y } else { hi.y },
            if k & 4 == 0 { lo.z } else { hi.z },
        ) - cam.eye;
        let z = p.dot(cam.forward);
        // (A NaN depth counts as behind the eye too.)
        if z.is_nan() || z <= 0.0 {
            return pixels;
        }
        // Continuous image coordinates (pixel centers at k + 0.5, y down).
        let fx = (p.dot(cam.right) / z / aspect_tan + 1.0) * 0.5 * f64::from(cam.width);
        let fy = (1.0 - p.dot(cam.up_ortho) / z / cam.tan_half_vfov) * 0.5 * f64::from(cam.height);
        (x0, x1, y0, y1) = (x0.min(fx), x1.max(fx), y0.min(fy), y1.max(fy));
    }
    let span = |a: f64, b: f64, n: u32| -> f64 {
        let (a, b) = (a.max(0.0), b.min(f64::from(n)));
        (b - a).max(0.0)
    };
    let area = span(x0, x1, cam.width) * span(y0, y1, cam.height);
    (area.ceil() as u64).min(pixels)
}

/// The bounding box of the scene's non-degenerate triangles (`None` when
/// there are none), in parallel chunks on rayon's current pool. The model's
/// one pass over the scene: it is part of every `render --renderer core`
/// (about 4 ms on a million triangles on one thread, reading 47 MB).
fn triangle_bounds(scene: &ResolvedScene) -> Option<(glam::DVec3, glam::DVec3)> {
    use rayon::prelude::*;
    /// Triangles per task.
    const GRAIN: usize = 1 << 15;
    let empty = (
        glam::DVec3::splat(f64::INFINITY),
        glam::DVec3::splat(f64::NEG_INFINITY),
    );
    let (lo, hi) = scene
        .triangles
        .par_chunks(GRAIN)
        .zip(scene.degenerate.par_chunks(GRAIN))
        .map(|(tris, deg)| {
            let (mut lo, mut hi) = empty;
            for (t, &degenerate) in tris.iter().zip(deg) {
                if !degenerate {
                    for v in t {
                        lo = lo.min(v.as_dvec3());
                        hi = hi.max(v.as_dvec3());
                    }
                }
            }
            (lo, hi)
        })
        .reduce(|| empty, |(a, b), (c, d)| (a.min(c), b.max(d)));
    (lo.x <= hi.x).then_some((lo, hi))
}

/// The model's inputs for rendering `scene` once on `threads` threads.
pub fn workload(scene: &ResolvedScene, threads: usize) -> Workload {
    let cam = &scene.camera;
    Workload {
        triangles: scene.degenerate.iter().filter(|&&d| !d).count() as u64,
        pixels: u64::from(cam.width) * u64::from(cam.height),
        covered: covered_pixels(scene),
        threads,
        frames: 1,
        bvh_needed_anyway: crate::shade::needs_shading(scene),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn grid(triangles: u64, threads: usize) -> Workload {
        Workload {
            triangles,
            pixels: 262144,
            covered: 262144,
            threads,
            frames: 1,
            bvh_needed_anyway: false,
        }
    }

    /// The covered pixels come from the box of the non-degenerate triangles
    /// only, wherever in the scene they lie (the box is made in parallel
    /// chunks): a far triangle in the last chunk widens it, a degenerate one
    /// at the image's corner does not, nothing is 0, and a box reaching
    /// behind the eye covers the image.
    #[test]
    fn covered_pixels_bound_the_non_degenerate_triangles() {
        use crate::scene::resolve::Tri;
        use glam::{DVec3, Vec3};
        let cam = crate::camera::Camera::new(
            DVec3::new(0.0, 0.0, 10.0),
            DVec3::ZERO,
            DVec3::Y,
            90.0,
            100,
            100,
            0.1,
            f64::INFINITY,
        )
        .unwrap();
        let tri = |x: f32, y: f32, r: f32| -> Tri {
            [
                Vec3::new(x - r, y - r, 0.0),
                Vec3::new(x + r, y - r, 0.0),
                Vec3::new(x, y + r, 0.0),
            ]
        };
        let covered =
            |tris: Vec<Tri>| covered_pixels(&ResolvedScene::from_triangles(cam.clone(), tris));
        // At z = 0 the 90-degree view spans [-10, 10]: 5 pixels a unit. The
        // area is rounded up, so a rounding error above it adds one pixel.
        let near = |got: u64, want: u64| got == want || got == want + 1;
        let mut tris = vec![tri(0.0, 0.0, 1.0); 3 * (1 << 15) + 7];
        assert!(near(covered(tris.clone()), 100));
        let zero_area: Tri = [
            Vec3::splat(-9.0),
            Vec3::splat(-9.0),
            Vec3::new(-9.0, -9.0, 0.0),
        ];
        tris.insert(5, zero_area);
        assert!(
            near(covered(tris.clone()), 100),
            "a degenerate triangle widened the box"
        );
        tris.push(tri(5.0, 5.0, 1.0));
        assert!(near(covered(tris.clone()), 35 * 35));
        assert_eq!(covered(Vec::new()), 0);
        tris.push(tri(0.0, 0.0, 20.0).map(|v| v + Vec3::Z * 15.0));
        assert_eq!(covered(tris), 100 * 100);
    }

    /// At the measured sizes the raster's estimate returns the measurements
    /// it was fitted to, the build's likewise (plus the leaves' set-up at
    /// its rate), and the tracer's is the raster's times the fitted ratio.
    #[test]
    fn the_model_passes_through_its_fit_data() {
        for (i, &d) in DENSITY.iter().enumerate() {
            let n = (d * 262144.0).round() as u64;
            for (threads, table) in [(1, &RASTER_PASS_1T), (2, &RASTER_PASS_2T)] {
                let w = grid(n, threads);
                let r = pass_seconds(Loop::Raster, &w);
                assert!((r / table[i] - 1.0).abs() < 1e-9, "{n} {threads}");
                let t = pass_seconds(Loop::Trace, &w);
                assert!((t / (r * trace_over_raster(&w)) - 1.0).abs() < 1e-12);
            }
            let leaves = n as f64 * LEAF_SET_UP_S_PER_TRIANGLE;
            assert!(((build_seconds(n) - leaves) / BUILD_S[i] - 1.0).abs() < 1e-9);
        }
    }

    /// The ratio is `exp(c . x)` with each coefficient on its own input:
    /// scaling one input by e moves the log ratio by exactly its coefficient.
    #[test]
    fn each_ratio_input_moves_the_log_ratio_by_its_coefficient() {
        let l = |w: &Workload| trace_over_raster(w).ln();
        let e = std::f64::consts::E;
        for (threads, c) in [(1, &RATIO_1T), (2, &RATIO_2T)] {
            let b = Workload {
                triangles: 1_000_000,
                pixels: 1_000_000,
                covered: 200_000,
                ..grid(1, threads)
            };
            let scaled = |x: u64| (x as f64 * e).round() as u64;
            let more = Workload {
                triangles: scaled(b.triangles),
                ..b
            };
            assert!((l(&more) - l(&b) - c[2]).abs() < 1e-6, "{threads}");
            let covered = Workload {
                covered: scaled(b.covered),
                ..b
            };
            assert!((l(&covered) - l(&b) - c[3]).abs() < 1e-6);
            // More pixels, the same covered count: ln P up by 1, ln(P_cov / P) down by 1.
            let image = Workload {
                pixels: scaled(b.pixels),
                ..b
            };
            assert!((l(&image) - l(&b) - (c[1] - c[3])).abs() < 1e-6);
        }
    }

    /// What the fit data showed, on their own workloads: the raster leads on
    /// a few large triangles (two screen-filling ones, 512x512: measured
    /// 11-13x, outside the fit data; fewer triangles lead by more, so the
    /// estimate must be at least the lead of the fit data's fewest, 32
    /// triangles on 512x512, measured 3.6x at the least), the tracer on a
    /// dense mesh over a small image
    /// (`nefertiti_scan`, 99,938 triangles on 9,481 of 160x120 pixels:
    /// measured 0.60-0.81x) and on `million` at 240x240 (0.67-0.71x); on
    /// `million` at 1920x1080 the raster's pass leads again (`bench peers`:
    /// 1.17x on 1 thread, 1.19x on 2).
    #[test]
    fn the_ratio_orders_the_fit_datas_clear_cases() {
        for threads in [1, 2] {
            let two = grid(2, threads);
            assert!(trace_over_raster(&two) > 3.6, "{threads}");
            let scan = Workload {
                triangles: 99938,
                pixels: 19200,
                covered: 9481,
                ..grid(1, threads)
            };
            assert!(trace_over_raster(&scan) < 0.9, "{threads}");
            let million = |pixels: u64| Workload {
                triangles: 1310722,
                pixels,
                covered: pixels,
                bvh_needed_anyway: true,
                ..grid(1, threads)
            };
            assert_eq!(choose(&million(240 * 240)).pick, Loop::Trace);
            assert_eq!(choose(&million(1920 * 1080)).pick, Loop::Raster);
        }
    }

    /// One frame pays the whole build: the raster wins at every measured size,
    /// as it did in every crossover run that counted the build; a BVH built
    /// anyway leaves the passes, where the tracer wins only at the largest
    /// sizes (the fitted ratio crosses 1 between 524,288 and 2,097,152
    /// triangles on 512x512 at 2 threads; measured at 524,288: the raster's
    /// pass 1.35-1.42x faster).
    #[test]
    fn the_build_decides_one_frame_and_the_passes_decide_many() {
        for &d in &DENSITY {
            let n = (d * 262144.0).round() as u64;
            assert_eq!(choose(&grid(n, 2)).pick, Loop::Raster, "{n}");
            let shared = Workload {
                bvh_needed_anyway: true,
                ..grid(n, 2)
            };
            let want = if n >= 2_097_152 {
                Loop::Trace
            } else {
                Loop::Raster
            };
            assert_eq!(choose(&shared).pick, want, "{n}");
        }
        // Enough frames amortise an 8.4M-triangle build; ten do not.
        let many = Workload {
            frames: 1000,
            ..grid(8_388_608, 2)
        };
        assert_eq!(choose(&many).pick, Loop::Trace);
        let few = Workload {
            frames: 10,
            ..grid(8_388_608, 2)
        };
        assert_eq!(choose(&few).pick, Loop::Raster);
    }

    /// Interpolation is monotone between the points and extends the ends.
    #[test]
    fn interpolation_stays_between_neighbours_and_extends() {
        let xs = [1.0, 10.0, 100.0];
        let ys = [2.0, 20.0, 20.0];
        assert!((log_interp(&xs, &ys, 10f64.sqrt()) - 2.0 * 10f64.sqrt()).abs() < 1e-9);
        assert!((log_interp(&xs, &ys, 0.1) - 0.2).abs() < 1e-12);
        assert!((log_interp(&xs, &ys, 1000.0) - 20.0).abs() < 1e-9);
        assert!(build_seconds(0) == 0.0);
    }

    /// The covered estimate: all of a screen-filling grid, none behind the
    /// camera's back, part of the image for a small object.
    #[test]
    fn covered_pixels_bounds_the_projection() {
        let g = crate::scene::generators::crossover_grid(4, 64, false).unwrap();
        assert_eq!(covered_pixels(&g), 64 * 64);
        let mut small = g.clone();
        for t in &mut small.triangles {
            for v in t.iter_mut() {
                *v *= 0.25;
            }
        }
        let c = covered_pixels(&small);
        assert!(c > 0 && c < 64 * 64 / 4 + 64, "{c}");
        let mut behind = g;
        for t in &mut behind.triangles {
            for v in t.iter_mut() {
                v.z += 10.0;
            }
        }
        // The box lies wholly behind the eye: every corner fails z > 0, so
        // the estimate gives up and counts the whole image (an upper bound).
        assert_eq!(covered_pixels(&behind), 64 * 64);
    }
}

//! Which of the core's two loops renders a scene sooner: a cost model fitted
//! to `bench crossover`'s measurements (docs/benchmarks.md, "Which loop").
//!
//! Raster and trace give the same buffers bit for bit (tests/raster_vs_trace.rs
//! holds them to it, on the loop this model picks too), so the choice changes
//! time, never a verdict. `render --renderer core` and `check`'s reference
//! render ask here; `--renderer raster|trace` still forces one.
//!
//! The model: each loop's visibility pass costs `P_cov * g(N / P_cov)`, with
//! `P_cov` the covered pixels (estimated by [`covered_pixels`]) and
//! `g(density)` the measured seconds per covered pixel at that many triangles
//! per covered pixel, interpolated piecewise linearly in log-log space between
//! the crossover grid's sizes (and extended along the end segments). The
//! tracer adds its BVH build (camera set-up included), `N * b(N)` from the same
//! runs, unless the BVH is built anyway (a shaded scene traces shadow or path
//! rays through it) or is shared by many frames. Threads: the 1-thread table
//! for one, the 2-thread table scaled by `2 / threads` for more (the passes
//! scale about linearly on the crossover runs; the build barely does, so its
//! table is not scaled).

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
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
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

/// Pass seconds at each [`DENSITY`], 512x512, 1 thread: raster, trace.
/// From the quiet runs of Nov 27 12:03 (build 45265b6, docs/benchmarks.md
/// "Crossover", separate medians).
const PASS_1T: [[f64; 10]; 2] = [
    [
        0.346e-3, 0.689e-3, 1.01e-3, 4.65e-3, 5.25e-3, 17.6e-3, 22.3e-3, 39.0e-3, 87.1e-3, 198e-3,
    ],
    [
        4.34e-3, 4.26e-3, 4.72e-3, 7.82e-3, 7.04e-3, 19.7e-3, 27.6e-3, 55.5e-3, 85.7e-3, 197e-3,
    ],
];

/// The same at 2 threads (reports/bench/crossover.json of that run).
const PASS_2T: [[f64; 10]; 2] = [
    [
        0.255e-3, 0.530e-3, 0.800e-3, 2.93e-3, 4.31e-3, 9.85e-3, 14.0e-3, 34.7e-3, 61.4e-3, 158e-3,
    ],
    [
        2.98e-3, 3.36e-3, 4.38e-3, 5.64e-3, 5.83e-3, 10.7e-3, 16.4e-3, 34.7e-3, 63.4e-3, 104e-3,
    ],
];

/// Triangles at which the BVH build was timed (the same grid).
const BUILD_TRIANGLES: [f64; 10] = [
    2.0, 8.0, 32.0, 512.0, 2048.0, 32768.0, 131072.0, 524288.0, 2097152.0, 8388608.0,
];

/// Build seconds (obvhs medium plus the camera set-up, `TraceBvh::build`) at
/// each [`BUILD_TRIANGLES`], 2 threads, from the same record. One thread
/// measured within 1.0-1.3x of it on `million`, so one table serves both.
const BUILD_S: [f64; 10] = [
    1.83e-5, 2.19e-5, 3.43e-5, 3.24e-4, 1.01e-3, 2.08e-2, 9.58e-2, 0.465, 2.25, 8.88,
];

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
    let side = match l {
        Loop::Raster => 0,
        Loop::Trace => 1,
    };
    let (table, scale) = if w.threads <= 1 {
        (&PASS_1T, 1.0)
    } else {
        (&PASS_2T, 2.0 / w.threads as f64)
    };
    let per_pixel = log_interp(&DENSITY, &table[side].map(|s| s / 262144.0), density);
    covered * per_pixel * scale
}

/// Estimated seconds of the tracer's BVH build for `triangles`.
pub fn build_seconds(triangles: u64) -> f64 {
    if triangles == 0 {
        return 0.0;
    }
    log_interp(&BUILD_TRIANGLES, &BUILD_S, triangles as f64)
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
    let mut lo = glam::DVec3::splat(f64::INFINITY);
    let mut hi = glam::DVec3::splat(f64::NEG_INFINITY);
    for (t, &degenerate) in scene.triangles.iter().zip(&scene.degenerate) {
        if !degenerate {
            for v in t {
                lo = lo.min(v.as_dvec3());
                hi = hi.max(v.as_dvec3());
            }
        }
    }
    if lo.x > hi.x {
        return 0;
    }
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

    /// At the measured sizes the model returns the measurements it was fitted to.
    #[test]
    fn the_model_passes_through_its_fit_data() {
        for (i, &d) in DENSITY.iter().enumerate() {
            let n = (d * 262144.0).round() as u64;
            for (threads, table) in [(1, &PASS_1T), (2, &PASS_2T)] {
                let w = grid(n, threads);
                for (l, side) in [(Loop::Raster, 0), (Loop::Trace, 1)] {
                    let got = pass_seconds(l, &w);
                    assert!(
                        (got / table[side][i] - 1.0).abs() < 1e-9,
                        "{n} {threads} {l:?}"
                    );
                }
            }
            assert!((build_seconds(n) / BUILD_S[i] - 1.0).abs() < 1e-9);
        }
    }

    /// One frame pays the whole build: the raster wins at every measured size,
    /// as it did in every crossover run that counted the build; a BVH built
    /// anyway leaves the passes, where the tracer wins only at the largest size.
    #[test]
    fn the_build_decides_one_frame_and_the_passes_decide_many() {
        for &d in &DENSITY {
            let n = (d * 262144.0).round() as u64;
            assert_eq!(choose(&grid(n, 2)).pick, Loop::Raster, "{n}");
            let shared = Workload {
                bvh_needed_anyway: true,
                ..grid(n, 2)
            };
            let want = if n >= 8_000_000 {
                Loop::Trace
            } else {
                Loop::Raster
            };
            assert_eq!(choose(&shared).pick, want, "{n}");
        }
        // Enough frames amortise an 8.4M-triangle build (8.9 s against a 54 ms
        // lead per frame: about 165 frames).
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

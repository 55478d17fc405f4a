//! `rendiff bench variance`: is the core path tracer's per-pixel variance of
//! the mean calibrated, and is its mean unbiased against the cached Mitsuba
//! reference? The statistical gate (Welch per pixel) trusts both.
//!
//! K renders with independent seeds at each spp give, per pixel and channel,
//! the empirical variance of the mean across seeds, compared with the mean of
//! the renders' own predictions ([`variance_stats::calibration`]), and split
//! one render's MSE against the reference into bias² + variance, net of the
//! reference's own noise ([`variance_stats::split`]). It also measures the
//! false-alarm rate and power of the quick calibration test that
//! `tests/variance_calibration.rs` runs ([`calibration_z`] at [`TEST_SPP`] spp
//! over [`TEST_SEEDS`] seeds, rejecting at |z| > [`TEST_Z`]).

use super::page::{num, Page};
use super::plot::{lines, Series};
use super::radiance;
use super::variance_stats::{self, Calibration, Reference, SeedStack, Split};
use super::Common;
use anyhow::{bail, Result};
use rendiff::scene::resolve::ResolvedScene;
use rendiff::shade::{path, Bias, ShadeOptions};
use rendiff::trace::{BvhQuality, TraceBvh};
use serde_json::{json, Value};
use std::path::PathBuf;
use std::time::Instant;

/// Samples per pixel of the quick calibration test.
pub const TEST_SPP: u32 = 16;
/// Seeds of the quick calibration test.
pub const TEST_SEEDS: u64 = 8;
/// The quick test's first seed; `bench variance` measures its z on the block
/// starting here and on the blocks after it.
pub const TEST_FIRST_SEED: u64 = 1_001_000;
/// Its two-sided rejection threshold on z. Far out on purpose: the measured z is
/// close to standard normal (sd 0.92 over 64 blocks), where this gives
/// [`TEST_NOMINAL_ALPHA`], and even an sd of 1.5 would keep false alarms under
/// 1e-3; a halved or doubled estimate gives |z| near 67, a 6% scale error about 5.
pub const TEST_Z: f64 = 5.0;
/// 2Φ(−[`TEST_Z`]): the quick test's false-alarm rate when z is standard normal.
pub const TEST_NOMINAL_ALPHA: f64 = 5.733e-7;

/// What `bench variance` measures.
#[derive(Debug, Clone)]
pub struct VarianceOptions {
    /// Shared options.
    pub common: Common,
    /// Global-illumination scene.
    pub scene: PathBuf,
    /// Its cached Monte Carlo reference (R,G,B + var.*).
    pub reference: PathBuf,
    /// Samples per pixel settings.
    pub spp: Vec<u32>,
    /// Independent seeds per setting (K).
    pub seeds: u64,
    /// First seed (the others follow).
    pub seed: u64,
    /// Blocks of [`TEST_SEEDS`] seeds on which the quick test's z is measured.
    pub test_blocks: u64,
    /// A second, independent reference of the scene (another seed): checks the
    /// reference's stated variance against the difference of the two.
    pub check_reference: Option<PathBuf>,
    /// Worker threads.
    pub threads: usize,
}

/// Calibration of `seeds` renders at `spp` from `first_seed` on, `bias`
/// injected (None for the real thing); `weight_var` (the reference's variance)
/// weights the balanced ratio.
pub fn calibration_z(
    scene: &ResolvedScene,
    bvh: &TraceBvh,
    spp: u32,
    first_seed: u64,
    seeds: u64,
    bias: Option<Bias>,
    weight_var: &[[f32; 3]],
) -> Result<Calibration> {
    variance_stats::calibration(
        &stack(scene, bvh, spp, first_seed, seeds, bias)?,
        weight_var,
    )
}

/// Renders seeds `first..first + seeds` into a stack.
fn stack(
    scene: &ResolvedScene,
    bvh: &TraceBvh,
    spp: u32,
    first: u64,
    seeds: u64,
    bias: Option<Bias>,
) -> Result<SeedStack> {
    let mut st = SeedStack::new(scene.camera.pixel_count());
    for seed in first..first + seeds {
        let r = path::render(
            scene,
            bvh,
            ShadeOptions {
                spp,
                seed,
                bias,
                deadline: None,
            },
        );
        let var = r
            .var
            .ok_or_else(|| anyhow::anyhow!("the path tracer reported no variance"))?;
        st.push(&r.rgb, &var)?;
    }
    Ok(st)
}

/// One spp setting: calibration and bias/variance split.
fn setting(
    scene: &ResolvedScene,
    bvh: &TraceBvh,
    reference: Reference,
    spp: u32,
    opts: &VarianceOptions,
) -> Result<(Calibration, Split, f64)> {
    let t = Instant::now();
    let st = stack(scene, bvh, spp, opts.seed, opts.seeds, None)?;
    let seconds = t.elapsed().as_secs_f64();
    Ok((
        variance_stats::calibration(&st, reference.var)?,
        variance_stats::split(&st, reference)?,
        seconds,
    ))
}

/// The quick test's z on `blocks` disjoint blocks of seeds (no bias), and with each variance bias.
fn test_check(
    scene: &ResolvedScene,
    bvh: &TraceBvh,
    opts: &VarianceOptions,
    weights: &[[f32; 3]],
) -> Result<Value> {
    // Block 0 is the test's own; far from the settings' default seeds.
    let base = TEST_FIRST_SEED;
    let mut zs = Vec::new();
    let mut pooled = Vec::new();
    for b in 0..opts.test_blocks {
        let c = calibration_z(
            scene,
            bvh,
            TEST_SPP,
            base + b * TEST_SEEDS,
            TEST_SEEDS,
            None,
            weights,
        )?;
        zs.push(c.balanced.z);
        pooled.push(c.pooled.z);
    }
    let z = variance_stats::mean_ci(&zs);
    let sd = z.se * (zs.len() as f64).sqrt();
    let over = |t: f64| zs.iter().filter(|z| z.abs() > t).count();
    let mut power = Vec::new();
    for bias in [Bias::VarianceHalved, Bias::VarianceDoubled] {
        let c = calibration_z(scene, bvh, TEST_SPP, base, TEST_SEEDS, Some(bias), weights)?;
        power.push(
            json!({"bias": bias, "ratio": c.balanced.ratio, "z": c.balanced.z,
                          "rejected": c.balanced.z.abs() > TEST_Z,
                          "pooled_ratio": c.pooled.ratio, "pooled_z": c.pooled.z}),
        );
    }
    Ok(json!({
        "spp": TEST_SPP, "seeds_per_block": TEST_SEEDS, "first_seed": TEST_FIRST_SEED,
        "test_z": zs.first(), "blocks": opts.test_blocks,
        "threshold_z": TEST_Z, "nominal_false_alarm_rate": TEST_NOMINAL_ALPHA,
        "z": zs, "z_mean": z.mean, "z_sd": sd,
        "z_max_abs": zs.iter().fold(0f64, |m, z| m.max(z.abs())),
        "exceed_1.96": over(1.96), "exceed_2.58": over(2.576), "exceed_3.29": over(3.291),
        "exceed_threshold": over(TEST_Z),
        "expected_exceed_1.96": 0.05 * zs.len() as f64, "expected_exceed_2.58": 0.01 * zs.len() as f64,
        "power": power,
        "pooled_z": pooled,
        "pooled_z_sd": variance_stats::mean_ci(&pooled).se * (pooled.len() as f64).sqrt(),
        "pooled_exceed_3.29": pooled.iter().filter(|z| z.abs() > 3.291).count(),
        "what": "z = log(balanced ratio)/se(log ratio), the quick test's statistic, on disjoint seed blocks (block 0 is the test's own): standard normal (mean 0, sd 1) when the estimate is calibrated and the delta-method interval is right. pooled_z: the unweighted ratio's z, for comparison (a few light-edge pixels dominate it, so its tails are heavier)",
    }))
}

/// A sentence per setting: is the estimate calibrated, is there bias?
fn verdict(spp: u32, c: &Calibration, s: &Split) -> String {
    let judge = |r: &variance_stats::RatioCi| {
        let [lo, hi] = r.ci95;
        let what = if lo > 1.0 {
            format!("too low by {:.1}%", 100.0 * (r.ratio - 1.0))
        } else if hi < 1.0 {
            format!("too high by {:.1}%", 100.0 * (1.0 / r.ratio - 1.0))
        } else {
            "calibrated".to_string()
        };
        format!(
            "{what} (empirical/predicted {:.3}, 95% CI {lo:.3}-{hi:.3})",
            r.ratio
        )
    };
    let z = &s.residual_over_noise;
    let bias = format!(
        "{}: Σw(M−r)²/Σw(noise) of the {}-seed mean {:.3} (95% CI {:.3}-{:.3}; 1 = noise only)",
        if z.ci95[0] > 1.0 {
            "BIAS against the reference"
        } else {
            "no bias resolved"
        },
        c.seeds,
        z.ratio,
        z.ci95[0],
        z.ci95[1]
    );
    format!(
        "{spp} spp: variance estimate {} pooled, {} balanced; {bias}; bias² {:.2e} (95% CI {:.2e} to {:.2e}, reference noise on {:.0} effective pixels); one render's RMSE/predicted {:.3} (seeds' 5-95%: {:.3}-{:.3})",
        judge(&c.pooled),
        judge(&c.balanced),
        s.bias2.mean,
        s.bias2.ci95[0],
        s.bias2.ci95[1],
        s.reference_variance_effective_pixels,
        s.rmse_over_predicted,
        s.rmse_over_predicted_per_seed_quantiles[0],
        s.rmse_over_predicted_per_seed_quantiles[4],
    )
}

/// Runs the measurement and builds its record and page.
pub fn run(opts: &VarianceOptions) -> Result<super::Output> {
    let environment = super::environment();
    if opts.seeds < 2 {
        bail!("--seeds must be at least 2, got {}", opts.seeds);
    }
    if let Some(spp) = opts.spp.iter().find(|&&n| n < 2) {
        bail!("spp {spp}: a variance estimate needs at least 2 samples per pixel");
    }
    let (scene, reference) =
        radiance::gi_scene_and_reference(&opts.scene, &opts.reference, "the variance benchmark")?;
    let cam = &scene.camera;
    let Some(ref_var) = reference.var.as_deref() else {
        bail!(
            "{}: the reference has no var.R/G/B channels",
            opts.reference.display()
        );
    };
    let refr = Reference {
        width: reference.width,
        rgb: &reference.rgb,
        var: ref_var,
    };
    let pool = super::pool(opts.threads)?;
    let bvh = TraceBvh::build(&scene, BvhQuality::Medium);
    let mut rows = Vec::new();
    let mut verdicts = Vec::new();
    let mut parts: Vec<(u32, Split)> = Vec::new();
    for &spp in &opts.spp {
        rendiff::errln!("variance: {spp} spp x {} seeds", opts.seeds);
        let (c, s, seconds) = pool.install(|| setting(&scene, &bvh, refr, spp, opts))?;
        verdicts.push(verdict(spp, &c, &s));
        rows.push(json!({"spp": spp, "seconds": seconds, "calibration": c, "split": s.clone()}));
        parts.push((spp, s));
    }
    rendiff::errln!("variance: the quick test on {} blocks", opts.test_blocks);
    let test = if opts.test_blocks > 0 {
        pool.install(|| test_check(&scene, &bvh, opts, ref_var))?
    } else {
        Value::Null
    };
    let reference_check = match &opts.check_reference {
        None => Value::Null,
        Some(path) => {
            let other = radiance::read_rgb(path)?;
            let Some(other_var) = other.var.as_deref() else {
                bail!(
                    "{}: the reference has no var.R/G/B channels",
                    path.display()
                );
            };
            if (other.width, other.height) != (reference.width, reference.height) {
                bail!(
                    "{}: {}x{}, the reference {}x{}",
                    path.display(),
                    other.width,
                    other.height,
                    reference.width,
                    reference.height
                );
            }
            let c = variance_stats::reference_check(
                refr,
                Reference {
                    width: other.width,
                    rgb: &other.rgb,
                    var: other_var,
                },
            )?;
            json!({"other": path.display().to_string(), "check": c,
                   "what": "(a - b)^2 against var_a + var_b for two independent references: 1 when the stated variance is right"})
        }
    };
    let record = json!({
        "benchmark": "variance",
        "environment": environment,
        "config": {
            "scene": opts.scene.display().to_string(),
            "reference": opts.reference.display().to_string(),
            "size": [cam.width, cam.height], "spp": opts.spp, "seeds": opts.seeds,
            "first_seed": opts.seed, "threads": opts.threads, "quick": opts.common.quick,
            "units": "pixels are the independent units of every interval (delta method); channels of a pixel are summed",
        },
        "settings": rows,
        "quick_test": test,
        "reference_check": reference_check,
        "verdicts": verdicts,
    });
    Ok(super::Output::with_plot(
        record,
        "error-parts",
        |_| error_plot(&parts),
        page,
    ))
}

fn error_plot(parts: &[(u32, Split)]) -> String {
    let series = |name: &str, f: &dyn Fn(&Split) -> f64, dashed: bool| Series {
        name: name.into(),
        points: parts.iter().map(|(n, s)| (f64::from(*n), f(s))).collect(),
        dashed,
    };
    lines(
        "one render's MSE against the reference, by part",
        "samples per pixel",
        "mean squared error per pixel-channel",
        &[
            series("MSE of one render", &|s| s.mse_single_render, false),
            series("variance (empirical)", &|s| s.variance_empirical, false),
            series("variance (predicted)", &|s| s.variance_predicted, true),
            series(
                "bias² + reference variance",
                &|s| s.bias2_plus_reference_variance.mean,
                false,
            ),
            series(
                "reference variance (stated)",
                &|s| s.reference_variance,
                true,
            ),
        ],
        &[],
    )
}

fn page(record: &Value, plot: &str) -> String {
    let mut p = Page::new("Is the path tracer's variance estimate calibrated?");
    p.para("K renders with independent seeds per spp. Calibration: Σ over pixels of the empirical variance of a pixel's mean across seeds, over Σ of the renders' mean predicted variance (1 when calibrated; 95% intervals by the delta method with pixels as units). Balanced: the same with each pixel-channel weighted by 1/(v + median v), v the reference's variance (fixed weights, independent of the renders), so that the few light-edge pixels holding most of the variance do not decide it alone. Split: one render's MSE against the cached reference = variance + (bias² + the reference's own variance); the reference's stated variance is subtracted to leave bias².");
    p.command("rendiff bench variance");
    p.heading("Verdicts");
    for v in record["verdicts"].as_array().into_iter().flatten() {
        p.para(v.as_str().unwrap_or(""));
    }
    let f = |v: &Value, k: usize| num(v.as_f64(), k);
    let ci = |v: &Value| format!("{} to {}", f(&v[0], 4), f(&v[1], 4));
    let settings = record["settings"].as_array().cloned().unwrap_or_default();
    p.heading("Calibration: empirical / predicted variance of the mean");
    let rows: Vec<Vec<String>> = settings
        .iter()
        .map(|r| {
            let c = &r["calibration"];
            vec![
                f(&r["spp"], 4),
                f(&c["pooled"]["ratio"], 4),
                ci(&c["pooled"]["ci95"]),
                f(&c["pooled"]["z"], 3),
                f(&c["pooled_effective_pixels"], 3),
                f(&c["balanced"]["ratio"], 4),
                ci(&c["balanced"]["ci95"]),
                (0..3)
                    .map(|k| f(&c["per_channel"][k]["ratio"], 3))
                    .collect::<Vec<_>>()
                    .join(" / "),
                c["by_predicted_quartile"]
                    .as_array()
                    .into_iter()
                    .flatten()
                    .map(|b| f(&b["ratio"]["ratio"], 3))
                    .collect::<Vec<_>>()
                    .join(" / "),
                f(&c["single_render_under_half"], 3),
            ]
        })
        .collect();
    p.table(
        &[
            "spp",
            "pooled ratio",
            "95% CI",
            "z",
            "effective pixels",
            "balanced ratio",
            "95% CI",
            "R / G / B",
            "by predicted-variance quartile (low to high)",
            "one render predicts < half",
        ],
        &rows,
    );
    let rows: Vec<Vec<String>> = settings
        .iter()
        .map(|r| {
            let c = &r["calibration"];
            let q = |k: &str| {
                c[k].as_array()
                    .into_iter()
                    .flatten()
                    .map(|v| f(v, 3))
                    .collect::<Vec<_>>()
                    .join(" / ")
            };
            vec![
                f(&r["spp"], 4),
                q("per_cell_ratio_quantiles"),
                q("per_cell_ratio_quantiles_if_calibrated"),
            ]
        })
        .collect();
    p.para("Per pixel-channel ratio (empirical/predicted) quantiles 5/25/50/75/95%, next to what χ²_{K-1}/(K-1) gives when calibrated with normal means (heavier tails widen the measured spread without any miscalibration).");
    p.table(&["spp", "measured", "if calibrated"], &rows);
    p.heading("One render's error against the reference");
    let rows: Vec<Vec<String>> = settings
        .iter()
        .map(|r| {
            let s = &r["split"];
            vec![
                f(&r["spp"], 4),
                f(&s["rmse_single_render"], 4),
                f(&s["rmse_predicted"], 4),
                f(&s["rmse_over_predicted"], 4),
                s["rmse_over_predicted_per_seed_quantiles"]
                    .as_array()
                    .into_iter()
                    .flatten()
                    .map(|v| f(v, 3))
                    .collect::<Vec<_>>()
                    .join(" / "),
                f(&s["variance_empirical"], 4),
                f(&s["variance_predicted"], 4),
                f(&s["reference_variance"], 4),
                f(&s["bias2"]["mean"], 3),
                ci(&s["bias2"]["ci95"]),
                f(&s["residual_over_noise"]["ratio"], 4),
                ci(&s["residual_over_noise"]["ci95"]),
                f(&s["neighbour_correlation"], 3),
            ]
        })
        .collect();
    p.table(
        &[
            "spp",
            "RMSE (one render)",
            "predicted RMSE",
            "ratio",
            "per seed 5/25/50/75/95%",
            "variance (empirical)",
            "variance (predicted)",
            "reference variance",
            "bias²",
            "bias² 95% CI",
            "residual/noise of K-seed mean (balanced)",
            "95% CI",
            "neighbour corr.",
        ],
        &rows,
    );
    p.svg(plot, Some("variance-error-parts.svg"));
    let t = &record["quick_test"];
    if !t.is_null() {
        p.heading("The quick calibration test (tests/variance_calibration.rs)");
        p.para(&format!(
            "{} spp, {} seeds, reject at |z| > {}. Over {} disjoint seed blocks without bias: z mean {}, sd {} (1 when the stated false-alarm rate holds), |z| > 1.96 in {} (expected {}), > 3.29 in {}, over the threshold in {}. Injected: {}.",
            f(&t["spp"], 3),
            f(&t["seeds_per_block"], 3),
            f(&t["threshold_z"], 3),
            f(&t["blocks"], 3),
            f(&t["z_mean"], 3),
            f(&t["z_sd"], 3),
            f(&t["exceed_1.96"], 3),
            f(&t["expected_exceed_1.96"], 3),
            f(&t["exceed_3.29"], 3),
            f(&t["exceed_threshold"], 3),
            t["power"]
                .as_array()
                .into_iter()
                .flatten()
                .map(|x| format!(
                    "{} ratio {} z {}",
                    super::page::compact(&x["bias"]),
                    f(&x["ratio"], 3),
                    f(&x["z"], 3)
                ))
                .collect::<Vec<_>>()
                .join("; ")
        ));
    }
    let rc = &record["reference_check"];
    if !rc.is_null() {
        p.heading("The reference's own noise");
        let c = &rc["check"];
        p.para(&format!(
            "Against {}: Σ(a−b)²/Σ(var_a+var_b) = {} (95% CI {}; {} effective pixels), mean per-cell z² {} (95% CI {}). 1 when the reference's stated variance is right.",
            super::page::compact(&rc["other"]),
            f(&c["pooled"]["ratio"], 3),
            ci(&c["pooled"]["ci95"]),
            f(&c["effective_pixels"], 3),
            f(&c["standardized_residual2"]["mean"], 3),
            ci(&c["standardized_residual2"]["ci95"]),
        ));
    }
    p.environment(&record["environment"]);
    p.finish()
}

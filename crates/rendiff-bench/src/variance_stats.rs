//! Statistics of `bench variance`: is a Monte Carlo renderer's per-pixel
//! "variance of the mean" estimate calibrated, and how does its error against
//! a noisy reference split into bias and variance?
//!
//! The input is K renders of one scene with independent seeds. Across seeds,
//! each pixel's mean has an empirical variance; the renders also predicted it
//! (one estimate per render). A calibrated estimate has
//! E[empirical] = E[predicted] in every pixel, so the ratio of their sums over
//! pixels is 1. Pixels are independent (each has its own random stream), so
//! pixels are the sampling units of every interval here (delta method), which
//! stays valid when pixels differ in variance and is conservative when the
//! calibration itself differs between pixels.

use anyhow::{bail, Result};
use serde::Serialize;

/// z of a two-sided 95% interval.
pub const Z95: f64 = 1.959_963_984_540_054;

/// K renders of one image: means and predicted variances of the means, seed-major.
#[derive(Debug, Clone, Default)]
pub struct SeedStack {
    /// Pixels per render.
    pub pixels: usize,
    /// Renders pushed so far (the K of the docs).
    pub seeds: usize,
    /// `means[k * pixels + p]`: pixel p's mean in render k.
    pub means: Vec<[f32; 3]>,
    /// `vars[k * pixels + p]`: its predicted variance of the mean.
    pub vars: Vec<[f32; 3]>,
}

impl SeedStack {
    /// An empty stack for images of `pixels` pixels.
    pub fn new(pixels: usize) -> SeedStack {
        SeedStack {
            pixels,
            ..SeedStack::default()
        }
    }

    /// Adds one render; an error when its size is not the stack's.
    pub fn push(&mut self, rgb: &[[f32; 3]], var: &[[f32; 3]]) -> Result<()> {
        if rgb.len() != self.pixels || var.len() != self.pixels {
            bail!(
                "render has {} means and {} variances, the stack {} pixels",
                rgb.len(),
                var.len(),
                self.pixels
            );
        }
        self.means.extend_from_slice(rgb);
        self.vars.extend_from_slice(var);
        self.seeds += 1;
        Ok(())
    }

    /// Per pixel and channel across seeds: mean, empirical variance (K-1 divisor) and mean prediction.
    fn cells(&self) -> Vec<[Cell; 3]> {
        let k = self.seeds as f64;
        (0..self.pixels)
            .map(|p| {
                std::array::from_fn(|c| {
                    let at = |v: &Vec<[f32; 3]>, s: usize| f64::from(v[s * self.pixels + p][c]);
                    let mean = (0..self.seeds).map(|s| at(&self.means, s)).sum::<f64>() / k;
                    let ss = (0..self.seeds)
                        .map(|s| (at(&self.means, s) - mean).powi(2))
                        .sum::<f64>();
                    let vbar = (0..self.seeds).map(|s| at(&self.vars, s)).sum::<f64>() / k;
                    Cell {
                        mean,
                        s2: ss / (k - 1.0),
                        vbar,
                    }
                })
            })
            .collect()
    }
}

#[derive(Debug, Clone, Copy)]
struct Cell {
    mean: f64,
    s2: f64,
    vbar: f64,
}

/// A ratio of sums over independent units with its delta-method interval.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct RatioCi {
    /// Σ numerator / Σ denominator.
    pub ratio: f64,
    /// Standard error of the ratio (delta method over units).
    pub se: f64,
    /// 95% interval, symmetric in log(ratio).
    pub ci95: [f64; 2],
    /// log(ratio) / se(log ratio): the z statistic of "ratio = 1".
    pub z: f64,
    /// Units (pixels) that entered.
    pub units: usize,
}

/// Σa / Σb over units (a, b) with the delta-method standard error
/// sqrt(n/(n-1) Σ(a - R b)²) / Σb.
pub fn ratio_ci(units: &[(f64, f64)]) -> RatioCi {
    let n = units.len() as f64;
    let sa: f64 = units.iter().map(|u| u.0).sum();
    let sb: f64 = units.iter().map(|u| u.1).sum();
    let r = sa / sb;
    let ss: f64 = units.iter().map(|(a, b)| (a - r * b).powi(2)).sum();
    let se = (ss * n / (n - 1.0).max(1.0)).sqrt() / sb;
    let se_log = se / r;
    RatioCi {
        ratio: r,
        se,
        ci95: [r * (-Z95 * se_log).exp(), r * (Z95 * se_log).exp()],
        z: r.ln() / se_log,
        units: units.len(),
    }
}

/// A mean over independent units with its standard error and 95% interval.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct MeanCi {
    /// The mean.
    pub mean: f64,
    /// Its standard error.
    pub se: f64,
    /// mean ± 1.96 se.
    pub ci95: [f64; 2],
}

/// Mean and standard error of `v` (independent units).
pub fn mean_ci(v: &[f64]) -> MeanCi {
    let n = v.len() as f64;
    let mean = v.iter().sum::<f64>() / n;
    let var = v.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / (n - 1.0).max(1.0);
    let se = (var / n).sqrt();
    MeanCi {
        mean,
        se,
        ci95: [mean - Z95 * se, mean + Z95 * se],
    }
}

/// Linear-interpolated quantiles of `v` at each `q` in [0, 1].
pub fn quantiles(v: &mut [f64], qs: &[f64]) -> Vec<f64> {
    v.sort_by(f64::total_cmp);
    qs.iter()
        .map(|&q| {
            if v.is_empty() {
                return f64::NAN;
            }
            let x = q.clamp(0.0, 1.0) * (v.len() - 1) as f64;
            let (i, f) = (x.floor() as usize, x.fract());
            let hi = v[(i + 1).min(v.len() - 1)];
            v[i] + f * (hi - v[i])
        })
        .collect()
}

/// The quantiles reported for per-cell ratios.
pub const QUANTILES: [f64; 5] = [0.05, 0.25, 0.5, 0.75, 0.95];
const QUANTILE_Z: [f64; 5] = [-1.644_853_6, -0.674_489_75, 0.0, 0.674_489_75, 1.644_853_6];

/// Quantiles of χ²_ν/ν (Wilson–Hilferty): the spread of one cell's
/// empirical/true variance ratio when the means are normal.
pub fn chi2_over_nu_quantiles(nu: f64) -> Vec<f64> {
    let a = 2.0 / (9.0 * nu);
    QUANTILE_Z
        .iter()
        .map(|z| (1.0 - a + z * a.sqrt()).max(0.0).powi(3))
        .collect()
}

/// A ratio within one band of pixels sorted by predicted variance.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Band {
    /// Smallest and largest per-pixel predicted variance (summed over channels) in the band.
    pub predicted_range: [f64; 2],
    /// Empirical / predicted within the band.
    pub ratio: RatioCi,
}

/// Is the predicted variance of the mean calibrated?
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Calibration {
    /// Independent renders (seeds).
    pub seeds: usize,
    /// Pixel-channels with any variance (predicted or empirical).
    pub random_cells: usize,
    /// Pixel-channels exactly constant and predicted so (e.g. the light seen directly).
    pub deterministic_cells: usize,
    /// Σ empirical across-seed variance / Σ mean predicted variance, units = pixels (channels summed).
    pub pooled: RatioCi,
    /// The same with each pixel-channel weighted by 1/(v + median v), v a variance scale
    /// independent of the renders (the reference's variance): fixed weights keep the ratio
    /// 1 when calibrated and move it exactly as `pooled` under a global scale error, but
    /// no handful of pixels decides it (at the light's edge a few pixels hold most of the
    /// variance), so its interval is tight and its z close to normal. The quick test uses it.
    pub balanced: RatioCi,
    /// The same per channel R, G, B.
    pub per_channel: [RatioCi; 3],
    /// Kish's effective number of pixels in `pooled`: (Σ predicted)² / Σ predicted².
    pub pooled_effective_pixels: f64,
    /// The same within quartiles of pixels by predicted variance: is it off where the noise is?
    pub by_predicted_quartile: Vec<Band>,
    /// Quantiles (5, 25, 50, 75, 95%) of the per-cell ratio empirical / mean predicted.
    pub per_cell_ratio_quantiles: Vec<f64>,
    /// The same quantiles if calibrated with normal means (χ²_{K-1}/(K-1)), for comparison.
    pub per_cell_ratio_quantiles_if_calibrated: Vec<f64>,
    /// Fraction of single renders' cells predicting under half (under a quarter) of the cell's
    /// mean prediction: how noisy one render's estimate is (it drives a per-pixel test's tails).
    pub single_render_under_half: f64,
    /// As `single_render_under_half`, for a quarter.
    pub single_render_under_quarter: f64,
}

/// Measures calibration over a stack of at least 2 seeds; `weight_var` is a
/// per-cell variance scale independent of the stack (the weights of `balanced`).
pub fn calibration(stack: &SeedStack, weight_var: &[[f32; 3]]) -> Result<Calibration> {
    if stack.seeds < 2 || stack.pixels < 2 {
        bail!(
            "calibration needs at least 2 seeds and 2 pixels, got {} and {}",
            stack.seeds,
            stack.pixels
        );
    }
    if weight_var.len() != stack.pixels {
        bail!(
            "the weights' variance has {} pixels, the stack {}",
            weight_var.len(),
            stack.pixels
        );
    }
    let cells = stack.cells();
    let floor = weight_floor(weight_var);
    let balanced: Vec<(f64, f64)> = cells
        .iter()
        .zip(weight_var)
        .map(|(c, v)| {
            let w = |k: usize| 1.0 / (f64::from(v[k]) + floor);
            (
                (0..3).map(|k| w(k) * c[k].s2).sum(),
                (0..3).map(|k| w(k) * c[k].vbar).sum(),
            )
        })
        .filter(|u| u.0 > 0.0 || u.1 > 0.0)
        .collect();
    let random = |c: &Cell| c.s2 > 0.0 || c.vbar > 0.0;
    let random_cells = cells.iter().flatten().filter(|c| random(c)).count();
    let deterministic_cells = 3 * cells.len() - random_cells;
    let units: Vec<(f64, f64)> = cells
        .iter()
        .map(|c| (c.iter().map(|x| x.s2).sum(), c.iter().map(|x| x.vbar).sum()))
        .filter(|u| u.0 > 0.0 || u.1 > 0.0)
        .collect();
    if units.len() < 2 {
        bail!("fewer than 2 pixels have any variance: nothing to calibrate");
    }
    let per_channel = std::array::from_fn(|k| {
        let u: Vec<(f64, f64)> = cells
            .iter()
            .map(|c| (c[k].s2, c[k].vbar))
            .filter(|u| u.0 > 0.0 || u.1 > 0.0)
            .collect();
        ratio_ci(&u)
    });
    let mut sorted = units.clone();
    sorted.sort_by(|a, b| a.1.total_cmp(&b.1));
    let by_predicted_quartile = (0..4)
        .map(|q| &sorted[q * sorted.len() / 4..(q + 1) * sorted.len() / 4])
        .filter(|b| b.len() >= 2)
        .map(|b| Band {
            predicted_range: [b[0].1, b[b.len() - 1].1],
            ratio: ratio_ci(b),
        })
        .collect();
    let mut per_cell: Vec<f64> = cells
        .iter()
        .flatten()
        .filter(|c| c.vbar > 0.0)
        .map(|c| c.s2 / c.vbar)
        .collect();
    let (mut half, mut quarter, mut n) = (0usize, 0usize, 0usize);
    for s in 0..stack.seeds {
        for (p, cell) in cells.iter().enumerate() {
            for (k, c) in cell.iter().enumerate() {
                if c.vbar > 0.0 {
                    let v = f64::from(stack.vars[s * stack.pixels + p][k]);
                    n += 1;
                    half += usize::from(v < 0.5 * c.vbar);
                    quarter += usize::from(v < 0.25 * c.vbar);
                }
            }
        }
    }
    Ok(Calibration {
        seeds: stack.seeds,
        random_cells,
        deterministic_cells,
        pooled: ratio_ci(&units),
        balanced: ratio_ci(&balanced),
        per_channel,
        pooled_effective_pixels: kish(units.iter().map(|u| u.1)),
        by_predicted_quartile,
        per_cell_ratio_quantiles: quantiles(&mut per_cell, &QUANTILES),
        per_cell_ratio_quantiles_if_calibrated: chi2_over_nu_quantiles((stack.seeds - 1) as f64),
        single_render_under_half: half as f64 / n.max(1) as f64,
        single_render_under_quarter: quarter as f64 / n.max(1) as f64,
    })
}

/// The balanced weights' floor: the median of the positive values, or 1 when
/// none is positive (every weight then equal).
fn weight_floor(v: &[[f32; 3]]) -> f64 {
    let mut positive: Vec<f64> = v
        .iter()
        .flatten()
        .map(|&x| f64::from(x))
        .filter(|x| *x > 0.0)
        .collect();
    if positive.is_empty() {
        1.0
    } else {
        quantiles(&mut positive, &[0.5])[0]
    }
}

/// Kish's effective sample size of weights: (Σw)² / Σw².
pub fn kish(w: impl Iterator<Item = f64> + Clone) -> f64 {
    let s: f64 = w.clone().sum();
    let s2: f64 = w.map(|x| x * x).sum();
    s * s / s2
}

/// A noisy reference: its means and the stated variance of each mean.
#[derive(Debug, Clone, Copy)]
pub struct Reference<'a> {
    /// Image width (for neighbour statistics).
    pub width: usize,
    /// Means.
    pub rgb: &'a [[f32; 3]],
    /// Stated variance of each mean.
    pub var: &'a [[f32; 3]],
}

/// One render's mean squared error against the reference, split into its parts.
///
/// With M the across-seed mean, s² the across-seed variance and r the reference,
/// exactly: mean over seeds of (m − r)² = (M − r)² + (K−1)/K s². In expectation
/// (M − r)² − s²/K = bias² + Var(r), so subtracting the reference's stated
/// variance leaves the squared bias (of the renderer against the reference's
/// expectation), whose interval uses pixels as units.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Split {
    /// Mean over seeds of one render's MSE (pixels and channels).
    pub mse_single_render: f64,
    /// Its square root: the RMSE one render has on average (in the MSE sense).
    pub rmse_single_render: f64,
    /// Mean across-seed variance of a pixel mean: the render's true noise.
    pub variance_empirical: f64,
    /// Mean predicted variance of a pixel mean.
    pub variance_predicted: f64,
    /// Mean stated variance of the reference.
    pub reference_variance: f64,
    /// mean((M − r)² − s²/K): bias² + the reference's true variance, per cell.
    pub bias2_plus_reference_variance: MeanCi,
    /// `bias2_plus_reference_variance` minus the stated reference variance, per cell.
    pub bias2: MeanCi,
    /// sqrt(max(bias2, 0)).
    pub bias_rms: f64,
    /// sqrt(variance_predicted + reference_variance): what the single-seed comparison called expected.
    pub rmse_predicted: f64,
    /// rmse_single_render / rmse_predicted.
    pub rmse_over_predicted: f64,
    /// Each render's own RMSE / its own predicted RMSE (sqrt(mean var + mean var_r)),
    /// seed by seed: the single-seed figure and how far chance moves it.
    pub rmse_over_predicted_per_seed: Vec<f64>,
    /// Quantiles (5, 25, 50, 75, 95%) of `rmse_over_predicted_per_seed`.
    pub rmse_over_predicted_per_seed_quantiles: Vec<f64>,
    /// Kish's effective number of pixels holding the reference's stated variance:
    /// few means the absolute-scale split rests on few independent numbers.
    pub reference_variance_effective_pixels: f64,
    /// Σ w (M − r)² / Σ w (v̄/K + var_r) with the balanced ratio's fixed weights
    /// w = 1/(var_r + median of positive var_r) (equal weights if none is positive), v̄ the mean predicted variance: 1 when unbiased
    /// and both variances are right, above 1 by bias² / noise. Fixed weights and sums
    /// (not a mean of per-cell ratios, which noisy variances push above 1) keep it
    /// exact in expectation; the weights stop a few light-edge pixels from deciding it.
    pub residual_over_noise: RatioCi,
    /// Correlation of (M − r)/sqrt(v̄/K + var_r) between horizontal neighbours: ~0 for noise
    /// (independent pixels), positive for a smooth bias.
    pub neighbour_correlation: f64,
}

/// Splits the error against `reference` into bias and variance.
pub fn split(stack: &SeedStack, reference: Reference) -> Result<Split> {
    if reference.rgb.len() != stack.pixels || reference.var.len() != stack.pixels {
        bail!(
            "reference has {} pixels, the renders {}",
            reference.rgb.len(),
            stack.pixels
        );
    }
    if stack.seeds < 2 || stack.pixels < 2 || reference.width == 0 {
        bail!("the split needs at least 2 seeds and 2 pixels");
    }
    let k = stack.seeds as f64;
    let cells = stack.cells();
    let n_cells = (3 * stack.pixels) as f64;
    let (mut mse, mut s2, mut vbar, mut vr) = (0.0, 0.0, 0.0, 0.0);
    let mut excess = Vec::with_capacity(stack.pixels);
    let mut bias2 = Vec::with_capacity(stack.pixels);
    let mut balanced = Vec::with_capacity(stack.pixels);
    let mut z = vec![[f64::NAN; 3]; stack.pixels];
    let floor = weight_floor(reference.var);
    for (p, cell) in cells.iter().enumerate() {
        let (mut e, mut b, mut wd2, mut wn) = (0.0, 0.0, 0.0, 0.0);
        for (ch, c) in cell.iter().enumerate() {
            let r = f64::from(reference.rgb[p][ch]);
            let var_r = f64::from(reference.var[p][ch]);
            let d2 = (c.mean - r).powi(2);
            mse += d2 + (k - 1.0) / k * c.s2;
            s2 += c.s2;
            vbar += c.vbar;
            vr += var_r;
            e += d2 - c.s2 / k;
            b += d2 - c.s2 / k - var_r;
            let noise = c.vbar / k + var_r;
            if noise > 0.0 {
                z[p][ch] = (c.mean - r) / noise.sqrt();
            }
            let w = 1.0 / (var_r + floor);
            wd2 += w * d2;
            wn += w * noise;
        }
        excess.push(e / 3.0);
        bias2.push(b / 3.0);
        if wd2 > 0.0 || wn > 0.0 {
            balanced.push((wd2, wn));
        }
    }
    let (mse, s2, vbar, vr) = (mse / n_cells, s2 / n_cells, vbar / n_cells, vr / n_cells);
    let bias2 = mean_ci(&bias2);
    let per_seed: Vec<f64> = (0..stack.seeds)
        .map(|s| {
            let (mut se, mut pv) = (0.0, 0.0);
            for p in 0..stack.pixels {
                let (m, v) = (
                    stack.means[s * stack.pixels + p],
                    stack.vars[s * stack.pixels + p],
                );
                for c in 0..3 {
                    se += (f64::from(m[c]) - f64::from(reference.rgb[p][c])).powi(2);
                    pv += f64::from(v[c]) + f64::from(reference.var[p][c]);
                }
            }
            (se / pv).sqrt()
        })
        .collect();
    let mut sorted = per_seed.clone();
    let predicted = (vbar + vr).sqrt();
    Ok(Split {
        mse_single_render: mse,
        rmse_single_render: mse.sqrt(),
        variance_empirical: s2,
        variance_predicted: vbar,
        reference_variance: vr,
        bias2_plus_reference_variance: mean_ci(&excess),
        bias2,
        bias_rms: bias2.mean.max(0.0).sqrt(),
        rmse_predicted: predicted,
        rmse_over_predicted: mse.sqrt() / predicted,
        rmse_over_predicted_per_seed_quantiles: quantiles(&mut sorted, &QUANTILES),
        rmse_over_predicted_per_seed: per_seed,
        reference_variance_effective_pixels: kish(
            reference
                .var
                .iter()
                .map(|v| v.iter().map(|&x| f64::from(x)).sum::<f64>()),
        ),
        residual_over_noise: ratio_ci(&balanced),
        neighbour_correlation: neighbour_correlation(&z, reference.width),
    })
}

/// Two independent references of one scene: is their stated variance right?
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct ReferenceCheck {
    /// Σ (a − b)² / Σ (var_a + var_b), units = pixels: 1 when the stated variances are right.
    pub pooled: RatioCi,
    /// mean over cells of (a − b)² / (var_a + var_b): the same, each cell weighted equally.
    pub standardized_residual2: MeanCi,
    /// Kish's effective number of pixels in `pooled`.
    pub effective_pixels: f64,
}

/// Compares two independent references (same size) against their stated variances.
pub fn reference_check(a: Reference, b: Reference) -> Result<ReferenceCheck> {
    let n = a.rgb.len();
    if [a.var.len(), b.rgb.len(), b.var.len()] != [n; 3] || n < 2 {
        bail!("the two references differ in size (or have under 2 pixels)");
    }
    let mut units = Vec::with_capacity(n);
    let mut z2 = Vec::with_capacity(n);
    for p in 0..n {
        let (mut d2, mut v, mut z) = (0.0, 0.0, 0.0);
        for c in 0..3 {
            let d = f64::from(a.rgb[p][c]) - f64::from(b.rgb[p][c]);
            let vv = f64::from(a.var[p][c]) + f64::from(b.var[p][c]);
            d2 += d * d;
            v += vv;
            z += if vv > 0.0 { d * d / vv } else { 1.0 };
        }
        units.push((d2, v));
        z2.push(z / 3.0);
    }
    let units: Vec<(f64, f64)> = units
        .into_iter()
        .filter(|u| u.0 > 0.0 || u.1 > 0.0)
        .collect();
    Ok(ReferenceCheck {
        pooled: ratio_ci(&units),
        standardized_residual2: mean_ci(&z2),
        effective_pixels: kish(units.iter().map(|u| u.1)),
    })
}

/// Pearson correlation of finite values with their right-hand neighbour, pooled over channels.
fn neighbour_correlation(z: &[[f64; 3]], width: usize) -> f64 {
    let pairs: Vec<(f64, f64)> = (0..z.len())
        .filter(|p| (p + 1) % width != 0 && p + 1 < z.len())
        .flat_map(|p| (0..3).map(move |c| (z[p][c], z[p + 1][c])))
        .filter(|(a, b)| a.is_finite() && b.is_finite())
        .collect();
    let n = pairs.len() as f64;
    let (ma, mb) = (
        pairs.iter().map(|p| p.0).sum::<f64>() / n,
        pairs.iter().map(|p| p.1).sum::<f64>() / n,
    );
    let cov: f64 = pairs.iter().map(|(a, b)| (a - ma) * (b - mb)).sum();
    let va: f64 = pairs.iter().map(|(a, _)| (a - ma).powi(2)).sum();
    let vb: f64 = pairs.iter().map(|(_, b)| (b - mb).powi(2)).sum();
    cov / (va * vb).sqrt()
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};
    use rand_pcg::Pcg64Mcg;

    /// Gaussian draw (Box–Muller).
    fn normal(rng: &mut Pcg64Mcg) -> f64 {
        let (u1, u2): (f64, f64) = (rng.random(), rng.random());
        (-2.0 * (1.0 - u1).ln()).sqrt() * (std::f64::consts::TAU * u2).cos()
    }

    /// K renders of n pixels, each the mean of `spp` Gaussian samples of
    /// pixel-dependent spread around `truth`, predicting `scale` × the sample variance / spp.
    fn synthetic(k: usize, n: usize, spp: usize, scale: f64, truth: f64) -> SeedStack {
        let mut rng = Pcg64Mcg::seed_from_u64(17);
        let mut st = SeedStack::new(n);
        for _ in 0..k {
            let mut rgb = Vec::new();
            let mut var = Vec::new();
            for p in 0..n {
                let sigma = 0.1 + (p % 7) as f64 * 0.2;
                let mut m = [0f32; 3];
                let mut v = [0f32; 3];
                for c in 0..3 {
                    let xs: Vec<f64> = (0..spp).map(|_| truth + sigma * normal(&mut rng)).collect();
                    let mean = xs.iter().sum::<f64>() / spp as f64;
                    let s2 = xs.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / (spp - 1) as f64;
                    m[c] = mean as f32;
                    v[c] = (scale * s2 / spp as f64) as f32;
                }
                rgb.push(m);
                var.push(v);
            }
            st.push(&rgb, &var).unwrap();
        }
        st
    }

    #[test]
    fn a_calibrated_estimate_has_ratio_one_and_a_scaled_one_does_not() {
        // Weights from an independent render, as the reference's variance would be.
        let pilot = synthetic(1, 400, 64, 1.0, 1.0).vars;
        let ok = calibration(&synthetic(16, 400, 8, 1.0, 1.0), &pilot).unwrap();
        assert!(ok.pooled.z.abs() < 3.3, "{:?}", ok.pooled);
        assert!(ok.pooled.ci95[0] < 1.0 && 1.0 < ok.pooled.ci95[1]);
        assert!(ok.balanced.z.abs() < 3.3, "{:?}", ok.balanced);
        let low = calibration(&synthetic(16, 400, 8, 0.5, 1.0), &pilot).unwrap();
        assert!((low.pooled.ratio - 2.0).abs() < 0.2 && low.pooled.z > 3.3);
        assert!((low.balanced.ratio - 2.0).abs() < 0.2 && low.balanced.z > 3.3);
        let high = calibration(&synthetic(16, 400, 8, 2.0, 1.0), &pilot).unwrap();
        assert!((high.pooled.ratio - 0.5).abs() < 0.05 && high.pooled.z < -3.3);
        assert!((high.balanced.ratio - 0.5).abs() < 0.05 && high.balanced.z < -3.3);
        assert!(calibration(&synthetic(4, 400, 8, 1.0, 1.0), &pilot[1..]).is_err());
        assert_eq!(ok.random_cells, 1200);
        assert_eq!(ok.by_predicted_quartile.len(), 4);
    }

    #[test]
    fn the_split_finds_a_bias_and_no_bias() {
        let st = synthetic(32, 500, 8, 1.0, 1.0);
        let n = st.pixels;
        let var = vec![[1e-4f32; 3]; n];
        // An unbiased reference at the truth, stated exactly (its variance is 1e-4 but it is exact:
        // the bias² estimate is then -1e-4 within noise).
        let exact = vec![[1.0f32; 3]; n];
        let s = split(
            &st,
            Reference {
                width: 25,
                rgb: &exact,
                var: &var,
            },
        )
        .unwrap();
        assert!((s.bias2.mean + 1e-4).abs() < 4.0 * s.bias2.se, "{s:?}");
        assert!((s.variance_empirical / s.variance_predicted - 1.0).abs() < 0.1);
        assert!(s.residual_over_noise.z < 3.3, "{:?}", s.residual_over_noise);
        // Off by 0.05 everywhere: bias² = 0.0025.
        let off = vec![[1.05f32; 3]; n];
        let s = split(
            &st,
            Reference {
                width: 25,
                rgb: &off,
                var: &vec![[0.0; 3]; n],
            },
        )
        .unwrap();
        assert!((s.bias2.mean - 0.0025).abs() < 4.0 * s.bias2.se, "{s:?}");
        assert!(s.bias2.ci95[0] > 0.0);
        assert!(
            s.residual_over_noise.ci95[0] > 1.0,
            "{:?}",
            s.residual_over_noise
        );
        assert!(s.neighbour_correlation.abs() < 0.2);
        assert!(split(
            &st,
            Reference {
                width: 25,
                rgb: &off[1..],
                var: &var
            }
        )
        .is_err());
        assert_eq!(s.rmse_over_predicted_per_seed.len(), 32);
    }

    #[test]
    fn two_references_agree_with_their_stated_variance() {
        // Renders 0 and 1 of one stack are independent draws: two references.
        let st = synthetic(2, 300, 8, 1.0, 1.0);
        let n = st.pixels;
        let part = |k: usize, scale: f32| {
            let var: Vec<[f32; 3]> = st.vars[k * n..(k + 1) * n]
                .iter()
                .map(|v| v.map(|x| x * scale))
                .collect();
            (st.means[k * n..(k + 1) * n].to_vec(), var)
        };
        let check = |scale: f32| {
            let ((am, av), (bm, bv)) = (part(0, scale), part(1, scale));
            reference_check(
                Reference {
                    width: 20,
                    rgb: &am,
                    var: &av,
                },
                Reference {
                    width: 20,
                    rgb: &bm,
                    var: &bv,
                },
            )
            .unwrap()
        };
        let ok = check(1.0);
        assert!(ok.pooled.z.abs() < 3.3, "{ok:?}");
        let low = check(0.25);
        assert!(low.pooled.z > 3.3, "{low:?}");
        let (am, av) = part(0, 1.0);
        assert!(reference_check(
            Reference {
                width: 20,
                rgb: &am[1..],
                var: &av
            },
            Reference {
                width: 20,
                rgb: &am,
                var: &av
            },
        )
        .is_err());
    }
}

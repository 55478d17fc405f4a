//! The path tracers at equal time, with an interval: paired rounds of the
//! core and Mitsuba on one global-illumination scene, a fresh seed per round.
//!
//! One render's RMSE swings widely from seed to seed (docs/radiance.md: on
//! `cornell_gi` the ratio of a render's RMSE to its predicted noise spans
//! 0.80-1.25 over seeds, since ~22 light-edge pixels hold most of the
//! error), so a single pair of renders cannot tell a 0.9x from a 1.1x. Each
//! round renders both with seed `seed + i`, in alternating order (core first
//! in even rounds), and records each side's squared error and time.
//!
//! The statistic is the RMSE ratio at equal time. For an unbiased renderer
//! the MSE is variance / spp, so MSE x time is the same at any spp (the
//! inverse of its efficiency), and Mitsuba's RMSE over the core's at equal
//! time is `sqrt(sum MSE_m t_m / sum MSE_c t_c)` over the rounds: at least 1
//! when the core's error at equal time is no larger. This also corrects for
//! the core's spp matching Mitsuba's time only roughly. The reference's own
//! noise (about 1% of the MSE on `cornell_gi`) is left in both sides. The
//! interval is a 95% percentile bootstrap over rounds (pairs resampled
//! together).

use super::harness::Harness;
use super::measure::{BOOTSTRAP_RESAMPLES, BOOTSTRAP_SEED};
use super::radiance::RgbImage;
use super::spp::{core_path, mitsuba_path, MitsubaRun};
use rendiff::scene::resolve::ResolvedScene;
use serde_json::{json, Value};
use std::path::Path;

/// One side of one round: squared error and seconds.
#[derive(Debug, Clone, Copy)]
struct Side {
    mse: f64,
    time_s: f64,
}

/// What the paired rounds compare.
#[derive(Debug, Clone, Copy)]
pub struct Pairing<'a> {
    /// Mitsuba's variant (`--variant`).
    pub variant: &'a str,
    /// Mitsuba's spp.
    pub mitsuba_spp: u32,
    /// The core's spp (chosen to take about as long).
    pub core_spp: u32,
    /// Seed of round 0; round i uses `seed + i` on both sides.
    pub seed: u64,
    /// Rounds.
    pub rounds: usize,
}

/// Runs the paired rounds and returns their record (or why they did not run).
pub fn paired(
    h: &Harness,
    resolved: &Path,
    scene: &ResolvedScene,
    reference: &RgbImage,
    p: Pairing,
) -> Value {
    let settings = ["--variant".to_string(), p.variant.to_string()];
    let mut core = Vec::new();
    let mut mitsuba = Vec::new();
    for i in 0..p.rounds {
        let seed = p.seed + i as u64;
        let run_core = || {
            core_path(scene, reference, p.core_spp, seed, 1)
                .map(|(t, e)| Side {
                    mse: e.rmse * e.rmse,
                    time_s: t.median_s,
                })
                .map_err(|e| format!("{e:#}"))
        };
        let name = format!("mitsuba-paired-{i}");
        let run = MitsubaRun {
            spp: p.mitsuba_spp,
            seed,
            settings: &settings,
            name: &name,
        };
        let run_mitsuba = || {
            mitsuba_path(h, resolved, reference, &run, 1).map(|m| Side {
                mse: m.error.rmse * m.error.rmse,
                time_s: m.time_s,
            })
        };
        rendiff::errln!("peers: equal time, paired round {}/{}", i + 1, p.rounds);
        let pair = if i % 2 == 0 {
            run_core().and_then(|c| run_mitsuba().map(|m| (c, m)))
        } else {
            run_mitsuba().and_then(|m| run_core().map(|c| (c, m)))
        };
        match pair {
            Ok((c, m)) => {
                core.push(c);
                mitsuba.push(m);
            }
            Err(why) => return json!({"skipped": format!("round {i}: {why}")}),
        }
    }
    let all: Vec<usize> = (0..core.len()).collect();
    let cost = |s: &[Side], idx: &[usize]| idx.iter().map(|&i| s[i].mse * s[i].time_s).sum::<f64>();
    let mse = |s: &[Side], idx: &[usize]| idx.iter().map(|&i| s[i].mse).sum::<f64>();
    let equal_time = |idx: &[usize]| (cost(&mitsuba, idx) / cost(&core, idx)).sqrt();
    let at_spp = |idx: &[usize]| (mse(&mitsuba, idx) / mse(&core, idx)).sqrt();
    let times = |s: &[Side]| s.iter().map(|x| x.time_s).collect::<Vec<_>>();
    json!({
        "rounds": core.len(),
        "seeds": format!("{}..{}", p.seed, p.seed + p.rounds as u64),
        "order": "alternating: core first in even rounds, Mitsuba first in odd ones",
        "variant": p.variant,
        "core_spp": p.core_spp,
        "mitsuba_spp": p.mitsuba_spp,
        "core_mse": core.iter().map(|s| s.mse).collect::<Vec<_>>(),
        "core_time_s": times(&core),
        "mitsuba_mse": mitsuba.iter().map(|s| s.mse).collect::<Vec<_>>(),
        "mitsuba_time_s": times(&mitsuba),
        "core_time_s_median": super::median(&times(&core)),
        "mitsuba_time_s_median": super::median(&times(&mitsuba)),
        "rmse_ratio_mitsuba_over_core_at_equal_time": equal_time(&all),
        "rmse_ratio_mitsuba_over_core_at_equal_time_interval_95": bootstrap(core.len(), &equal_time),
        "rmse_ratio_mitsuba_over_core_at_these_spp": at_spp(&all),
        "rmse_ratio_mitsuba_over_core_at_these_spp_interval_95": bootstrap(core.len(), &at_spp),
        "statistic": "sqrt(sum over rounds of Mitsuba's MSE x seconds / the core's): the RMSE ratio at equal time for unbiased renderers (MSE = variance / spp); at least 1 when the core's error at equal time is no larger",
        "interval": "95% percentile bootstrap over rounds (each round's pair resampled together)",
    })
}

/// The goal row: the paired rounds' equal-time ratio and its interval
/// (goal: at least 1.0).
pub fn goal(paired: &Value) -> Value {
    json!({
        "rmse_ratio_mitsuba_over_core_at_equal_time": paired["rmse_ratio_mitsuba_over_core_at_equal_time"],
        "interval_95": paired["rmse_ratio_mitsuba_over_core_at_equal_time_interval_95"],
        "rounds": paired["rounds"],
        "goal": "at least 1.0",
    })
}

/// 95% percentile-bootstrap interval of `stat` over `n` rounds resampled
/// with replacement; None for fewer than 2 rounds.
fn bootstrap(n: usize, stat: &dyn Fn(&[usize]) -> f64) -> Option<[f64; 2]> {
    use rand::{Rng, SeedableRng};
    if n < 2 {
        return None;
    }
    let mut rng = rand_pcg::Pcg64::seed_from_u64(BOOTSTRAP_SEED);
    let mut idx = vec![0; n];
    let mut v: Vec<f64> = (0..BOOTSTRAP_RESAMPLES)
        .map(|_| {
            for i in idx.iter_mut() {
                *i = rng.random_range(0..n);
            }
            stat(&idx)
        })
        .collect();
    v.sort_by(f64::total_cmp);
    let q = |p: f64| v[((p * (v.len() - 1) as f64).round()) as usize];
    Some([q(0.025), q(0.975)])
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The interval brackets the statistic on every round, and a constant
    /// statistic gives a zero-width interval.
    #[test]
    fn bootstrap_brackets_the_statistic() {
        let v = [1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0];
        let mean = |idx: &[usize]| idx.iter().map(|&i| v[i]).sum::<f64>() / idx.len() as f64;
        let [lo, hi] = bootstrap(v.len(), &mean).unwrap();
        assert!(lo < 4.0 && 4.0 < hi, "{lo} {hi}");
        assert!(lo >= 1.0 && hi <= 7.0);
        assert_eq!(bootstrap(5, &|_| 2.0), Some([2.0, 2.0]));
        assert_eq!(bootstrap(1, &mean), None);
    }
}

//! The core path tracer's variance of the mean is calibrated: across
//! independent seeds, the empirical variance of each pixel's mean matches the
//! renders' own estimates (the balanced ratio over pixels, see
//! `rendiff_bench::variance_stats::Calibration`), and an estimate halved or
//! doubled through the bias hook is rejected. Deterministic seeds; the
//! threshold |z| > 5 is a two-sided test with false-alarm rate 5.7e-7 when z is
//! standard normal, which `rendiff bench variance` checks on 64 disjoint seed
//! blocks (its record's `quick_test`: sd 0.92, max |z| 2.8); a halved or
//! doubled estimate gives |z| near 67, so the power is not in doubt.

use rendiff::exr_io::read_radiance;
use rendiff::scene::resolve::ResolvedScene;
use rendiff::scene::Scene;
use rendiff::shade::Bias;
use rendiff::trace::{BvhQuality, TraceBvh};
use rendiff_bench::variance::{calibration_z, TEST_FIRST_SEED, TEST_SEEDS, TEST_SPP, TEST_Z};
use std::path::Path;

/// The scene, its BVH and the cached reference's variance (the balanced ratio's weights).
fn cornell() -> (ResolvedScene, TraceBvh, Vec<[f32; 3]>) {
    let root = Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/../.."));
    let scene = ResolvedScene::resolve(&Scene::load(&root.join("scenes/cornell_gi.toml")).unwrap())
        .unwrap();
    let bvh = TraceBvh::build(&scene, BvhQuality::Medium);
    let reference = read_radiance(&root.join("tests/references/cornell_gi.exr"))
        .unwrap()
        .expect("the reference has radiance");
    (
        scene,
        bvh,
        reference.var.expect("the reference has var.R/G/B"),
    )
}

#[test]
fn variance_of_the_mean_is_calibrated_and_a_scaled_one_is_not() {
    let (scene, bvh, weights) = cornell();
    let z = |bias: Option<Bias>| {
        let c = calibration_z(
            &scene,
            &bvh,
            TEST_SPP,
            TEST_FIRST_SEED,
            TEST_SEEDS,
            bias,
            &weights,
        )
        .unwrap();
        eprintln!("{bias:?}: {:?}", c.balanced);
        c.balanced
    };
    let ok = z(None);
    assert!(
        ok.z.abs() <= TEST_Z,
        "empirical/predicted variance {:.3} (95% CI {:.3}-{:.3}), z {:.2}: the estimate is miscalibrated",
        ok.ratio,
        ok.ci95[0],
        ok.ci95[1],
        ok.z
    );
    // Halving the estimate doubles the ratio; doubling it halves the ratio.
    let low = z(Some(Bias::VarianceHalved));
    assert!(
        low.z > TEST_Z,
        "a halved variance was not detected: {low:?}"
    );
    let high = z(Some(Bias::VarianceDoubled));
    assert!(
        high.z < -TEST_Z,
        "a doubled variance was not detected: {high:?}"
    );
}

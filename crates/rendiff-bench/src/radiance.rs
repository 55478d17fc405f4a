//! Radiance error against a cached Monte Carlo reference (a high-spp Mitsuba
//! render in `tests/references/`): RMSE, relative RMSE and relMSE over all
//! pixels and channels, plus the reference's own noise, below which no error
//! can be resolved. Used by the spp knobs and the equal-time comparison.

use anyhow::{bail, Result};
use std::path::Path;

pub use rendiff::exr_io::RgbImage;

/// Reads `R,G,B` (and `var.*` when stored) from an EXR; an error when there is no radiance.
pub fn read_rgb(path: &Path) -> Result<RgbImage> {
    rendiff::exr_io::read_radiance(path)?
        .ok_or_else(|| anyhow::anyhow!("{}: no R,G,B channels", path.display()))
}

/// Loads a global-illumination scene and its cached reference, and checks
/// they fit together (the spp knobs and the variance benchmark both need this).
/// `what` names the caller in the error.
pub fn gi_scene_and_reference(
    scene: &Path,
    reference: &Path,
    what: &str,
) -> Result<(rendiff::scene::resolve::ResolvedScene, RgbImage)> {
    let resolved = super::load_scene(scene)?;
    if !resolved.requires.contains("global_illumination") {
        bail!(
            "{}: not a global_illumination scene, which {what} needs",
            scene.display()
        );
    }
    let image = read_rgb(reference)?;
    let cam = &resolved.camera;
    if (image.width, image.height) != (cam.width as usize, cam.height as usize) {
        bail!(
            "{}: reference is {}x{}, the scene {}x{}",
            reference.display(),
            image.width,
            image.height,
            cam.width,
            cam.height
        );
    }
    Ok((resolved, image))
}

/// How far a render is from the reference.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct RgbError {
    /// Root mean squared error over pixels and channels.
    pub rmse: f64,
    /// RMSE divided by the reference's mean value: a scale-free error.
    pub relative_rmse: f64,
    /// Mean of (x - ref)^2 / (ref^2 + 0.01): the rendering literature's relMSE.
    pub rel_mse: f64,
    /// sqrt(mean variance of the reference's mean): its own noise, the error floor.
    pub reference_noise_rmse: Option<f64>,
    /// sqrt(mean(var_test + var_ref)): the RMSE that noise alone would give if
    /// both sides were unbiased (None without both variances).
    pub expected_rmse_if_unbiased: Option<f64>,
    /// `rmse / expected_rmse_if_unbiased`: near 1 for pure noise; well above 1
    /// means bias (or a variance estimate that is too small).
    pub rmse_over_expected: Option<f64>,
}

/// Mean over pixels and channels.
fn mean3(v: &[[f32; 3]]) -> f64 {
    let s: f64 = v.iter().flatten().map(|&x| f64::from(x)).sum();
    s / (3 * v.len()).max(1) as f64
}

/// Compares `test` (with its variance of the mean, when known) with `reference` (same size).
pub fn error(
    reference: &RgbImage,
    test: &[[f32; 3]],
    test_var: Option<&[[f32; 3]]>,
) -> Result<RgbError> {
    if test.len() != reference.rgb.len() {
        bail!(
            "image sizes differ: {} pixels vs the reference's {}",
            test.len(),
            reference.rgb.len()
        );
    }
    let (mut se, mut rel, mut sum) = (0.0, 0.0, 0.0);
    for (r, t) in reference.rgb.iter().zip(test) {
        for k in 0..3 {
            let (r, t) = (f64::from(r[k]), f64::from(t[k]));
            let d = t - r;
            se += d * d;
            rel += d * d / (r * r + 0.01);
            sum += r;
        }
    }
    let n = (3 * test.len()).max(1) as f64;
    let rmse = (se / n).sqrt();
    let mean = sum / n;
    let ref_var = reference.var.as_deref().map(mean3);
    // A zero variance means "not estimated" (one sample per pixel), not "exact".
    let test_var = test_var
        .filter(|v| v.len() == test.len())
        .map(mean3)
        .filter(|v| *v > 0.0);
    let expected = match (ref_var, test_var) {
        (Some(r), Some(t)) => Some((r + t).sqrt()),
        _ => None,
    };
    Ok(RgbError {
        rmse,
        relative_rmse: if mean > 0.0 { rmse / mean } else { f64::NAN },
        rel_mse: rel / n,
        reference_noise_rmse: ref_var.map(f64::sqrt),
        expected_rmse_if_unbiased: expected,
        rmse_over_expected: expected.filter(|e| *e > 0.0).map(|e| rmse / e),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn error_of_a_constant_offset() {
        let reference = RgbImage {
            width: 2,
            height: 1,
            rgb: vec![[1.0; 3], [3.0; 3]],
            var: Some(vec![[0.04; 3]; 2]),
        };
        let e = error(&reference, &[[1.5; 3], [3.5; 3]], Some(&[[0.21; 3]; 2])).unwrap();
        assert!((e.rmse - 0.5).abs() < 1e-12);
        assert!((e.relative_rmse - 0.25).abs() < 1e-12);
        assert!((e.reference_noise_rmse.unwrap() - 0.2).abs() < 1e-6);
        assert!((e.expected_rmse_if_unbiased.unwrap() - 0.5).abs() < 1e-6);
        assert!((e.rmse_over_expected.unwrap() - 1.0).abs() < 1e-5);
        assert!(error(&reference, &[[0.0; 3]], None).is_err());
    }
}

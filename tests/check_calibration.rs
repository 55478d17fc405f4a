//! Calibration probes in `rendiff check`: rendered first, on every backend, and
//! recorded in manifest.json with `role: "calibration"`; a missing probe
//! folder stops the run before anything renders, with one line saying what to do.
//!
//! These copy one of the repository's probes into a folder of their own (with a
//! file that is not a scene), so they test the mechanism and stay fast (the core
//! tracer only); the probes' own measurement is tested in harness/tests.

mod common;

use common::cli::{need_venv, rendiff, succeeds};
use serde_json::Value;

/// The repository's near probe (the far one is the same view 2.5e4 away).
const PROBE: &str = "scenes/calibration/camera_near.toml";

#[test]
fn probes_run_first_and_are_marked_in_the_manifest() {
    need_venv();
    let dir = tempfile::tempdir().unwrap();
    let probes = dir.path().join("probes");
    std::fs::create_dir(&probes).unwrap();
    std::fs::copy(PROBE, probes.join("probe_near.toml")).unwrap();
    std::fs::write(probes.join("notes.txt"), "not a scene").unwrap();
    // No expectations: verdicts are not what this test is about.
    let none = dir.path().join("expectations.toml");
    std::fs::write(&none, "# none\n").unwrap();
    let run = dir.path().join("run");
    succeeds(
        rendiff()
            .args(["check", "scenes/three_triangles.toml", "--only", "trace"])
            .arg("--calibration")
            .arg(&probes)
            .arg("--expectations")
            .arg(&none)
            .args(["--quiet", "-o"])
            .arg(&run),
    );
    let text = std::fs::read_to_string(run.join("manifest.json")).unwrap();
    let manifest: Value = serde_json::from_str(&text).unwrap();
    let scenes = manifest["scenes"].as_array().unwrap();
    let names: Vec<&str> = scenes
        .iter()
        .map(|s| s["scene"].as_str().unwrap())
        .collect();
    assert_eq!(names, ["probe_near", "three_triangles"]);
    assert_eq!(scenes[0]["role"], "calibration");
    assert!(
        scenes[1].get("role").is_none(),
        "an ordinary scene has no role field: {}",
        scenes[1]
    );
    for backend in ["raster", "trace"] {
        let r = scenes[0]["renders"]
            .as_array()
            .unwrap()
            .iter()
            .find(|r| r["backend"] == backend)
            .unwrap_or_else(|| panic!("probe not rendered by {backend}"));
        assert_eq!(r["status"], "ok", "{r}");
    }
    // Each backend's camera is measured on it, and the core's passes.
    let results: Value =
        serde_json::from_str(&std::fs::read_to_string(run.join("results.json")).unwrap()).unwrap();
    for backend in ["raster", "trace"] {
        assert_eq!(
            results["calibration"][backend]["status"], "pass",
            "{}",
            results["calibration"]
        );
    }
}

#[test]
fn a_missing_probe_folder_fails_early_with_one_clear_line() {
    let dir = tempfile::tempdir().unwrap();
    let missing = dir.path().join("no-probes-here");
    let run = dir.path().join("run");
    let out = rendiff()
        .args(["check", "scenes/three_triangles.toml", "--calibration"])
        .arg(&missing)
        .arg("-o")
        .arg(&run)
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{stderr}");
    let line = stderr.trim();
    assert_eq!(line.lines().count(), 1, "{stderr}");
    assert!(
        line.contains(&missing.display().to_string()) && line.contains("--no-calibration"),
        "{stderr}"
    );
    assert!(!run.join("manifest.json").exists(), "nothing may render");
}

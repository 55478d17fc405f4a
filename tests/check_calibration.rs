//! Calibration probes in `rendiff check`: rendered first, on every backend, and
//! recorded in manifest.json with `role: "calibration"`; a missing probe
//! folder stops the run before anything renders, with one line saying what to do.
//!
//! These use a throwaway probe of their own (a small depth/ids scene), so they
//! test the mechanism, not the probe set in scenes/calibration/, and stay fast
//! (the core tracer only).

mod common_cli;

use common_cli::{need_venv, rendiff};
use serde_json::Value;

const PROBE: &str = r#"
description = "throwaway probe: one triangle"
requires = ["depth", "ids"]

[camera]
eye = [0.0, 0.0, 4.0]
look_at = [0.0, 0.0, 0.0]
vfov = 45.0
width = 16
height = 12

[[materials]]
name = "grey"
albedo = [0.5, 0.5, 0.5]

[[objects]]
name = "tri"
material = "grey"
shape = { kind = "triangles", vertices = [[-1.0, -1.0, 0.0], [1.0, -1.0, 0.0], [0.0, 1.0, 0.0]] }
"#;

#[test]
fn probes_run_first_and_are_marked_in_the_manifest() {
    need_venv();
    let dir = tempfile::tempdir().unwrap();
    let probes = dir.path().join("probes");
    std::fs::create_dir(&probes).unwrap();
    std::fs::write(probes.join("probe_tri.toml"), PROBE).unwrap();
    std::fs::write(probes.join("notes.txt"), "not a scene").unwrap();
    // No expectations: verdicts are not what this test is about.
    let none = dir.path().join("expectations.toml");
    std::fs::write(&none, "# none\n").unwrap();
    let run = dir.path().join("run");
    let out = rendiff()
        .args(["check", "scenes/three_triangles.toml", "--only", "trace"])
        .arg("--calibration")
        .arg(&probes)
        .arg("--expectations")
        .arg(&none)
        .args(["--quiet", "-o"])
        .arg(&run)
        .output()
        .unwrap();
    assert_eq!(
        out.status.code(),
        Some(0),
        "stdout: {}\nstderr: {}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    let text = std::fs::read_to_string(run.join("manifest.json")).unwrap();
    let manifest: Value = serde_json::from_str(&text).unwrap();
    let scenes = manifest["scenes"].as_array().unwrap();
    let names: Vec<&str> = scenes
        .iter()
        .map(|s| s["scene"].as_str().unwrap())
        .collect();
    assert_eq!(names, ["probe_tri", "three_triangles"]);
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

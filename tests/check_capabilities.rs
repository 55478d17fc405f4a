//! Capabilities per buffer in `rendiff check`: a backend that cannot model a
//! scene's shading (Embree shades nothing; pyrender has no shadows) still
//! renders its depth and ID buffers there, and they are compared; only RGB is
//! left out, with the missing features as the reason.

mod common;

use common::cli::{need_venv, rendiff};
use serde_json::Value;

const SCENE: &str = "scenes/directional_shadows.toml";

#[test]
fn backends_without_the_shading_features_are_compared_on_depth_and_ids() {
    need_venv();
    let dir = tempfile::tempdir().unwrap();
    let run = dir.path().join("run");
    // No expectations: whether a comparison passes is not the question here,
    // only that it happens (pass or fail, never skipped).
    let none = dir.path().join("expectations.toml");
    std::fs::write(&none, "# none\n").unwrap();
    // No calibration probes: one scene and two backends are what this test is about.
    let out = rendiff()
        .args([
            "check",
            SCENE,
            "--only",
            "embree,pyrender",
            "--no-calibration",
            "--quiet",
            "-o",
        ])
        .arg(&run)
        .arg("--expectations")
        .arg(&none)
        .output()
        .unwrap();
    let log = format!(
        "stdout: {}\nstderr: {}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(matches!(out.status.code(), Some(0 | 1)), "{log}");

    let manifest: Value =
        serde_json::from_str(&std::fs::read_to_string(run.join("manifest.json")).unwrap()).unwrap();
    let renders = manifest["scenes"][0]["renders"].as_array().unwrap();
    let record = |backend: &str| -> &Value {
        renders
            .iter()
            .find(|r| r["backend"] == backend)
            .unwrap_or_else(|| panic!("no render record for {backend}\n{log}"))
    };
    let expected = [
        (
            "embree",
            "RGB not rendered: missing features: directional_light, lambert, shadows, two_sided",
        ),
        ("pyrender", "RGB not rendered: missing features: shadows"),
    ];
    for (backend, reason) in expected {
        let r = record(backend);
        assert_eq!(r["status"], "ok", "{backend}: {r}");
        assert_eq!(r["reason"], reason, "{backend}: {r}");
        let buffers: Vec<&str> = r["buffers"]
            .as_array()
            .unwrap()
            .iter()
            .map(|b| b.as_str().unwrap())
            .collect();
        assert!(
            buffers.contains(&"Z") && buffers.contains(&"id") && !buffers.contains(&"RGB"),
            "{backend}: {buffers:?}"
        );
    }
    // The reference still shades.
    assert!(record("raster")["buffers"]
        .as_array()
        .unwrap()
        .iter()
        .any(|b| b == "RGB"));

    let results: Value =
        serde_json::from_str(&std::fs::read_to_string(run.join("results.json")).unwrap()).unwrap();
    let entry = |backend: &str, buffer: &str| -> Option<&Value> {
        results["results"]
            .as_array()
            .unwrap()
            .iter()
            .find(|e| e["backend"] == backend && e["buffer"] == buffer)
    };
    for (backend, reason) in expected {
        for buffer in ["id", "Z"] {
            let e = entry(backend, buffer)
                .unwrap_or_else(|| panic!("no result for {backend}/{buffer}\n{log}"));
            let status = e["status"].as_str().unwrap();
            assert!(
                matches!(
                    status,
                    "pass" | "fail" | "expected_fail" | "unexpected_pass"
                ),
                "{backend}/{buffer} was not compared: {e}"
            );
        }
        if let Some(e) = entry(backend, "RGB") {
            assert_eq!(e["status"], "skipped", "{backend}/RGB: {e}");
            let missing = reason.trim_start_matches("RGB not rendered: ");
            assert!(
                e["reason"].as_str().unwrap_or("").contains(missing),
                "{backend}/RGB must name the missing features ({missing}): {e}"
            );
        }
    }
}

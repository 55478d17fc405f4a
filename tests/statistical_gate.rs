//! Detection power of the Monte Carlo gate: the core's path tracer must pass
//! against the cached Mitsuba reference at several seeds (noise is not a
//! failure), and deliberately biased variants must fail (bias is). The
//! measured false-alarm rate and each bias's verdict are written to
//! target/tmp/statistical-gate.json.

use serde_json::{json, Value};
use std::path::Path;
use std::process::Command;

const SCENE: &str = "scenes/cornell_gi.toml";

/// Runs the core alone on the GI scene and returns the verdict against the cached reference.
fn verdict(run: &Path, seed: u64, spp: u32, bias: Option<&str>) -> (String, Value) {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    assert!(
        root.join(".venv/bin/python").exists(),
        "the comparison needs the Python harness: run scripts/setup.sh"
    );
    let mut cmd = Command::new(env!("CARGO_BIN_EXE_rendiff"));
    cmd.current_dir(root)
        .args(["check", SCENE, "--only", "raster", "--quiet", "--seed"])
        .arg(seed.to_string())
        .arg("--spp")
        .arg(spp.to_string())
        .arg("-o")
        .arg(run);
    if let Some(b) = bias {
        cmd.args(["--inject-bias", b]);
    }
    let out = cmd.output().unwrap();
    let results: Value = serde_json::from_str(
        &std::fs::read_to_string(run.join("results.json")).unwrap_or_else(|e| {
            panic!(
                "no results.json ({e}); stderr: {}",
                String::from_utf8_lossy(&out.stderr)
            )
        }),
    )
    .unwrap();
    let entry = results["results"]
        .as_array()
        .unwrap()
        .iter()
        .find(|e| e["backend"] == "mitsuba_ref" && e["buffer"] == "RGB")
        .cloned()
        .expect("a comparison against the cached Mitsuba reference");
    let status = entry["status"].as_str().unwrap().to_string();
    assert_eq!(
        out.status.code(),
        Some(if status == "pass" { 0 } else { 1 }),
        "exit code must follow the verdict"
    );
    (status, entry)
}

#[test]
fn gate_accepts_noise_and_rejects_bias() {
    let tmp = tempfile::tempdir().unwrap();
    let mut seeds = Vec::new();
    let mut false_alarms = 0;
    for seed in 1..=4u64 {
        let (status, e) = verdict(&tmp.path().join(format!("seed{seed}")), seed, 64, None);
        assert!(status != "error", "seed {seed}: {}", e["reason"]);
        if status != "pass" {
            false_alarms += 1;
        }
        seeds.push(json!({"seed": seed, "status": status, "min_p": e["min_p"], "failing_pixels": e["failing_pixels"]}));
    }
    let mut biases = Vec::new();
    for (bias, spp) in [
        ("missing-cosine", 64),
        ("one-bounce-fewer", 64),
        ("light-times-pi", 64),
        ("albedo2-percent", 1024),
    ] {
        let (status, e) = verdict(&tmp.path().join(bias), 1, spp, Some(bias));
        biases.push(json!({"bias": bias, "spp": spp, "status": status,
                           "failing_pixels": e["failing_pixels"], "cluster_failures": e["cluster_failures"]}));
        assert_eq!(
            status, "fail",
            "{bias} at {spp} spp was not detected: {}",
            e["reason"]
        );
    }
    let summary = json!({
        "scene": SCENE,
        "reference": "tests/references/cornell_gi.exr",
        "seeds": seeds,
        "false_alarm_rate": false_alarms as f64 / 4.0,
        "biases": biases,
    });
    let out = Path::new(env!("CARGO_TARGET_TMPDIR")).join("statistical-gate.json");
    std::fs::write(&out, serde_json::to_vec_pretty(&summary).unwrap()).unwrap();
    eprintln!("{}", serde_json::to_string_pretty(&summary).unwrap());
    // Family-wise alpha is 0.01: 4 seeds should essentially never all pass by luck
    // of a bias, and a false alarm on more than one seed means the gate is miscalibrated.
    assert!(
        false_alarms <= 1,
        "{false_alarms} of 4 unbiased seeds failed"
    );
}

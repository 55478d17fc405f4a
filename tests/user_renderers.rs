//! A user's own renderer, declared by command in a renderers file
//! (`check --renderers`, docs/your-renderer.md), runs from a folder outside
//! the checkout, goes through calibration and the verifier like a built-in
//! backend, and a missing or malformed file is a clear error.

use std::path::Path;
use std::process::Command;

fn rendiff(dir: &Path) -> Command {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let mut c = Command::new(env!("CARGO_BIN_EXE_rendiff"));
    // The example renderer runs with `python3` from PATH and needs numpy: the venv's.
    let path = format!(
        "{}:{}",
        root.join(".venv/bin").display(),
        std::env::var("PATH").unwrap_or_default()
    );
    c.current_dir(dir)
        .env("PATH", path)
        .env_remove("RENDIFF_HOME");
    c
}

#[test]
fn a_declared_renderer_is_calibrated_and_judged_from_any_folder() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let dir = tempfile::tempdir().unwrap();
    for f in ["renderers.toml", "tiny_renderer.py"] {
        std::fs::copy(root.join("harness/examples").join(f), dir.path().join(f)).unwrap();
    }
    let scene = root.join("scenes/three_triangles.toml");
    let out = rendiff(dir.path())
        .arg("check")
        .arg(&scene)
        .args(["--renderers", "renderers.toml", "--only", "tiny", "--quiet"])
        .args(["-o", "run"])
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(0), "{stderr}");
    let results: serde_json::Value = serde_json::from_str(
        &std::fs::read_to_string(dir.path().join("run/results.json")).unwrap(),
    )
    .unwrap();
    let of = |scene: &str, buffer: &str| -> String {
        results["results"]
            .as_array()
            .unwrap()
            .iter()
            .find(|e| e["backend"] == "tiny" && e["scene"] == scene && e["buffer"] == buffer)
            .unwrap_or_else(|| panic!("no tiny/{scene}/{buffer} in results"))["status"]
            .as_str()
            .unwrap()
            .to_string()
    };
    for buffer in ["id", "Z", "N"] {
        assert_eq!(of("three_triangles", buffer), "pass", "{buffer}");
    }
    // Calibrated on both probes, like a built-in backend.
    assert_eq!(of("camera_near", "camera"), "pass");
    assert_eq!(of("camera_far", "camera"), "pass");
    // The manifest's reproduction command names the renderers file.
    let manifest = std::fs::read_to_string(dir.path().join("run/manifest.json")).unwrap();
    assert!(manifest.contains("RENDIFF_RENDERERS="), "{manifest}");
}

#[test]
fn a_missing_or_malformed_renderers_file_is_one_clear_error() {
    let dir = tempfile::tempdir().unwrap();
    let scene = Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes/three_triangles.toml");
    let out = rendiff(dir.path())
        .arg("check")
        .arg(&scene)
        .args(["--renderers", "nope.toml", "--quiet", "-o", "run"])
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_ne!(out.status.code(), Some(0));
    assert!(
        stderr.contains("nope.toml: renderers file not found"),
        "{stderr}"
    );
    assert!(
        !dir.path().join("run").exists(),
        "no run folder for a refused command"
    );

    std::fs::write(
        dir.path().join("bad.toml"),
        "[[renderer]]\nname = \"x\"\ncommand = [\"./x\", \"{nope}\"]\n",
    )
    .unwrap();
    let out = rendiff(dir.path())
        .arg("check")
        .arg(&scene)
        .args([
            "--renderers",
            "bad.toml",
            "--no-calibration",
            "--quiet",
            "-o",
            "run",
        ])
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_ne!(out.status.code(), Some(0), "{stderr}");
    // Refused before anything runs, in one line naming the file and the entry.
    assert!(
        stderr.contains("bad.toml: [[renderer]] #1 (x): missing key 'features'"),
        "{stderr}"
    );
    assert!(
        !dir.path().join("run").exists(),
        "no run folder for a refused file"
    );
}

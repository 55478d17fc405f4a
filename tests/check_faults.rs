//! Fault injection for `rendiff check`: an external renderer that hangs, one
//! that crashes, and one that claims success without writing its buffers are
//! each reported as an error for that renderer only; the core and the other
//! renderers still run, and the run still produces results.json.

use std::path::Path;
use std::process::Command;

const FAKE_PYTHON: &str = r#"#!/bin/bash
# Stands in for the venv's python: fakes three broken backends, delegates the rest.
if [ "$3" = "info" ]; then
  b='"version":"0","features":["depth","ids"],"buffers":["Z","id"],"available":true,"reason":null'
  echo "{\"backends\":[{\"name\":\"hang\",$b},{\"name\":\"crash\",$b},{\"name\":\"liar\",$b},{\"name\":\"partial\",$b}]}"
  exit 0
fi
if [ "$3" = "render" ]; then
  out=""; prev=""
  for a in "$@"; do [ "$prev" = "--out" ] && out="$a"; prev="$a"; done
  case "$5" in
    hang) exec sleep 600 ;;
    crash) kill -SEGV $$ ;;
    liar) echo '{"status":"ok"}'; exit 0 ;;
    partial) printf 'half an EXR' > "$out"; echo "renderer died mid-write" >&2; exit 1 ;;
  esac
fi
exec "$REAL_PYTHON" "$@"
"#;

#[test]
fn broken_renderers_are_reported_per_renderer_and_do_not_stop_the_run() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let real = root.join(".venv/bin/python");
    assert!(
        real.exists(),
        "{} is missing: run scripts/setup.sh (the comparison needs the Python harness)",
        real.display()
    );
    let dir = tempfile::tempdir().unwrap();
    let fake = dir.path().join("python");
    std::fs::write(&fake, FAKE_PYTHON).unwrap();
    Command::new("chmod").arg("+x").arg(&fake).status().unwrap();
    let run = dir.path().join("run");
    let started = std::time::Instant::now();
    let out = Command::new(env!("CARGO_BIN_EXE_rendiff"))
        .current_dir(root)
        .env("RENDIFF_PYTHON", &fake)
        .env("REAL_PYTHON", &real)
        // No calibration probes: the fakes would hang, crash and lie on each probe
        // too (a hang costs the 1 s timeout per scene); one scene shows the faults.
        .args([
            "check",
            "scenes/three_triangles.toml",
            "--no-calibration",
            "--timeout",
            "1",
            "--quiet",
            "-o",
        ])
        .arg(&run)
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(
        out.status.code(),
        Some(1),
        "stdout: {stdout}\nstderr: {stderr}"
    );
    assert!(
        started.elapsed().as_secs() < 60,
        "the hanging renderer was not killed in time"
    );
    let results: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(run.join("results.json")).unwrap()).unwrap();
    let status = |backend: &str, buffer: &str| -> (String, String) {
        let e = results["results"]
            .as_array()
            .unwrap()
            .iter()
            .find(|e| e["backend"] == backend && e["buffer"] == buffer)
            .unwrap_or_else(|| panic!("no result for {backend}/{buffer}"));
        (
            e["status"].as_str().unwrap().to_string(),
            e["reason"].as_str().unwrap_or("").to_string(),
        )
    };
    let (s, why) = status("hang", "id");
    assert_eq!(s, "error");
    assert!(why.contains("timed out"), "{why}");
    // The limit it names is the one applied, with the slack explained.
    assert!(why.contains("--timeout"), "{why}");
    let (s, why) = status("crash", "Z");
    assert_eq!(s, "error");
    assert!(why.contains("killed by signal 11 (SIGSEGV)"), "{why}");
    let (s, why) = status("liar", "id");
    assert_eq!(s, "error");
    assert!(why.contains("wrote no buffer file"), "{why}");
    let (s, why) = status("partial", "id");
    assert_eq!(s, "error");
    assert!(why.contains("died mid-write"), "{why}");
    assert!(
        !run.join("scenes/three_triangles/partial.exr").exists(),
        "a partial output was kept"
    );
    for healthy in ["trace", "embree", "embree_robust"] {
        assert_eq!(status(healthy, "id").0, "pass", "{healthy} must still run");
    }
}

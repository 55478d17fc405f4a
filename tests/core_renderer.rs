//! `render --renderer core` and `check`'s reference: the loop the cost model
//! (`rendiff::loop_cost`) picks renders, says which, and gives the forced
//! loops' buffers.

mod common;

use common::cli::*;

/// The pick is printed and its EXR is the raster's and the tracer's, buffer
/// for buffer (`rendiff diff` exits 0 only on identical buffers).
#[test]
fn render_core_prints_its_pick_and_writes_both_loops_buffers() {
    let dir = tempfile::tempdir().unwrap();
    for scene in ["scenes/three_triangles.toml", "scenes/icosphere.toml"] {
        let core = dir.path().join("core.exr");
        let out = output_within(
            rendiff()
                .args([
                    "render",
                    scene,
                    "--renderer",
                    "core",
                    "--quiet",
                    "--no-preview",
                    "-o",
                ])
                .arg(&core),
            120,
        );
        let stdout = String::from_utf8_lossy(&out.stdout);
        assert!(
            out.status.success(),
            "{stdout}{}",
            String::from_utf8_lossy(&out.stderr)
        );
        let picked = stdout
            .lines()
            .find_map(|l| l.strip_prefix("core: "))
            .and_then(|l| l.split_whitespace().next())
            .unwrap_or_else(|| panic!("no pick printed: {stdout}"))
            .to_string();
        assert!(["raster", "trace"].contains(&picked.as_str()), "{stdout}");
        for forced in ["raster", "trace"] {
            let exr = dir.path().join(format!("{forced}.exr"));
            let o = output_within(
                rendiff()
                    .args([
                        "render",
                        scene,
                        "--renderer",
                        forced,
                        "--quiet",
                        "--no-preview",
                        "-o",
                    ])
                    .arg(&exr),
                120,
            );
            assert!(o.status.success());
            let d = output_within(rendiff().arg("diff").arg(&core).arg(&exr), 120);
            assert!(
                d.status.success(),
                "{scene}: core ({picked}) differs from {forced}: {}",
                String::from_utf8_lossy(&d.stdout)
            );
        }
    }
}

/// Without the tracer in the run, `check`'s reference is rendered by the
/// model's pick, recorded in its info; with the tracer, the reference is the
/// raster (so the run compares the loops) and no pick is recorded.
#[test]
fn check_records_the_reference_loop_pick_only_without_the_tracer() {
    need_venv();
    let dir = tempfile::tempdir().unwrap();
    for (only, picked) in [("embree", true), ("trace", false)] {
        let run = dir.path().join(only);
        let out = output_within(
            rendiff()
                .args([
                    "check",
                    "scenes/three_triangles.toml",
                    "--no-calibration",
                    "--quiet",
                ])
                .args(["--only", only, "-o"])
                .arg(&run),
            300,
        );
        let text = std::fs::read_to_string(run.join("manifest.json"))
            .unwrap_or_else(|e| panic!("{e}: {}", String::from_utf8_lossy(&out.stdout)));
        let manifest: serde_json::Value = serde_json::from_str(&text).unwrap();
        let reference = manifest["scenes"][0]["renders"]
            .as_array()
            .unwrap()
            .iter()
            .find(|r| r["backend"] == "raster")
            .unwrap()
            .clone();
        assert_eq!(reference["status"], "ok", "{reference}");
        let choice = &reference["info"]["loop_choice"];
        if picked {
            assert!(
                ["raster", "trace"].contains(&choice["pick"].as_str().unwrap_or("")),
                "{reference}"
            );
        } else {
            assert!(choice.is_null(), "{reference}");
        }
    }
}
